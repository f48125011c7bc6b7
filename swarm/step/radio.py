"""The radio step: the UWB network's two-way-ranging exchanges of one tick (paper sec. III).

:class:`UwbNetwork` is the mothership's simulated radio network: one round-robin radio per vehicle, each
with its own ``uwb`` random stream (:func:`swarm.step.streams.stream`), its tag where the vehicle kind's
mounts put it. The mothership process wraps it, the in-process simulation calls it directly, and the
compiled fast path calls its kernel :func:`uwb_tick`, the same code.

Faults do not live here. The world owns the fault schedule and hands the radio step the *radio
environment* of each vehicle at the tick (:func:`radio_env`: every reply lost inside a dropout window, the
NLOS outlier probability inside a burst window), in the truth message it sends the mothership, so one
schedule decides for every runner.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba
import numpy as np

from swarm.core import range_errors as re_
from swarm.core import tdoa_radio as tr
from swarm.core._rot_nb import qrotate
from swarm.core.sensors import UwbRadio, UwbSample, uwb_exchange
from swarm.step.streams import seed_sequence, stream

NOISE_BLOCK = 1024
"""Exchanges of pre-drawn normals per radio; the ranges are the same for any block size
(:attr:`UwbNetwork.noise_block`)."""


@numba.njit(cache=True)
def radio_env(t_s, drop_w, nlos_w):
    """``(lost, nlos_probability)`` at ``t_s`` [s]: inside one of the dropout windows ``drop_w`` (m, 2)
    ``[start, end)``, and the largest outlier probability of the NLOS burst windows ``nlos_w`` (m, 3)
    ``[start, end, p]`` that contain ``t_s`` (0 outside every one). An exchange is an outlier when its
    uniform is below the probability of any window that holds it, i.e. below their largest."""
    lost = False
    for i in range(drop_w.shape[0]):
        if drop_w[i, 0] <= t_s < drop_w[i, 1]:
            lost = True
            break
    p = 0.0
    for i in range(nlos_w.shape[0]):
        if nlos_w[i, 0] <= t_s < nlos_w[i, 1] and nlos_w[i, 2] > p:
            p = nlos_w[i, 2]
    return lost, p


@dataclass(frozen=True)
class TdoaSample:
    """The distance differences one tag heard since the last UWB tick (``uwb.mode`` tdoa2/tdoa3)."""

    t_s: float
    rows: np.ndarray
    """(K, 3): anchor ``A``, anchor ``B``, ``d_B - d_A`` [m] (the Crazyflie's ``distanceDiff``), in the order
    heard."""


TDOA_MARGIN_S = 5.0
"""The TDoA channel is simulated over the run's longest duration plus this [s]."""


class UwbNetwork:
    """The mothership's simulated radio network (module docstring)."""

    noise_block = NOISE_BLOCK
    """Exchanges per radio of a refill of the pre-drawn noise (:meth:`reserve_noise`); a mothership process
    draws smaller blocks, more often, so that no tick of its ranges stalls."""

    def __init__(self, scenario, seed: int) -> None:
        self.sc = scenario
        self.ids = list(scenario.vehicles)
        n = len(self.ids)
        self.anchors = np.ascontiguousarray(scenario.anchors_m, dtype=float)
        self.lever = np.array([scenario.kind(v).mounts.tag_lever_arm_body_m for v in self.ids], dtype=float)
        radio = UwbRadio(self.anchors, scenario.uwb)  # validates the parameters against the anchors
        self.prm = radio.vector
        self.drift = np.array([radio.drift_rate(i) for i in range(len(self.anchors))])
        self.rng = {vid: stream(seed, i, "uwb") for i, vid in enumerate(self.ids)}
        self.every = scenario.every(scenario.uwb.rate_hz)
        self.next_anchor = np.zeros(n, dtype=np.int64)
        self.noise = np.zeros((n, 0, 4))
        self.ui = np.zeros(1, dtype=np.int64)
        self.lost = np.zeros(n, dtype=np.bool_)
        self.anchor_id = np.zeros(n, dtype=np.int64)
        self.range_m = np.zeros(n)
        self.outlier = np.zeros(n, dtype=np.bool_)
        self.env_lost = np.zeros(n, dtype=np.bool_)
        self.env_p = np.zeros(n)
        # TDMA (uwb.tdma): each tag's slot (-1: off) and (slot length, frame length, UWB tick period);
        # per tag, whether this tick had no slot of it, whether it collided, and the collisions so far
        self.tdma_slot, self.tdma_prm = tdma_channel(scenario)
        self.idle = np.zeros(n, dtype=np.bool_)
        self.collided = np.zeros(n, dtype=np.bool_)
        self.collisions = np.zeros(n, dtype=np.int64)
        # the range errors of real flights (swarm.core.range_errors), off unless [uwb] switches them on: the
        # per-anchor offsets (one stream for the network), each link's take-off step, state and draws (a
        # stream per vehicle, uwb_errors), so that switching them on changes no other draw
        u, m = scenario.uwb, len(self.anchors)
        self.err_prm = re_.range_error_vector(u)
        self.err_on = bool(self.err_prm[re_.RE_ON])
        self.airborne = np.array([not scenario.kind(v).planar for v in self.ids], dtype=np.bool_)
        self.err_state = np.zeros((n, m, re_.RS_N))
        self.err_state[:, :, re_.RS_T] = np.nan
        self.err_offset, self.err_step = np.zeros(m), np.zeros((n, m))
        self.err_noise = np.zeros((n, 0, re_.ERR_DRAWS))
        self.err_rng = {}
        if self.err_on:
            self.err_offset = re_.draw_offsets(u, stream(seed, 0, "uwb_anchors"), m)
            self.err_rng = {vid: stream(seed, i, "uwb_errors") for i, vid in enumerate(self.ids)}
            self.err_step = np.array([re_.draw_steps(u, self.err_rng[v], m) for v in self.ids]).reshape(n, m)
        # TDoA (uwb.mode tdoa2/tdoa3): one channel heard by every tag, its own streams ("tdoa"); the range
        # errors of each link drawn as the TWR radios draw theirs
        self.tdoa = None
        self.heard: dict[str, TdoaSample] = {}  # each tag's differences of the last TDoA slot (_tdoa_step)
        if u.mode != "twr":
            errors = None
            if self.err_on:
                errors = tr.LinkErrors(self.err_prm, self.err_offset, self.err_step)
            params = replace(scenario.tdoa, mode=u.mode)
            duration = float(scenario.sim.max_duration_s) + TDOA_MARGIN_S
            ss = seed_sequence(seed, 0, "tdoa")
            self.tdoa = tr.TdoaRadio(params, self.anchors, n, duration, ss, errors)

    def reserve_noise(self, exchanges: int) -> None:
        """Pre-draw the normals of the next ``exchanges`` exchanges of every radio (four each)."""
        used = int(self.ui[0])
        if used + exchanges <= self.noise.shape[1]:
            return
        rows = max(self.noise_block, exchanges)
        new = np.empty((self.noise.shape[0], rows, 4))
        left = self.noise.shape[1] - used
        for i, vid in enumerate(self.ids):
            new[i, :left] = self.noise[i, used:]
            new[i, left:] = self.rng[vid].standard_normal((rows - left, 4))
        if self.err_on:  # the range errors' draws, row for row with the exchanges'
            err = np.empty((self.noise.shape[0], rows, re_.ERR_DRAWS))
            for i, vid in enumerate(self.ids):
                err[i, :left] = self.err_noise[i, used:]
                err[i, left:] = self.err_rng[vid].standard_normal((rows - left, re_.ERR_DRAWS))
            self.err_noise = err
        self.noise, self.ui[0] = new, 0

    def step(self, k: int, t_s: float, truth, env_lost=None, env_p=None) -> dict[str, UwbSample]:
        """Ranges of tick ``k`` from the truth states (13,) of each vehicle (a ``{id: state}`` map or an
        ``(n, 13)`` array in vehicle order) in the radio environment ``env_lost`` / ``env_p`` ((n,) each,
        or one value for all; :func:`radio_env`; ``None``: a clear channel): ``{id: UwbSample}``; a vehicle
        is missing when it has no exchange this tick or the reply was lost."""
        if k % self.every:
            return {}
        X = np.ascontiguousarray([truth[v] for v in self.ids]) if isinstance(truth, dict) else truth
        if self.tdoa is not None:
            return self._tdoa_step(t_s, X, env_lost)
        self.env_lost[:] = False if env_lost is None else env_lost
        self.env_p[:] = 0.0 if env_p is None else env_p
        self.reserve_noise(1)
        uwb_tick(
            t_s, X, self.lever, self.anchors, self.drift, self.prm, self.next_anchor, self.noise, self.ui,
            self.env_lost, self.env_p, self.lost, self.anchor_id, self.range_m, self.outlier,
            self.tdma_slot, self.tdma_prm, self.idle, self.collided, self.collisions,
        )  # fmt: skip
        uwb_errors_tick(t_s, self.lost, self.anchor_id, self.range_m, self.outlier, self.airborne,
                        self.err_state, self.err_offset, self.err_step, self.err_noise, self.ui,
                        self.err_prm)  # fmt: skip
        return {
            vid: UwbSample(t_s, int(self.anchor_id[i]), float(self.range_m[i]), bool(self.outlier[i]))
            for i, vid in enumerate(self.ids)
            if not self.lost[i]
        }

    def _tdoa_step(self, t_s: float, X: np.ndarray, env_lost) -> dict[str, TdoaSample]:
        """Each tag's distance differences of the packets sent up to ``t_s``, heard at its tag position
        (truth position plus the lever arm turned by the truth attitude); a vehicle inside a dropout window
        hears nothing (its rows are drawn and dropped, so the channel's draws do not depend on faults)."""
        tags = np.array([X[i, 0:3] + qrotate(X[i, 6:10], self.lever[i]) for i in range(len(self.ids))])
        rows = self.tdoa.step(t_s, tags, self.airborne)
        lost = np.broadcast_to(np.asarray(False if env_lost is None else env_lost), (len(self.ids),))
        # kept for the mothership's messages (swarm.transport.wire.tdoa_slot), as the TWR radios'
        # ranges are kept in range_m
        self.heard = {
            vid: TdoaSample(t_s, np.ascontiguousarray(rows[i][:, [tr.ROW_A, tr.ROW_B, tr.ROW_DDIST]]))
            for i, vid in enumerate(self.ids)
            if not lost[i] and len(rows[i])
        }
        return self.heard


def tdma_slots(scenario) -> tuple[np.ndarray, int]:
    """``(slot of each vehicle's tag (n,), frame length in slots)`` of the scenario's TDMA channel
    (:class:`swarm.core.sensors.UwbParams`): slots ``address % frame``, the frame ``uwb.tdma_frame_slots``
    or the smallest power of two >= the number of tags; slots all -1 (and frame 1) when TDMA is off."""
    ids = list(scenario.vehicles)
    n = len(ids)
    if not scenario.uwb.tdma:
        return np.full(n, -1, dtype=np.int64), 1
    frame = scenario.uwb.tdma_frame_slots or 1 << max(0, (n - 1).bit_length())
    addresses = [scenario.vehicles[v].uwb_address for v in ids]
    slots = np.array([(i if a is None else a) % frame for i, a in enumerate(addresses)], dtype=np.int64)
    return slots, frame


def exchange_ticks(scenario, vehicle_id: str):
    """The UWB slot ticks on which ``vehicle_id``'s tag has an exchange, as a predicate of the tick ``k``
    (``k % every == 0`` assumed): with TDMA on, those whose period holds the tag's slot (:func:`tdma_has_slot`
    at ``t = k * dt``, as :meth:`UwbNetwork.step` has it); ``None`` with TDMA off (every slot tick). On the
    other ticks the tag is idle: no range, and the mothership sends no ``uwb`` for it (docs/protocol.md,
    "Rates"), so a lockstep agent does not wait for one."""
    slots, prm = tdma_channel(scenario)
    slot = int(slots[list(scenario.vehicles).index(vehicle_id)])
    if slot < 0:
        return None
    dt = scenario.dt_s
    return lambda k: bool(tdma_has_slot(k * dt, slot, prm))


def tdma_channel(scenario) -> tuple[np.ndarray, np.ndarray]:
    """``(each tag's slot (n,), tdma_prm)`` of the scenario's TDMA channel: :func:`tdma_slots` and the
    parameters :func:`tdma_has_slot` takes, ``(slot length [s], frame length [slots], UWB period [s])``."""
    slots, frame = tdma_slots(scenario)
    period_s = scenario.every(scenario.uwb.rate_hz) * scenario.dt_s
    return slots, np.array([scenario.uwb.tdma_slot_s, float(frame), period_s])


@numba.njit(cache=True)
def tdma_has_slot(t_s, slot, tdma_prm):
    """Whether the tag of TDMA ``slot`` had its slot in the UWB tick period ``(t_s - period, t_s]``:
    its slots start at ``(m * frame + slot) * slot_s``, ``m = 0, 1, ...`` (``tdma_prm`` = ``(slot_s, frame,
    period)``). At most one counts per period: the tick carries one range per tag."""
    slot_s, frame, period = tdma_prm[0], tdma_prm[1], tdma_prm[2]
    eps = 1e-9 * slot_s  # t_s is k * dt: a slot start on a tick boundary belongs to the period it ends
    m = np.floor((t_s + eps) / (frame * slot_s) - slot / frame)
    if m < 0:
        return False
    start = (m * frame + slot) * slot_s
    return start > t_s - period + eps


@numba.njit(cache=True)
def uwb_tick(t_s, X, lever, anchors, drift, prm, next_anchor, noise, ui, env_lost, env_p, lost, anchor_id,
             range_m, outlier, tdma_slot, tdma_prm, idle, collided, collisions):  # fmt: skip
    """One exchange of every radio at ``t_s`` from the truth ``X`` (n, 13) in the radio environment
    ``env_lost``/``env_p`` (n,): the tag is ``p + R(q) P1`` (paper Fig. 2, ``lever`` (n, 3) per vehicle),
    the anchor the next in round robin (which advances even when the reply is lost). With TDMA on
    (``tdma_slot[v] >= 0``, :func:`tdma_slots`), a tag whose slot did not come in this tick's period has
    no exchange (``idle``, ``lost``, its anchor kept), and tags that share a slot collide: both exchanges
    lost (``collided``, ``collisions`` counted), their anchors advanced. The exchange is evaluated on the
    truth at ``t_s``, at most one UWB period after its slot (a vehicle at 2 cm/s moves 0.4 mm in 20 ms)."""
    n = X.shape[0]
    for v in range(n):
        idle[v] = tdma_slot[v] >= 0 and not tdma_has_slot(t_s, tdma_slot[v], tdma_prm)
        collided[v] = False
    for v in range(n):
        if tdma_slot[v] < 0 or idle[v]:
            continue
        for u in range(n):
            if u != v and not idle[u] and tdma_slot[u] == tdma_slot[v]:
                collided[v] = True
                collisions[v] += 1
                break
    for v in range(n):
        if idle[v]:
            lost[v], outlier[v] = True, False
            continue
        tag = X[v, 0:3] + qrotate(X[v, 6:10], lever[v])
        i = next_anchor[v]
        next_anchor[v] = (i + 1) % anchors.shape[0]
        anchor_id[v] = i
        lost[v], range_m[v], outlier[v] = uwb_exchange(
            t_s, tag, anchors[i], noise[v, ui[0]], drift[i], prm, env_lost[v], env_p[v]
        )
        if collided[v]:
            lost[v], outlier[v] = True, False
    ui[0] += 1


@numba.njit(cache=True)
def uwb_errors_tick(t_s, lost, anchor_id, range_m, outlier, airborne, state, offset, step, noise, ui, prm):
    """The range errors of real flights (:mod:`swarm.core.range_errors`) added to the exchanges
    :func:`uwb_tick` just made (its noise row ``ui[0] - 1``): every reply not lost gets
    :func:`~swarm.core.range_errors.range_error_step` of its vehicle-anchor link, clipped at zero as the
    exchange's range is; one in an NLOS episode is marked an outlier. Nothing when ``prm`` is off."""
    if prm[re_.RE_ON] == 0.0:
        return
    row = ui[0] - 1
    for v in range(range_m.shape[0]):
        if lost[v]:
            continue
        a = anchor_id[v]
        extra, blocked = re_.range_error_step(
            t_s, airborne[v], state[v, a], noise[v, row], prm, offset[a], step[v, a]
        )
        r = range_m[v] + extra
        range_m[v] = r if r > 0.0 else 0.0
        outlier[v] = outlier[v] or blocked


def clear_env(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The radio environment of ``n`` vehicles on a clear channel: nothing lost, no NLOS burst."""
    return np.zeros(n, dtype=np.bool_), np.zeros(n)
