"""The simulated world: truth dynamics of every vehicle and their on-board sensors (gyro, AHRS, camera),
and the mothership's simulated UWB radio network.

Like :class:`swarm.core.agent.VehicleAgent`, these objects do no I/O: the world process and the
mothership process (issue 4) wrap them, and the in-process simulation calls them directly, in the same
order, with the same random streams (:func:`stream`), so one seed is one trajectory in either runner.

Tick ``k`` is time ``t_k = k dt``. :meth:`World.step` applies each vehicle's held nozzle thrusts over
``[t_k, t_k+1]`` (paper eq. 1-2, :func:`swarm.core.dynamics.propagate`) and returns the sensor samples
of tick ``k + 1``: the gyro reports the mean body rate over the step (the delta-angle an IMU integrates)
plus noise and bias; the camera, at its rate, what the chaser sees of its target's docking face.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from swarm.core._rot_nb import qconj, qexp, qlog, qmul, qnormalize, qrotate
from swarm.core.camera import camera_pose_nav, feature_vectors, project_markers, visible
from swarm.core.dynamics import propagate
from swarm.core.guidance import contact_state, pair_geometry
from swarm.core.sensors import (
    UwbRadio,
    UwbSample,
    _gyro_kernel,
    gyro_init_bias,
    uwb_exchange,
    uwb_fault_vector,
)
from swarm.core.thrusters import allocation_matrix

NOISE_BLOCK = 1024
"""Rows of pre-drawn standard normals per sensor stream; drawn in blocks from the stream's Generator,
which gives the very sequence of one draw per sample (numpy fills arrays in order)."""

# world parameter vector (``World.prm``)
W_DT, W_MASS, W_IXX, W_IYY, W_IZZ, W_HMAX, W_SW, W_PHI, W_SB, W_AHRS_SIGMA = range(10)

STREAMS = ("init", "gyro", "ahrs", "camera", "uwb")


def stream(seed: int, vehicle_index: int, name: str) -> np.random.Generator:
    """The random stream ``name`` of vehicle ``vehicle_index`` for root ``seed``: independent streams from
    one ``SeedSequence`` (spawn keys), the same in every process that asks for them."""
    key = (int(vehicle_index), STREAMS.index(name))
    return np.random.default_rng(np.random.SeedSequence(entropy=int(seed), spawn_key=key))


def initial_state(scenario, vehicle_id: str) -> np.ndarray:
    """Truth state (13,) of ``vehicle_id`` at tick 0: at rest at its scenario position and attitude,
    ``[p_nav, v_nav, q_nav_body, w_body]``. An agent process derives its initial estimate from it exactly as
    :class:`World` starts, so neither runner needs the other's objects."""
    x = np.zeros(13)
    x[0:3] = scenario.vehicles[vehicle_id].position_m
    x[6:10] = scenario.q0(vehicle_id)
    return x


@dataclass
class SensorFrame:
    """The on-board sensor samples of one vehicle at one tick."""

    t_s: float
    gyro_body: np.ndarray
    q_ahrs_nav_body: np.ndarray | None = None
    vision_kind: str | None = None  # "features" or "pixels"
    vision: np.ndarray | None = None


class World:
    """Truth of every vehicle of a scenario and their on-board sensors (module docstring)."""

    def __init__(self, scenario, seed: int) -> None:
        sc = scenario
        self.sc = sc
        self.ids = list(sc.vehicles)
        self.index = {vid: i for i, vid in enumerate(self.ids)}
        n = len(self.ids)
        self.dt = sc.dt_s
        self.k = 0
        self.B = allocation_matrix(sc.thrusters)
        g = sc.gyro
        phi = math.exp(-self.dt / g.bias_corr_time_s) if g.enabled_bias else 1.0
        s_b = g.bias_sigma_rad_s * math.sqrt(1.0 - phi * phi) if g.enabled_bias else 0.0
        self.prm = np.array(
            [self.dt, sc.dynamics.mass_kg, *sc.dynamics.inertia_diag_kgm2, sc.dynamics.integration_step_s,
             g.arw_rad_rts / math.sqrt(self.dt), phi, s_b, sc.ahrs.sigma_rad]
        )  # fmt: skip
        # truth and actuator state, one row per vehicle (views by id in ``x``)
        self.X = np.zeros((n, 13))
        self.thrusts = np.zeros((n, self.B.shape[1]))
        self.wrench = np.zeros((n, 6))
        self.thrust_sum = np.zeros(n)
        self.impulse = np.zeros(n)
        self.attached_arr = np.zeros(n, dtype=np.bool_)
        self.bias = np.zeros((n, 3))
        self.rng: dict[tuple[str, str], np.random.Generator] = {}
        for i, vid in enumerate(self.ids):
            self.X[i] = initial_state(sc, vid)
            for name in ("gyro", "ahrs", "camera"):
                self.rng[vid, name] = stream(seed, i, name)
            self.bias[i] = gyro_init_bias(sc.gyro, self.rng[vid, "gyro"])
        self.x = {vid: self.X[i] for i, vid in enumerate(self.ids)}
        self.gyro_noise = np.zeros((n, 0, 6))
        self.gi = np.zeros(1, dtype=np.int64)
        self.ahrs_noise = np.zeros((n, 0, 3))
        self.ai = np.zeros(1, dtype=np.int64)
        # how the current noise block of each stream was drawn (the streams' states before the draw, the
        # rows carried over, the block's length), so that a snapshot re-draws it instead of copying it
        # (states, carried rows, their bytes, block rows)
        self._blocks: dict[str, tuple[list[dict], int, bytes, int] | None] = {"gyro": None, "ahrs": None}
        self.gyro_out = np.zeros((n, 3))
        self.ahrs_out = np.zeros((n, 4))
        self.markers_target = sc.markers.markers(sc.guidance.docking_face)
        self.vision_every = sc.every(sc.camera.rate_hz)
        self.ahrs_every = sc.every(sc.ahrs.rate_hz)
        # faults (swarm.core.faults): the gyro bias step per vehicle (time inf: none) and the windows in
        # which a chaser's camera is lost, fixed ones from the scenario, mode-triggered ones set by a runner
        self.gyro_step_t = np.full(n, np.inf)
        self.gyro_step = np.zeros((n, 3))
        for i, vid in enumerate(self.ids):
            self.gyro_step_t[i], self.gyro_step[i] = sc.faults.gyro_step_rad_s(vid, sc.chasers)
        self.camera_loss: dict[str, list] = {c: list(sc.faults.camera_loss.windows_s) for c in sc.chasers}
        self.camera_frames_lost = 0
        """Camera frames with the target in view dropped by a camera-loss window (a fault's footprint)."""

    @property
    def impulse_ns(self) -> dict[str, float]:
        """Total impulse so far per vehicle, sum over nozzles of |f| dt [N s]."""
        return {vid: float(self.impulse[i]) for i, vid in enumerate(self.ids)}

    @property
    def attached(self) -> dict[str, bool]:
        return {vid: bool(self.attached_arr[i]) for i, vid in enumerate(self.ids)}

    @property
    def t_s(self) -> float:
        return self.k * self.dt

    def reserve_noise(self, ticks: int) -> None:
        """Make sure the pre-drawn noise covers the next ``ticks`` ticks (no sample is ever discarded)."""
        self.gyro_noise, self.gi[0] = self._refill(self.gyro_noise, int(self.gi[0]), ticks, "gyro")
        ahrs_ticks = ticks // self.ahrs_every + 1
        self.ahrs_noise, self.ai[0] = self._refill(self.ahrs_noise, int(self.ai[0]), ahrs_ticks, "ahrs")

    def _refill(self, buf: np.ndarray, used: int, need: int, name: str) -> tuple[np.ndarray, int]:
        if used + need <= buf.shape[1]:
            return buf, used
        carried = buf[:, used:].copy()
        states = [self.rng[vid, name].bit_generator.state for vid in self.ids]
        rows = max(NOISE_BLOCK, need)
        self._blocks[name] = (states, carried.shape[1], carried.tobytes(), rows)
        return self._draw_block(name, carried, rows), 0

    def _draw_block(self, name: str, carried: np.ndarray, rows: int) -> np.ndarray:
        """A noise block of ``rows`` rows per vehicle: the ``carried`` rows (n, left, d) not yet used,
        then fresh normals of each vehicle's stream ``name``."""
        left = carried.shape[1]
        new = np.empty((carried.shape[0], rows, carried.shape[2]))
        for i, vid in enumerate(self.ids):
            new[i, :left] = carried[i]
            new[i, left:] = self.rng[vid, name].standard_normal((rows - left, carried.shape[2]))
        return new

    # ---- snapshots (a world process's checkpoint) ----------------------------------------------------
    _ARRAYS = ("X", "thrusts", "wrench", "thrust_sum", "impulse", "attached_arr", "bias", "gyro_out",
               "ahrs_out", "gyro_step_t", "gyro_step")  # fmt: skip

    def snapshot(self) -> dict:
        """Everything of this world that changes while it runs, as copies: the arrays as raw bytes (C
        order, their own dtypes; pickling an ndarray costs ~4 us, its bytes 0.3 us), ints, lists and the
        random streams' ``bit_generator.state`` dicts. :meth:`restore` on a ``World`` of the same scenario
        and seed continues exactly where this one is, bit for bit. The pre-drawn noise blocks are not
        copied (up to 1024 rows per vehicle) but re-drawn on restore from the streams' states before their
        draw, which costs nothing per tick."""
        snap = {name: getattr(self, name).tobytes() for name in self._ARRAYS}
        snap.update(
            k=self.k, gi=int(self.gi[0]), ai=int(self.ai[0]), blocks=dict(self._blocks),
            rng={key: g.bit_generator.state for key, g in self.rng.items()},
            camera_loss={c: list(w) for c, w in self.camera_loss.items()},
            camera_frames_lost=self.camera_frames_lost,
        )  # fmt: skip
        return snap

    def restore(self, snap: dict) -> None:
        """Continue from :meth:`snapshot` ``snap`` (of a world of this scenario and seed). ValueError if it
        does not fit: another number of vehicles, or random streams that do not end where they ended."""
        for name in self._ARRAYS:
            raw, mine = snap[name], getattr(self, name)
            if len(raw) != mine.nbytes:
                raise ValueError(f"snapshot {name}: {len(raw)} bytes, this world's has {mine.nbytes}")
            mine[...] = np.frombuffer(raw, dtype=mine.dtype).reshape(mine.shape)  # in place: x views X
        self.k = int(snap["k"])
        for name, bufname, idx in (("gyro", "gyro_noise", "gi"), ("ahrs", "ahrs_noise", "ai")):
            block = snap["blocks"][name]
            self._blocks[name] = block
            width = getattr(self, bufname).shape[2]
            if block is None:
                setattr(self, bufname, np.zeros((len(self.ids), 0, width)))
            else:
                states, left, raw, rows = block
                carried = np.frombuffer(raw, dtype=np.float64).reshape(len(self.ids), left, width)
                for vid, state in zip(self.ids, states, strict=True):
                    self.rng[vid, name].bit_generator.state = state
                setattr(self, bufname, self._draw_block(name, carried, rows))
            getattr(self, idx)[0] = int(snap[idx])
        for key, state in snap["rng"].items():
            g = self.rng[key]
            if key[1] == "camera":
                g.bit_generator.state = state
            elif g.bit_generator.state != state:  # re-drawing the block must end where the stream was
                raise ValueError(f"snapshot: random stream {key} does not end where it did")
        self.camera_loss = {c: list(w) for c, w in snap["camera_loss"].items()}
        self.camera_frames_lost = int(snap["camera_frames_lost"])

    def set_command(self, vehicle_id: str, thrusts_n) -> None:
        """Nozzle thrusts [N] to hold from now on (clipped to the nozzles' range: a command cannot make a
        nozzle pull or exceed its maximum). Ignored once the vehicle is docked (:meth:`attach`)."""
        i = self.index[vehicle_id]
        if self.attached_arr[i]:
            return
        f = np.asarray(thrusts_n, dtype=float)
        if self.thrust_sum[i] == 0.0 and f.shape == self.thrusts[i].shape and not f.any():
            return  # still all off: nothing to recompute
        f = np.clip(f, 0.0, self.sc.thrusters.max_thrust_n)
        self.thrusts[i] = np.where(np.isfinite(f), f, 0.0)
        self.wrench[i] = self.B @ self.thrusts[i]
        self.thrust_sum[i] = float(np.sum(self.thrusts[i]))

    def step(self, build_frames: bool = True) -> dict[str, SensorFrame] | None:
        """Advance every vehicle by one tick and return the sensor frames of the new tick (``None`` with
        ``build_frames=False``: the samples stay in ``gyro_out``/``ahrs_out``, and the caller vouches that
        no camera can see its target, so no camera frame is skipped)."""
        self.reserve_noise(1)
        k1 = self.k + 1
        do_ahrs = self.sc.ahrs.enabled and k1 % self.ahrs_every == 0
        world_tick(
            self.X, self.wrench, self.thrust_sum, self.attached_arr, self.impulse, self.bias, self.gyro_noise,
            self.gi, self.ahrs_noise, self.ai, do_ahrs, self.prm, self.gyro_out, self.ahrs_out,
            self.k * self.dt, self.gyro_step_t, self.gyro_step,
        )  # fmt: skip
        self.k = k1
        return self.frames() if build_frames else None

    def frames(self) -> dict[str, SensorFrame]:
        """The sensor frames of the current tick ``k`` from the last :func:`world_tick` (gyro, AHRS) and,
        at camera ticks, what each chaser sees."""
        k1 = self.k
        t1 = k1 * self.dt
        do_ahrs = self.sc.ahrs.enabled and k1 % self.ahrs_every == 0
        frames = {
            vid: SensorFrame(t1, self.gyro_out[i].copy(), self.ahrs_out[i].copy() if do_ahrs else None)
            for i, vid in enumerate(self.ids)
        }
        if k1 % self.vision_every == 0:
            for vid in self.ids:
                spec = self.sc.vehicles[vid]
                if spec.role == "chaser":
                    self._vision(vid, spec.target, frames[vid])
        return frames

    def _vision(self, chaser: str, target: str, frame: SensorFrame) -> None:
        cam = self.sc.camera
        xc, xt = self.x[chaser], self.x[target]
        p_cam, q_cam = camera_pose_nav(xc[0:3], xc[6:10], cam)
        if not visible(p_cam, q_cam, xt[0:3], xt[6:10], self.sc.guidance.docking_face, cam, self.sc.markers):
            return
        rng = self.rng[chaser, "camera"]
        if cam.model == "pnp":
            frame.vision_kind = "pixels"
            frame.vision = project_markers(self.markers_target, xt[0:3], xt[6:10], p_cam, q_cam, cam, rng)
        else:
            frame.vision_kind = "features"
            frame.vision = feature_vectors(self.markers_target, xt[0:3], xt[6:10], p_cam, q_cam, cam, rng)
        if any(w[0] <= frame.t_s < w[1] for w in self.camera_loss.get(chaser, ())):
            # camera lost (a fault): the frame was drawn, so the camera stream stays aligned, and dropped
            frame.vision_kind = frame.vision = None
            self.camera_frames_lost += 1

    # ---- truth-side metrics -------------------------------------------------------------------------
    def contact(self, chaser: str, target: str) -> dict:
        """Port-to-port geometry of a pair on the truth (:func:`swarm.core.guidance.contact_state`)."""
        xc, xt = self.x[chaser], self.x[target]
        return contact_state(self.sc.guidance, xc[0:3], xc[3:6], xc[6:10], xt[0:3], xt[6:10], xt[3:6])

    def keepout_violated(self, chaser: str, target: str, docking: bool) -> bool:
        """The chaser's centre inside the target's keep-out sphere, outside the docking corridor (or
        inside it while not docking)."""
        g = self.sc.guidance
        xc, xt = self.x[chaser], self.x[target]
        geo = pair_geometry(
            xc[0:3], xc[3:6], xc[6:10], xt[0:3], xt[3:6], xt[6:10], g.face_normal_target,
            g.q_target_chaser_docked, g.half_size_m,
        )  # fmt: skip
        return keepout_from_geometry(geo[0], geo[5], g.keepout_radius_m, g.corridor_cos, docking)

    def attach(self, chaser: str, target: str) -> None:
        """Docked: the chaser rides with the target from now on (no further propagation)."""
        self.set_command(chaser, np.zeros(self.thrusts.shape[1]))
        self.attached_arr[self.index[chaser]] = True


@numba.njit(cache=True)
def world_tick(X, wrench, thrust_sum, attached, impulse, bias, gyro_noise, gi, ahrs_noise, ai, do_ahrs, prm,
               gyro_out, ahrs_out, t_s, step_t, step):  # fmt: skip
    """Advance every vehicle one tick (in place) and write its sensor samples.

    Truth: :func:`swarm.core.dynamics.propagate` with the held wrench (paper eq. 1-2); impulse
    ``+= sum |f| dt``. Gyro: the mean body rate over the tick, ``log(q0^-1 (x) q1) / dt`` (the delta-angle
    an IMU integrates), plus white noise and the Gauss-Markov bias of ``sensors.gyro_sample`` on the next
    pre-drawn normals. AHRS (when ``do_ahrs``): ``q (x) exp(sigma z)`` as ``sensors.ahrs_sample``.
    A gyro bias step (a fault, :mod:`swarm.core.faults`): ``step[v]`` [rad/s] adds to vehicle ``v``'s
    sample of the tick starting at ``t_s`` [s] when ``t_s >= step_t[v]`` (``inf``: never).
    """
    dt = prm[W_DT]
    inertia = prm[W_IXX : W_IZZ + 1]
    z = np.empty(6)
    for v in range(X.shape[0]):
        x0 = X[v].copy()
        if not attached[v]:
            X[v] = propagate(x0, wrench[v, 0:3], wrench[v, 3:6], dt, prm[W_MASS], inertia, prm[W_HMAX])
            impulse[v] += thrust_sum[v] * dt
        w = qlog(qmul(qconj(x0[6:10]), X[v, 6:10]))
        for i in range(3):
            w[i] /= dt
        z[:] = gyro_noise[v, gi[0]]
        _gyro_kernel(w, bias[v], z, prm[W_SW], prm[W_PHI], prm[W_SB])
        if t_s >= step_t[v]:
            for i in range(3):
                z[i] += step[v, i]
        gyro_out[v] = z[0:3]
        bias[v] = z[3:6]
        if do_ahrs:
            e = np.empty(3)
            for i in range(3):
                e[i] = prm[W_AHRS_SIGMA] * ahrs_noise[v, ai[0], i]
            ahrs_out[v] = qnormalize(qmul(X[v, 6:10], qexp(e)))
    gi[0] += 1
    if do_ahrs:
        ai[0] += 1


class UwbNetwork:
    """The mothership's simulated radio network: one round-robin UWB radio per agent (paper sec. III),
    each with its own ``uwb`` stream; the exchange itself is :func:`swarm.core.sensors.uwb_exchange`."""

    def __init__(self, scenario, seed: int) -> None:
        self.sc = scenario
        self.ids = list(scenario.vehicles)
        n = len(self.ids)
        self.anchors = np.ascontiguousarray(scenario.anchors_m, dtype=float)
        self.lever = np.asarray(scenario.tag_lever_arm_body_m, dtype=float)
        radio = UwbRadio(self.anchors, scenario.uwb)  # validates the parameters against the anchors
        self.base_prm = radio.vector
        f = scenario.faults
        self.prm = self.base_prm
        self.set_fault_windows(
            f.uwb_dropout.windows_s,
            [(a, b, f.nlos_burst_probability) for a, b in f.nlos_burst.windows_s]
            if f.nlos_burst_probability
            else [],
        )
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

    def set_fault_windows(self, dropouts, nlos_bursts) -> None:
        """Every fault window of the network from now on (:mod:`swarm.core.faults`): dropout windows
        ``(start, end)`` and NLOS bursts ``(start, end, probability)`` [s], on top of
        ``uwb.dropout_windows_s`` (a :class:`~swarm.core.faults.FaultSchedule` gives both lists, fixed
        windows included)."""
        self.prm = uwb_fault_vector(self.base_prm, dropouts, nlos_bursts)

    def reserve_noise(self, exchanges: int) -> None:
        """Pre-draw the normals of the next ``exchanges`` exchanges of every radio (four each)."""
        used = int(self.ui[0])
        if used + exchanges <= self.noise.shape[1]:
            return
        rows = max(NOISE_BLOCK, exchanges)
        new = np.empty((self.noise.shape[0], rows, 4))
        left = self.noise.shape[1] - used
        for i, vid in enumerate(self.ids):
            new[i, :left] = self.noise[i, used:]
            new[i, left:] = self.rng[vid].standard_normal((rows - left, 4))
        self.noise, self.ui[0] = new, 0

    def step(self, k: int, t_s: float, truth) -> dict[str, UwbSample]:
        """Ranges of tick ``k`` from the truth states (13,) of each vehicle (a ``{id: state}`` map or an
        ``(n, 13)`` array in vehicle order): ``{id: UwbSample}``; a vehicle is missing when it has no
        exchange this tick or the reply was lost."""
        if k % self.every:
            return {}
        X = np.ascontiguousarray([truth[v] for v in self.ids]) if isinstance(truth, dict) else truth
        self.reserve_noise(1)
        uwb_tick(
            t_s, X, self.lever, self.anchors, self.drift, self.prm, self.next_anchor, self.noise, self.ui,
            self.lost, self.anchor_id, self.range_m, self.outlier,
        )  # fmt: skip
        return {
            vid: UwbSample(t_s, int(self.anchor_id[i]), float(self.range_m[i]), bool(self.outlier[i]))
            for i, vid in enumerate(self.ids)
            if not self.lost[i]
        }


@numba.njit(cache=True)
def uwb_tick(t_s, X, lever, anchors, drift, prm, next_anchor, noise, ui, lost, anchor_id, range_m, outlier):
    """One exchange of every radio at ``t_s`` from the truth ``X`` (n, 13): the tag is
    ``p + R(q) P1`` (paper Fig. 2), the anchor the next in round robin (which advances even when the
    reply is lost)."""
    for v in range(X.shape[0]):
        tag = X[v, 0:3] + qrotate(X[v, 6:10], lever)
        i = next_anchor[v]
        next_anchor[v] = (i + 1) % anchors.shape[0]
        anchor_id[v] = i
        lost[v], range_m[v], outlier[v] = uwb_exchange(t_s, tag, anchors[i], noise[v, ui[0]], drift[i], prm)
    ui[0] += 1


@numba.njit(cache=True)
def keepout_from_geometry(centre, axial, keepout_r, corridor_cos, docking):
    """Keep-out violation from :func:`swarm.core.guidance.pair_geometry`'s centre distance and axial
    offset: inside the sphere and not (docking inside the corridor)."""
    if centre >= keepout_r:
        return False
    return not (docking and axial >= centre * corridor_cos)
