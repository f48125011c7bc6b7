"""The landing agent process (``python -m agents.landing SCENARIO --id UAV``; started by ``swarm launch`` for
a landing scenario): one UAV's on-board software, the agent step of :mod:`swarm.step.landing`, over Zenoh.

It subscribes its UAV's ``imu``, ``uwb`` (``tdoa`` on a TDoA radio), ``gnss``, ``rangefinder`` and ``vision``
(and, for a moving pad,
the robot's shared ``estimate`` on ``agent/<platform.id>/estimate``, waited for on its share ticks) and the
world's events,
declares its liveliness, and runs tick by tick in lockstep: once tick ``k``'s samples are all in (the IMU
every tick, a range, a fix, a distance and a camera frame on their ticks, as the scenario's rates say, so
nothing is waited for that will not come), it fuses them, decides, and publishes its ``command`` (rotor speeds
[rad/s], the landing mode), its ``estimate`` (the position, velocity and attitude block of the IMU-driven
filter's covariance), its ``guidance`` (mode, distance to its pad) and each mode switch as an ``event``. At
the world's ``run_end`` it publishes a ``summary`` event (its half of the run's outcome) and stays up until
stopped. Behind a free-running world (``--clock realtime`` or ``scaled:N``), a tick whose successor is already
complete is only fused (its command would reach the world after it flew that tick): the agent decides and
publishes on the newest tick, as a flight controller's estimator runs at the sensors' rate and its controller
on the newest estimate. A message that does not decode is dropped and counted; a sample of a tick already
flown is ignored.

Restarts (``swarm launch`` does them). A UAV cannot hang in the sky while a restarted agent re-initialises
from its sensors, as a docking agent does: with ``--checkpoint-dir`` each UAV's agent writes its complete
state (filter, guidance and its records, controller: :meth:`~swarm.step.landing.LandingAgent.snapshot`) to
``agent-<id>.ckpt`` there after each tick's command has gone out (while the world collects the others': off
the tick's critical path), as a flight computer keeps its state in memory that survives a reboot.
``--resume`` restarts warm from it (none written yet: from the start), sends its last two commands again
(the world drops those of ticks it has stepped) and goes on with the tick after the checkpoint's, whose
samples (and the current tick's) the world sends again when the agent's liveliness token comes back. In
lockstep the run is then the uninterrupted run, bit for bit. On the world's ``world_resumed`` at tick ``j``
an agent sends again its commands of tick ``j`` or later (the new world never had them).
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from collections import deque
from functools import partial

from swarm.transport.process import print_ready, process_main

_LOG = logging.getLogger("agents.landing")
DESCRIPTION = "One landing UAV's on-board software: IMU-driven filter, landing guidance, quadrotor control."


def add_arguments(p: argparse.ArgumentParser) -> None:
    from swarm.transport.process import add_checkpoint_arguments, add_process_arguments

    add_process_arguments(p)
    p.add_argument(
        "--id",
        required=True,
        help="the UAV this agent flies (a [[fleet]] id, or 'uav'); several, comma-separated, make this "
        "process an agent host: their agents on one Zenoh session, each on its own thread, keys and "
        "liveliness per UAV",
    )
    add_checkpoint_arguments(
        p,
        "each UAV's agent state to DIR/agent-<id>.ckpt after every tick, so that a restart with --resume "
        "goes on warm",
        "restart warm from the checkpoints in --checkpoint-dir (a UAV without one starts from the beginning)",
    )


def run(args: argparse.Namespace, stop: threading.Event) -> int:
    from agents.cli import hosted_ids, run_host
    from swarm.config import parse_override
    from swarm.errors import ConfigError
    from swarm.landing_scenario import load_landing
    from swarm.transport.checkpoint import EXIT_BAD_CHECKPOINT, CheckpointError
    from swarm.transport.keys import Keys
    from swarm.transport.session import open_session, zenoh_args_from

    sc = load_landing(args.scenario, dict(parse_override(o) for o in args.overrides))
    uavs = {u.id: u for u in sc.uavs()}
    ids = hosted_ids(args.id, "UAV")
    for uid in ids:
        if uid not in uavs:
            raise ConfigError(f"--id: no UAV {uid!r} in the scenario; it has {', '.join(uavs)}")
    if args.resume and args.checkpoint_dir is None:
        raise ConfigError("--resume needs --checkpoint-dir (the directory of the checkpoints to resume)")
    policy = args.policy or sc.policy
    try:  # read before joining the swarm: a bad checkpoint never shows up as an agent
        resumed = {u: Resume(args, sc, uavs[u], policy) for u in ids}
    except CheckpointError as exc:
        print(f"agents.landing: error: {exc}; not resuming", file=sys.stderr, flush=True)
        return EXIT_BAD_CHECKPOINT
    warm_up(sc, args.seed, uavs[ids[0]].index, policy)
    keys = Keys(args.namespace)
    with open_session(zenoh_args_from(args)) as session:
        free = not args.clock.lockstep
        if len(ids) == 1:
            _fly(session, keys, sc, args.seed, uavs[ids[0]], policy, stop, free, resumed[ids[0]])
            return 0
        # an agent host: one session, one thread per UAV (agents.cli.run_host)
        flights = {u: partial(_fly, session, keys, sc, args.seed, uavs[u], policy, stop, free, resumed[u])
                   for u in ids}  # fmt: skip
        return run_host(flights, stop)


class Resume:
    """One UAV's agent checkpoint (module docstring): the file, the state read from it by ``--resume``
    (None: not resuming, or nothing written yet), and what it must share with this run."""

    def __init__(self, args: argparse.Namespace, sc, uav, policy: str) -> None:
        from swarm.transport import checkpoint

        self.run_id = {"scenario": sc.name, "fingerprint": checkpoint.fingerprint(sc), "seed": args.seed,
                       "policy": policy, "uav": uav.id, "clock": str(args.clock)}  # fmt: skip
        self.path = None
        self.state: dict | None = None
        if args.checkpoint_dir is None:
            return
        self.path = checkpoint.checkpoint_path(args.checkpoint_dir, f"agent-{uav.id}.ckpt")
        if args.resume and self.path.exists():
            st = checkpoint.load(self.path)
            checkpoint.check_run(f"checkpoint {self.path}", st.get("run"), self.run_id, "agent")
            self.state = st

    def file(self):
        """The file to write this UAV's checkpoints to (after the one resumed from), or None."""
        from swarm.transport import checkpoint

        if self.path is None:
            return None
        return checkpoint.CheckpointFile(self.path, None if self.state is None else self.state["checkpoint"])


def _fly(session, keys, sc, seed: int, uav, policy: str, stop: threading.Event, free: bool = False,
         resume: Resume | None = None) -> None:  # fmt: skip
    """One UAV's agent on ``session`` until the run ends (then its summary, and it waits for ``stop``).
    ``free``: the world is free-running (module docstring): a tick with a later one already complete is
    fused, not decided on. ``resume``: its checkpoint (module docstring)."""
    from swarm.step.landing import LandingAgent, LandingInputs, Rates
    from swarm.transport import wire
    from swarm.transport.messages import (
        DropCounter,
        Estimate,
        Event,
        Gnss,
        Imu,
        MessageError,
        Rangefinder,
        Tdoa,
        Uwb,
        Vision,
    )
    from swarm.transport.process import declare_reliable
    from swarm.transport.session import declare_liveliness, subscribe_decoded
    from swarm.transport.stopping import Stopping, wait_for_stop

    uid = uav.id
    stopping = Stopping(stop)  # (the launcher's stopping event, a signal: swarm.transport.stopping)
    agent = LandingAgent(sc, seed, uav.index, policy)
    rates = Rates.of(sc)
    dt = sc.dt_s
    cond = threading.Condition()
    inbox: dict[str, dict[int, object]] = {"imu": {}, "uwb": {}, "gnss": {}, "rangefinder": {}, "vision": {},
                                           "pad": {}, "tdoa": {}}  # fmt: skip
    state = {"k": 1, "ended": False}
    sent: deque = deque(maxlen=2)  # the last two commands sent, (tick, key, payload): sent again on a restart
    drops = DropCounter()
    n_anchors = len(sc.uwb.anchors_m) if sc.uwb.enabled else 0

    def usable(kind: str, msg):
        """What the agent step takes of a message (None for nothing), or MessageError: a message of the
        protocol that this agent cannot use is dropped and counted like one that does not decode."""
        if kind == "vision":
            return wire.camera_frame(msg)
        if kind == "uwb":
            return wire.range_input(msg, n_anchors)
        if kind == "tdoa":
            return wire.tdoa_input(msg)
        if kind == "gnss":
            return msg.p_nav
        if kind == "rangefinder":
            return msg.range_m
        if kind == "pad":
            return wire.pad_input(msg)
        if msg.acc_body is None:
            raise MessageError("acc_body: an IMU sample without the specific force cannot drive this filter")
        return msg.gyro_body, msg.acc_body

    def on_sample(kind: str):
        def handler(key: str, msg) -> None:
            try:
                value = usable(kind, msg)
            except MessageError as exc:
                drops.drop(key, str(exc))
                return
            with cond:
                if msg.tick >= state["k"]:
                    inbox[kind][msg.tick] = value
                    cond.notify_all()

        return handler

    def on_world_event(_key: str, msg: Event) -> None:
        if stopping.hear(msg.kind):
            return
        if msg.kind == "run_end":
            with cond:
                state["ended"] = True
                cond.notify_all()
        elif msg.kind == "world_resumed":
            j = msg.data.get("tick")
            with cond:
                again = [c for c in sent if isinstance(j, int) and c[0] >= j]
            for tick, key, payload in again:  # the world that had them is gone
                try:
                    pub[key].put(payload)
                except Exception as exc:
                    if not stopping.quiet(exc):  # (its session closing while it stops: no error)
                        raise
                    return
                _LOG.warning("%s: world resumed at tick %s: its command of tick %d sent again", uid, j, tick)

    def complete(k: int) -> bool:
        return (
            k in inbox["imu"]
            and (not rates.uwb_tick(sc, k) or k in inbox["uwb"])
            and (not rates.tdoa_tick(sc, k) or k in inbox["tdoa"])
            and (not rates.gnss_tick(sc, k) or k in inbox["gnss"])
            and (not rates.rangefinder_tick(sc, k) or k in inbox["rangefinder"])
            and (not rates.camera_tick(k) or k in inbox["vision"])
            and (not rates.share_tick(sc, k) or k in inbox["pad"])
        )

    def inputs(k: int) -> LandingInputs:
        gyro, acc = inbox["imu"].pop(k)
        inp = LandingInputs(k, k * dt, gyro, acc)
        inp.uwb = inbox["uwb"].pop(k, None)
        inp.gnss = inbox["gnss"].pop(k, None)
        inp.rangefinder = inbox["rangefinder"].pop(k, None)
        inp.camera = inbox["vision"].pop(k, None)
        inp.pad = inbox["pad"].pop(k, None)
        inp.tdoa = inbox["tdoa"].pop(k, None)
        return inp

    pub = {getattr(keys, kind)(uid): declare_reliable(session, getattr(keys, kind)(uid))
           for kind in ("command", "estimate", "guidance", "event")}  # fmt: skip
    for kind, cls in (
        ("imu", Imu),
        ("uwb", Uwb),
        ("gnss", Gnss),
        ("rangefinder", Rangefinder),
        ("vision", Vision),
    ):
        subscribe_decoded(session, getattr(keys, kind)(uid), cls, on_sample(kind), drops)
    if sc.uwb.mode != "twr":  # a TDoA radio's differences, a Tdoa every UWB tick
        subscribe_decoded(session, keys.tdoa(uid), Tdoa, on_sample("tdoa"), drops)
    if sc.platform.enabled and sc.platform.share_estimate:  # the moving pad's robot's shared estimate
        subscribe_decoded(session, keys.estimate(sc.platform.id), Estimate, on_sample("pad"), drops)
    n_modes = skipped = 0
    ckpt = None if resume is None else resume.file()
    if resume is not None and resume.state is not None:  # warm from the checkpoint: the tick after it next
        st = resume.state
        agent.restore({"state": st["agent"], "records": st["samples"]})
        state["k"], n_modes, skipped = st["k"], st["n_modes"], st["skipped"]
        sent.extend(st["sent"])
        _LOG.warning("%s: resumed from its checkpoint of tick %d", uid, st["k"] - 1)
    subscribe_decoded(session, keys.world_event(), Event, on_world_event, drops)
    token = declare_liveliness(session, keys, "agent", uid)
    print_ready("agent", uid)
    for _tick, key, payload in sent:  # (the world may be waiting for one: the agent was killed meanwhile)
        pub[key].put(payload)
    while not stop.is_set():
        with cond:
            k = state["k"]
            while not (complete(k) or state["ended"] or stop.is_set()):
                cond.wait(0.05)
            if stop.is_set() or not complete(k):  # stopped, or the run ended
                break
            # free-running and behind: the ticks before the newest complete one would be flown before their
            # commands came; they are fused, and the newest decided on
            stale = []
            while free and complete(k + 1):
                stale.append(inputs(k))
                k += 1
            inp = inputs(k)
            state["k"] = k + 1
        for old in stale:
            agent.fuse(old)
        skipped += len(stale)
        cmd = agent.tick(inp)
        out, n_modes = wire.landing_agent_tick(keys, uid, agent, cmd, n_modes)
        with cond:
            sent.append((k, *out[0]))  # the command, first
        for key, payload in out:
            pub[key].put(payload)
        if ckpt is not None:  # after the command went out, while the world collects the others (off the
            # tick's critical path): an agent killed before this write comes back at tick k, which the world
            # sends it again
            snap = agent.snapshot()  # (its records go as the file's samples: each checksummed once)
            ckpt.write({"run": resume.run_id, "k": k + 1, "agent": snap["state"], "n_modes": n_modes,
                        "skipped": skipped, "sent": list(sent)}, snap["records"])  # fmt: skip
    if state["ended"]:
        key, payload = wire.landing_summary(keys, uid, agent)
        pub[key].put(payload)
        _LOG.info("%s: run ended: %s (%d ticks fused without a decision, behind the world)", uid,
                  agent.outcome()["final_mode"], skipped)  # fmt: skip
        wait_for_stop(stop)  # (in steps: a signal's handler must get to run, swarm.transport.stopping)
    if ckpt is not None:
        ckpt.close()
    token.undeclare()


def warm_up(sc, seed: int, index: int, policy: str) -> None:
    """Compile (or load from numba's cache) every kernel a tick may call, on a scratch world and agent, before
    the agent says it is up: a first compilation inside the run would outlast the world's step timeout. One
    tick of each sensor's rate compiles them all (numba compiles a kernel whole, every branch)."""
    from swarm.step.landing import LandingAgent, LandingWorld, Rates

    world, agent = LandingWorld(sc, seed), LandingAgent(sc, seed, index, policy)
    uid = sc.uavs()[index].id
    for k in range(1, max(vars(Rates.of(sc)).values()) + 1):
        inp = world.step(k)[uid]
        world.hold(uid, agent.tick(inp))


def main(argv: list[str] | None = None) -> int:
    return process_main("agents.landing", DESCRIPTION, add_arguments, run, argv)


if __name__ == "__main__":
    sys.exit(main())
