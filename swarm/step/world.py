"""The world step: truth dynamics of every vehicle and their on-board sensors (gyro, AHRS, camera).

:class:`World` holds a run's truth and is stepped by every runner: the in-process simulation calls it
directly, the world process (``python -m swarm.world``) wraps it, in the same order, with the same random
streams (:func:`stream`), so one seed is one trajectory in either runner (docs/architecture.md, "The one
tick"). Each vehicle moves by its kind's dynamics (:mod:`swarm.kinds`); the run's randomness is the
world's own: it draws the dispersions (:mod:`swarm.kinds.dispersions`) and owns the fault schedule
(:class:`swarm.core.faults.FaultSchedule`), fed by the guidance modes the commands carry
(:meth:`World.take_commands`) and by run-time faults (:meth:`World.add_fault`), so no runner can miss them.

Tick ``k`` is time ``t_k = k dt``. :meth:`World.step` holds each vehicle's actuator command over
``[t_k, t_k+1]`` and returns the sensor samples of tick ``k + 1``: the gyro reports the mean body rate over
the step (the delta-angle an IMU integrates) plus noise and bias; the camera, at its rate, what the chaser
sees of its target's docking face. :meth:`World.radio_env` is the radio environment of a tick (UWB
dropouts and NLOS bursts) that the radio step (:mod:`swarm.step.radio`) applies.
"""

from __future__ import annotations

import math
import pickle
from dataclasses import dataclass

import numba
import numpy as np

from swarm.core._noise_nb import noise_key
from swarm.core._rot_nb import qconj, qexp, qlog, qmul, qnormalize, qrotate
from swarm.core.camera import (
    POSE_N,
    CameraModel,
    camera_pose_nav,
    features_frame,
    pose_frame,
    project_markers,
    visible,
)
from swarm.core.faults import FaultSchedule
from swarm.core.sensors import _gyro_kernel, gyro_init_bias
from swarm.kinds._dispatch import hold, truth_step
from swarm.kinds.dispersions import Dispersion, draw_dispersion
from swarm.step.radio import radio_env
from swarm.step.streams import STREAMS, stream  # noqa: F401 (re-exported)

NOISE_BLOCK = 1024
"""Rows of pre-drawn standard normals per sensor stream; drawn in blocks from the stream's Generator,
which gives the very sequence of one draw per sample (numpy fills arrays in order), whatever the block's
size (:attr:`World.noise_block`)."""

# world parameter vector (``World.prm``): the sensors' (each vehicle's dynamics are its kind's ``kp`` row)
W_DT, W_SW, W_PHI, W_SB, W_AHRS_SIGMA = range(5)


def nominal_state(scenario, vehicle_id: str) -> np.ndarray:
    """Nominal truth state (13,) of ``vehicle_id`` at tick 0: at rest at its scenario position and
    attitude, ``[p_nav, v_nav, q_nav_body, w_body]``, before dispersions."""
    x = np.zeros(13)
    x[0:3] = scenario.vehicles[vehicle_id].position_m
    x[6:10] = scenario.q0(vehicle_id)
    return x


def initial_truth(scenario, seed: int, vehicle_id: str, disp: Dispersion | None = None) -> np.ndarray:
    """The truth state (13,) of ``vehicle_id`` at tick 0 of run ``seed``: the nominal state with the run's
    dispersions (:func:`swarm.kinds.dispersions.draw_dispersion`). An agent process builds its initial
    estimate from it exactly as :class:`World` starts, so neither runner needs the other's objects."""
    from swarm.core import rotations as rot

    d = (disp or draw_dispersion(scenario, seed)).vehicles[vehicle_id]
    p = scenario.dispersions
    x = nominal_state(scenario, vehicle_id)
    if vehicle_id in scenario.chasers:
        if p.position_sigma_m > 0:
            x[0:3] += d.position_m
        if p.velocity_sigma_m_s > 0:
            x[3:6] += d.velocity_m_s
        if p.attitude_sigma_deg > 0:
            x[6:10] = rot.multiplicative_reset(x[6:10], d.attitude_rad)
    scenario.kind(vehicle_id).constrain_initial(x)
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

    noise_block = NOISE_BLOCK
    """Rows per vehicle of a refill of the pre-drawn noise (:meth:`reserve_noise`). The samples are the same
    for any size; a world process draws smaller blocks, more often, so that no tick stalls (1024 rows of 128
    vehicles' two streams take ~16 ms: a tick and a half of real time)."""

    def __init__(self, scenario, seed: int) -> None:
        sc = scenario
        self.sc = sc
        self.seed = int(seed)
        self.ids = list(sc.vehicles)
        self.index = {vid: i for i, vid in enumerate(self.ids)}
        n = len(self.ids)
        self.dt = sc.dt_s
        self.k = 0
        g = sc.gyro
        phi = math.exp(-self.dt / g.bias_corr_time_s) if g.enabled_bias else 1.0
        s_b = g.bias_sigma_rad_s * math.sqrt(1.0 - phi * phi) if g.enabled_bias else 0.0
        sigma_w = g.gyro_noise_rad_s_rthz / math.sqrt(self.dt)
        self.prm = np.array([self.dt, sigma_w, phi, s_b, sc.ahrs.sigma_rad])
        # truth and actuator state, one row per vehicle (views by id in ``x``), padded to the widest kind
        self.kinds = [sc.kind(vid) for vid in self.ids]
        self.codes = np.array([k.code for k in self.kinds], dtype=np.int64)
        self.dispersion = draw_dispersion(sc, self.seed)
        self.truth_act = [
            k.truth(self.dispersion.vehicles[vid]) for k, vid in zip(self.kinds, self.ids, strict=True)
        ]
        width = lambda attr: max(getattr(k, attr) for k in self.kinds)  # noqa: E731
        self.X = np.zeros((n, 13))
        self.S = np.zeros((n, width("S_N")))
        self.U = np.zeros((n, width("U_N")))
        self.KP = np.zeros((n, width("KP_N")))
        self.effort = np.zeros(n)
        """Each vehicle's effort so far in its kind's unit (total impulse [N s], wheel travel [rad])."""
        self.attached_arr = np.zeros(n, dtype=np.bool_)
        self.bias = np.zeros((n, 3))
        self.rng: dict[tuple[str, str], np.random.Generator] = {}
        for i, vid in enumerate(self.ids):
            self.X[i] = initial_truth(sc, self.seed, vid, self.dispersion)
            act = self.truth_act[i]
            self.KP[i, : len(act.kp)] = act.kp
            self.S[i, : len(act.s0)] = act.s0
            for name in ("gyro", "ahrs", "camera"):
                self.rng[vid, name] = stream(self.seed, i, name)
            self.bias[i] = gyro_init_bias(sc.gyro, self.rng[vid, "gyro"])
        self.x = {vid: self.X[i] for i, vid in enumerate(self.ids)}
        # each stream's bit_generator.state as of the last snapshot, and the streams drawn from since (a
        # draw must add its stream: the noise blocks' refills and the camera's pixels do; the state dicts
        # of 100 streams cost ~75 us to build, and most streams are drawn once per 1024 ticks)
        self._rng_state: dict[tuple[str, str], dict] = {}
        self._rng_drawn: set[tuple[str, str]] = set(self.rng)
        self.gyro_noise = np.zeros((n, 0, 6))
        self.gi = np.zeros(1, dtype=np.int64)
        self.ahrs_noise = np.zeros((n, 0, 3))
        self.ai = np.zeros(1, dtype=np.int64)
        # how the current noise block of each stream was drawn (the streams' states before the draw, the
        # rows carried over, the block's length), so that a snapshot re-draws it instead of copying it
        self._blocks: dict[str, tuple[list[dict], int, bytes, int] | None] = {"gyro": None, "ahrs": None}
        # the two pickled once for snapshot(pickled_streams=True) until they change (None: to pickle again)
        self._rng_blob: bytes | None = None
        self._blocks_blob: bytes | None = None
        self.gyro_out = np.zeros((n, 3))
        self.ahrs_out = np.zeros((n, 4))
        self.markers_target = sc.markers.markers(sc.guidance.docking_face)
        self.vision_every = sc.every(sc.camera.rate_hz)
        self.ahrs_every = sc.every(sc.ahrs.rate_hz)
        self.cameras = {c: sc.camera_for(c) for c in sc.chasers}
        self._chasers = list(sc.chasers)  # (a Scenario builds the list on each call: twice per camera tick)
        self._targets = [sc.vehicles[c].target for c in self._chasers]
        # faults (swarm.core.faults): the gyro bias step per vehicle (time inf: none) and the schedule of
        # windows (fixed ones from the scenario, mode-triggered ones from the commands, run-time ones)
        self.gyro_step_t = np.full(n, np.inf)
        self.gyro_step = np.zeros((n, 3))
        for i, vid in enumerate(self.ids):
            self.gyro_step_t[i], self.gyro_step[i] = sc.faults.gyro_step_rad_s(vid, sc.chasers)
        self.faults = FaultSchedule(sc.faults, self.dt, sc.chasers, sc.uwb.dropout_windows_s)
        self.drop_w = np.zeros((0, 2))
        self.nlos_w = np.zeros((0, 3))
        self.cam_lost = np.zeros(1, dtype=np.int64)
        self.cam_arrays = self._camera_arrays()
        self._refresh_windows()

    def _camera_arrays(self) -> tuple:
        """The arrays of :func:`camera_frame` (the compiled camera models, ``"features"`` and ``"pose"``):
        per chaser (in the referee's order) its row and its target's, its camera mount and its noise key;
        the docking face's markers, centre and normal; the camera's visibility vector and pixel noise; the
        camera-loss windows ``(chaser, start, end)`` (refreshed with the fault schedule) and the count of
        frames they dropped; per chaser its camera model's code (:data:`CAMERA_CODES`) and feature noise."""
        sc = self.sc
        chasers = list(sc.chasers)
        face = sc.guidance.docking_face
        normal = np.zeros(3)
        normal["xyz".index(face[1])] = 1.0 if face[0] == "+" else -1.0
        cams = [self.cameras[c] for c in chasers]
        return (
            np.array([[self.index[c], self.index[sc.vehicles[c].target]] for c in chasers],
                     dtype=np.int64).reshape(-1, 2),
            np.array([c.pos_body for c in cams]).reshape(-1, 3),
            np.array([c.q_body_cam_arr for c in cams]).reshape(-1, 4),
            np.array([noise_key(self.seed, self.index[c], STREAM_CAMERA) for c in chasers], dtype=np.uint64),
            np.ascontiguousarray(sc.markers.markers(face)), sc.markers.half_size_m * normal, normal,
            np.array(sc.camera.visibility_vector), float(sc.camera.pixel_sigma_px), np.zeros((0, 3)),
            self.cam_lost, np.array([CAMERA_CODES[str(c.model)] for c in cams], dtype=np.int64),
            np.array([c.feature_sigma_m for c in cams], dtype=float),
        )  # fmt: skip

    @property
    def frame_width(self) -> int:
        """Length of one compiled camera frame row: a pose (:data:`POSE_N`) or 3 per marker."""
        return max(POSE_N, 3 * self.cam_arrays[4].shape[0])

    @property
    def camera_frames_lost(self) -> int:
        """Camera frames with the target in view dropped by a camera-loss window (a fault's footprint)."""
        return int(self.cam_lost[0])

    @property
    def compiled_cameras(self) -> bool:
        """Every chaser's camera model is compiled (``"features"`` or ``"pose"``): the compiled loop builds
        and fuses the camera frames (``"pnp"`` solves PnP in Python)."""
        return all(self.cameras[c].model != CameraModel.PNP for c in self.sc.chasers)

    @property
    def effort_by_vehicle(self) -> dict[str, float]:
        """Each vehicle's effort so far, in its kind's unit (:attr:`effort`)."""
        return {vid: float(self.effort[i]) for i, vid in enumerate(self.ids)}

    @property
    def attached(self) -> dict[str, bool]:
        return {vid: bool(self.attached_arr[i]) for i, vid in enumerate(self.ids)}

    @property
    def t_s(self) -> float:
        return self.k * self.dt

    @property
    def camera_loss(self) -> dict[str, list]:
        """Each chaser's camera-loss windows ``[start, end]`` [s] (the schedule's, fixed ones included)."""
        return self.faults.camera

    # ---- faults --------------------------------------------------------------------------------------
    def _refresh_windows(self) -> None:
        """The radio windows as the arrays :func:`swarm.step.radio.radio_env` reads."""
        self.drop_w = np.array(self.faults.uwb_dropout, dtype=float).reshape(-1, 2)
        self.nlos_w = np.array(self.faults.nlos, dtype=float).reshape(-1, 3)
        chasers = list(self.sc.chasers)
        cam_w = [[c, w[0], w[1]] for c, cid in enumerate(chasers) for w in self.faults.camera.get(cid, ())]
        pc = self.cam_arrays
        self.cam_arrays = (*pc[:9], np.array(cam_w, dtype=float).reshape(-1, 3), *pc[10:])

    def radio_env(self, t_s: float) -> tuple[bool, float]:
        """The radio environment at ``t_s``: every reply lost (a dropout window), and the NLOS outlier
        probability of an exchange inside a burst window (0 outside one)."""
        return radio_env(t_s, self.drop_w, self.nlos_w)

    def take_commands(self, k: int, commands) -> None:
        """Tick ``k``'s commands ``{vehicle id: (u, mode)}`` (the vehicles that decided one, in any
        order): each held from now on (:meth:`set_command`, in vehicle order), and each chaser's guidance
        ``mode`` handed to the fault schedule, which opens (or closes) the mode-triggered windows from the
        next tick on (:class:`swarm.core.faults.FaultSchedule`)."""
        for vid in self.ids:
            if vid in commands:
                self.set_command(vid, commands[vid][0])
        changed = False
        t = k * self.dt
        for cid in self.sc.chasers:
            if cid in commands and commands[cid][1] is not None:
                changed |= self.faults.on_mode(t, cid, commands[cid][1])
        if changed:
            self._refresh_windows()

    def add_fault(self, kind: str, start_s: float, duration_s: float, vehicles, value=None) -> None:
        """A fault injected at run time from ``start_s`` [s] (after the current tick: the caller makes sure)
        for ``duration_s`` [s]: ``uwb_dropout`` and ``nlos_burst`` (``value`` its outlier probability) on
        the radio network, ``camera_loss`` on the chasers in ``vehicles``, ``gyro_bias_step`` (``value``
        the step (3,) [rad/s], from ``start_s`` on) on each of ``vehicles``."""
        if kind == "gyro_bias_step":
            for v in vehicles:
                i = self.index[v]
                self.gyro_step_t[i], self.gyro_step[i] = start_s, value
            return
        prob = float(value) if kind == "nlos_burst" else 0.0
        self.faults.add(kind, start_s, start_s + duration_s, vehicles, prob)
        self._refresh_windows()

    # ---- noise ---------------------------------------------------------------------------------------
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
        rows = max(self.noise_block, need)
        self._blocks[name] = (states, carried.shape[1], carried.tobytes(), rows)
        self._blocks_blob = None
        return self._draw_block(name, carried, rows), 0

    def _draw_block(self, name: str, carried: np.ndarray, rows: int) -> np.ndarray:
        """A noise block of ``rows`` rows per vehicle: the ``carried`` rows (n, left, d) not yet used,
        then fresh normals of each vehicle's stream ``name``."""
        left = carried.shape[1]
        new = np.empty((carried.shape[0], rows, carried.shape[2]))
        for i, vid in enumerate(self.ids):
            new[i, :left] = carried[i]
            new[i, left:] = self.rng[vid, name].standard_normal((rows - left, carried.shape[2]))
            self._rng_drawn.add((vid, name))
        return new

    # ---- snapshots (a world process's checkpoint) ----------------------------------------------------
    _ARRAYS = ("X", "S", "U", "effort", "attached_arr", "bias", "gyro_out", "ahrs_out", "gyro_step_t",
               "gyro_step")  # fmt: skip

    def snapshot(self, pickled_streams: bool = False) -> dict:
        """Everything of this world that changes while it runs, as copies: the arrays as raw bytes (C
        order, their own dtypes; pickling an ndarray costs ~4 us, its bytes 0.3 us), ints, lists and the
        random streams' ``bit_generator.state`` dicts. :meth:`restore` on a ``World`` of the same scenario
        and seed continues exactly where this one is, bit for bit. The pre-drawn noise blocks are not
        copied (up to 1024 rows per vehicle) but re-drawn on restore from the streams' states before their
        draw, which costs nothing per tick.

        ``pickled_streams``: ``rng`` and ``blocks`` as their pickles, made again only when they changed (a
        stream drawn from, a block drawn): a world process checkpoints every tick, and pickling those
        dicts of big integers each time cost ~90 us of a 32-vehicle tick for what changes once in 1024
        ticks (:meth:`restore` takes either form)."""
        snap = {name: getattr(self, name).tobytes() for name in self._ARRAYS}
        if self._rng_drawn:  # the other streams are where the last snapshot saw them
            for key in self._rng_drawn:
                self._rng_state[key] = self.rng[key].bit_generator.state
            self._rng_drawn.clear()
            self._rng_blob = None
        if pickled_streams:
            if self._rng_blob is None:
                self._rng_blob = pickle.dumps(self._rng_state, protocol=pickle.HIGHEST_PROTOCOL)
            if self._blocks_blob is None:
                self._blocks_blob = pickle.dumps(self._blocks, protocol=pickle.HIGHEST_PROTOCOL)
            rng, blocks = self._rng_blob, self._blocks_blob
        else:
            rng, blocks = dict(self._rng_state), dict(self._blocks)
        snap.update(
            k=self.k, gi=int(self.gi[0]), ai=int(self.ai[0]), blocks=blocks, rng=rng,
            faults=self.faults.state(), camera_frames_lost=int(self.cam_lost[0]),
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
        blocks, rngs = snap["blocks"], snap["rng"]
        blocks = pickle.loads(blocks) if isinstance(blocks, bytes) else blocks  # snapshot(pickled_streams)
        rngs = pickle.loads(rngs) if isinstance(rngs, bytes) else rngs
        self._rng_blob = self._blocks_blob = None
        for name, bufname, idx in (("gyro", "gyro_noise", "gi"), ("ahrs", "ahrs_noise", "ai")):
            block = blocks[name]
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
        self._rng_drawn.update(self.rng)
        for key, state in rngs.items():
            g = self.rng[key]
            if key[1] == "camera":
                g.bit_generator.state = state
            elif g.bit_generator.state != state:  # re-drawing the block must end where the stream was
                raise ValueError(f"snapshot: random stream {key} does not end where it did")
        self.faults.restore(snap["faults"])
        self._refresh_windows()
        self.cam_lost[0] = int(snap["camera_frames_lost"])

    # ---- the step ------------------------------------------------------------------------------------
    def set_command(self, vehicle_id: str, u) -> None:
        """Actuator command ``u`` to hold from now on, in the vehicle kind's units; brought into the
        actuators' range by the kind (:func:`swarm.kinds._dispatch.hold`). Ignored once the
        vehicle is docked (:meth:`attach`)."""
        i = self.index[vehicle_id]
        if self.attached_arr[i]:
            return
        hold(self.truth_act[i], u, self.S[i], self.U[i])

    def command_size(self, vehicle_id: str) -> int:
        """Length of ``vehicle_id``'s actuator command (its kind's ``U_N``)."""
        return self.kinds[self.index[vehicle_id]].U_N

    def step(self, build_frames: bool = True) -> dict[str, SensorFrame] | None:
        """Advance every vehicle by one tick and return the sensor frames of the new tick (``None`` with
        ``build_frames=False``: the samples stay in ``gyro_out``/``ahrs_out``, and the caller vouches that
        no camera can see its target, so no camera frame is skipped)."""
        self.reserve_noise(1)
        k1 = self.k + 1
        do_ahrs = self.sc.ahrs.enabled and k1 % self.ahrs_every == 0
        world_tick(
            self.X, self.S, self.U, self.KP, self.codes, self.effort, self.attached_arr, self.bias,
            self.gyro_noise, self.gi, self.ahrs_noise, self.ai, do_ahrs, self.prm, self.gyro_out,
            self.ahrs_out, self.k * self.dt, self.gyro_step_t, self.gyro_step,
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
            for c, vid in enumerate(self._chasers):
                self._vision(c, vid, self._targets[c], frames[vid])
        return frames

    def _vision(self, c: int, chaser: str, target: str, frame: SensorFrame) -> None:
        """Chaser ``chaser``'s (the ``c``-th) camera frame of its target ``target`` into ``frame``."""
        cam = self.cameras[chaser]
        if cam.model != CameraModel.PNP:  # compiled: the loop's own frames
            out = np.empty(self.frame_width)
            if camera_frame(c, self.k, self.dt, self.X, *self.cam_arrays, out):
                frame.vision_kind = str(cam.model)
                n = self.cam_arrays[4].shape[0]
                frame.vision = out[:POSE_N] if cam.model == CameraModel.POSE else out[: 3 * n].reshape(n, 3)
            return
        xc, xt = self.x[chaser], self.x[target]
        p_cam, q_cam = camera_pose_nav(xc[0:3], xc[6:10], cam)
        if not visible(p_cam, q_cam, xt[0:3], xt[6:10], self.sc.guidance.docking_face, cam, self.sc.markers):
            return
        rng = self.rng[chaser, "camera"]
        self._rng_drawn.add((chaser, "camera"))
        frame.vision_kind = "pixels"
        frame.vision = project_markers(self.markers_target, xt[0:3], xt[6:10], p_cam, q_cam, cam, rng)
        if any(w[0] <= frame.t_s < w[1] for w in self.faults.camera.get(chaser, ())):
            # camera lost (a fault): the frame was drawn, so the camera stream stays aligned, and dropped
            frame.vision_kind = frame.vision = None
            self.cam_lost[0] += 1

    def attach(self, chaser: str, target: str) -> None:
        """Docked: the chaser rides with the target from now on (no further propagation)."""
        self.set_command(chaser, np.zeros(self.command_size(chaser)))
        self.attached_arr[self.index[chaser]] = True


@numba.njit(cache=True)
def world_tick(X, S, U, KP, codes, effort, attached, bias, gyro_noise, gi, ahrs_noise, ai, do_ahrs, prm,
               gyro_out, ahrs_out, t_s, step_t, step):  # fmt: skip
    """Advance every vehicle one tick (in place) and write its sensor samples.

    Truth: each vehicle's kind (:func:`swarm.kinds._dispatch.truth_step`) under its held command; its
    effort accumulates. Gyro: the mean body rate over the tick, ``log(q0^-1 (x) q1) / dt`` (the
    delta-angle an IMU integrates), plus white noise and the Gauss-Markov bias of ``sensors.gyro_sample``
    on the next pre-drawn normals. AHRS (when ``do_ahrs``): ``q (x) exp(sigma z)`` as
    ``sensors.ahrs_sample``. A gyro bias step (a fault, :mod:`swarm.core.faults`): ``step[v]`` [rad/s]
    adds to vehicle ``v``'s sample of the tick starting at ``t_s`` [s] when ``t_s >= step_t[v]``
    (``inf``: never).
    """
    dt = prm[W_DT]
    z = np.empty(6)
    for v in range(X.shape[0]):
        x0 = X[v].copy()
        if not attached[v]:
            effort[v] += truth_step(codes[v], X[v], S[v], U[v], KP[v], dt)
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


STREAM_CAMERA = 3
"""The compiled camera models' noise stream number (:func:`swarm.core._noise_nb.noise_key`)."""

CAM_FEATURES, CAM_POSE, CAM_PNP = 0, 1, 2
CAMERA_CODES = {"features": CAM_FEATURES, "pose": CAM_POSE, "pnp": CAM_PNP}
"""Each camera model's code in :func:`camera_frame` (``"pnp"`` is not compiled)."""


@numba.njit(cache=True)
def camera_frame(c, k, dt, X, pairs, cam_pos, q_bc, keys, markers, centre, normal, vis, sigma_px, cam_w, lost,
                 model, sigma_f, out):  # fmt: skip
    """The camera frame of chaser ``c`` (row ``pairs[c]``, :meth:`World._camera_arrays`) at tick ``k``
    (period ``dt`` [s]) on the truth ``X``, in its camera model ``model[c]``: ``"pose"``
    (:func:`swarm.core.camera.pose_frame`, ``out[:POSE_N]``) or ``"features"``
    (:func:`swarm.core.camera.features_frame`, ``out[:3 N]``). True with ``out`` written when it sees its
    target's docking face; a frame inside one of its camera-loss windows is drawn, then dropped (and
    counted in ``lost``), so the noise of later frames does not depend on the fault."""
    ic, it = pairs[c, 0], pairs[c, 1]
    x = X[ic]
    r = qrotate(x[6:10], cam_pos[c])
    p_cam = np.empty(3)
    for i in range(3):
        p_cam[i] = x[i] + r[i]
    q_cam = qmul(x[6:10], q_bc[c])
    if model[c] == CAM_POSE:
        seen = pose_frame(markers, centre, normal, X[it, 0:3], X[it, 6:10], p_cam, q_cam, vis, sigma_px,
                          keys[c], k, out)  # fmt: skip
    elif model[c] == CAM_FEATURES:
        seen = features_frame(markers, centre, normal, X[it, 0:3], X[it, 6:10], p_cam, q_cam, vis, sigma_f[c],
                              keys[c], k, out)  # fmt: skip
    else:
        seen = False
    if not seen:
        return False
    t = k * dt
    for w in range(cam_w.shape[0]):
        if cam_w[w, 0] == c and cam_w[w, 1] <= t < cam_w[w, 2]:
            lost[0] += 1
            return False
    return True
