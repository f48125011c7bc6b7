"""The landing agent process (``python -m agents.landing SCENARIO --id UAV``; started by ``swarm launch`` for
a landing scenario): one UAV's on-board software, the agent step of :mod:`swarm.step.landing`, over Zenoh.

It runs in the agent host (:class:`agents.host.AgentHost`: one Zenoh session and one stepping thread for
the UAVs of ``--id a,b,...``), as a docking agent does; :class:`LandingAgentProcess` is the host's face of
one UAV. It subscribes its UAV's ``imu``, ``uwb`` (``tdoa`` on a TDoA radio), ``gnss``, ``rangefinder`` and
``vision`` (and, for a moving pad, the robot's shared ``estimate`` on ``agent/<platform.id>/estimate``,
waited for on its share ticks) and the world's events, declares its liveliness, and runs tick by tick in
lockstep (:class:`LandingTicks`): once tick ``k``'s samples are all in (the IMU every tick, a range, a fix,
a distance and a camera frame on their ticks, as the scenario's rates say, so nothing is waited for that
will not come), it fuses them, decides, and publishes its ``command`` (rotor speeds [rad/s], the landing
mode), its ``estimate`` (the position, velocity and attitude block of the IMU-driven filter's covariance),
its ``guidance`` (mode, distance to its pad) and each mode switch as an ``event``. At
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
from typing import NamedTuple

from agents.cli import hosted_ids
from agents.host import AgentHost
from swarm.config import parse_override
from swarm.errors import ConfigError
from swarm.landing_scenario import load_landing
from swarm.step.landing import LandingAgent, LandingInputs, LandingWorld, Rates
from swarm.transport import checkpoint, wire
from swarm.transport.keys import Keys
from swarm.transport.messages import (
    DropCounter,
    Estimate,
    Gnss,
    Imu,
    MessageError,
    Rangefinder,
    Tdoa,
    Uwb,
    Vision,
)
from swarm.transport.process import (
    add_checkpoint_arguments,
    add_process_arguments,
    declare_reliable,
    exit_process,
    print_ready,
    process_main,
)
from swarm.transport.session import declare_liveliness, open_session, subscribe_decoded, zenoh_args_from

_LOG = logging.getLogger("agents.landing")
DESCRIPTION = "One landing UAV's on-board software: IMU-driven filter, landing guidance, quadrotor control."


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_process_arguments(p)
    p.add_argument(
        "--id",
        required=True,
        help="the UAV this agent flies (a [[fleet]] id, or 'uav'); several, comma-separated, make this "
        "process an agent host: their agents on one Zenoh session, stepped by one thread, keys and "
        "liveliness per UAV",
    )
    add_checkpoint_arguments(
        p,
        "each UAV's agent state to DIR/agent-<id>.ckpt after every tick, so that a restart with --resume "
        "goes on warm",
        "restart warm from the checkpoints in --checkpoint-dir (a UAV without one starts from the beginning)",
    )


def run(args: argparse.Namespace, stop: threading.Event) -> int:
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
    except checkpoint.CheckpointError as exc:
        print(f"agents.landing: error: {exc}; not resuming", file=sys.stderr, flush=True)
        return checkpoint.EXIT_BAD_CHECKPOINT
    warm_up(sc, args.seed, uavs[ids[0]].index, policy)
    keys = Keys(args.namespace)
    with open_session(zenoh_args_from(args)) as session:
        # the UAVs' tick assemblers share a condition and a set of those with news: one thread steps all
        cond, ready = threading.Condition(), set()
        procs = [LandingAgentProcess(session, keys, sc, args.seed, uavs[u], policy, args.clock, resumed[u],
                                     cond, ready, len(ids)) for u in ids]  # fmt: skip
        try:
            AgentHost(procs, session, keys, stop).run()
        except Exception as exc:  # logged with the UAV; its supervisor restarts every hosted UAV
            _LOG.error("agent host of %s failed: %s", ",".join(ids), exc)
            stop.set()
            return 1
    return 0


class Resume:
    """One UAV's agent checkpoint (module docstring): the file, the state read from it by ``--resume``
    (None: not resuming, or nothing written yet), and what it must share with this run."""

    def __init__(self, args: argparse.Namespace, sc, uav, policy: str) -> None:
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
        if self.path is None:
            return None
        return checkpoint.CheckpointFile(self.path, None if self.state is None else self.state["checkpoint"])


SAMPLES = ("imu", "uwb", "tdoa", "gnss", "rangefinder", "vision", "pad")
"""What a landing tick is made of (:class:`swarm.step.landing.LandingInputs`; ``pad``: a moving pad's
robot's shared estimate)."""


class Tick(NamedTuple):
    """A complete tick as the host takes it (its ``tick``, as a docking agent's
    :class:`~swarm.transport.lockstep.TickInputs`), and what the agent step takes."""

    tick: int
    inputs: LandingInputs


class LandingTicks:
    """One UAV's samples collected into complete ticks, for :class:`agents.host.AgentHost` (the landing
    agent's :class:`~swarm.transport.lockstep.AgentTickAssembler`): tick ``k`` is complete once its IMU
    sample and each sample its ticks' rates say is due (:class:`swarm.step.landing.Rates`) are in, so nothing
    is waited for that will not come; a sample of a tick already taken is ignored. ``cond`` and ``ready``
    are the host's, shared by its UAVs."""

    def __init__(self, sc, k: int, free: bool, cond: threading.Condition, ready: set) -> None:
        self.sc, self.rates, self.k, self.free = sc, Rates.of(sc), k, free
        self.cond, self.ready = cond, ready
        self.inbox: dict[str, dict[int, object]] = {kind: {} for kind in SAMPLES}

    def add(self, kind: str, tick: int, value) -> bool:
        """Keep ``value``, tick ``tick``'s sample of ``kind``; True if kept (a tick not taken yet)."""
        with self.cond:
            if tick < self.k:
                return False
            self.inbox[kind][tick] = value
            if self.complete(self.k):
                self.ready.add(self)
                self.cond.notify_all()
            return True

    def complete(self, k: int) -> bool:
        sc, r, box = self.sc, self.rates, self.inbox
        return (
            k in box["imu"]
            and (not r.uwb_tick(sc, k) or k in box["uwb"])
            and (not r.tdoa_tick(sc, k) or k in box["tdoa"])
            and (not r.gnss_tick(sc, k) or k in box["gnss"])
            and (not r.rangefinder_tick(sc, k) or k in box["rangefinder"])
            and (not r.camera_tick(k) or k in box["vision"])
            and (not r.share_tick(sc, k) or k in box["pad"])
        )

    def _take(self, k: int):
        box = self.inbox
        gyro, acc = box["imu"].pop(k)
        inp = LandingInputs(k, k * self.sc.dt_s, gyro, acc)
        inp.uwb, inp.gnss = box["uwb"].pop(k, None), box["gnss"].pop(k, None)
        inp.rangefinder, inp.camera = box["rangefinder"].pop(k, None), box["vision"].pop(k, None)
        inp.pad, inp.tdoa = box["pad"].pop(k, None), box["tdoa"].pop(k, None)
        return inp

    def poll_round(self, _grace_s=None) -> tuple[list, object, bool]:
        """The host's look at this UAV (``cond`` held by the host): ``(stale, inputs, more)``. ``inputs``: the
        next tick if it is complete (else None). Behind a free-running world, the ticks before the newest
        complete one would be flown before their commands came: they are ``stale``, only fused, and the
        newest is decided on. ``more``: the tick after is complete already."""
        if not self.complete(self.k):
            return [], None, False
        stale = []
        while self.free and self.complete(self.k + 1):
            stale.append(self._take(self.k))
            self.k += 1
        inp = Tick(self.k, self._take(self.k))
        self.k += 1
        return stale, inp, self.complete(self.k)


class LandingAgentProcess:
    """One UAV's agent over an open Zenoh session, stepped by :class:`agents.host.AgentHost` (module
    docstring): the interface of :class:`agents.process.AgentProcess` that the host uses."""

    batched = False  # its own keys only: no clock or batches from the world, no CommandBatch to it
    chaser, rejoin, wake_at_control = False, False, False

    def __init__(self, session, keys, sc, seed: int, uav, policy: str, clock, resume: Resume,
                 cond: threading.Condition, ready: set, hosted: int) -> None:  # fmt: skip
        self.session, self.keys, self.sc, self.id, self.clock = session, keys, sc, uav.id, clock
        self.agent = LandingAgent(sc, seed, uav.index, policy)
        self.drops = DropCounter()
        self.direct = hosted > 1  # several UAVs: their callbacks on Zenoh's own threads, as docking's
        self.n_anchors = len(sc.uwb.anchors_m) if sc.uwb.enabled else 0
        self.on_news = None  # set by a host of this UAV alone: called after a kept sample
        self.stopping = None  # set by the host
        self.resume, self.ckpt = resume, resume.file()
        self.ended = False
        self.n_modes = self.skipped = 0
        # the last two commands, (tick, key, payload): sent again on restarts
        self.sent: deque = deque(maxlen=2)
        self._rest: list = []  # the tick's messages after its command, for flush()
        k = 1
        if resume.state is not None:  # warm from the checkpoint: the tick after it next
            st = resume.state
            self.agent.restore({"state": st["agent"], "records": st["samples"]})
            k, self.n_modes, self.skipped = st["k"], st["n_modes"], st["skipped"]
            self.sent.extend(st["sent"])
            _LOG.warning("%s: resumed from its checkpoint of tick %d", self.id, k - 1)
        self.assembler = LandingTicks(sc, k, not clock.lockstep, cond, ready)

    # ------------------------------------------------------------------------------ Zenoh side

    def _usable(self, kind: str, msg):
        """What the agent step takes of a message (None for nothing), or MessageError: a message of the
        protocol that this agent cannot use is dropped and counted like one that does not decode."""
        if kind == "vision":
            return wire.camera_frame(msg)
        if kind == "uwb":
            return wire.range_input(msg, self.n_anchors)
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

    def _on_sample(self, kind: str):
        def handler(key: str, msg) -> None:
            try:
                value = self._usable(kind, msg)
            except MessageError as exc:
                self.drops.drop(key, str(exc))
                return
            if self.assembler.add(kind, msg.tick, value) and self.on_news is not None:
                self.on_news()

        return handler

    def _on_world_event(self, _key: str, msg) -> None:
        """``run_end``: the run is over; ``world_resumed`` at tick ``j``: the commands of tick ``j`` or later
        sent again (the world that had them is gone)."""
        if self.stopping.hear(msg.kind):
            return
        if msg.kind == "run_end":
            with self.assembler.cond:
                self.ended = True
        elif msg.kind == "world_resumed":
            j = msg.data.get("tick")
            with self.assembler.cond:
                again = [c for c in self.sent if isinstance(j, int) and c[0] >= j]
            for tick, key, payload in again:
                try:
                    self.pub[key].put(payload)
                except Exception as exc:
                    if not self.stopping.quiet(exc):  # (its session closing while it stops: no error)
                        raise
                    return
                _LOG.warning(
                    "%s: world resumed at tick %s: its command of tick %d sent again", self.id, j, tick
                )

    def _on_alive(self, _role: str, _pid: str, _alive: bool) -> None:
        pass  # (a landing agent waits for no peer: the world sends every sample)

    # ------------------------------------------------------------------------------ driven by AgentHost

    def open(self, shared: bool = False) -> None:
        """Declare the publishers and subscribe this UAV's samples (the host subscribes the world's events
        for all of its UAVs)."""
        k, sc, uid = self.keys, self.sc, self.id
        self.pub = {getattr(k, kind)(uid): declare_reliable(self.session, getattr(k, kind)(uid))
                    for kind in ("command", "estimate", "guidance", "event")}  # fmt: skip
        subs = [("imu", Imu), ("uwb", Uwb), ("gnss", Gnss), ("rangefinder", Rangefinder), ("vision", Vision)]
        if sc.uwb.mode != "twr":  # a TDoA radio's differences, a Tdoa every UWB tick
            subs.append(("tdoa", Tdoa))
        for kind, cls in subs:
            subscribe_decoded(self.session, getattr(k, kind)(uid), cls, self._on_sample(kind), self.drops,
                              direct=self.direct)  # fmt: skip
        if sc.platform.enabled and sc.platform.share_estimate:  # the moving pad's robot's shared estimate
            subscribe_decoded(self.session, k.estimate(sc.platform.id), Estimate, self._on_sample("pad"),
                              self.drops, direct=self.direct)  # fmt: skip

    def announce(self) -> None:
        """Declare this UAV's liveliness token, print its ready line, and send its last commands again (a
        resumed agent: the world may be waiting for one, the agent was killed meanwhile)."""
        self._token = declare_liveliness(self.session, self.keys, "agent", self.id)
        print_ready("agent", self.id)
        for _tick, key, payload in self.sent:
            self.pub[key].put(payload)

    def ticking(self) -> bool:
        return True

    def commands_at(self, _k: int) -> bool:
        return True  # a rotor command every tick

    def fuse_late(self, stale: list) -> None:
        """Free-running and behind: the ticks before the newest complete one, fused without a decision."""
        for inp in stale:
            self.agent.fuse(inp)
        self.skipped += len(stale)

    def process(self, inp: Tick) -> None:
        """Tick ``inp.tick``: fuse, decide, send the command (its estimate, guidance and mode events go out
        with :meth:`flush`)."""
        cmd = self.agent.tick(inp.inputs)
        out, self.n_modes = wire.landing_agent_tick(self.keys, self.id, self.agent, cmd, self.n_modes)
        with self.assembler.cond:
            self.sent.append((inp.tick, *out[0]))  # the command, first
        self.pub[out[0][0]].put(out[0][1])
        self._rest, self._k = out[1:], inp.tick

    def flush(self) -> None:
        """The tick's estimate, guidance and events, then its checkpoint: after the host's round sent its
        commands, while the world collects the others' (off the tick's critical path). An agent killed
        before this write comes back at that tick, which the world sends it again."""
        rest, self._rest = self._rest, []
        for key, payload in rest:
            self.pub[key].put(payload)
        if self.ckpt is not None:
            snap = self.agent.snapshot()  # (its records go as the file's samples: each checksummed once)
            self.ckpt.write({"run": self.resume.run_id, "k": self._k + 1, "agent": snap["state"],
                             "n_modes": self.n_modes, "skipped": self.skipped, "sent": list(self.sent)},
                            snap["records"])  # fmt: skip

    def done(self, _now: float) -> bool:
        """The world's ``run_end`` came and no tick is complete."""
        with self.assembler.cond:
            return self.ended and not self.assembler.complete(self.assembler.k)

    def finish(self) -> bool:
        """At the run's end: the ``summary`` event (its half of the outcome)."""
        key, payload = wire.landing_summary(self.keys, self.id, self.agent)
        self.pub[key].put(payload)
        _LOG.info("%s: run ended: %s (%d ticks fused without a decision, behind the world)", self.id,
                  self.agent.outcome()["final_mode"], self.skipped)  # fmt: skip
        if self.ckpt is not None:
            self.ckpt.close()
        return True


def warm_up(sc, seed: int, index: int, policy: str) -> None:
    """Compile (or load from numba's cache) every kernel a tick may call, on a scratch world and agent, before
    the agent says it is up: a first compilation inside the run would outlast the world's step timeout. One
    tick of each sensor's rate compiles them all (numba compiles a kernel whole, every branch)."""
    world, agent = LandingWorld(sc, seed), LandingAgent(sc, seed, index, policy)
    uid = sc.uavs()[index].id
    for k in range(1, max(vars(Rates.of(sc)).values()) + 1):
        inp = world.step(k)[uid]
        world.hold(uid, agent.tick(inp))


def main(argv: list[str] | None = None) -> int:
    return process_main("agents.landing", DESCRIPTION, add_arguments, run, argv)


if __name__ == "__main__":
    exit_process(main())
