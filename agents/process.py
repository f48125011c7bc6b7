"""The agent process: one vehicle's estimator, switcher, guidance and control over Zenoh.

A thin adapter around the agent step, :class:`swarm.step.agent.VehicleAgent`, the object the in-process
simulation steps.
It subscribes only to its own sensors (``imu``, ``uwb``, ``vision`` for a chaser, and in lockstep their
``bundle`` of several ticks), its target's
``estimate`` (a chaser), ``world/clock`` and liveliness; it publishes ``estimate`` (every tick; a target's
on the ticks before its chasers read it), ``guidance`` and ``command`` (every control tick: the world holds
the command in between) and ``event`` (mode transitions; a ``summary`` when the run ends).

Lockstep (``--clock lockstep``): ticks come from :class:`swarm.transport.lockstep.AgentTickAssembler`,
complete and in order, and each goes through :meth:`~swarm.step.agent.VehicleAgent.tick` as in the
in-process run: the target's estimate of tick ``k - 1``, then gyro (+ AHRS), range, vision of tick ``k``;
guidance, the kind's controller and ``command(k)`` on control ticks; then ``estimate(k)`` and the control
tick's ``guidance(k)`` (:meth:`AgentProcess.flush`, once the host's round has sent its commands). Tick 0 (no
sensor yet) starts when the world announces the run.
Realtime or scaled: tick ``k`` is processed as soon as ``imu(k)`` is in, with whatever else of it has come,
and ``estimate(k)`` goes out before guidance and control run (an autopilot's estimator publishes before its
controllers run): the sensor-to-estimate latency includes neither a control tick's work nor the range's
route through the mothership. A range or frame that comes after its tick is fused before the next one
(:meth:`AgentProcess.fuse_late`, "late fusion", ``agent.late_fusion_s``), as PX4's EKF2 fuses its slower
sensors when they come. A free-running vehicle alone in its process takes its ranges, frames and target
estimates from queues when its imu comes (:class:`~swarm.transport.session.QueuedSubscriber`), not on a
Python thread woken for each: the same inputs for the same ticks, without a wake per message.

A restarted world (``world/event`` ``world_resumed`` at tick ``k``) publishes tick ``k``'s samples again:
the assembler drops those the agent already has (counted ``stale`` or ``duplicates``), and an agent whose
last command is of tick ``k`` (a control tick) sends it again, since the new world never received it.
While the world is gone (its liveliness token went) the agent says so and waits: no sample, no tick. Once
the swarm is stopping (its own SIGINT/SIGTERM, or the launcher's ``stopping`` event on ``world/event``), a
peer's going is logged as a stop, not a loss, and a publication its closing session no longer takes is no
error (:mod:`swarm.transport.stopping`).

A restarted agent (``--rejoin``) joins the run in progress: it publishes zero-thrust HOLD commands while it
re-initialises from its own sensors (the AHRS attitude, and its position by least squares on one range to
each anchor, :func:`swarm.core.ranging.position_from_ranges`; on a TDoA radio, ``uwb.mode`` tdoa2/tdoa3, by
multilateration on its last distance differences, :func:`swarm.core.ranging.position_from_tdoa`), then
flies again from that estimate (:meth:`AgentProcess._collect_init`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import numpy as np

from swarm.core import rotations as rot
from swarm.core.ranging import position_from_ranges, position_from_tdoa
from swarm.errors import ConfigError
from swarm.scenario import Scenario
from swarm.step.agent import AgentInputs, TargetEstimate, VehicleAgent
from swarm.step.initial import initial_estimate
from swarm.step.radio import exchange_ticks
from swarm.step.world import initial_truth
from swarm.transport.keys import Keys
from swarm.transport.lockstep import AgentTickAssembler, TickInputs
from swarm.transport.messages import (
    Bundle,
    Clock,
    DropCounter,
    Estimate,
    Event,
    Imu,
    Tdoa,
    Uwb,
    Vision,
    bundle_messages,
    encode,
    estimate_and_payload,
)
from swarm.transport.process import ClockSpec, declare_reliable, print_ready
from swarm.transport.session import (
    QueuedSubscriber,
    declare_liveliness,
    imu_stamp_attachment,
    subscribe_decoded,
    watch_liveliness,
)
from swarm.transport.stopping import Stopping, process_name
from swarm.transport.wire import (
    command_payload,
    estimate_args,
    estimate_payload,
    estimate_read,
    estimate_reads,
    filter_counts,
    guidance_payload,
    mode_events,
    target_reads,
)

_LOG = logging.getLogger("swarm.agent")

_STAMPS_KEPT = 64
"""The imu publication stamps an agent keeps for its estimates' attachments at most (ticks)."""

END_DRAIN_S = 5.0
"""After the world's stopped clock at tick ``k``, a lockstep agent processes the ticks up to ``k`` (their
samples may come after the stopped clock, on other subscribers' threads, or all at once from a recording),
and gives up on them after this long without a complete tick [s]."""


_SENSOR_TYPES = ("Imu", "Uwb", "Tdoa", "Vision")
"""The entries of a bundle an agent takes: its own sensors' samples."""


def _target(e: Estimate) -> TargetEstimate:
    """A target's published estimate as the chaser's agent step takes it."""
    return TargetEstimate(e.t_s, e.p_nav, e.q_nav_body, e.cov[:3, :3].copy())


class AgentProcess:
    """One vehicle's on-board software over an open Zenoh session (module docstring)."""

    batched = True  # its host takes the world's clock and batches, and may send CommandBatch messages

    def __init__(
        self,
        scenario,
        vehicle_id: str,
        seed: int,
        policy: str,
        session,
        keys: Keys,
        clock: ClockSpec,
        stop: threading.Event,
        *,
        rejoin: bool = False,
        hosted: int = 1,
        cond: threading.Condition | None = None,
        ready: set | None = None,
    ) -> None:
        sc = scenario
        self.hosted = hosted  # vehicles in this process (an agent host): its CPU time is shared by them
        if vehicle_id not in sc.vehicles:
            raise ConfigError(
                f"--id must be a vehicle of the scenario, one of {sorted(sc.vehicles)}, got {vehicle_id!r}"
            )
        self.sc, self.id, self.seed, self.policy = sc, vehicle_id, seed, policy
        self.session, self.keys, self.clock, self.stop = session, keys, clock, stop
        # the swarm stops: a peer's going is no loss (an agent host gives its vehicles one, agents.host)
        self.stopping = Stopping(stop)
        self.rejoin = rejoin
        spec = sc.vehicles[vehicle_id]
        self.chaser = spec.role == "chaser"
        self.target_id = spec.target
        self.dt = sc.dt_s
        self.control_every = sc.control_every(vehicle_id)
        self.control_phase = sc.control_phase(vehicle_id)
        self.vision_every = sc.every(sc.camera.rate_hz) if self.chaser else None
        self.drops = DropCounter()
        self.assembler = AgentTickAssembler(
            vehicle_id, self.chaser, self.target_id, sc.every(sc.uwb.rate_hz), self.vision_every,
            start=None if rejoin else 0, wait_for_target=clock.lockstep, cond=cond,
            ready=set() if ready is None else ready,
            target_reads=target_reads(sc, vehicle_id) if self.chaser else None,
            late_ticks=None if clock.lockstep else round(sc.agent.late_fusion_s / sc.dt_s),
            # a TDMA channel: ranges on the tag's slots only; a TDoA tag transmits nothing: every slot's tdoa
            uwb_slots=exchange_ticks(sc, vehicle_id) if sc.uwb.mode == "twr" else None,
        )  # fmt: skip
        self.tdoa = sc.uwb.mode != "twr"  # uwb.mode tdoa2/tdoa3: a Tdoa on agent/<id>/tdoa, no Uwb
        self.estimate_reads = estimate_reads(sc, vehicle_id)  # the ticks whose estimate goes out
        if rejoin:
            # who is alive is not known yet: wait for nobody until the liveliness history says (a mothership
            # or target lost before this process subscribed would otherwise be waited for forever)
            self.assembler.set_uwb_live(False)
            self.assembler.set_target_live(False)
        self.agent: VehicleAgent | None = None
        if not rejoin:
            # the dispersed truth this run starts from, as the world builds it: the same initial estimate
            x0 = initial_truth(sc, seed, vehicle_id)
            p0, v0, q0, cov0 = initial_estimate(sc, list(sc.vehicles).index(vehicle_id), x0, seed)
            self.agent = VehicleAgent(sc, vehicle_id, p0, v0, q0, cov0, policy)
        self._u = np.zeros(sc.kind(vehicle_id).U_N)
        self._force: np.ndarray | None = None
        self._torque: np.ndarray | None = None
        self._mode = "HOLD" if self.chaser else "STATION"
        self._started = threading.Event()
        self._ended = threading.Event()
        self._end_tick = 0
        self._init_ranges: dict[int, float] = {}
        self._init_rows = np.empty((0, 3))  # a rejoining TDoA tag's last differences (_collect_init)
        self._init_q: np.ndarray | None = None
        self._last_decision_t: float | None = None
        self.ticks = 0
        self._last_tick: int | None = None
        self._cpu0: float | None = None
        self._waited_since = time.monotonic()  # the last tick processed (or the start): for the end's drain
        self._warned_at = 0.0
        self._command_lock = threading.Lock()  # a round sends commands, a Zenoh thread re-sends one
        self._last_command: tuple[int, bytes] | None = None  # (tick, payload) of the last command sent
        self.resent = 0  # commands sent again for a resumed world
        self._estimate_due: int | None = None  # the tick whose estimate flush() publishes
        self._guidance_due: tuple | None = None  # (tick, command) whose guidance flush() publishes
        self._estimate_listened = False  # a subscriber matches this vehicle's estimates (_declare)
        self._guidance_listened = False  # ... and its guidance (the launcher its chasers', a viewer any)
        # set by an agent host (agents.host.AgentHost) when the target and its chaser are both in it
        self.local_chasers: list[AgentProcess] = []  # the chasers in this host that fly to this vehicle
        self.target_local = False  # this chaser's target is in this host: no subscriber to its estimates
        self.command_sink: list[tuple[str, bytes]] | None = None  # a host of several: its round's commands
        # set by a host of this vehicle alone: called after a kept message, on the subscriber's thread
        self.on_news: Callable[[], None] | None = None
        self._queued: list[QueuedSubscriber] = []  # free-running, a host of one: drained at each imu (open)
        # free-running, a host of one, agent.wake_at_control: the imu queued too, and everything drained once
        # per control period by the host's pacer (agents.host.AgentHost._pace)
        self.wake_at_control = sc.agent.wake_at_control and hosted == 1 and not clock.lockstep
        self.newest_imu: int | None = None  # the newest imu tick taken from its queue (wake_at_control)
        # each imu's publication stamp [ns] (a world with Zenoh timestamping on), until its tick's estimate
        # carries it as an attachment (docs/protocol.md, "Estimate"): any subscriber can then tell the
        # sensor-to-estimate latency without taking the imu itself (swarm bench's probe)
        self._imu_published: dict[int, int] = {}

    # ------------------------------------------------------------------------------ Zenoh side

    def _on_sensor(self, key: str, msg, published_ns: int | None = None) -> None:
        if isinstance(msg, Imu):
            if published_ns is not None:
                self._stamp_imu(msg.tick, published_ns)
            if self._queued:
                self.drain_inputs()  # what came since the last imu: fused in the tick this imu makes ready
        if self.assembler.add(msg, self.id) and self.on_news is not None:
            self.on_news()

    def _on_bundle(self, key: str, msg: Bundle, published_ns: int | None = None) -> None:
        """A bundle's samples (docs/protocol.md, "Bundles"), each as its own key would have brought it (its
        ``imu`` stamped with the bundle's publication)."""
        for sample in bundle_messages(msg, key, self.drops, _SENSOR_TYPES):
            self._on_sensor(key, sample, published_ns)

    def _on_queued(self, key: str, msg, published_ns: int | None = None) -> None:
        """A range, frame or target estimate taken from its queue at an imu (:meth:`open`); with
        ``wake_at_control``, also the imu, taken at the host's wake."""
        if isinstance(msg, Imu):
            if self.newest_imu is None or msg.tick > self.newest_imu:
                self.newest_imu = msg.tick
            if published_ns is not None:
                self._stamp_imu(msg.tick, published_ns)
        self.assembler.add(msg, self.target_id if isinstance(msg, Estimate) else self.id)

    def drain_inputs(self) -> None:
        """Take everything the queues hold into the tick assembler (with ``wake_at_control``, the imu first),
        for the tick or the round that follows."""
        for sub in self._queued:
            sub.drain()

    def next_control_tick(self) -> int:
        """The first of this vehicle's control ticks after the newest imu taken (from tick 1 before any)."""
        k = 1 if self.newest_imu is None else self.newest_imu + 1
        return k + (self.control_phase - k) % self.control_every

    def _on_target(self, key: str, msg: Estimate) -> None:
        if self.assembler.add(msg, self.target_id) and self.on_news is not None:
            self.on_news()

    def _on_clock(self, _key: str, msg: Clock) -> None:
        if msg.state in ("running", "paused"):
            if not self._started.is_set():
                self._waited_since = time.monotonic()  # a stalled tick is timed from the run's start
                self._started.set()
                self.assembler.wake()
        elif msg.state == "stopped" and self._started.is_set():
            self._end_tick = msg.tick
            self._ended.set()
            self.assembler.wake()

    def _on_world_event(self, _key: str, msg: Event) -> None:
        """``world_resumed`` at tick ``k``: send ``command(k)`` again if it is the last one sent (the world
        that got it is gone); a command not computed yet goes out as usual once tick ``k`` is processed.
        The launcher's ``stopping``: the swarm is stopping (:mod:`swarm.transport.stopping`)."""
        if self.stopping.hear(msg.kind) or msg.kind != "world_resumed":
            return
        k = msg.data.get("tick")
        with self._command_lock:
            last = self._last_command
            if last is not None and last[0] == k:
                try:
                    self.pub_command.put(last[1])
                except Exception as exc:
                    if not self.stopping.quiet(exc):  # (its session closing while it stops: no error)
                        raise
                    return
                self.resent += 1
        _LOG.warning(
            "%s: world resumed at tick %s%s", self.id, k,
            f"; command({k}) sent again" if last is not None and last[0] == k else "",
        )  # fmt: skip

    def _on_alive(self, role: str, pid: str, alive: bool) -> None:
        """A peer this vehicle depends on joins or goes: the world, the mothership, its target. Gone, it is
        lost (a warning), or stopped if the swarm is stopping (:mod:`swarm.transport.stopping`)."""
        name = f"{self.id}: {process_name(role, pid)}"
        if role == "world":
            if alive:
                _LOG.info("%s is alive", name)
            else:
                self.stopping.gone(_LOG, name, "%s lost; no samples (no ticks) until it is back", name)
            return
        if role == "mothership":
            if not alive:
                self.stopping.gone(_LOG, name, "%s lost; flying without ranges until it is back", name)
            if self.clock.lockstep:
                self.assembler.set_uwb_live(alive)
            return
        if role == "agent" and pid == self.target_id:
            if not alive:
                name = f"{self.id}: target {pid}"
                self.stopping.gone(_LOG, name, "%s lost; holding its last estimate", name)
            if self.clock.lockstep:
                self.assembler.set_target_live(alive)

    # ------------------------------------------------------------------------------ publishing

    def _await_world_subscriber(self, timeout_s: float = 5.0) -> None:
        """A rejoining agent declares its liveliness token (which makes a lockstep world hand it the current
        tick) only once its command publisher knows the world's subscriber: Zenoh drops a publication
        that no known subscriber matches, and a session a few milliseconds old may not know the router's
        subscribers yet (a command lost there cost the run a 5 s step timeout)."""
        deadline = time.monotonic() + timeout_s
        while not self.pub_command.matching_status.matching:
            if self.stop.is_set() or time.monotonic() > deadline:
                _LOG.warning(
                    "%s: no subscriber of its commands after %.0f s; joining anyway", self.id, timeout_s
                )
                return
            time.sleep(0.005)

    def _declare(self) -> None:
        k = self.keys
        ex = self.hosted == 1  # an agent host's ticks are a burst: batched (docs/protocol.md, "QoS")
        self.pub_estimate = declare_reliable(self.session, k.estimate(self.id), ex)
        # whether a subscriber matches the estimate, kept by Zenoh's matching listener: asking the publisher
        # every tick (matching_status) took 6 % of a lockstep host of 16 (it waits on Zenoh's routing
        # tables, which its receiving threads hold); the listener first, so no change is missed
        self._estimate_matching = self.pub_estimate.declare_matching_listener(self._on_estimate_matching)
        self._estimate_listened = bool(self.pub_estimate.matching_status.matching)
        self.pub_command = declare_reliable(self.session, k.command(self.id), ex)
        self.pub_guidance = declare_reliable(self.session, k.guidance(self.id), ex)
        # guidance likewise: the launcher reads its chasers' only, so a headless swarm's targets send none
        self._guidance_matching = self.pub_guidance.declare_matching_listener(self._on_guidance_matching)
        self._guidance_listened = bool(self.pub_guidance.matching_status.matching)
        self.pub_event = declare_reliable(self.session, k.event(self.id))

    def _on_estimate_matching(self, status) -> None:
        self._estimate_listened = bool(status.matching)

    def _on_guidance_matching(self, status) -> None:
        self._guidance_listened = bool(status.matching)

    def _counts(self) -> dict[str, int]:
        return filter_counts(self.agent)

    def _stamp_imu(self, k: int, published_ns: int) -> None:
        """Keep ``imu(k)``'s publication stamp for ``estimate(k)`` (on a subscriber's thread), the newest
        ``_STAMPS_KEPT`` at most (a vehicle that publishes no estimate for a while: re-initialising)."""
        stamps = self._imu_published
        stamps[k] = published_ns
        if len(stamps) > _STAMPS_KEPT:
            for tick in [t for t in list(stamps) if t <= k - _STAMPS_KEPT]:
                stamps.pop(tick, None)

    def _imu_stamp(self, k: int) -> bytes | None:
        """The attachment of ``estimate(k)``: ``imu(k)``'s publication stamp, if it had one (those of ticks up
        to ``k`` forgotten either way)."""
        stamps = self._imu_published
        if not stamps:
            return None
        ns = stamps.pop(k, None)
        if stamps:  # (a later tick's, or older ones no estimate took)
            for tick in [t for t in list(stamps) if t < k]:
                stamps.pop(tick, None)
        return None if ns is None else imu_stamp_attachment(ns)

    def _put_estimate(self, payload: bytes, stamp: bytes | None) -> None:
        if stamp is None:
            self.pub_estimate.put(payload)
        else:
            self.pub_estimate.put(payload, attachment=stamp)

    def _publish_estimate(self, k: int) -> None:
        # a target's estimate goes out on the ticks before those its chasers read it (docs/protocol.md,
        # "Rates"): a fifth of them with a 20 Hz camera and 10 Hz control; any other vehicle's, every tick
        stamp = self._imu_stamp(k)
        if not estimate_read(self.estimate_reads, k):
            return
        # an estimate no subscriber matches is not encoded (Zenoh would drop it unsent): in a headless swarm
        # nobody but the chaser listens, and a chaser in this host takes the message itself, not the bytes
        # back through Zenoh to decode them; a viewer or a recorder that subscribes gets every estimate this
        # vehicle sends from then on (its subscription reaches this publisher within a millisecond or so)
        listened = self._estimate_listened
        if not self.local_chasers:
            if listened:
                self._put_estimate(estimate_payload(self.agent, k), stamp)
            return
        msg, payload = estimate_and_payload(*estimate_args(self.agent, k), payload=listened)
        if payload is not None:
            self._put_estimate(payload, stamp)
        for chaser in self.local_chasers:
            chaser.assembler.add(msg, self.id)

    def commands_at(self, k: int) -> bool:
        """Whether tick ``k`` is one of this vehicle's control ticks, on which it sends a command."""
        return (k - self.control_phase) % self.control_every == 0

    def _publish_command(self, k: int) -> None:
        """``command(k)`` on the vehicle's control ticks only: the world holds it until the next one, and
        a lockstep world waits for it on those ticks only (docs/protocol.md, "Rates")."""
        if not self.commands_at(k):
            return
        payload = command_payload(k, self.dt, self._u, self._mode, self._force, self._torque)
        with self._command_lock:
            if self.command_sink is None:
                self.pub_command.put(payload)
            else:  # a host of several: the round's commands leave in one message (AgentHost)
                self.command_sink.append((self.id, payload))
            self._last_command = (k, payload)

    def _commanded(self, k: int, cmd) -> None:
        """A control tick's command: held and published from now on; its events out, its guidance due
        (:meth:`flush`)."""
        self._u, self._force, self._torque = cmd.u, cmd.force_body_n, cmd.torque_body_nm
        self._mode = self.agent.mode.value
        for payload in mode_events(cmd):
            self.pub_event.put(payload)
        self._guidance_due = (k, cmd)

    def _publish_guidance(self) -> None:
        """The guidance of the last control tick, after the round's commands: building and sending it took
        a chaser ~45 us at the median and up to ~2 ms (the put waits for the GIL while the host's Zenoh
        threads hand out a batch), which put a free-running host of 64 vehicles' commands after the
        world's next tick (BENCHMARKS.md). Not encoded for no one (Zenoh would drop it unsent): "Rates"."""
        due, self._guidance_due = self._guidance_due, None
        if due is not None and self._guidance_listened:
            k, cmd = due  # in the mode it was decided in (_mode changes with the next command only)
            payload = guidance_payload(self.sc, self.policy, self.chaser, self.agent, k, self._mode, cmd)
            self.pub_guidance.put(payload)

    # ------------------------------------------------------------------------------ re-initialisation

    def _collect_init(self, imu: Imu | None, uwb: Uwb | Tdoa | None) -> bool:
        """Gather the AHRS attitude and ranges (one per anchor), or on a TDoA radio (``uwb.mode``
        tdoa2/tdoa3) distance differences (``agent.reinit_tdoa_rows`` of them, naming every anchor: a
        multilateration, :func:`swarm.core.ranging.position_from_tdoa`); build the agent from the fix,
        its covariance the fix's own (an anchor layout that leaves a direction nearly unseen gives a large
        one, and the chaser holds on it)."""
        if imu is not None and imu.q_ahrs_nav_body is not None:
            self._init_q = imu.q_ahrs_nav_body
        sc = self.sc
        n_anchors = len(sc.anchors_m)
        if self.tdoa:
            if isinstance(uwb, Tdoa) and len(uwb.anchor_a):
                # a row naming an unknown anchor, or one twice, is skipped (as the filter skips it)
                r = uwb.rows()
                a, b = r[:, 0], r[:, 1]
                ok = (a != b) & (a >= 0) & (a < n_anchors) & (b >= 0) & (b < n_anchors) & np.isfinite(r[:, 2])
                self._init_rows = np.vstack([self._init_rows, r[ok]])[-sc.agent.reinit_tdoa_rows :]
            heard = np.union1d(self._init_rows[:, 0], self._init_rows[:, 1])
            if (
                self._init_q is None
                or len(self._init_rows) < sc.agent.reinit_tdoa_rows
                or len(heard) < n_anchors
            ):
                return False
        elif uwb is not None and uwb.range_m is not None and uwb.anchor_id < n_anchors:
            self._init_ranges[uwb.anchor_id] = uwb.range_m
        if self._init_q is None or (not self.tdoa and len(self._init_ranges) < n_anchors):
            return False
        lever_body = np.asarray(sc.kind(self.id).mounts.tag_lever_arm_body_m, dtype=float)
        lever_nav = rot.quat_rotate(self._init_q, lever_body)
        anchors = np.asarray(sc.anchors_m, dtype=float)
        guess = sc.vehicles[self.id].position_m
        if self.tdoa:
            p0, JtJ_inv = position_from_tdoa(anchors, self._init_rows, lever_nav, guess)
            sigma = sc.estimator.sigma_tdoa_m
        else:
            p0, JtJ_inv = position_from_ranges(anchors, self._init_ranges, lever_nav, guess)
            sigma = sc.estimator.sigma_range_m
        sig = sc.initial.sigmas
        var_pos = max(float(np.max(np.diag(JtJ_inv))) * sigma**2, sig[0] ** 2)
        var_vel = max(sig[3] ** 2, sc.guidance.approach_speed_m_s**2)  # moving at up to the approach speed
        var_att = max(np.radians(sc.ahrs.sigma_deg) ** 2, sig[6] ** 2)
        cov0 = np.array([var_pos] * 3 + [var_vel] * 3 + [var_att] * 3)
        self.agent = VehicleAgent(sc, self.id, p0, np.zeros(3), self._init_q, cov0, self.policy)
        _LOG.info("%s re-initialised from its sensors at p = %s m", self.id, np.round(p0, 3).tolist())
        self.pub_event.put(
            encode(Event(0.0 if imu is None else imu.t_s, "restarted", {"p_nav": p0.tolist()}))
        )
        return True

    # ------------------------------------------------------------------------------ the loops

    def _process(self, inp: TickInputs) -> None:
        if self._cpu0 is None:
            self._cpu0 = time.process_time()  # the run's CPU time starts at its first tick
        k = inp.tick
        t = k * self.dt
        if self.agent is None:
            self._collect_init(inp.imu, inp.uwb)
            if self.agent is None:
                self._publish_command(k)  # zero thrust, HOLD (on control ticks) while re-initialising
                return
            if self.chaser and inp.target_estimate is not None:
                self._set_target(inp.target_estimate)
            self._publish_command(k)
            self._estimate_due = k
            return
        # a free-running agent that skipped ticks propagates over the whole gap
        gap = k - self._last_tick if self._last_tick is not None and k > self._last_tick else 1
        self._last_tick = k
        imu, uwb, vis, te = inp.imu, inp.uwb, inp.vision, inp.target_estimate
        # free-running: the estimate leaves as soon as the filter has the tick's samples, before guidance and
        # control (as an autopilot's estimator publishes before its controllers run); lockstep: after the
        # command, which the world waits for (the host's commands of a round, then their estimates)
        early = not self.clock.lockstep
        cmd = self.agent.tick(AgentInputs(
            k, t, gap * self.dt,
            None if imu is None else imu.gyro_body, None if imu is None else imu.q_ahrs_nav_body,
            None if not isinstance(uwb, Uwb) or uwb.range_m is None else (uwb.anchor_id, uwb.range_m),
            None if vis is None or not vis.seen else (vis.kind, vis.data),
            None if te is None or not self.chaser else _target(te), control=not early,
            tdoa=uwb.rows() if isinstance(uwb, Tdoa) and uwb.anchor_a else None,
        ))  # fmt: skip
        if early:
            self._publish_estimate(k)
            cmd = self.agent.decide(k, t)
        if cmd is not None:
            self._commanded(k, cmd)
        self._publish_command(k)
        if not early:
            self._estimate_due = k  # published by flush(), after the commands of the host's round
        self.ticks += 1

    def fuse_late(self, late) -> None:
        """Free-running: the ranges and frames that came after their tick's estimate went out
        (:meth:`~swarm.transport.lockstep.AgentTickAssembler.take_late`), fused now, before the next tick
        (a re-initialising agent takes the ranges it lacks)."""
        for m in late:
            if isinstance(m, Uwb):
                if self.agent is None:
                    self._collect_init(None, m)
                elif m.range_m is not None:
                    self.agent.on_uwb(m.anchor_id, m.range_m)
            elif isinstance(m, Tdoa):
                if self.agent is None:
                    self._collect_init(None, m)
                elif m.anchor_a:
                    self.agent.on_tdoa(m.rows())
            elif self.agent is not None and self.chaser and m.seen:
                self.agent.on_vision(m.tick * self.dt, m.kind, m.data)

    def _done_through(self, k: int) -> bool:
        return self._last_tick is not None and self._last_tick >= k

    def _set_target(self, e: Estimate) -> None:
        self.agent.set_target_estimate(_target(e))

    # ------------------------------------------------------------------------------ driven by AgentHost

    def open(self, shared: bool = True) -> None:
        """Warm the kernels up, declare the publishers, subscribe this vehicle's inputs; ``shared`` also
        subscribes the world's clock and events and liveliness (an agent host subscribes those once for
        all of its vehicles and hands each message to every one)."""
        k = self.keys
        warm_up(self.sc, self.seed, self.id, self.policy)  # not inside the first lockstep ticks
        self._declare()
        # an agent host's sensor callbacks run on Zenoh's own receiving threads: 16 vehicles would otherwise
        # be ~60 Python threads (one per subscriber) taking the GIL in turn (BENCHMARKS.md, "The swarm at
        # scale"); a single vehicle gains nothing measurable from it, and keeps Zenoh's default
        d = self.hosted > 1
        # a free-running vehicle alone in its process takes its ranges, frames and target estimates from
        # queues at each imu, not on a Python thread woken for each (QueuedSubscriber): its tick is ready on
        # its imu alone, and what comes after it is fused before the next tick anyway (late fusion); 32
        # vehicles a process each: -12 % agent CPU, late ticks 1.8-7.0 % against 3.9-22.1 % (BENCHMARKS.md,
        # "Queued inputs"). Lockstep ticks wait for every input, and agent hosts take theirs on Zenoh's thread
        queued = self.hosted == 1 and not self.clock.lockstep

        def subscribe(key: str, cls, handler, stamped: bool = False) -> None:
            if queued:
                self._queued.append(
                    QueuedSubscriber(self.session, key, cls, self._on_queued, self.drops, stamped=stamped)
                )
            else:
                subscribe_decoded(self.session, key, cls, handler, self.drops, direct=d, stamped=stamped)

        if self.wake_at_control:  # queued too (first: drained first, so that a tick's range finds its imu)
            subscribe(k.imu(self.id), Imu, self._on_sensor, stamped=True)
        else:
            subscribe_decoded(self.session, k.imu(self.id), Imu, self._on_sensor, self.drops, direct=d,
                              stamped=True)  # fmt: skip
        if self.tdoa:  # uwb.mode tdoa2/tdoa3: the tag's distance differences, one Tdoa a slot
            subscribe(k.tdoa(self.id), Tdoa, self._on_sensor)
        else:
            subscribe(k.uwb(self.id), Uwb, self._on_sensor)
        if self.clock.lockstep:  # a lockstep world's (and mothership's) ticks in one message each
            subscribe_decoded(self.session, k.bundle(self.id), Bundle, self._on_bundle, self.drops, direct=d,
                              stamped=True)  # fmt: skip
        if self.chaser:
            subscribe(k.vision(self.id), Vision, self._on_sensor)
            if not self.target_local:  # else the target's agent in this host hands its estimates over
                subscribe(k.estimate(self.target_id), Estimate, self._on_target)
        if shared:
            watch_liveliness(self.session, k, self._on_alive, history=self.rejoin)
            subscribe_decoded(self.session, k.world_clock(), Clock, self._on_clock, self.drops)
            subscribe_decoded(self.session, k.world_event(), Event, self._on_world_event, self.drops)

    def announce(self) -> None:
        """Declare this vehicle's liveliness token (a rejoining agent once its commands have a subscriber)
        and print its ready line."""
        if self.rejoin:
            self._await_world_subscriber()
        self._token = declare_liveliness(self.session, self.keys, "agent", self.id)
        print_ready("agent", self.id)

    def ticking(self) -> bool:
        """Whether ticks are processed: once the world announced the run (a rejoining agent at once)."""
        return self.rejoin or self._started.is_set()

    def process(self, inp: TickInputs) -> None:
        """One tick, as the in-process run steps it (module docstring), up to its command; its estimate
        goes out with :meth:`flush`."""
        self._waited_since = time.monotonic()
        self._process(inp)

    def flush(self) -> None:
        """Publish the estimate of the tick :meth:`process` stepped last (if it has not gone out yet) and
        the guidance of its command. An agent host calls it once every vehicle of its round has sent its
        command: the world waits for the commands, while the estimates are wanted a tick later (by a
        chaser) or by a viewer, and the guidance by the launcher or a viewer."""
        k, self._estimate_due = self._estimate_due, None
        if k is not None:
            self._publish_estimate(k)
        self._publish_guidance()

    def done(self, now: float) -> bool:
        """Whether this vehicle's run is over: free-running, once the world's clock stopped; lockstep, once
        every tick up to the stopped one is processed, or none came for :data:`END_DRAIN_S`. A lockstep
        tick that stays incomplete for 5 s is logged with what it lacks."""
        if self.clock.lockstep:
            if self._ended.is_set() and (self._done_through(self._end_tick) or
                                         now - self._waited_since >= END_DRAIN_S):  # fmt: skip
                return True
            stalled = now - self._waited_since > 5.0 and now - self._warned_at > 5.0
            if self.ticking() and stalled and not self.stopping:  # (stopping: the world went first)
                _LOG.warning(
                    "%s: tick %s still lacks %s",
                    self.id, self.assembler.next_expected, self.assembler.waiting_for(),
                )  # fmt: skip
                self._warned_at = now
            return False
        return self._ended.is_set()

    def finish(self) -> bool:
        """After :meth:`done`: publish this vehicle's summary if its run ended (``True``), not if the
        process was told to stop first."""
        if not (self._ended.is_set() and self.agent is not None):
            return False
        a = self.agent
        sw = a.switcher
        data = {
            "final_mode": a.mode.value, "counts": self._counts(), "ticks": self.ticks,
            "r1_m": None if sw is None else sw.r1_m, "r2_m": None if sw is None else sw.r2_m,
            "dropped": self.drops.total, "assembler": self.assembler.counts(), "resent": self.resent,
            "cpu_s": (time.process_time() - (self._cpu0 or time.process_time())) / self.hosted,
        }  # fmt: skip
        self.pub_event.put(encode(Event(a.t_s, "summary", data)))
        _LOG.info("%s: run ended in mode %s", self.id, a.mode.value)
        return True

    def run(self) -> None:
        """This one vehicle in this process: an agent host of one (:class:`agents.host.AgentHost`)."""
        from agents.host import AgentHost

        AgentHost([self], self.session, self.keys, self.stop).run()


def warm_up(sc: Scenario, seed: int, vid: str, policy: str) -> None:
    """Run every compiled kernel of vehicle ``vid``'s agent once on a throwaway agent (propagation, a range,
    for a chaser a camera frame, the control step, the estimate's compiled checks), so that numba's
    compilation or cache load happens before an agent process says it is ready. ``swarm compile`` calls it."""
    dt = sc.dt_s
    x = initial_truth(sc, seed, vid)
    scratch = VehicleAgent(sc, vid, x[0:3], x[3:6], x[6:10], np.full(9, 1e-4), policy)
    scratch.on_imu(dt, dt, np.zeros(3), x[6:10])
    scratch.on_uwb(0, float(np.linalg.norm(np.asarray(sc.anchors_m[0]) - x[0:3])))
    if sc.vehicles[vid].role == "chaser":
        scratch.set_target_estimate(
            TargetEstimate(0.0, x[0:3] + np.array([0.0, 0.0, 0.3]), x[6:10], np.eye(3) * 1e-4)
        )
        points = np.array([[0.01 * i, 0.01 * (i % 2), 0.3] for i in range(len(scratch.markers_target))])
        scratch.on_vision(dt, "features", points)
    scratch.control(0.0, sc.control_every(vid) * dt)
    estimate_payload(scratch, 1)  # and the estimate's compiled checks (swarm.transport._codec_nb)
