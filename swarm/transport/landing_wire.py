"""The landing tick's messages (``docs/protocol.md``, the landing swarm): what the landing world and a landing
agent publish for tick ``k``, encoded once here for the processes (:mod:`swarm.world.landing`,
:mod:`agents.landing`) and for ``swarm sim landing --mcap`` (the in-process run written as the processes
would have published it)."""

from __future__ import annotations

import numpy as np

from swarm.core import rotations as rot
from swarm.step import landing_nb as lnb
from swarm.transport.keys import Keys
from swarm.transport.messages import (
    CLOCK_EVERY,
    NEW_RUN_COMMANDS,
    Clock,
    Command,
    Estimate,
    Event,
    Gnss,
    Guidance,
    Imu,
    MessageError,
    Rangefinder,
    Tdoa,
    Truth,
    Uwb,
    Vision,
    encode,
    encode_tdoa,
    estimate_message,
)

Wire = list[tuple[str, bytes]]
"""``(key, payload)`` in publishing order."""


def world_tick(keys: Keys, world, k: int, inputs: dict, seed: int, clock_every: int = CLOCK_EVERY) -> Wire:
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
        out.append(running_clock(keys, k, dt, seed))
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


def running_clock(keys: Keys, k: int, dt: float, seed: int) -> tuple[str, bytes]:
    """The world's ``running`` clock at tick ``k``."""
    return clock(keys, k, dt, seed, "running")


def clock(keys: Keys, k: int, dt: float, seed: int, state: str) -> tuple[str, bytes]:
    """The world's clock at tick ``k`` in ``state`` (``running``, ``paused``)."""
    return keys.world_clock(), encode(Clock(k, k * dt, state, seed))


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


def agent_tick(keys: Keys, uid: str, agent, cmd, n_modes: int) -> tuple[Wire, int]:
    """A landing agent's answer to tick ``k = cmd.k``: ``command``, ``estimate``, ``guidance`` and a ``mode``
    event per switch since the ``n_modes`` already sent; returns them and the new count."""
    k, t = cmd.k, cmd.k * agent.dt
    mode = str(cmd.mode)
    out: Wire = [(keys.command(uid), encode(Command(k, t, cmd.u, mode)))]
    out.append((keys.estimate(uid), encode(_estimate(agent, k, t))))
    dist = float(np.linalg.norm(agent.p_est[:2] - agent.pad_est[:2]))
    modes = agent.guidance.modes
    reason = str(modes[-1]["reason"])[:1024] if modes else ""
    out.append((keys.guidance(uid), encode(Guidance(k, t, mode, dist, reason=reason))))
    for m in modes[n_modes:]:
        data = {"from": m["from"], "to": m["mode"], "reason": m["reason"], "p_est_nav": m["p_est_nav"]}
        out.append((keys.event(uid), encode(Event(m["t_s"], "mode", data))))
    return out, len(modes)


def _estimate(agent, k: int, t: float) -> Estimate:
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


def agent_summary(keys: Keys, uid: str, agent) -> tuple[str, bytes]:
    """The agent's ``summary`` event at the run's end: its half of the outcome (the number of Algorithm 1
    records, not the records)."""
    out = agent.outcome()
    out["decisions"] = len(out["decisions"])
    return keys.event(uid), encode(Event(agent.landed_t or 0.0, "summary", out))


def world_event(keys: Keys, kind: str, t_s: float, data: dict) -> tuple[str, bytes]:
    """An event of the landing world on ``world/event`` (``fault``, ``fault_refused``)."""
    return keys.world_event(), encode(Event(t_s, kind, data))


def run_start(keys: Keys, sc, seed: int, policy: str, ids: list[str], clock: str) -> tuple[str, bytes]:
    data = {
        "scenario": sc.name,
        "mission": "landing",
        "seed": seed,
        "policy": policy,
        "uavs": ids,
        "clock": clock,
    }
    return keys.world_event(), encode(Event(0.0, "run_start", data))


def run_end(
    keys: Keys,
    world,
    k: int,
    reason: str,
    wall_s: float,
    late: dict[str, int] | None = None,
    next_seed: int | None = None,
) -> Wire:
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
    return [
        (keys.world_event(), encode(Event(t, "run_end", data))),
        clock(keys, k, world.sc.dt_s, world.seed, "stopped"),
    ]


class McapTap:
    """``swarm sim landing --mcap FILE``: the in-process run written as its processes would have published
    it (the same encoders, in the same order per key), through the recorder's :class:`McapSink`; a tap of
    :func:`swarm.sim.landing.run_landing_fleet`."""

    def __init__(self, path, seed: int, namespace: str = "tpods") -> None:
        from swarm.transport.recording import sim_sink

        self.keys = Keys(namespace)
        self.seed = seed
        self.sink = sim_sink(path, self.keys)
        self.n_modes: dict[str, int] = {}

    def _write(self, wire: Wire) -> None:
        for key, payload in wire:
            self.sink.write(key, payload)

    def start(self, world, policy: str) -> None:
        ids = [u for u in world.uavs if not world.uavs[u].done]
        self._write([run_start(self.keys, world.sc, self.seed, policy, ids, "sim"),
                     running_clock(self.keys, 0, world.sc.dt_s, self.seed)])  # fmt: skip

    def world(self, k: int, world, inputs: dict) -> None:
        self._write(world_tick(self.keys, world, k, inputs, self.seed))

    def agent(self, uid: str, agent, cmd) -> None:
        out, self.n_modes[uid] = agent_tick(self.keys, uid, agent, cmd, self.n_modes.get(uid, 0))
        self._write(out)

    def end(self, world, agents: dict, k: int, wall_s: float) -> None:
        self._write(run_end(self.keys, world, k, "done", wall_s))
        self._write([agent_summary(self.keys, uid, a) for uid, a in agents.items()])
        self.sink.close()
