"""The landing agent process (``python -m agents.landing SCENARIO --id UAV``; started by ``swarm launch`` for
a landing scenario): one UAV's on-board software, the agent step of :mod:`swarm.step.landing`, over Zenoh.

It subscribes its UAV's ``imu``, ``uwb``, ``gnss`` and ``vision`` and the world's events, declares its
liveliness, and runs tick by tick in lockstep: once tick ``k``'s samples are all in (the IMU every tick,
a range, a fix and a camera frame on their ticks, as the scenario's rates say, so nothing is waited for
that will not come), it fuses them, decides, and publishes its ``command`` (rotor speeds [rad/s], the
landing mode), its ``estimate`` (the position, velocity and attitude block of the IMU-driven filter's
covariance), its ``guidance`` (mode, distance to its pad) and each mode switch as an ``event``. At the
world's ``run_end`` it publishes a ``summary`` event (its half of the run's outcome) and stays up until
stopped. A message that does not decode is dropped and counted; a sample of a tick already flown is
ignored.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading

import numpy as np

from swarm.transport.process import print_ready, process_main

_LOG = logging.getLogger("agents.landing")
DESCRIPTION = "One landing UAV's on-board software: IMU-driven filter, landing guidance, quadrotor control."


def add_arguments(p: argparse.ArgumentParser) -> None:
    from swarm.transport.process import add_process_arguments

    add_process_arguments(p)
    p.add_argument("--id", required=True, help="the UAV this agent flies (a [[fleet]] id, or 'uav')")


def run(args: argparse.Namespace, stop: threading.Event) -> int:
    from swarm.config import parse_override
    from swarm.errors import ConfigError
    from swarm.landing_scenario import load_landing
    from swarm.step.landing import LandingAgent, LandingInputs, Rates
    from swarm.transport.keys import Keys
    from swarm.transport.messages import (
        Command,
        DropCounter,
        Estimate,
        Event,
        Gnss,
        Guidance,
        Imu,
        MessageError,
        Uwb,
        Vision,
        encode,
    )
    from swarm.transport.process import declare_reliable
    from swarm.transport.session import declare_liveliness, open_session, subscribe_decoded, zenoh_args_from

    sc = load_landing(args.scenario, dict(parse_override(o) for o in args.overrides))
    uavs = {u.id: u for u in sc.uavs()}
    if args.id not in uavs:
        raise ConfigError(f"--id: no UAV {args.id!r} in the scenario; it has {', '.join(uavs)}")
    policy = args.policy or sc.policy
    _warm_up(sc, args.seed, uavs[args.id].index, policy)
    agent = LandingAgent(sc, args.seed, uavs[args.id].index, policy)
    rates = Rates.of(sc)
    keys = Keys(args.namespace)
    dt = sc.dt_s
    cond = threading.Condition()
    inbox: dict[str, dict[int, object]] = {"imu": {}, "uwb": {}, "gnss": {}, "vision": {}}
    state = {"k": 1, "ended": False}
    drops = DropCounter()

    def on_sample(kind: str):
        def handler(_key: str, msg) -> None:
            with cond:
                if msg.tick >= state["k"]:
                    inbox[kind][msg.tick] = msg
                    cond.notify_all()

        return handler

    def on_world_event(_key: str, msg: Event) -> None:
        if msg.kind == "run_end":
            with cond:
                state["ended"] = True
                cond.notify_all()

    def complete(k: int) -> bool:
        return (
            k in inbox["imu"]
            and (not rates.uwb_tick(sc, k) or k in inbox["uwb"])
            and (not rates.gnss_tick(sc, k) or k in inbox["gnss"])
            and (not rates.camera_tick(k) or k in inbox["vision"])
        )

    def inputs(k: int) -> LandingInputs:
        imu = inbox["imu"].pop(k)
        inp = LandingInputs(k, k * dt, imu.gyro_body, imu.acc_body)
        u = inbox["uwb"].pop(k, None)
        if u is not None and u.range_m is not None:
            inp.uwb = (u.anchor_id, u.range_m)
        g = inbox["gnss"].pop(k, None)
        if g is not None:
            inp.gnss = g.p_nav
        v = inbox["vision"].pop(k, None)
        if v is not None:
            mids = np.array(v.marker_ids[::4], dtype=np.int64) // 4
            inp.camera = (mids, v.data.reshape(-1, 4, 2))
        return inp

    with open_session(zenoh_args_from(args)) as session:
        pub = {kind: declare_reliable(session, getattr(keys, kind)(args.id))
               for kind in ("command", "estimate", "guidance", "event")}  # fmt: skip
        for kind, cls in (("imu", Imu), ("uwb", Uwb), ("gnss", Gnss), ("vision", Vision)):
            subscribe_decoded(session, getattr(keys, kind)(args.id), cls, on_sample(kind), drops)
        subscribe_decoded(session, keys.world_event(), Event, on_world_event, drops)
        _token = declare_liveliness(session, keys, "agent", args.id)
        print_ready("agent", args.id)
        n_modes = 0
        while not stop.is_set():
            with cond:
                k = state["k"]
                while not (complete(k) or state["ended"] or stop.is_set()):
                    cond.wait(0.05)
                if stop.is_set():
                    break
                if not complete(k):  # the run ended
                    break
                inp = inputs(k)
                state["k"] = k + 1
            if inp.acc is None:
                drops.drop(keys.imu(args.id), "an IMU sample without acc_body cannot drive this filter")
                inp.acc = np.full(3, np.nan)  # refused by the filter's predict, counted there
            cmd = agent.tick(inp)
            t = k * dt
            pub["command"].put(encode(Command(k, t, cmd.u, str(cmd.mode))))
            _publish_estimate(pub["estimate"], agent, k, t, Estimate, MessageError, encode)
            dist = float(np.linalg.norm(agent.p_est[:2] - agent.setup.pad[:2]))
            pub["guidance"].put(encode(Guidance(k, t, str(cmd.mode), dist, reason=_reason(agent))))
            for m in agent.guidance.modes[n_modes:]:
                data = {
                    "from": m["from"],
                    "to": m["mode"],
                    "reason": m["reason"],
                    "p_est_nav": m["p_est_nav"],
                }
                pub["event"].put(encode(Event(m["t_s"], "mode", data)))
            n_modes = len(agent.guidance.modes)
        if state["ended"]:
            out = agent.outcome()
            out["decisions"] = len(out["decisions"])
            pub["event"].put(encode(Event(agent.landed_t or 0.0, "summary", out)))
            _LOG.info("run ended: %s", out["final_mode"])
            stop.wait()
        _ = _token
    return 0


def _warm_up(sc, seed: int, index: int, policy: str) -> None:
    """Compile (or load from numba's cache) every kernel a tick may call, on a scratch agent, before the
    agent says it is up: a first compilation inside the run would outlast the world's step timeout."""
    from swarm.step.landing import R_BODY_CAM, LandingAgent, LandingWorld, Rates

    world, agent = LandingWorld(sc, seed), LandingAgent(sc, seed, index, policy)
    uid = sc.uavs()[index].id
    for k in range(1, max(vars(Rates.of(sc)).values()) + 1):
        inp = world.step(k)[uid]
        world.hold(uid, agent.tick(inp))
    f, t = agent.filt, agent.filt.t
    f.update_position(t, f.p_nav[0], np.eye(3))
    f.update_pad(t, agent.setup.pad, np.array([0.0, 0.0, 5.0]), np.eye(3) * 1e-4, agent.cam_pos, R_BODY_CAM)


def _reason(agent) -> str:
    modes = agent.guidance.modes
    return str(modes[-1]["reason"])[:1024] if modes else ""


def _publish_estimate(pub, agent, k, t, Estimate, MessageError, encode) -> None:
    f = agent.filt
    P = f.P[0, 0:9, 0:9]
    d2 = getattr(f, "last_d2", None)  # the latest range's (none before the first)
    d = float(np.sqrt(d2[0])) if d2 is not None and np.isfinite(d2[0]) else 0.0
    counts = {
        f"range_{w}": int(f.counts[:, i].sum()) for i, w in enumerate(("accepted", "rejected", "refused"))
    }
    sigma = float(np.sqrt(np.max(np.diag(P)[0:3])))
    args = [k, t, f.p_nav[0], f.v_nav[0], f.q_nav_body[0], P, sigma, d, 0.0, counts]
    try:
        msg = Estimate(*args)
    except MessageError:  # a covariance off symmetry by rounding only: send its symmetric part
        args[5] = 0.5 * (P + P.T)
        msg = Estimate(*args)
    pub.put(encode(msg))


def main(argv: list[str] | None = None) -> int:
    return process_main("agents.landing", DESCRIPTION, add_arguments, run, argv)


if __name__ == "__main__":
    sys.exit(main())
