"""The landing tick (paper section VI-B; ``docs/architecture.md``, "The landing tick"): a world step that
flies every UAV's quadrotor truth and samples its sensors, an agent step that fuses them and decides the rotor
command, and the hold of that command, called in this order by every runner: the in-process simulation
(:mod:`swarm.sim.landing`) and the landing world and agent processes.

Per tick ``k`` (``t = k dt``), for each UAV not done:

1. **world** (:meth:`LandingWorld.step`): the truth advances by ``dt`` under the held command, then the
   sensors of tick ``k`` sample, in this order, from the UAV's own random stream: the IMU (the mean specific
   force and rate over ``(t - dt, t]``, stamped ``t - dt``, with biases and white noise), the UWB range to the
   next anchor (a UWB tick, within the anchors' reach; on a TDoA radio, ``uwb.mode`` tdoa2/tdoa3, each UAV's
   distance differences heard since the last UWB tick instead, :meth:`LandingWorld._tdoa_step`), the GNSS
   fix (a GNSS tick), the rangefinder's distance to the ground (a rangefinder tick, within its reach and
   tilt), and the camera (a camera tick): the pad's marker corners in pixels, by corner projection with
   pixel noise or by rendering the image and detecting the ArUco markers in it; none when the pad is hidden
   or behind the camera.
2. **agent** (:meth:`LandingAgent.tick`): the IMU-driven filter takes the IMU sample, the range, the fix, the
   rangefinder's distance and the pad's pose from PnP of the corners, then the TDoA differences
   (:func:`swarm.step.landing_nb.agent_tdoa`); the guidance (fixed deviation or Algorithm 1) and the
   quadrotor controller give the rotor speeds, or the idle command once landed.
3. **world** (:meth:`LandingWorld.hold`): the rotors take the command; the UAV's run is over once it has
   been landed for ``end_after_landed_s``, or hovers at the abort height after an abort
   (:func:`swarm.step.landing_nb.world_hold`).

:func:`landing_setup` is what the seed decides for one UAV; both sides call it, so an agent process that has
no world starts from the same first estimate as the in-process agent.
"""

from __future__ import annotations

import io
import math
import pickle
import zlib
from dataclasses import dataclass, field, replace

import numpy as np

from swarm.core import _imu_nb as inb
from swarm.core import _landing_nb as gnb
from swarm.core import range_errors as rerr
from swarm.core import rotations as rot
from swarm.core import tdoa_radio as tr
from swarm.core._pad_nb import camera_vector
from swarm.core._rot_nb import qrotate
from swarm.core.imu_filter import ImuFilterParams, PhaseParams, chi2_gate, robust_vector
from swarm.core.landing import MODES, LandingGuidance, LandingMode
from swarm.core.mdp import nan_to_none
from swarm.core.pad_vision import Renderer, detect, estimate_pose, make_detector
from swarm.core.platform_path import PATH_HEAD, path_length_m
from swarm.kinds import KINDS
from swarm.kinds.base import VehicleDispersion
from swarm.kinds.quadrotor.dynamics import S_GROUND
from swarm.landing_scenario import LandingScenario, Uav, platform_path, platform_pose
from swarm.navigation import NAVIGATORS, navigator_name
from swarm.step import landing_nb as lnb

GATE_PROBABILITY = 0.9995
"""The filter's gate on a fix, a pad measurement and a rangefinder distance: the chi-square quantile."""

QUADROTOR = KINDS["quadrotor"]
"""The vehicle kind every UAV of a landing scenario is (:class:`swarm.kinds.quadrotor.QuadrotorKind`)."""
R_BODY_CAM = rot.quat_to_matrix(np.array([1.0, 0.0, 0.0, 0.0]))
"""Camera to body of the downward camera: its optical axis (+z) along body -z."""


def _seeds(seed: int, index: int, stream: int) -> np.random.SeedSequence:
    """UAV ``index``'s stream: the one-UAV scenario's for index 0, so its runs did not change."""
    return np.random.SeedSequence([seed, stream] if index == 0 else [seed, stream, index])


@dataclass
class LandingSetup:
    """What the seed decides for one UAV (module docstring)."""

    uav: Uav
    start: np.ndarray
    yaw_rad: float
    pad: np.ndarray
    q_nav_pad: np.ndarray
    uwb_range_m: float
    accel_bias: np.ndarray
    gyro_bias: np.ndarray
    p0: np.ndarray
    q0: np.ndarray
    accel_bias0: np.ndarray
    gyro_bias0: np.ndarray
    rng: np.random.Generator
    """The sensors' stream, after the draws above."""
    arc0_m: float = 0.0
    """A moving pad: where on its path the robot starts [m] (``[platform]``; drawn with the dispersions)."""
    pad_v: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """A moving pad's velocity at t = 0 (nav) [m/s]; ``pad`` and ``q_nav_pad`` are its pose then."""


def landing_setup(sc: LandingScenario, seed: int, index: int) -> LandingSetup:
    uav = sc.uavs()[index]
    rng = np.random.default_rng(_seeds(seed, index, 15))
    start = np.asarray(uav.start_m, float)
    uwb_range = sc.uwb.max_range_m
    disp = sc.dispersions
    if disp.enabled:
        drng = np.random.default_rng(_seeds(seed, index, 16))
        start = start + drng.normal(0.0, 1.0, 3) * np.asarray(disp.start_sigma_m)
        start[2] = max(start[2], 2.0)
        uwb_range = float(drng.uniform(*disp.uwb_range_m))
    yaw = math.radians(uav.yaw_deg)
    q_start = rot.rotvec_exp(np.array([0.0, 0.0, yaw]))
    ba = rng.uniform(-sc.imu.accel_bias_m_s2, sc.imu.accel_bias_m_s2, 3)
    bg = rng.uniform(-sc.imu.gyro_bias_rad_s, sc.imu.gyro_bias_rad_s, 3)
    ini = sc.initial
    p0 = start + rng.normal(0.0, ini.sigma_position_m, 3)
    q0 = rot.quat_mul(q_start, rot.rotvec_exp(rng.normal(0.0, math.radians(ini.sigma_attitude_deg), 3)))
    ba0 = ba + rng.normal(0, ini.sigma_accel_bias_m_s2, 3)
    bg0 = bg + rng.normal(0, ini.sigma_gyro_bias_rad_s, 3)
    pad = np.asarray(uav.pad_m, float)
    q_nav_pad = rot.rotvec_exp(np.array([0.0, 0.0, math.radians(uav.pad_yaw_deg)]))
    st = LandingSetup(uav, start, yaw, pad, q_nav_pad, uwb_range, ba, bg, p0, q0, ba0, bg0, rng)
    pf = sc.platform
    if pf.enabled:  # the robot's pose at t = 0, from where it starts on its path
        st.arc0_m = pf.start_arc_m
        if disp.enabled and pf.closed:
            st.arc0_m = float(drng.uniform(0.0, path_length_m(platform_path(sc))))
        x, y, vx, vy, heading = platform_pose(sc, st.arc0_m, 0.0)
        st.pad = np.array([x, y, sc.pad.position_m[2]])
        st.pad_v = np.array([vx, vy, 0.0])
        st.q_nav_pad = rot.rotvec_exp(np.array([0.0, 0.0, heading + math.radians(sc.pad.yaw_deg)]))
    return st


def anchors_of(sc: LandingScenario) -> np.ndarray:
    return np.asarray(sc.uwb.anchors_m, float) if sc.uwb.enabled else np.zeros((0, 3))


@dataclass
class Rates:
    """Every how many ticks each sensor samples."""

    camera: int
    uwb: int
    gnss: int
    rangefinder: int
    share: int = 1
    """A moving pad's robot shares its estimate (``[platform]``)."""

    @classmethod
    def of(cls, sc: LandingScenario) -> Rates:
        dt = sc.dt_s
        return cls(
            max(1, round(1.0 / (sc.camera.rate_hz * dt))),
            max(1, round(1.0 / (sc.uwb.rate_hz * dt))),
            max(1, round(1.0 / (sc.gnss.rate_hz * dt))),
            max(1, round(1.0 / (sc.rangefinder.rate_hz * dt))),
            max(1, round(1.0 / (sc.platform.share_rate_hz * dt))),
        )

    def uwb_tick(self, sc: LandingScenario, k: int) -> bool:
        """A two-way range (``uwb.mode = "twr"``) this tick."""
        return bool(sc.uwb.mode == "twr" and sc.uwb.enabled and len(sc.uwb.anchors_m) and k % self.uwb == 0)

    def tdoa_tick(self, sc: LandingScenario, k: int) -> bool:
        """A TDoA radio (``uwb.mode`` tdoa2/tdoa3) hands each tag the differences it heard since the last
        one (on the UWB ticks, ``uwb.rate_hz``)."""
        return bool(sc.uwb.mode != "twr" and sc.uwb.enabled and k % self.uwb == 0)

    def gnss_tick(self, sc: LandingScenario, k: int) -> bool:
        return bool(sc.gnss.enabled and k % self.gnss == 0)

    def rangefinder_tick(self, sc: LandingScenario, k: int) -> bool:
        return bool(sc.rangefinder.enabled and k % self.rangefinder == 0)

    def camera_tick(self, k: int) -> bool:
        return k % self.camera == 0

    def share_tick(self, sc: LandingScenario, k: int) -> bool:
        return bool(sc.platform.enabled and sc.platform.share_estimate and k % self.share == 0)


@dataclass
class LandingInputs:
    """One UAV's samples of tick ``k`` (module docstring, step 1)."""

    k: int
    t: float
    gyro: np.ndarray
    """Rate [rad/s], body; the IMU sample is stamped ``t - dt``."""
    acc: np.ndarray
    """Specific force [m/s^2], body."""
    uwb: tuple[int, float] | None = None
    """(anchor index, range [m]) on a UWB tick within reach."""
    gnss: np.ndarray | None = None
    """Position fix [m], nav, on a GNSS tick."""
    rangefinder: float | None = None
    """The downward distance [m] on a rangefinder tick (None: none, or no reading: out of reach, tilted)."""
    camera: tuple[np.ndarray, np.ndarray] | None = None
    """On a camera tick: the detected marker ids (n,) and their corners (n, 4, 2) [px] (n = 0: nothing)."""
    pad: np.ndarray | None = None
    """A moving pad, on a share tick: the robot's estimate, position (3,) [m] and velocity (3,) [m/s] (nav),
    as one (6,) array."""
    tdoa: np.ndarray | None = None
    """A TDoA radio, on a UWB tick: the differences heard since the last one, (K, 3) anchor ``A``, anchor
    ``B``, ``d_B - d_A`` [m] (:class:`swarm.step.radio.TdoaSample`'s rows; K may be 0)."""


@dataclass
class LandingCommand:
    """The agent's answer to tick ``k``: rotor speeds (4,) [rad/s] and the guidance mode that gave them."""

    k: int
    u: np.ndarray
    mode: LandingMode


class NoiseStream:
    """A UAV's sensor draws: standard normals from its generator, read in order by the compiled world step
    (:mod:`swarm.step.landing_nb`, "Random draws") from ``Z`` at ``pos[0]``.

    A block is drawn when fewer than a tick's draws are left, after what was left (``carry``); the
    generator's state before the draw is kept, so that :meth:`state` is a few hundred bytes, not the block:
    :meth:`restore` draws the same block again."""

    BLOCK = 4096

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.Z = np.zeros(0)
        self.pos = np.zeros(1, dtype=np.int64)
        self._before: dict | None = None  # the generator's state before the block in Z was drawn
        self._carry = np.zeros(0)  # the draws left over from the block before, at the start of Z

    def ensure(self, n: int) -> None:
        """At least ``n`` draws left in ``Z``."""
        left = len(self.Z) - int(self.pos[0])
        if left < n:
            self._before = self.rng.bit_generator.state
            self._carry = self.Z[self.pos[0] :].copy()
            self.Z = np.concatenate([self._carry, self.rng.standard_normal(max(self.BLOCK, n))])
            self.pos[0] = 0

    def state(self) -> dict:
        """Where the stream is (:meth:`restore`)."""
        return {"before": self._before, "carry": self._carry, "size": len(self.Z) - len(self._carry),
                "pos": int(self.pos[0])}  # fmt: skip

    def restore(self, st: dict) -> None:
        """Back to :meth:`state` ``st`` of a stream of the same seed: the block drawn again (which leaves the
        generator where it was: only :meth:`ensure` draws from it), the position."""
        self._before, self._carry = st["before"], np.asarray(st["carry"], dtype=float)
        if self._before is None:
            self.Z = np.zeros(0)
        else:
            self.rng.bit_generator.state = self._before
            self.Z = np.concatenate([self._carry, self.rng.standard_normal(int(st["size"]))])
        self.pos[0] = int(st["pos"])


class FixedNoise:
    """The draws of a UAV's ``uwb_errors`` stream (:func:`swarm.step.landing_nb.world_errors`): as
    :class:`NoiseStream`, but the buffer ``Z`` is refilled in place, so that the compiled loop's world tuple
    holds it for the whole run (the leftover draws moved to its start, the rest drawn anew). Empty when
    ``size`` is 0: a scenario without the errors draws nothing."""

    def __init__(self, rng: np.random.Generator, size: int) -> None:
        self.rng = rng
        self.Z = np.zeros(size)
        self.pos = np.array([size], dtype=np.int64)  # nothing drawn yet: every slot used
        self._before: dict | None = None
        self._carry = np.zeros(0)

    def ensure(self, n: int) -> None:
        """At least ``n`` (<= the buffer's size) draws left in ``Z``."""
        size, used = len(self.Z), int(self.pos[0])
        if size - used < n:
            self._before = self.rng.bit_generator.state
            self._carry = self.Z[used:].copy()
            self.Z[: len(self._carry)] = self._carry
            self.Z[len(self._carry) :] = self.rng.standard_normal(size - len(self._carry))
            self.pos[0] = 0

    def state(self) -> dict:
        """Where the stream is (:meth:`restore`)."""
        return {"before": self._before, "carry": self._carry, "pos": int(self.pos[0])}

    def restore(self, st: dict) -> None:
        """Back to :meth:`state` ``st`` of a stream of the same seed (the block drawn again)."""
        self._before, self._carry = st["before"], np.asarray(st["carry"], dtype=float)
        if self._before is not None:
            self.rng.bit_generator.state = self._before
            self.Z[: len(self._carry)] = self._carry
            self.Z[len(self._carry) :] = self.rng.standard_normal(len(self.Z) - len(self._carry))
        self.pos[0] = int(st["pos"])


TDOA_KEY = "~tdoa"
"""A world snapshot's entry of the TDoA radio's state (not a UAV id: ``~`` is not allowed in one)."""


class SnapshotError(ValueError):
    """A snapshot that does not fit the object it is restored into (another scenario, seed or version)."""


_CONFIG = frozenset({"sc", "setup", "board", "rates", "params", "p", "filt", "guidance", "noise", "renderer",
                     "detector", "render_rng", "decisions", "modes", "_records", "errs"})  # fmt: skip
"""Attributes :func:`snapshot_state` leaves out: what the scenario and the seed build again, the parts
snapshot on their own (``filt``, ``guidance``, ``noise``, ``render_rng``, ``errs``) and the guidance's records
(:class:`_Records`)."""

_LAYOUTS: dict[tuple, str] = {}  # (name, shape, dtype) of each array, in order -> its layout string


def _walk(parts: dict[str, object]) -> tuple[list[tuple[str, np.ndarray]], dict[str, object]]:
    """The arrays (``part.name``, array), in a fixed order, and the other mutable attributes of ``parts``."""
    arrays, rest = [], {}
    for part, obj in parts.items():
        for name, v in vars(obj).items():
            if name in _CONFIG:
                continue
            if isinstance(v, np.ndarray):
                arrays.append((f"{part}.{name}", v))
            else:
                rest[f"{part}.{name}"] = v
    return arrays, rest


def _layout(arrays: list[tuple[str, np.ndarray]]) -> str:
    """What a snapshot's raw bytes are: every array's name, shape and dtype, in order (formatted once)."""
    key = tuple((n, a.shape, a.dtype.str) for n, a in arrays)
    layout = _LAYOUTS.get(key)
    if layout is None:
        layout = _LAYOUTS[key] = ";".join(f"{n}:{shape}:{dtype}" for n, shape, dtype in key)
    return layout


def snapshot_state(parts: dict[str, object]) -> dict:
    """The mutable state of ``parts`` (name -> object): every array attribute's bytes, in one string, and
    the other attributes (numbers, lists, records) as they are; the configuration (:data:`_CONFIG`) left out.
    :func:`restore_state` puts it into objects built again from the same scenario and seed."""
    arrays, rest = _walk(parts)
    return {"layout": _layout(arrays), "arrays": b"".join(a.tobytes() for _, a in arrays), "rest": rest}


def restore_state(parts: dict[str, object], snap: dict) -> None:
    """``snap`` (:func:`snapshot_state`) into ``parts``, arrays in place; :class:`SnapshotError` if its
    layout is not theirs."""
    arrays, rest = _walk(parts)
    layout = _layout(arrays)
    if snap.get("layout") != layout or set(snap.get("rest", {})) != set(rest):
        raise SnapshotError(
            "the snapshot's layout is not this object's (another scenario, or another version)"
        )
    data, at = snap["arrays"], 0
    if len(data) != sum(a.nbytes for _, a in arrays):
        raise SnapshotError(
            f"the snapshot has {len(data)} bytes of arrays, not {sum(a.nbytes for _, a in arrays)}"
        )
    for _, a in arrays:
        a[...] = np.frombuffer(data, dtype=a.dtype, count=a.size, offset=at).reshape(a.shape)
        at += a.nbytes
    for key, v in snap["rest"].items():
        part, name = key.split(".", 1)
        setattr(parts[part], name, v)


class _Records:
    """An append-only list of records (the guidance's decisions or mode switches) as checkpoint entries
    ``(tag, pickled chunk, its CRC-32)`` (:func:`swarm.transport.checkpoint.sample_entry`'s shape):
    :meth:`entries` pickles only the records added since its last call, and checksums each chunk once; past
    :attr:`MERGE` chunks it merges them into one, so that a checkpoint's table stays short. :meth:`load`
    reads the records back from the entries of one tag."""

    MERGE = 8

    def __init__(self, tag: int) -> None:
        self.tag, self.n, self.chunks = tag, 0, []

    def entries(self, records: list) -> list[tuple[int, bytes, int]]:
        if len(records) < self.n:  # (not a list that only grows: start again)
            self.n, self.chunks = 0, []
        if len(records) > self.n:
            data = pickle.dumps(records[self.n :], protocol=pickle.HIGHEST_PROTOCOL)
            self.chunks.append((self.tag, data, zlib.crc32(data)))
            self.n = len(records)
            if len(self.chunks) > self.MERGE:
                data = b"".join(c[1] for c in self.chunks)
                self.chunks = [(self.tag, data, zlib.crc32(data))]
        return self.chunks

    @staticmethod
    def load(entries, tag: int) -> list:
        """The records of the entries ``(tag, chunk, ...)`` of ``tag``, in order."""
        out = []
        for entry in entries:
            if entry[0] != tag:
                continue
            f = io.BytesIO(entry[1])
            while f.tell() < len(entry[1]):
                out.extend(pickle.load(f))
        return out


@dataclass
class _Errors:
    """What a UAV's world needs of the scenario's range errors and vibration: the ``[uwb]`` params, the
    anchors' offsets, its ``uwb_errors`` stream and the size of its block of draws (0: none on)."""

    uwb: object
    offsets: np.ndarray
    rng: np.random.Generator
    block: int


class _Truth:
    """One UAV's truth, its world state (``WSC``) and its sensors' draws."""

    def __init__(self, setup: LandingSetup, x: np.ndarray, s: np.ndarray, held: np.ndarray, n_markers: int,
                 render_rng: np.random.Generator, errors: _Errors) -> None:  # fmt: skip
        self.setup, self.x, self.s, self.held = setup, x, s, held
        self.WSC = np.zeros(lnb.WSC_N)
        self.WSC[lnb.WSC_LANDED_T] = np.nan
        self.WC = np.zeros(lnb.WC_N)
        self.WC[lnb.WC_BA : lnb.WC_BA + 3] = setup.accel_bias
        self.WC[lnb.WC_BG : lnb.WC_BG + 3] = setup.gyro_bias
        self.WC[lnb.WC_PAD : lnb.WC_PAD + 3] = setup.pad
        self.WC[lnb.WC_UWB_RANGE] = setup.uwb_range_m
        self.WC[lnb.WC_R_NAV_PAD : lnb.WC_R_NAV_PAD + 9] = rot.quat_to_matrix(setup.q_nav_pad).ravel()
        self.WC[lnb.WC_CAM_OFF : lnb.WC_CAM_OFF + 2] = np.nan
        self.WC[lnb.WC_UWB_OFF : lnb.WC_UWB_OFF + 2] = np.nan
        self.WC[lnb.WC_ARC0] = setup.arc0_m
        self.WC[lnb.WC_PAD_V : lnb.WC_PAD_V + 3] = setup.pad_v
        self.WSC[lnb.WSC_TD_T] = np.nan
        self.noise = NoiseStream(setup.rng)
        self.render_rng = render_rng
        # the range errors and vibration of real flights (swarm.core.range_errors), drawn from the UAV's own
        # uwb_errors stream: the anchors' offsets (set by the world), the take-off steps, each link's state
        m, u = len(errors.offsets), errors.uwb
        self.errs = FixedNoise(errors.rng, errors.block)
        self.ERR_OFF = np.array(errors.offsets, dtype=float)
        self.ERR_STEP = rerr.draw_steps(u, errors.rng, m) if errors.block else np.zeros(m)
        self.ERR_RS = np.zeros((m, rerr.RS_N))
        self.ERR_RS[:, rerr.RS_T] = np.nan
        self.INP = np.zeros(lnb.INP_N)
        self.CIDX = np.zeros(n_markers, dtype=np.int64)
        self.CPX = np.zeros((n_markers, 4, 2))

    @property
    def next_anchor(self) -> int:
        return int(self.WSC[lnb.WSC_NEXT_ANCHOR])

    @property
    def energy_j(self) -> float:
        return float(self.WSC[lnb.WSC_ENERGY])

    @property
    def frames(self) -> int:
        return int(self.WSC[lnb.WSC_FRAMES])

    @property
    def landed_t(self) -> float | None:
        return nan_to_none(self.WSC[lnb.WSC_LANDED_T])

    @property
    def done(self) -> bool:
        return bool(self.WSC[lnb.WSC_DONE])

    @done.setter
    def done(self, v: bool) -> None:
        self.WSC[lnb.WSC_DONE] = float(v)

    @property
    def end_k(self) -> int:
        return int(self.WSC[lnb.WSC_END_K])

    @end_k.setter
    def end_k(self, k: int) -> None:
        self.WSC[lnb.WSC_END_K] = k


def world_row(sc: LandingScenario) -> np.ndarray:
    """The compiled world step's scenario parameters ``WP`` (:mod:`swarm.step.landing_nb`)."""
    rates, f = Rates.of(sc), sc.faults
    WP = np.zeros(lnb.WP_N)
    for i, v in (
        (lnb.WP_DT, sc.dt_s), (lnb.WP_G, sc.kinds.quadrotor.airframe.gravity_m_s2),
        (lnb.WP_ACC_NOISE, sc.imu.accel_noise_m_s2_rthz), (lnb.WP_GYRO_NOISE, sc.imu.gyro_noise_rad_s_rthz),
        (lnb.WP_UWB_SIGMA, sc.uwb.sigma_m), (lnb.WP_RATE_CAM, rates.camera), (lnb.WP_RATE_UWB, rates.uwb),
        (lnb.WP_RATE_GNSS, rates.gnss),
        (lnb.WP_UWB_ON, sc.uwb.mode == "twr" and sc.uwb.enabled and len(sc.uwb.anchors_m) > 0),
        (lnb.WP_GNSS_ON, sc.gnss.enabled), (lnb.WP_HIDDEN_ALWAYS, f.pad_hidden_always),
        (lnb.WP_HIDDEN_FROM, math.nan if f.pad_hidden_from_s is None else f.pad_hidden_from_s),
        (lnb.WP_HIDDEN_FOR, f.pad_hidden_for_s), (lnb.WP_CORNERS, sc.camera.mode == "corners"),
        (lnb.WP_END_AFTER, sc.end_after_landed_s), (lnb.WP_ABORT_H, sc.landing.abort_height_m),
        (lnb.WP_ABORT_TOL, sc.abort_hold_tolerance_m), (lnb.WP_ABORT_V, sc.abort_hold_speed_m_s),
        (lnb.WP_RF_ON, sc.rangefinder.enabled), (lnb.WP_RF_RATE, rates.rangefinder),
        (lnb.WP_RF_SIGMA, sc.rangefinder.sigma_m), (lnb.WP_RF_MIN, sc.rangefinder.min_range_m),
        (lnb.WP_RF_MAX, sc.rangefinder.max_range_m),
        (lnb.WP_RF_COS_TILT, math.cos(math.radians(sc.rangefinder.max_tilt_deg))),
        (lnb.WP_GROUND_Z, sc.kinds.quadrotor.airframe.ground_z_m),
    ):  # fmt: skip
        WP[i] = float(v)
    pf = sc.platform
    if pf.enabled:
        WP[lnb.WP_PLATFORM], WP[lnb.WP_SHARE_ON] = 1.0, float(pf.share_estimate)
        WP[lnb.WP_SHARE_RATE] = rates.share
        WP[lnb.WP_SHARE_SIGMA_P], WP[lnb.WP_SHARE_SIGMA_V] = pf.share_sigma_m, pf.share_sigma_m_s
        WP[lnb.WP_PAD_YAW] = math.radians(sc.pad.yaw_deg)
    WP[lnb.WP_GNSS_SIGMA : lnb.WP_GNSS_SIGMA + 3] = sc.gnss.sigma_m
    WP[lnb.WP_CAM_POS : lnb.WP_CAM_POS + 3] = sc.camera.pos_body_m
    WP[lnb.WP_LEVER : lnb.WP_LEVER + 3] = sc.uwb.lever_arm_m
    return WP


class LandingWorld:
    """The truth and the sensors of every UAV of a landing scenario (module docstring), on the compiled
    steps of :mod:`swarm.step.landing_nb`."""

    def __init__(self, sc: LandingScenario, seed: int) -> None:
        self.sc, self.seed = sc, seed
        qp = sc.kinds.quadrotor
        self.air = qp.airframe
        self.kp = QUADROTOR(qp, sc).truth(VehicleDispersion()).kp
        self.rates = Rates.of(sc)
        self.anchors = np.ascontiguousarray(anchors_of(sc))
        self.gnss_cov = np.diag(np.asarray(sc.gnss.sigma_m, float) ** 2)
        """The fixes' covariance, the receiver's claim (what the GNSS message carries)."""
        cam = sc.camera
        self.WP = world_row(sc)
        self.board = sc.pad.board
        self.corners = np.ascontiguousarray(self.board.corners)
        self.CAM = camera_vector(cam.intrinsics)
        n_markers = len(self.corners)
        pf = sc.platform
        self.draws = lnb.draws_per_tick(n_markers, pf.enabled and pf.share_estimate)
        self.PATH = platform_path(sc) if pf.enabled else np.zeros(PATH_HEAD)
        """A moving pad's path (:mod:`swarm.core.platform_path`; unused otherwise)."""
        self.err_prm = rerr.range_error_vector(sc.uwb, sc.uwb.outlier_probability, sc.uwb.outlier_excess_m)
        self.vib = np.zeros(lnb.VIB_N)
        self.vib[lnb.VIB_ACC] = sc.imu.vibration_accel_m_s2
        self.vib[lnb.VIB_GYRO] = sc.imu.vibration_gyro_rad_s
        self.errors_on = bool(self.err_prm[rerr.RE_ON] or self.vib.any())
        m = len(self.anchors)
        offsets = np.zeros(m)
        if self.err_prm[rerr.RE_ON]:  # the anchors' offsets: one stream for the fleet, which shares them
            offsets = rerr.draw_offsets(sc.uwb, np.random.default_rng(_seeds(seed, 0, 19)), m)
        self.renderer = Renderer(sc.pad.board, cam.intrinsics) if cam.mode == "rendered" else None
        self.detector = make_detector(sc.pad.board) if cam.mode == "rendered" else None
        self.uavs: dict[str, _Truth] = {}
        for u in sc.uavs():
            st = landing_setup(sc, seed, u.index)
            x = np.zeros(13)
            x[0:3] = st.start
            x[6:10] = rot.rotvec_exp(np.array([0.0, 0.0, st.yaw_rad]))
            s = np.zeros(QUADROTOR.S_N)
            s[0:4] = self.air.hover_omega_rad_s
            held = np.full(4, self.air.hover_omega_rad_s)
            render_rng = np.random.default_rng(_seeds(seed, u.index, 17))
            errors = _Errors(sc.uwb, offsets, np.random.default_rng(_seeds(seed, u.index, 18)),
                             NoiseStream.BLOCK if self.errors_on else 0)  # fmt: skip
            self.uavs[u.id] = _Truth(st, x, s, held, n_markers, render_rng, errors)
        self.tdoa = self._tdoa_radio(sc, seed, offsets) if sc.uwb.mode != "twr" and sc.uwb.enabled else None
        """The TDoA radio (``uwb.mode`` tdoa2/tdoa3; None on two-way ranging): one channel every UAV's tag
        hears (:meth:`_tdoa_step`)."""

    TDOA_MARGIN_S = 5.0
    """The TDoA channel is simulated over ``max_duration_s`` plus this [s] (as the docking radio's)."""

    def _tdoa_radio(self, sc: LandingScenario, seed: int, offsets: np.ndarray) -> tr.TdoaRadio:
        """The docking swarm's TDoA radio (:class:`swarm.core.tdoa_radio.TdoaRadio`, ``[tdoa]``) for the
        landing's anchors, one tag per UAV in the scenario's order, its own stream (``[seed, 20]``: the
        channel, then each tag's); the range errors of each tag-anchor link from the TWR model's draws (the
        anchors' offsets, each UAV's take-off steps), so that they enter the differences per anchor."""
        errors = None
        if self.err_prm[rerr.RE_ON]:
            steps = np.array([u.ERR_STEP for u in self.uavs.values()]).reshape(len(self.uavs), -1)
            errors = tr.LinkErrors(self.err_prm, offsets, steps)
        params = replace(sc.tdoa, mode=sc.uwb.mode)
        duration = sc.max_duration_s + self.TDOA_MARGIN_S
        ss = np.random.SeedSequence([seed, 20])
        return tr.TdoaRadio(params, self.anchors, len(self.uavs), duration, ss, errors)

    def _tdoa_step(self, k: int, inputs: dict[str, LandingInputs]) -> None:
        """A UWB tick of the TDoA radio: the packets sent up to ``t = k dt``, heard by every UAV's tag at its
        position (the truth plus the lever arm turned by the attitude, after the tick's step) and airborne
        flag (:meth:`swarm.core.tdoa_radio.TdoaRadio.step`, every tag, so that no tag's draws depend on
        which UAVs are done); each active UAV's rows of anchors both within its reach (``WC_UWB_RANGE``),
        none inside a ``uwb_dropout`` window, in ``inputs[id].tdoa``. An anchor out of reach is taken out
        after the tag's engine (whose clock correction of it goes on as if heard: a simplification)."""
        t = k * self.sc.dt_s
        lever = np.asarray(self.sc.uwb.lever_arm_m, float)
        U = list(self.uavs.values())
        tags = np.array([u.x[0:3] + qrotate(u.x[6:10], lever) for u in U])
        airborne = np.array([u.s[S_GROUND] == 0.0 for u in U])
        rows = self.tdoa.step(t, tags, airborne)
        for i, (uid, u) in enumerate(self.uavs.items()):
            if uid not in inputs:
                continue
            r = rows[i]
            a, b = r[:, tr.ROW_A].astype(np.int64), r[:, tr.ROW_B].astype(np.int64)
            near = np.linalg.norm(self.anchors - tags[i], axis=1) <= u.WC[lnb.WC_UWB_RANGE]
            keep = near[a] & near[b]
            if u.WC[lnb.WC_UWB_OFF] <= t < u.WC[lnb.WC_UWB_OFF + 1]:  # a dropout (False with NaN)
                keep[:] = False
            inputs[uid].tdoa = np.ascontiguousarray(r[keep][:, [tr.ROW_A, tr.ROW_B, tr.ROW_DDIST]])

    def active(self) -> list[str]:
        return [i for i, u in self.uavs.items() if not u.done]

    def step(self, k: int) -> dict[str, LandingInputs]:
        """Step 1 of the tick for every UAV not done (and, on a TDoA radio's UWB tick, its differences)."""
        out = {i: self._step_one(u, k) for i, u in self.uavs.items() if not u.done}
        if self.tdoa is not None and out and self.rates.tdoa_tick(self.sc, k):
            self._tdoa_step(k, out)
        return out

    def arrays(self, u: _Truth) -> tuple:
        """The arrays of :func:`swarm.step.landing_nb.world_sample` (after ``k``, without the draws), in
        :func:`~swarm.step.landing_nb.run_landing_ticks`' order."""
        return (u.x, u.s, u.held, self.kp, u.WSC, u.WC, self.WP, self.anchors, self.corners, self.CAM, u.INP,
                u.CIDX, u.CPX, self.err_prm, self.vib, u.ERR_RS, u.ERR_OFF, u.ERR_STEP, u.errs.Z,
                u.errs.pos, self.PATH)  # fmt: skip

    def ensure_draws(self, u: _Truth) -> None:
        """At least a tick's draws left in each of the UAV's buffers."""
        u.noise.ensure(self.draws)
        if self.errors_on:
            u.errs.ensure(lnb.ERR_DRAWS_PER_TICK)

    def _step_one(self, u: _Truth, k: int) -> LandingInputs:
        self.ensure_draws(u)
        lnb.world_platform(k, u.x, u.WSC, u.WC, self.WP, self.PATH, u.noise.Z, u.noise.pos, u.INP)
        lnb.world_sample(k, *self.arrays(u)[:10], u.noise.Z, u.noise.pos, u.INP, u.CIDX, u.CPX)
        if self.errors_on:
            lnb.world_errors(u.s, self.err_prm, self.vib, u.ERR_RS, u.ERR_OFF, u.ERR_STEP, u.errs.Z,
                             u.errs.pos, u.INP)  # fmt: skip
        inp = inputs_of(u.INP, u.CIDX, u.CPX, self.board)
        if u.INP[lnb.INP_CAM] == lnb.CAM_RENDER:
            t_cam = u.INP[lnb.INP_T_CAM : lnb.INP_T_CAM + 3].copy()
            q_cam_pad = rot.matrix_to_quat(u.INP[lnb.INP_R_CAM_PAD : lnb.INP_R_CAM_PAD + 9].reshape(3, 3))
            ids, corners = detect(
                self.renderer.render(t_cam, q_cam_pad, u.render_rng), self.board, self.detector
            )
            inp.camera = (
                np.asarray(ids, dtype=np.int64).reshape(-1),
                np.asarray(corners, float).reshape(-1, 4, 2),
            )
        return inp

    def hold(self, uav_id: str, cmd: LandingCommand) -> None:
        """Step 3 (module docstring): the rotors take the command; the UAV's run may end."""
        u = self.uavs[uav_id]
        mode = float(MODES.index(cmd.mode))
        lnb.world_hold(np.asarray(cmd.u, float), mode, cmd.k, u.x, u.s, u.held, self.kp,
                       u.WSC, u.WC, self.WP)  # fmt: skip

    FAULTS = ("camera_loss", "uwb_dropout")
    """The run-time faults a landing world models (``swarm fault``; ``docs/protocol.md``, Fault)."""

    def add_fault(self, kind: str, start_s: float, duration_s: float, uav_ids) -> None:
        """A run-time fault on UAVs ``uav_ids`` over ``[start_s, start_s + duration_s)``: ``camera_loss``
        hides the pad from their cameras, ``uwb_dropout`` loses every UWB reply (the range is nil). A UAV
        keeps one window of each kind: a new one replaces it. ValueError for another kind or UAV."""
        if kind not in self.FAULTS:
            raise ValueError(f"kind: a landing world models {' and '.join(self.FAULTS)}, not {kind!r}")
        at = lnb.WC_CAM_OFF if kind == "camera_loss" else lnb.WC_UWB_OFF
        for uid in uav_ids:
            if uid not in self.uavs:
                raise ValueError(f"vehicle: {uid!r} is not a UAV of this scenario")
            self.uavs[uid].WC[at : at + 2] = (start_s, start_s + duration_s)

    def snapshot(self) -> dict:
        """The world's complete mutable state (each UAV's truth, its sensors' pending draws and random
        streams, its faults), for a checkpoint: :meth:`restore` on a world of the same scenario and seed
        continues exactly as this one does."""
        snap = {
            uid: {
                "state": snapshot_state({"u": u}),
                "noise": u.noise.state(),
                "render_rng": u.render_rng.bit_generator.state,
            }
            for uid, u in self.uavs.items()
        }
        if self.errors_on:  # (only then: a snapshot without them is the one of before)
            for uid, u in self.uavs.items():
                snap[uid]["errs"] = u.errs.state()
        if self.tdoa is not None:  # the tags' engines and draws (the channel is the seed's)
            r = self.tdoa
            snap[TDOA_KEY] = {"ts": r.ts.copy(), "tc": r.tc.copy(), "link": r.link.copy(), "k": r.k,
                              "rng": [g.bit_generator.state for g in r.rng]}  # fmt: skip
        return snap

    def restore(self, snap: dict) -> None:
        """A :meth:`snapshot` into this world (built from the same scenario and seed); :class:`SnapshotError`
        if it is another world's."""
        radio = snap.get(TDOA_KEY)
        snap = {k: v for k, v in snap.items() if k != TDOA_KEY}
        if set(snap) != set(self.uavs):
            raise SnapshotError(
                f"the snapshot's UAVs {sorted(snap)} are not this world's {sorted(self.uavs)}"
            )
        if (radio is None) != (self.tdoa is None):
            raise SnapshotError("the snapshot's radio is not this world's (uwb.mode)")
        if radio is not None:
            r = self.tdoa
            r.ts[...], r.tc[...], r.link[...], r.k = radio["ts"], radio["tc"], radio["link"], radio["k"]
            for g, st in zip(r.rng, radio["rng"], strict=True):
                g.bit_generator.state = st
        for uid, u in self.uavs.items():
            s = snap[uid]
            restore_state({"u": u}, s["state"])
            u.noise.restore(s["noise"])
            u.render_rng.bit_generator.state = s["render_rng"]
            if self.errors_on:
                u.errs.restore(s["errs"])

    def outcome(self, uav_id: str) -> dict:
        """The world's half of a UAV's summary: where and how it ended."""
        u = self.uavs[uav_id]
        on_ground = u.s[S_GROUND] != 0.0
        out = {
            "on_ground": bool(on_ground),
            "error_m": float(np.linalg.norm(u.x[0:2] - u.setup.pad[0:2])),
            "energy_j": float(u.energy_j),
            "pad_frames": u.frames,
            "start_m": [float(v) for v in u.setup.start],
            "uwb_range_m": u.setup.uwb_range_m,
        }
        if self.sc.platform.enabled:  # a moving pad: judged at the touchdown, relative to the deck
            W = u.WSC
            touched = not math.isnan(W[lnb.WSC_TD_T])
            pad_now = u.WC[lnb.WC_PAD : lnb.WC_PAD + 2]
            out["error_m"] = float(W[lnb.WSC_TD_ERR] if touched else np.linalg.norm(u.x[0:2] - pad_now))
            for key, i in (("touchdown_t_s", lnb.WSC_TD_T), ("touchdown_rel_speed_m_s", lnb.WSC_TD_REL_V),
                           ("touchdown_vz_m_s", lnb.WSC_TD_VZ)):  # fmt: skip
                out[key] = float(W[i]) if touched else None
            out["platform_start_arc_m"] = u.setup.arc0_m
        return out


def inputs_of(INP: np.ndarray, CIDX: np.ndarray, CPX: np.ndarray, board) -> LandingInputs:
    """The samples of the compiled world step as :class:`LandingInputs` (marker ids, not board indices)."""
    k = int(INP[lnb.INP_K])
    inp = LandingInputs(k, float(INP[lnb.INP_T]), INP[lnb.INP_GYRO : lnb.INP_GYRO + 3].copy(),
                        INP[lnb.INP_ACC : lnb.INP_ACC + 3].copy())  # fmt: skip
    if INP[lnb.INP_HAS_UWB]:
        inp.uwb = (int(INP[lnb.INP_ANCHOR]), float(INP[lnb.INP_RANGE]))
    if INP[lnb.INP_HAS_GNSS]:
        inp.gnss = INP[lnb.INP_GNSS : lnb.INP_GNSS + 3].copy()
    if INP[lnb.INP_HAS_RF] and not math.isnan(INP[lnb.INP_RF]):
        inp.rangefinder = float(INP[lnb.INP_RF])
    if INP[lnb.INP_HAS_PAD]:
        inp.pad = INP[lnb.INP_PAD_P : lnb.INP_PAD_P + 6].copy()
    if INP[lnb.INP_CAM] == lnb.CAM_MARKERS:
        n = int(INP[lnb.INP_N_MARKERS])
        inp.camera = (board.markers[0][CIDX[:n]].astype(np.int64), CPX[:n].copy())
    return inp


@dataclass
class _Series:
    t_s: list = field(default_factory=list)
    p_true_nav: list = field(default_factory=list)
    p_est_nav: list = field(default_factory=list)
    sigma_h_m: list = field(default_factory=list)
    mode: list = field(default_factory=list)
    pad_seen: list = field(default_factory=list)

    def add(self, row: np.ndarray) -> None:
        """One sample, a row of :func:`swarm.step.landing_nb.series_sample`."""
        self.t_s.append(round(float(row[lnb.SER_T]), 4))
        self.p_true_nav.append([float(v) for v in row[lnb.SER_PTRUE : lnb.SER_PTRUE + 3]])
        self.p_est_nav.append([float(v) for v in row[lnb.SER_PEST : lnb.SER_PEST + 3]])
        self.sigma_h_m.append(float(row[lnb.SER_SIGMA]))
        self.mode.append(str(MODES[int(row[lnb.SER_MODE])]))
        self.pad_seen.append(bool(row[lnb.SER_SEEN]))


class LandingAgent:
    """One UAV's on-board software (module docstring, step 2): filter, guidance, controller, on the compiled
    steps of :mod:`swarm.step.landing_nb`."""

    NIS_WINDOW = 20
    """The filter's consistency ``d`` is the RMS of this many recent normalised innovations."""

    def __init__(self, sc: LandingScenario, seed: int, index: int, policy: str) -> None:
        self.sc, self.policy = sc, policy
        st = landing_setup(sc, seed, index)
        self.setup = st
        qp = sc.kinds.quadrotor
        air = qp.airframe
        self.cp = QUADROTOR(qp, sc).control_row()
        self.dt = sc.dt_s
        self.rates = Rates.of(sc)
        anchors = anchors_of(sc)
        ini = sc.initial
        params = ImuFilterParams(
            **{
                **sc.estimator.__dict__,
                "lever_arm_m": tuple(sc.uwb.lever_arm_m),
                "gravity_nav": (0.0, 0.0, -air.gravity_m_s2),
                "accel_noise": sc.imu.accel_noise_m_s2_rthz,
                "gyro_noise": sc.imu.gyro_noise_rad_s_rthz,
            }
        )
        # the navigator the quadrotor's IMU (gyro and accelerometer) calls for: "eskf" (swarm.navigation)
        self.filt = NAVIGATORS[navigator_name(QUADROTOR.imu_measures)].create(
            params,
            anchors if len(anchors) else np.zeros((1, 3)),
            st.p0,
            np.zeros(3),
            st.q0,
            0.0,
            sc.uwb.sigma_m,
            (
                ini.sigma_position_m,
                ini.sigma_velocity_m_s,
                math.radians(ini.sigma_attitude_deg),
                ini.sigma_accel_bias_m_s2,
                ini.sigma_gyro_bias_rad_s,
                ini.sigma_range_offset_m,
            ),
            accel_bias=st.accel_bias0,
            gyro_bias=st.gyro_bias0,
            sigma_common_m=ini.sigma_common_offset_m,
        )
        # a TDoA radio (uwb.mode tdoa2/tdoa3): the robust update of log replay (lnb.agent_tdoa), each pair's
        # noise from [tdoa] sigma_m (adapted upward), each anchor's NLOS state, per-pair outcome counts
        m, sig = len(self.filt.anchors), sc.tdoa.sigma_m
        self.TV = np.full((m, m, inb.N_TV), np.nan)
        self.TV[:, :, inb.TV_VAR] = self.TV[:, :, inb.TV_PRIOR] = sig**2
        self.RS = np.zeros((m, inb.N_RS))
        inb.robust_init(self.RS, np.full(m, sig))
        self.RP = robust_vector(sc.robust, PhaseParams(enabled=False), sig, air.ground_z_m, -1, m,
                                g_norm_m_s2=air.gravity_m_s2)  # fmt: skip
        self.TC = np.zeros((m, m, 3), dtype=np.int64)
        self.TD2 = np.zeros((m, m))
        self.TSKIP = np.zeros(1, dtype=np.int64)
        self.TRES = np.zeros(4)
        cam = sc.camera
        self.cam_pos = np.asarray(cam.pos_body_m, float)
        half_fov = math.atan(min(cam.intrinsics.cx_px, cam.intrinsics.cy_px) / cam.intrinsics.fx_px)
        self.guidance = LandingGuidance(sc.landing, policy, st.pad, st.start, half_fov, air.gear_height_m)
        self.cs, self.u, self.act = np.zeros(QUADROTOR.CS_N), np.zeros(4), np.zeros(9)
        self.board = sc.pad.board
        self.corners = np.ascontiguousarray(self.board.corners)
        self.CAM = camera_vector(cam.intrinsics)
        m = len(self.corners)
        self.AC = np.zeros(lnb.AC_N)
        self.AC[lnb.AC_DT], self.AC[lnb.AC_GATE3] = self.dt, chi2_gate(GATE_PROBABILITY, 3)
        rf = sc.rangefinder
        self.AC[lnb.AC_RF_SIGMA], self.AC[lnb.AC_GATE1] = rf.sigma_m, chi2_gate(GATE_PROBABILITY, 1)
        self.AC[lnb.AC_GROUND_Z], self.AC[lnb.AC_RF_COS_TILT] = (
            air.ground_z_m,
            math.cos(math.radians(rf.max_tilt_deg)),
        )
        self.AC[lnb.AC_PAD : lnb.AC_PAD + 3] = st.pad
        self.AC[lnb.AC_CAM_POS : lnb.AC_CAM_POS + 3] = self.cam_pos
        self.AC[lnb.AC_R_BC : lnb.AC_R_BC + 9] = R_BODY_CAM.ravel()
        self.AC[lnb.AC_GNSS_COV : lnb.AC_GNSS_COV + 9] = np.diag(
            np.asarray(sc.gnss.sigma_m, float) ** 2
        ).ravel()
        self.AF = np.zeros(lnb.AF_N)
        for i in (lnb.AF_PAD_SEEN, lnb.AF_LANDED_T, lnb.AF_LAST_D2, lnb.AF_LAST_PAD_D2):
            self.AF[i] = np.nan
        self.AF[lnb.AF_P_EST : lnb.AF_P_EST + 3] = st.p0
        if sc.platform.enabled:  # a moving pad: its pose at t = 0 (told before take-off), then shared
            self.AC[lnb.AC_PLATFORM], self.AC[lnb.AC_SHARE_VAR] = 1.0, sc.platform.share_sigma_m**2
            self.AF[lnb.AF_SHARE_T] = 0.0
            self.AF[lnb.AF_SHARE_P : lnb.AF_SHARE_P + 3] = st.pad
            self.AF[lnb.AF_SHARE_V : lnb.AF_SHARE_V + 3] = st.pad_v
            self.AF[lnb.AF_PAD_EST : lnb.AF_PAD_EST + 3] = st.pad
            GP = self.guidance.GP
            GP[gnb.GP_MOVING] = 1.0
            GP[gnb.GP_PAD_V : gnb.GP_PAD_V + 3] = st.pad_v
        self.HELD, self.NIS = np.zeros((2, 3)), np.zeros(self.NIS_WINDOW)
        self.INP, self.POSE = np.zeros(lnb.INP_N), np.zeros(lnb.POSE_N)
        self.CIDX, self.CPX = np.zeros(m, dtype=np.int64), np.zeros((m, 4, 2))
        self.OBJ, self.IMG, self.VAR = np.zeros((4 * m, 3)), np.zeros((4 * m, 2)), np.zeros(4 * m)
        self.T_OUT, self.R_OUT, self.COV_OUT = np.zeros(3), np.zeros((3, 3)), np.zeros((6, 6))
        self.series = _Series()
        self._ser, self._ser_n = np.zeros((1, lnb.SER_N)), np.zeros(1, dtype=np.int64)
        self._records = (_Records(0), _Records(1))  # the snapshots' pickled decisions and mode switches

    # the agent's state, as the wire and the summary read it
    @property
    def pad_seen(self) -> float | None:
        return nan_to_none(self.AF[lnb.AF_PAD_SEEN])

    @property
    def landed_t(self) -> float | None:
        return nan_to_none(self.AF[lnb.AF_LANDED_T])

    @property
    def detections(self) -> int:
        return int(self.AF[lnb.AF_DETECTIONS])

    @property
    def p_est(self) -> np.ndarray:
        """The estimate the last decision used."""
        return self.AF[lnb.AF_P_EST : lnb.AF_P_EST + 3].copy()

    @property
    def pad_est(self) -> np.ndarray:
        """The pad the guidance targets: the surveyed pad, or a moving pad's estimate (the robot's)."""
        if self.AC[lnb.AC_PLATFORM]:
            return self.AF[lnb.AF_PAD_EST : lnb.AF_PAD_EST + 3].copy()
        return self.setup.pad

    @property
    def sigma_h(self) -> float:
        return float(self.AF[lnb.AF_SIGMA_H])

    @property
    def last_d2(self) -> float | None:
        """The squared Mahalanobis distance of the latest range (None before the first)."""
        return nan_to_none(self.AF[lnb.AF_LAST_D2])

    def arrays(self) -> tuple:
        """The arrays of :func:`swarm.step.landing_nb.agent_fuse` after ``INP, CIDX, CPX``, in
        :func:`~swarm.step.landing_nb.run_landing_ticks`' order (the agent tuple)."""
        f = self.filt
        return (self.POSE, f.X[0], f.P[0], self.AF, self.HELD, self.NIS, f.counts, f.anchors, f.ridx,
                f.sigma, f.prm, f._work, f._res, self.AC, self.OBJ, self.IMG, self.VAR, self.T_OUT,
                self.R_OUT, self.COV_OUT)  # fmt: skip

    def guidance_arrays(self) -> tuple:
        g = self.guidance
        return g.G, g.GP, g.REF, g.EV, g.EV_n, g.DEC, g.DEC_n

    def tick(self, inp: LandingInputs, truth_p=None) -> LandingCommand:
        """Step 2 (module docstring): :meth:`fuse` the tick's samples, then :meth:`decide`; ``truth_p``, the
        true position (in process only), goes to the series."""
        self.fuse(inp)
        return self.decide(inp, truth_p)

    def _load(self, inp: LandingInputs) -> None:
        """``inp`` into the kernels' ``INP``: the markers as board indices (ids not on the board dropped), or,
        for a rendered camera, the pad's pose solved by OpenCV
        (:func:`swarm.core.pad_vision.estimate_pose`)."""
        I = self.INP
        I[:] = 0.0
        I[lnb.INP_K], I[lnb.INP_T] = inp.k, inp.t
        I[lnb.INP_GYRO : lnb.INP_GYRO + 3], I[lnb.INP_ACC : lnb.INP_ACC + 3] = inp.gyro, inp.acc
        if inp.uwb is not None:
            I[lnb.INP_HAS_UWB], I[lnb.INP_ANCHOR], I[lnb.INP_RANGE] = 1.0, inp.uwb[0], inp.uwb[1]
        if inp.gnss is not None:
            I[lnb.INP_HAS_GNSS] = 1.0
            I[lnb.INP_GNSS : lnb.INP_GNSS + 3] = inp.gnss
        I[lnb.INP_RF] = np.nan
        if inp.rangefinder is not None:
            I[lnb.INP_HAS_RF], I[lnb.INP_RF] = 1.0, inp.rangefinder
        if inp.pad is not None:
            I[lnb.INP_HAS_PAD] = 1.0
            I[lnb.INP_PAD_P : lnb.INP_PAD_P + 6] = inp.pad
        if inp.camera is None or not len(inp.camera[0]):
            return
        ids, corners = inp.camera
        if self.sc.camera.mode == "rendered":
            est = estimate_pose(ids, corners, self.board, self.sc.camera.intrinsics)
            if est is not None:
                I[lnb.INP_CAM] = lnb.CAM_POSE
                self.POSE[0:3], self.POSE[3:12] = est.t_cam_m, est.cov_cam[:3, :3].ravel()
            return
        index = np.asarray(ids, dtype=np.int64) - self.board.first_id
        ok = (index >= 0) & (index < len(self.corners))
        n = int(ok.sum())
        I[lnb.INP_CAM], I[lnb.INP_N_MARKERS] = lnb.CAM_MARKERS, n
        self.CIDX[:n], self.CPX[:n] = index[ok], np.asarray(corners, float)[ok]

    def fuse(self, inp: LandingInputs) -> None:
        """The filter's half of a tick: the IMU sample, then the range, the fix and the pad's pose from the
        camera's corners (PnP). A free-running agent that has fallen behind fuses the ticks it missed with
        this alone and decides only on the newest (:mod:`agents.landing`)."""
        self._load(inp)
        a = self.arrays()
        lnb.agent_fuse(self.INP, self.CIDX, self.CPX, *a[:14], self.corners, self.CAM, *a[14:])
        if inp.tdoa is not None:
            f = self.filt
            rows = np.ascontiguousarray(inp.tdoa, dtype=float).reshape(-1, 3)
            lnb.agent_tdoa(self.INP, rows, f.X[0], f.P[0], self.AF, self.HELD, self.NIS, f.prm, self.RP,
                           f.anchors, f.ridx, self.TV, self.RS, self.TC, self.TD2, self.TSKIP, f._work,
                           self.TRES)  # fmt: skip

    def decide(self, inp: LandingInputs, truth_p=None) -> LandingCommand:
        """The guidance and control half of a tick, on the filter's estimate after :meth:`fuse`."""
        f = self.filt
        if int(self.INP[lnb.INP_K]) != inp.k:
            self._load(inp)
        mode = lnb.agent_decide(self.INP, f.X[0], f.P[0], self.AF, self.NIS, *self.guidance_arrays(), self.cs,
                                self.cp, self.u, self.act)  # fmt: skip
        self.guidance.drain()
        if truth_p is not None and inp.k % lnb.SERIES_EVERY == 0:
            lnb.series_sample(self._ser, self._ser_n, inp.t, np.asarray(truth_p, float), self.AF, mode)
            self.series.add(self._ser[0])
            self._ser_n[0] = 0
        return LandingCommand(inp.k, self.u.copy(), MODES[int(mode)])

    def snapshot(self) -> dict:
        """The agent's complete mutable state (filter, guidance and its records, controller), for a warm
        restart: :meth:`restore` on an agent of the same scenario, seed, UAV and policy continues exactly as
        this one does. ``state``: everything but the guidance's records; ``records``: those, as checkpoint
        entries (a checkpoint file's samples, :class:`swarm.transport.checkpoint.CheckpointFile`): they only
        grow, and each is pickled and checksummed once, at the first snapshot after it."""
        g = self.guidance
        records = [*self._records[0].entries(g.decisions), *self._records[1].entries(g.modes)]
        return {"state": snapshot_state({"a": self, "f": self.filt, "g": g}), "records": records}

    def restore(self, snap: dict) -> None:
        """A :meth:`snapshot` into this agent (``records``: entries ``(tag, chunk, ...)``, as a checkpoint
        file reads them back); :class:`SnapshotError` if it is another agent's."""
        g = self.guidance
        restore_state({"a": self, "f": self.filt, "g": g}, snap["state"])
        g.decisions, g.modes = _Records.load(snap["records"], 0), _Records.load(snap["records"], 1)
        self._records = (_Records(0), _Records(1))

    def tdoa_counts(self) -> dict:
        """The TDoA differences fused so far (:func:`swarm.step.landing_nb.agent_tdoa`): accepted, rejected
        (gated or an anchor held out as NLOS), refused, and skipped (naming an anchor the scenario does not
        have); ``tdoa_pairs``: per anchor pair heard (``"A-B"``, anchor indices) its counts, rejected share
        and the mean NIS of its accepted rows (1 for a consistent filter)."""
        c = self.TC.sum(axis=(0, 1))
        pairs = {}
        for a, b in zip(*np.nonzero(self.TC.sum(axis=2)), strict=True):
            acc, rej, ref = (int(x) for x in self.TC[a, b])
            pairs[f"{a}-{b}"] = {"accepted": acc, "rejected": rej, "refused": ref,
                                 "rejected_share": rej / (acc + rej) if acc + rej else None,
                                 "nis_mean": float(self.TD2[a, b] / acc) if acc else None}  # fmt: skip
        return {"tdoa_accepted": int(c[inb.ACCEPTED]), "tdoa_rejected": int(c[inb.REJECTED]),
                "tdoa_refused": int(c[inb.REFUSED]), "tdoa_skipped": int(self.TSKIP[0]),
                "tdoa_pairs": pairs}  # fmt: skip

    def outcome(self) -> dict:
        """The agent's half of a UAV's summary: modes, decisions, deviation, detections (and on a TDoA radio
        :meth:`tdoa_counts`)."""
        g = self.guidance
        dev = g.deviation_point
        pad = self.setup.pad
        tdoa = self.tdoa_counts() if self.sc.uwb.mode != "twr" else {}
        return tdoa | {
            "final_mode": str(g.mode),
            "landing_time_s": float(self.landed_t) if self.landed_t is not None else None,
            "deviation_distance_m": float(np.linalg.norm(dev[:2] - pad[:2])) if dev is not None else None,
            "retries": g.retries,
            "pad_detections": self.detections,
            "modes": g.modes,
            "decisions": [dd.as_dict() for dd in g.decisions if dd.switched or self.policy == "mdp"],
        }


TDOA_COUNTS = ("tdoa_accepted", "tdoa_rejected", "tdoa_refused", "tdoa_skipped", "tdoa_pairs")
"""What a TDoA landing's summary adds (:meth:`LandingAgent.tdoa_counts`)."""


def landing_summary(sc: LandingScenario, policy: str, seed: int, world_half: dict, agent_half: dict,
                    end_k: int, wall: float) -> dict:  # fmt: skip
    """One UAV's summary (``swarm sim landing --json``) from the world's half (:meth:`LandingWorld.outcome`:
    where it ended) and the agent's (:meth:`LandingAgent.outcome`), in process or gathered over Zenoh."""
    w, a = world_half, agent_half
    landed = bool(a["final_mode"] == "LANDED" and w["on_ground"])
    moving = {k: a[k] for k in TDOA_COUNTS if k in a}
    if sc.platform.enabled:  # the deck's rule: on the pad and slow enough relative to it at the touchdown
        rel = w.get("touchdown_rel_speed_m_s")
        landed = landed and rel is not None and rel <= sc.platform.touchdown_speed_m_s
        moving |= {k: w.get(k) for k in ("touchdown_t_s", "touchdown_rel_speed_m_s", "touchdown_vz_m_s",
                                        "platform_start_arc_m")}  # fmt: skip
        moving["platform_speed_m_s"] = sc.platform.speed_m_s
    return moving | {
        "scenario": sc.name,
        "policy": policy,
        "seed": seed,
        "camera_mode": sc.camera.mode,
        "landed": landed and w["error_m"] <= sc.pad_tolerance_m,
        "landed_off_pad": bool(w["on_ground"] and w["error_m"] > sc.pad_tolerance_m),
        "aborted": a["final_mode"] == "ABORT",
        "final_mode": a["final_mode"],
        "landing_error_m": w["error_m"] if landed else None,
        "landing_time_s": a["landing_time_s"],
        "energy_j": w["energy_j"],
        "hover_equivalent_s": w["energy_j"] / sc.kinds.quadrotor.airframe.hover_power_w,
        "deviation_distance_m": a["deviation_distance_m"],
        "retries": a["retries"],
        "start_m": w["start_m"],
        "uwb_range_m": w["uwb_range_m"],
        "pad_frames": w["pad_frames"],
        "pad_detections": a["pad_detections"],
        "sim_time_s": round(end_k * sc.dt_s, 4),
        "wall_s": wall,
        "realtime_factor": end_k * sc.dt_s / wall if wall > 0 else None,
        "modes": a["modes"],
        "decisions": a["decisions"],
    }
