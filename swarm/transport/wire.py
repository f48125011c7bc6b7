"""The wire form of a tick (``docs/protocol.md``): what each process of a mission publishes for tick ``k``,
encoded once here for the processes and for ``swarm sim --mcap`` (a tap: the in-process run written as the
processes would have published it, the same encoders in the same order per key).

Every mission: the world's clock (:func:`clock`), its events (:func:`world_event`) and the taps' writer
(:class:`Tap`). Docking: the world's samples (:func:`world_sensors`; :mod:`swarm.world.process`), the
mothership's ranges (:func:`uwb_slot`; :mod:`mothership.process`), an agent's estimate, guidance and command
(:mod:`agents.process`), the referee's events, :class:`DockingTap`. Landing: the landing world's tick
(:func:`landing_world_tick`; :mod:`swarm.world.landing`), a landing agent's answer
(:func:`landing_agent_tick`; :mod:`agents.landing`), :class:`LandingTap`."""

from __future__ import annotations

import numpy as np

from swarm.core import rotations as rot
from swarm.core.estimator import MeasKind
from swarm.step import landing_nb as lnb
from swarm.transport.keys import Keys
from swarm.transport.lockstep import period_phase, reads_target
from swarm.transport.messages import (
    CLOCK_EVERY,
    MAX_BATCH,
    NEW_RUN_COMMANDS,
    Clock,
    Command,
    Estimate,
    Event,
    Gnss,
    Guidance,
    Imu,
    ImuBatch,
    MessageError,
    Rangefinder,
    Tdoa,
    TdoaBatch,
    Truth,
    Uwb,
    UwbBatch,
    Vision,
    VisionBatch,
    decode,
    encode,
    encode_command,
    encode_estimate,
    encode_imu,
    encode_tdoa,
    encode_truth,
    encode_truth_batch,
    encode_uwb,
    encode_vision,
    estimate_message,
    pack_entries,
)

Wire = list[tuple[str, bytes]]
"""``(key, payload)`` in publishing order."""


def clock(keys: Keys, k: int, dt: float, seed: int, state: str = "running") -> tuple[str, bytes]:
    """The world's clock at tick ``k`` in ``state`` (``running``, ``paused``, ``stopped``)."""
    return keys.world_clock(), encode(Clock(k, k * dt, state, seed))


def world_event(keys: Keys, kind: str, t_s: float, data: dict) -> tuple[str, bytes]:
    """An event of the world on ``world/event`` (``run_start``, ``fault``, ``fault_refused``, ...)."""
    return keys.world_event(), encode(Event(t_s, kind, data))


class Tap:
    """What a tap of ``swarm sim --mcap FILE`` shares: the recorder's
    :class:`~swarm.transport.recording.McapSink` on the run's namespace, written in publishing order."""

    def __init__(self, path, seed: int, namespace: str = "tpods") -> None:
        from swarm.transport.recording import sim_sink

        self.keys = Keys(namespace)
        self.seed = seed
        self.sink = sim_sink(path, self.keys)

    def _put(self, key: str, payload: bytes) -> None:
        self.sink.write(key, payload)

    def _write(self, wire: Wire) -> None:
        for key, payload in wire:
            self.sink.write(key, payload)


# ---------------------------------------------------------------------------------------------- docking

Sensors = list[tuple[str, str, bytes]]
"""``(kind, vehicle, payload)`` in publishing order; ``kind`` is ``truth``, ``vision``, ``imu``, or
``truth_batch``, ``vision_batch`` and ``imu_batch`` (vehicle ``""``: the ``world/truth`` key of every world,
the ``world/vision`` and ``world/imu`` keys of a world that serves agent hosts)."""


def batch_samples(sensors: Sensors, vid: str) -> list[tuple[str, bytes]]:
    """Vehicle ``vid``'s samples taken out of the tick's batches in ``sensors``, as ``(kind, payload)`` on
    its own keys: its ``imu`` (re-encoded as one :class:`~swarm.transport.messages.Imu`) and its ``vision``
    (the frame's own bytes); empty when no batch holds it. What a world sends to an agent that alone needs
    the tick again (a rejoined agent)."""
    out = []
    for kind, _vid, payload in sensors:
        if kind == "imu_batch":
            imu = decode(payload, ImuBatch).sample(vid)
            if imu is not None:
                out.append(("imu", encode(imu)))
        elif kind == "vision_batch":
            batch = decode(payload, VisionBatch)
            row = batch.index().get(vid)
            if row is not None:
                out.append(("vision", batch.frames[row]))
    return out


FILTER_KINDS = {
    "range": MeasKind.RANGE,
    "features": MeasKind.FEATURES,
    "pose": MeasKind.POSE,
    "ahrs": MeasKind.ATTITUDE,
}
"""The filter's update kinds (its counters' columns) by their name in an ``Estimate``'s ``counts``."""
FILTER_OUTCOMES = ("accepted", "rejected", "refused")


def world_sensors(
    world, ids: list[str], chasers: list[str], k: int, frames, truth_every: int, batch: bool = False,
    solo=frozenset(), viewed=None,
) -> Sensors:  # fmt: skip
    """The world's samples of tick ``k``, encoded, in publishing order: truth(k) of every vehicle (on UWB
    slot ticks: the mothership's radios need no other, and a viewer draws at 50 Hz as well as at 100;
    docs/protocol.md, "Rates"), then per vehicle vision(k) (camera ticks, chasers) and imu(k). With
    ``batch`` (a world serving agent hosts) the frames and the imu of every vehicle not in ``solo`` go
    last, each kind in as few messages as fit: :class:`~swarm.transport.messages.VisionBatch` (within
    :data:`~swarm.transport.messages.MAX_PAYLOAD_BYTES`), then :class:`~swarm.transport.messages.ImuBatch`
    (:data:`~swarm.transport.messages.MAX_BATCH` vehicles each), the imu last as in every tick (a host's
    tick is ready on its imu); ``solo`` (vehicles whose samples a ``sensor_delay`` fault holds back) keep
    their own keys. The truths go first as :class:`~swarm.transport.messages.TruthBatch` messages (the
    mothership's radios take them so), then one per vehicle in ``viewed`` (those a viewer subscribes to;
    ``None``: every vehicle). A free-running world of agents a process each holds the truths back and
    sends them halfway to the next tick (:meth:`swarm.world.process.WorldProcess._pace_to`)."""
    sc = world.sc
    t = k * sc.dt_s
    camera_tick = k % world.vision_every == 0
    face = sc.guidance.docking_face
    out: Sensors = []
    lost, p_nlos = world.radio_env(t)
    truth_tick = k % truth_every == 0
    if truth_tick:
        out.extend(_truth_batches(world, ids, k, t, bool(lost), float(p_nlos)))
    for i, vid in enumerate(ids if truth_tick else ()):
        if viewed is not None and vid not in viewed:
            continue
        x = world.X[i]
        truth = encode_truth(k, t, x[0:3], x[3:6], x[6:10], x[10:13], float(world.effort[i]), bool(lost),
                             float(p_nlos))  # fmt: skip
        out.append(("truth", vid, truth))
    seen: list[tuple[str, bytes]] = []  # batch: the frames of the vehicles not in solo
    chasers = frozenset(chasers) if camera_tick else frozenset()
    for vid in ids:
        fr = frames[vid]
        alone = not batch or vid in solo
        if vid in chasers:
            target = sc.vehicles[vid].target
            if fr.vision is None:
                data, kind, mids = np.zeros((0, 3)), "features", ()
            elif fr.vision_kind == "pose":  # one pose, from every marker of the face
                data, kind, mids = fr.vision.reshape(1, -1), "pose", tuple(range(len(world.markers_target)))
            else:
                data, kind, mids = fr.vision, fr.vision_kind, tuple(range(len(fr.vision)))
            payload = encode_vision(k, t, target, face, kind, data, mids)
            if alone:
                out.append(("vision", vid, payload))
            else:
                seen.append((vid, payload))
        if alone:
            out.append(("imu", vid, encode_imu(k, t, sc.dt_s, fr.gyro_body, fr.q_ahrs_nav_body)))
    vision = pack_entries(seen, lambda vids, blobs: VisionBatch(k, t, vids, blobs))
    out.extend(("vision_batch", "", p) for p in vision)
    rows = [vid for vid in ids if vid not in solo] if batch else []
    for a in range(0, len(rows), MAX_BATCH):
        chunk = rows[a : a + MAX_BATCH]
        gyro = np.array([frames[vid].gyro_body for vid in chunk], dtype=np.float64)
        ahrs = [vid for vid in chunk if frames[vid].q_ahrs_nav_body is not None]
        q = np.array([frames[vid].q_ahrs_nav_body for vid in ahrs], dtype=np.float64).reshape(len(ahrs), 4)
        out.append(("imu_batch", "", encode(ImuBatch(k, t, sc.dt_s, tuple(chunk), gyro, tuple(ahrs), q))))
    return out


def _truth_batches(world, ids: list[str], k: int, t: float, lost: bool, p_nlos: float) -> Sensors:
    """Every vehicle's truth of tick ``k`` in :class:`~swarm.transport.messages.TruthBatch` messages of at
    most :data:`~swarm.transport.messages.MAX_BATCH` vehicles each (``world.X`` rows in ``ids`` order)."""
    out: Sensors = []
    X, effort = world.X, np.asarray(world.effort, dtype=np.float64)
    for a in range(0, len(ids), MAX_BATCH):
        b = min(a + MAX_BATCH, len(ids))
        payload = encode_truth_batch(k, t, tuple(ids[a:b]), X[a:b], effort[a:b], lost, p_nlos)
        out.append(("truth_batch", "", payload))
    return out


def target_reads(sc, chaser_id: str) -> tuple | None:
    """The tick periods at which chaser ``chaser_id`` reads its target's estimate: tick ``k`` uses the
    target's ``estimate(k - 1)`` only when ``k`` is a multiple of one of them, its camera ticks (the vision
    update is relative to the target) and its control ticks (guidance flies to the target; a pair
    ``(period, phase)`` when its control clock is staggered, ``vehicles.<id>.control_phase``). Between them
    the target's estimate is not read, provided the chaser latches it while vision lasts
    (``agent.latch_target_with_vision``): the navigation that is relative to the target starts after a
    camera or control tick, whose estimate it then holds. Without the latch, ``None``: every tick (the
    published covariance reads it on each). docs/protocol.md, "Rates"."""
    if not sc.agent.latch_target_with_vision:
        return None
    phase = sc.control_phase(chaser_id)
    control = (sc.control_every(chaser_id), phase) if phase else sc.control_every(chaser_id)
    return tuple(sorted({sc.every(sc.camera.rate_hz), control}, key=period_phase))


def estimate_reads(sc, vehicle_id: str) -> tuple[int, ...] | None:
    """The tick periods of the estimates of ``vehicle_id`` its chasers read (:func:`target_reads`, all of
    them); ``None`` (every tick) for a vehicle that no chaser flies to, or one that a chaser without the
    latch does."""
    periods: set = set()
    chasers = [c for c in sc.chasers if sc.vehicles[c].target == vehicle_id]
    for c in chasers:
        reads = target_reads(sc, c)
        if reads is None:
            return None
        periods.update(reads)
    return tuple(sorted(periods, key=period_phase)) if chasers else None


def estimate_read(reads: tuple[int, ...] | None, k: int) -> bool:
    """Whether ``estimate(k)`` is read by a chaser whose reads are ``reads`` (:func:`estimate_reads`): at
    tick ``k + 1`` (:func:`~swarm.transport.lockstep.reads_target`, the chaser's side of the rule), and
    ``estimate(0)``, the initial one, by tick 0 as well."""
    return k == 0 or reads_target(reads, k + 1)


def uwb_slot(network, ids: list[str], k: int, t: float) -> list[tuple[str, bytes]]:
    """The mothership's ranges of slot tick ``k`` after ``network.step``: ``(vehicle, payload)``, one per
    vehicle with an exchange (``range_m`` None where the reply was lost); none for a tag idle on a TDMA
    channel (its slot not in this tick: :func:`~swarm.step.radio.exchange_ticks`)."""
    ranges = _ranges(network)
    return [
        (vid, encode_uwb(k, t, int(network.anchor_id[i]), ranges[i]))
        for i, vid in enumerate(ids)
        if not network.idle[i]
    ]


def _ranges(network) -> tuple[float | None, ...]:
    """Each vehicle's range of the slot just stepped, ``None`` where the reply was lost."""
    return tuple(None if lost else float(r) for lost, r in zip(network.lost, network.range_m, strict=True))


def uwb_slot_batch(network, ids: list[str], k: int, t: float) -> bytes | None:
    """:func:`uwb_slot`'s ranges in one :class:`~swarm.transport.messages.UwbBatch` (agent hosts); ``None``
    when every tag is idle (TDMA)."""
    rows = [i for i in range(len(ids)) if not network.idle[i]]
    if not rows:
        return None
    ranges = _ranges(network)
    return encode(UwbBatch(k, t, tuple(ids[i] for i in rows), tuple(int(network.anchor_id[i]) for i in rows),
                           tuple(ranges[i] for i in rows)))  # fmt: skip


_NO_ROWS = np.zeros((0, 3))


def tdoa_slot(network, ids: list[str], k: int, t: float) -> list[tuple[str, bytes]]:
    """The mothership's distance differences of slot tick ``k`` after ``network.step`` (``uwb.mode``
    tdoa2/tdoa3): ``(vehicle, payload)``, one :class:`~swarm.transport.messages.Tdoa` per vehicle, every
    slot, with no rows for a tag that heard none (or is inside a dropout), so a lockstep agent knows the
    slot is complete."""
    heard = network.heard
    return [(vid, encode_tdoa(k, t, heard[vid].rows if vid in heard else _NO_ROWS)) for vid in ids]


def tdoa_slot_batch(network, ids: list[str], k: int, t: float) -> list[bytes]:
    """:func:`tdoa_slot`'s messages in as few :class:`~swarm.transport.messages.TdoaBatch` messages as keep
    each within the payload cap (agent hosts)."""
    return pack_entries(tdoa_slot(network, ids, k, t), lambda vids, blobs: TdoaBatch(k, t, vids, blobs))


def filter_counts(agent) -> dict[str, int]:
    """The filter's cumulative update counters ``<kind>_<outcome>``, the non-zero ones (an absent counter is
    zero: a dozen zeros per tick would cost every receiver their validation)."""
    counts = agent.est.counts[0]  # (outcome, kind)
    return {
        f"{name}_{what}": int(counts[row, int(kind)])
        for name, kind in FILTER_KINDS.items()
        for row, what in enumerate(FILTER_OUTCOMES)
        if counts[row, int(kind)]
    }


def estimate_args(agent, k: int) -> tuple:
    """The fields of an agent's ``estimate(k)``, in the order of
    :func:`~swarm.transport.messages.encode_estimate`."""
    e = agent.est
    return (
        k, agent.t_s, e.p_nav[0], e.v_nav[0], e.q_nav_body[0], agent.published_cov(), agent.sigma_pos_max_m,
        agent.mahalanobis_d, agent.rejection_fraction, filter_counts(agent),
    )  # fmt: skip


def estimate_payload(agent, k: int) -> bytes:
    """An agent's ``estimate(k)``."""
    return encode_estimate(*estimate_args(agent, k))


def mode_events(cmd) -> list[bytes]:
    """A control tick's mode switches, as ``mode`` events."""
    return [encode(Event(float(ev["t_s"]), "mode", dict(ev))) for ev in cmd.events]


def guidance_payload(sc, policy: str, chaser: bool, agent, k: int, mode: str, cmd) -> bytes:
    """An agent's ``guidance(k)`` on a control tick: its mode, the range to its target, Algorithm 1's radii
    and last decision (mdp), the reason of the last switch."""
    sw = agent.switcher
    range_m = decision = r_t = None
    if agent.target is not None and chaser:
        range_m = float(np.linalg.norm(agent.est.p_nav[0] - agent.target.p_nav))
    if sw is not None and policy == "mdp":
        r_t = float(sc.mdp.r_t_m)
        if sw.decisions:
            decision = sw.decisions[-1].as_dict()
    reason = cmd.events[-1]["reason"] if cmd.events else ""
    dt = sc.dt_s
    msg = Guidance(
        k, k * dt, mode, range_m, None if sw is None else sw.r1_m, None if sw is None else sw.r2_m, r_t,
        decision, str(reason)[:1024],
    )  # fmt: skip
    return encode(msg)


def command_payload(k: int, dt: float, u, mode: str, force, torque) -> bytes:
    """An agent's ``command(k)``: the held actuator command and the mode it was decided in."""
    return encode_command(k, k * dt, u, mode, force, torque)


def contact_event(t: float, mode: str, ct) -> bytes:
    """The referee's ``contact`` (docked) or ``collision`` event on the chaser's event key."""
    data = {
        **ct.event(mode), "docked": ct.docked, "docking_time_s": t, "contact": ct.contact,
        "position_error_m": ct.position_error_m, "attitude_error_rad": ct.attitude_error_rad,
    }  # fmt: skip
    return encode(Event(t, "contact" if ct.docked else "collision", data))


def keepout_event(t: float, mode: str, range_m: float) -> bytes:
    """The referee's ``keepout_violation`` event on the chaser's event key."""
    return encode(Event(t, "keepout_violation", {"t_s": t, "mode": mode, "range_m": range_m}))


class DockingTap(Tap):
    """``swarm sim docking --mcap FILE``: the in-process run written as its processes would have published
    it in lockstep (the same encoders, in the same order per key), through the recorder's
    :class:`~swarm.transport.recording.McapSink`; a tap of :class:`swarm.sim.docking.DockingSim` (which then
    runs every tick through its per-object Python path, so that each tick's samples exist)."""

    def __init__(self, path, seed: int, namespace: str = "tpods", clock_every: int = 10) -> None:
        super().__init__(path, seed, namespace)
        self.clock_every = clock_every
        self._held: dict[str, tuple] = {}

    def start(self, sim) -> None:
        """Tick 0: ``run_start`` and the clock."""
        sc = sim.sc
        self._ids, self._chasers = list(sc.vehicles), list(sc.chasers)
        self._reads = {vid: estimate_reads(sc, vid) for vid in self._ids}  # as an agent publishes them
        self._truth_every = sc.every(sc.uwb.rate_hz)  # as the world process: truth on UWB slot ticks
        # as an agent: on its control ticks
        self._command_every = {vid: (sc.control_every(vid), sc.control_phase(vid)) for vid in self._ids}
        ids = self._ids
        data = {"seed": self.seed, "vehicles": ids, "clock": "lockstep", "scenario": sc.name}
        self._write([world_event(self.keys, "run_start", 0.0, data), clock(self.keys, 0, sc.dt_s, self.seed)])
        for vid in ids:
            mode = "HOLD" if vid in sc.chasers else "STATION"
            self._held[vid] = (np.zeros(sc.kind(vid).U_N), mode, None, None)

    def world(self, sim, k: int, frames) -> None:
        """The world's samples of tick ``k`` (and the clock on its ticks)."""
        # as the world of a default launch (a process per vehicle): one imu message per vehicle, the truths
        # in one world/truth batch for the mothership and on each vehicle's key for a recorder (a viewer)
        for kind, vid, payload in world_sensors(
            sim.world, self._ids, self._chasers, k, frames, self._truth_every
        ):
            key = self.keys.world_truth() if kind == "truth_batch" else getattr(self.keys, kind)(vid)
            self._put(key, payload)
        if k % self.clock_every == 0:
            self._write([clock(self.keys, k, sim.sc.dt_s, self.seed)])

    def uwb(self, sim, k: int) -> None:
        """The mothership's ranges of slot tick ``k`` (after the network's step)."""
        if k == 0 or k % sim.network.every:
            return
        if sim.network.tdoa is not None:  # uwb.mode tdoa2/tdoa3: the differences on agent/<id>/tdoa
            for vid, payload in tdoa_slot(sim.network, self._ids, k, k * sim.sc.dt_s):
                self._put(self.keys.tdoa(vid), payload)
            return
        for vid, payload in uwb_slot(sim.network, self._ids, k, k * sim.sc.dt_s):
            self._put(self.keys.uwb(vid), payload)

    def agent(self, sim, vid: str, k: int, cmd) -> None:
        """Agent ``vid``'s answer to tick ``k``: ``estimate`` (a target's on the ticks its chasers read),
        then on a control tick its mode events, ``guidance`` and ``command`` (held by the world until the
        next)."""
        a, sc = sim.agents[vid], sim.sc
        if estimate_read(self._reads[vid], k):
            self._put(self.keys.estimate(vid), estimate_payload(a, k))
        if cmd is not None:
            mode = a.mode.value
            self._held[vid] = (cmd.u, mode, cmd.force_body_n, cmd.torque_body_nm)
            for payload in mode_events(cmd):
                self._put(self.keys.event(vid), payload)
            self._put(
                self.keys.guidance(vid), guidance_payload(sc, sim.policy, vid in sc.chasers, a, k, mode, cmd)
            )
        every, phase = self._command_every[vid]
        if (k - phase) % every == 0:
            u, mode, force, torque = self._held[vid]
            self._put(self.keys.command(vid), command_payload(k, sc.dt_s, u, mode, force, torque))

    def keepout(self, cid: str, t: float, mode: str, range_m: float) -> None:
        """The referee's keep-out verdict on the chaser's event key."""
        self._put(self.keys.event(cid), keepout_event(t, mode, range_m))

    def contact(self, cid: str, t: float, mode: str, ct) -> None:
        """The referee's contact or collision on the chaser's event key."""
        self._put(self.keys.event(cid), contact_event(t, mode, ct))

    def end(self, sim, k: int, reason: str, wall_s: float) -> None:
        """``run_end`` and the stopped clock; the file is closed."""
        t = k * sim.sc.dt_s
        data = {"reason": reason, "tick": k, "t_s": t, "seed": self.seed, "wall_s": wall_s,
                "effort": sim.world.effort_by_vehicle, "done": sorted(sim.done)}  # fmt: skip
        self._write([world_event(self.keys, "run_end", t, data), clock(self.keys, k, sim.sc.dt_s, self.seed,
                                                                             "stopped")])  # fmt: skip
        self.sink.close()


# ---------------------------------------------------------------------------------------------- landing


def landing_world_tick(keys: Keys, world, k: int, inputs: dict, seed: int, clock_every: int = CLOCK_EVERY
                       ) -> Wire:  # fmt: skip
    """The world's tick ``k``: per UAV ``imu``, ``uwb`` (a UWB tick; on a TDoA radio a ``tdoa`` instead: the
    differences heard since the last, none in it when there were none), ``gnss`` (a fix), ``rangefinder`` (a
    rangefinder tick), ``vision`` (a camera tick: the pad's corners as pixels) and ``truth``; a moving pad's
    robot's shared estimate on its share ticks (:func:`platform_estimate`); then, every ``clock_every``
    ticks, the clock."""
    sc, dt = world.sc, world.sc.dt_s
    t = k * dt
    out: Wire = []
    for uid, inp in inputs.items():
        out.append((keys.imu(uid), encode(Imu(k, t - dt, dt, inp.gyro, None, inp.acc))))
        if world.rates.uwb_tick(sc, k):
            a, z = inp.uwb if inp.uwb is not None else (world.uavs[uid].next_anchor - 1, None)
            out.append((keys.uwb(uid), encode(Uwb(k, t, int(a) % len(world.anchors), z))))
        elif world.rates.tdoa_tick(sc, k):
            rows = inp.tdoa if inp.tdoa is not None else np.zeros((0, 3))
            out.append((keys.tdoa(uid), encode_tdoa(k, t, rows)))
        if inp.gnss is not None:
            out.append((keys.gnss(uid), encode(Gnss(k, t, inp.gnss, world.gnss_cov))))
        if world.rates.rangefinder_tick(sc, k):
            out.append(
                (keys.rangefinder(uid), encode(Rangefinder(k, t, inp.rangefinder, sc.rangefinder.sigma_m)))
            )
        if inp.camera is not None:
            mids, corners = inp.camera
            rows = tuple(int(m) * 4 + c for m in mids for c in range(4))
            vis = Vision(k, t, f"pad-{uid}", "+z", "pixels", corners.reshape(-1, 2), rows)
            out.append((keys.vision(uid), encode(vis)))
        u = world.uavs[uid]
        x = u.x
        out.append((keys.truth(uid), encode(Truth(k, t, x[0:3], x[3:6], x[6:10], x[10:13], u.energy_j))))
        if inp.pad is not None:
            out.append(platform_estimate(keys, world, uid, k, inp.pad))
    if k % clock_every == 0:
        out.append(clock(keys, k, dt, seed))
    return out


def platform_estimate(keys: Keys, world, uid: str, k: int, pad: np.ndarray) -> tuple[str, bytes]:
    """A moving pad's robot shares its estimate of the pad (``[platform]``): an ``Estimate`` on
    ``<ns>/agent/<platform.id>/estimate`` (docs/protocol.md), its position and velocity the tick's shared
    ones (``pad``, (6,)), its attitude the robot's heading, its covariance the stated sigmas' (the attitude
    block zero: the UAV does not use it)."""
    pf, t = world.sc.platform, k * world.sc.dt_s
    R = world.uavs[uid].WC[lnb.WC_R_NAV_PAD : lnb.WC_R_NAV_PAD + 9].reshape(3, 3)
    cov = np.diag([pf.share_sigma_m**2] * 3 + [pf.share_sigma_m_s**2] * 3 + [0.0] * 3)
    q = rot.matrix_to_quat(R)
    msg = estimate_message(k, t, pad[0:3], pad[3:6], q, cov, pf.share_sigma_m, 0.0, 0.0, {})
    return keys.estimate(pf.id), encode(msg)


def pad_input(msg: Estimate) -> np.ndarray:
    """A robot's shared ``Estimate`` as the agent step's moving pad (position and velocity, (6,))."""
    return np.concatenate([msg.p_nav, msg.v_nav])


def camera_frame(msg: Vision) -> tuple[np.ndarray, np.ndarray]:
    """The pad's frame back from a ``Vision`` of :func:`world_tick`: marker ids (n,), corners (n, 4, 2).
    MessageError for a frame that is not one (another kind, or rows that are not every corner ``4 m + c``
    of each marker in order): a valid message of the protocol that a landing agent cannot use."""
    if msg.kind != "pixels":
        raise MessageError(f"kind: a landing camera frame is 'pixels', got {msg.kind!r}")
    ids = np.asarray(msg.marker_ids, dtype=np.int64)
    if len(ids) % 4:
        raise MessageError(f"marker_ids: {len(ids)} rows, not the four corners of each marker")
    quads = ids.reshape(-1, 4)
    if np.any(quads % 4 != np.arange(4)) or np.any(quads // 4 != quads[:, :1] // 4):
        raise MessageError("marker_ids: rows must be 4 m, 4 m + 1, 4 m + 2, 4 m + 3 for each marker m")
    return quads[:, 0] // 4, msg.data.reshape(-1, 4, 2)


def tdoa_input(msg: Tdoa) -> np.ndarray:
    """A ``Tdoa`` as the agent step's differences (K, 3) (:attr:`swarm.step.landing.LandingInputs.tdoa`); a
    row naming an anchor the scenario does not have is the agent step's to skip and count."""
    return msg.rows()


def range_input(msg: Uwb, n_anchors: int) -> tuple[int, float] | None:
    """A ``Uwb`` as the agent step's ``(anchor index, range)`` (None: no reply in this slot). MessageError for
    an anchor the scenario does not have."""
    if not 0 <= msg.anchor_id < n_anchors:
        raise MessageError(f"anchor_id: {msg.anchor_id} is not one of the scenario's {n_anchors} anchors")
    return None if msg.range_m is None else (msg.anchor_id, msg.range_m)


def landing_agent_tick(keys: Keys, uid: str, agent, cmd, n_modes: int) -> tuple[Wire, int]:
    """A landing agent's answer to tick ``k = cmd.k``: ``command``, ``estimate``, ``guidance`` and a ``mode``
    event per switch since the ``n_modes`` already sent; returns them and the new count."""
    k, t = cmd.k, cmd.k * agent.dt
    mode = str(cmd.mode)
    out: Wire = [(keys.command(uid), encode(Command(k, t, cmd.u, mode)))]
    out.append((keys.estimate(uid), encode(_landing_estimate(agent, k, t))))
    dist = float(np.linalg.norm(agent.p_est[:2] - agent.pad_est[:2]))
    modes = agent.guidance.modes
    reason = str(modes[-1]["reason"])[:1024] if modes else ""
    out.append((keys.guidance(uid), encode(Guidance(k, t, mode, dist, reason=reason))))
    for m in modes[n_modes:]:
        data = {"from": m["from"], "to": m["mode"], "reason": m["reason"], "p_est_nav": m["p_est_nav"]}
        out.append((keys.event(uid), encode(Event(m["t_s"], "mode", data))))
    return out, len(modes)


def _landing_estimate(agent, k: int, t: float) -> Estimate:
    f = agent.filt
    P = f.P[0, 0:9, 0:9]
    d2 = agent.last_d2  # the latest range's (none before the first)
    d = float(np.sqrt(d2)) if d2 is not None else 0.0
    # a TDoA difference counts as a range (the dashboard's accepted rate), one naming no anchor as refused
    tc = agent.TC.sum(axis=(0, 1))
    tc[2] += agent.TSKIP[0]
    outcomes = ("accepted", "rejected", "refused")
    counts = {f"range_{w}": int(f.counts[:, i].sum() + tc[i]) for i, w in enumerate(outcomes)}
    sigma = float(np.sqrt(np.max(np.diag(P)[0:3])))
    return estimate_message(k, t, f.p_nav[0], f.v_nav[0], f.q_nav_body[0], P, sigma, d, 0.0, counts)


def landing_summary(keys: Keys, uid: str, agent) -> tuple[str, bytes]:
    """The agent's ``summary`` event at the run's end: its half of the outcome (the number of Algorithm 1
    records, not the records)."""
    out = agent.outcome()
    out["decisions"] = len(out["decisions"])
    return keys.event(uid), encode(Event(agent.landed_t or 0.0, "summary", out))


def landing_run_start(
    keys: Keys, sc, seed: int, policy: str, ids: list[str], clock: str
) -> tuple[str, bytes]:
    """The landing world's ``run_start`` on ``world/event``."""
    data = {"scenario": sc.name, "mission": "landing", "seed": seed, "policy": policy, "uavs": ids,
            "clock": clock}  # fmt: skip
    return world_event(keys, "run_start", 0.0, data)


def landing_run_end(keys: Keys, world, k: int, reason: str, wall_s: float, late: dict[str, int] | None = None,
                    next_seed: int | None = None) -> Wire:  # fmt: skip
    """The world's ``run_end`` (each UAV's outcome) and its ``stopped`` clock; a free-running world adds each
    UAV's ``late_ticks`` (ticks whose command had not come by the tick's wall time), a run ended by a
    ``reset`` or ``new_seed`` the ``next_seed`` asked for (nil: the same seed, or the launcher's next)."""
    outcome = {uid: {**world.outcome(uid), "end_tick": world.uavs[uid].end_k} for uid in world.uavs}
    for uid, n in (late or {}).items():
        outcome[uid]["late_ticks"] = n
    t = k * world.sc.dt_s
    data = {"reason": reason, "ticks": k, "wall_s": wall_s, "uavs": outcome}
    if reason in NEW_RUN_COMMANDS:
        data["next_seed"] = next_seed
    return [world_event(keys, "run_end", t, data), clock(keys, k, world.sc.dt_s, world.seed, "stopped")]


class LandingTap(Tap):
    """``swarm sim landing --mcap FILE``: the in-process run written as its processes would have published
    it (the same encoders, in the same order per key), through the recorder's :class:`McapSink`; a tap of
    :func:`swarm.sim.landing.run_landing_fleet`."""

    def __init__(self, path, seed: int, namespace: str = "tpods") -> None:
        super().__init__(path, seed, namespace)
        self.n_modes: dict[str, int] = {}

    def start(self, world, policy: str) -> None:
        ids = [u for u in world.uavs if not world.uavs[u].done]
        self._write([landing_run_start(self.keys, world.sc, self.seed, policy, ids, "sim"),
                     clock(self.keys, 0, world.sc.dt_s, self.seed)])  # fmt: skip

    def world(self, k: int, world, inputs: dict) -> None:
        self._write(landing_world_tick(self.keys, world, k, inputs, self.seed))

    def agent(self, uid: str, agent, cmd) -> None:
        out, self.n_modes[uid] = landing_agent_tick(self.keys, uid, agent, cmd, self.n_modes.get(uid, 0))
        self._write(out)

    def end(self, world, agents: dict, k: int, wall_s: float) -> None:
        self._write(landing_run_end(self.keys, world, k, "done", wall_s))
        self._write([landing_summary(self.keys, uid, a) for uid, a in agents.items()])
        self.sink.close()
