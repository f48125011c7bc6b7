"""A synthetic flight log with what real UWB + IMU logs have (``swarm synth-log``, the replay tests and
the bench).

A quadrotor stands on a surveyed pad for ``static_s``, takes off and flies a Lissajous figure in a room of
anchors, with a coordinated attitude (its thrust axis along the acceleration minus gravity, the heading
turning slowly). From that trajectory, sampled exactly at each sensor's (jittered) time:

* a 6-axis IMU at ``imu_rate_hz``: rate and specific force in the body frame, with constant biases plus a
  random walk, white noise, and a dropout (a gap with no sample);
* two-way ranges at ``range_rate_hz`` in all, to one anchor after another (Loco Positioning TWR), each with
  a per-anchor bias drawn in ``range_bias_m`` that steps once airborne and then drifts (random walk), white
  noise, lost exchanges, and one NLOS anchor whose ranges, once airborne, are long by an exponential excess
  most of the time;
* with ``vision_rate_hz > 0``, a downward camera that sees the floor markers (a 3 x 3 grid, the pad at its
  centre) inside its field of view: each marker's position in the camera frame with the noise a PnP of a
  ``marker_size_m`` marker gives for ``pixel_sigma`` (lateral ``z s_px / f``, depth ``z^2 s_px / (f w)``),
  written with its sigma, and now and then a misdetection off by ``outlier_m``;
* the truth at 100 Hz, and a ``log.toml`` with the noise densities and the pad's position (the
  calibration segment), as a user would write it.

Everything is drawn from ``numpy.random.default_rng(seed)``: the same seed gives the same files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarm.core import rotations as rot
from swarm.logs import phenomena as ph

GRAVITY = np.array([0.0, 0.0, -9.81])


@dataclass(frozen=True)
class SyntheticSpec:
    """What the synthetic log contains (defaults: a Crazyflie-like flight in an 8-anchor room)."""

    duration_s: float = 60.0
    static_s: float = 5.0
    takeoff_s: float = 3.0
    imu_rate_hz: float = 1000.0
    imu_jitter_s: float = 5e-5
    imu_gap_at_s: float = 30.0
    imu_gap_s: float = 0.05
    accel_noise: float = 0.02  # [m/s^2/sqrt(Hz)]
    gyro_noise: float = 0.002  # [rad/s/sqrt(Hz)]
    accel_bias_m_s2: float = 0.1  # |b_a| per axis, drawn in [-x, x]
    gyro_bias_rad_s: float = 0.005
    accel_bias_rw: float = 5e-4
    gyro_bias_rw: float = 5e-6
    range_rate_hz: float = 80.0
    range_jitter_s: float = 0.002
    range_sigma_m: float = 0.05
    range_bias_m: tuple[float, float] = (0.2, 0.5)
    range_bias_step_m: float = 0.0  # once airborne, each bias steps by U(-x, x) (a model the filter lacks)
    range_bias_rw: float = 0.003  # [m/sqrt(s)]
    range_loss: float = 0.05
    nlos_anchor: int = 3
    nlos_probability: float = 0.6  # of each of its ranges while airborne
    nlos_excess_m: float = 1.0  # mean of the exponential excess
    pad_m: tuple[float, float, float] = (0.0, 0.0, 0.05)
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.03)
    yaw0_deg: float = 30.0
    vision_rate_hz: float = 0.0  # 0: no camera, no vision.csv
    vision_sigma_columns: bool = True  # False: no sigma columns (log.toml's vision.sigma_m, as a live feed)
    camera_position_m: tuple[float, float, float] = (0.0, 0.0, -0.02)
    fov_half_deg: float = 40.0
    vision_max_range_m: float = 4.0
    focal_px: float = 400.0
    pixel_sigma: float = 1.0
    marker_size_m: float = 0.15
    outlier_probability: float = 0.01
    outlier_m: float = 0.5
    nlos_episode: tuple[int, float, float, float] | None = None
    """``(anchor, t_start_s, duration_s, excess_m)``: one deterministic NLOS episode, every range of that
    anchor in ``[t_start_s, t_start_s + duration_s)`` long by ``excess_m`` (None: none)."""
    blackout: tuple[float, float] | None = None
    """``(t_start_s, duration_s)``: no range at all in that window (no rows; None: none)."""
    height_rate_hz: float = 0.0
    """A downward range finder's rate (``height.csv``; 0: none)."""
    height_sigma_m: float = 0.005
    height_max_range_m: float = 4.0
    height_min_cos_tilt: float = 0.866
    """No return when tilted more than this (cos 30 deg)."""
    height_ground_z_m: float = 0.0
    """The floor's height in nav: the pad's IMU stands ``pad_m[2]`` above it."""
    baro_rate_hz: float = 0.0
    """A barometer's rate (``baro.csv``; 0: none)."""
    baro_sigma_m: float = 0.2
    baro_offset_m: float = 92.5
    """The altitude of the nav origin the barometer reads (any constant) [m]."""
    baro_drift_m_rts: float = 0.01
    """The barometer's slow drift, a random walk [m/sqrt(s)] (weather, temperature)."""
    tdoa: str = ""
    """``"tdoa2"`` or ``"tdoa3"``: a passive tag on the Loco Positioning TDoA radio writes ``tdoa.csv``
    (:mod:`swarm.logs.synth_tdoa`) and ``uwb.csv`` has no rows; empty: two-way ranging."""
    tdoa_nlos_anchor: int | None = None
    """With TDoA: this anchor's packets in flight are long (``nlos_probability``, ``nlos_excess_m``), so
    are all its pairs (None: none)."""
    tdoa_sigma_m: float | None = None
    """With TDoA: the white noise of one difference [m] (None: sqrt(2) times the ranges' white sigma)."""


ANCHORS = np.array(
    [
        [-4.0, -3.0, 0.2],
        [4.0, -3.0, 0.2],
        [4.0, 3.0, 0.2],
        [-4.0, 3.0, 0.2],
        [-4.0, -3.0, 2.8],
        [4.0, -3.0, 2.8],
        [4.0, 3.0, 2.8],
        [-4.0, 3.0, 2.8],
    ]
)
"""Eight anchors in the corners of an 8 x 6 x 3 m room, nav frame (z up)."""

R_BODY_CAM = np.diag([1.0, -1.0, -1.0])
"""Camera to body of the downward camera: optical axis (camera +z) along body -z, image x along body x."""


def markers(spec: SyntheticSpec) -> np.ndarray:
    """Nine floor markers, nav [m]: a 3 x 3 grid of 2.5 x 1.8 m, the pad's marker at its centre."""
    g = np.array([[x, y, 0.0] for y in (-1.8, 0.0, 1.8) for x in (-2.5, 0.0, 2.5)])
    g[4] = spec.pad_m
    return g


def _blend(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """0 before t0, 1 after t1, a quintic smoothstep between (C2: continuous acceleration)."""
    s = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
    return s**3 * (10.0 - 15.0 * s + 6.0 * s * s)


def _position(spec: SyntheticSpec, t: np.ndarray) -> np.ndarray:
    pad = np.array(spec.pad_m)
    t0, t1 = spec.static_s, spec.static_s + spec.takeoff_s
    lift = _blend(t, t0, t1)
    fly = _blend(t, t1, t1 + 2.0)
    tau = np.maximum(t - t1, 0.0)
    figure = np.stack([2.5 * np.sin(0.25 * tau), 1.8 * np.sin(0.5 * tau), 0.4 * np.sin(0.15 * tau)], axis=-1)
    up = np.array([0.0, 0.0, 1.5])
    return pad + lift[:, None] * up + fly[:, None] * figure


def _derivatives(spec: SyntheticSpec, t: np.ndarray, h: float = 1e-3):
    """Position, velocity and acceleration by central differences of the smooth trajectory (error ~h^2)."""
    p = _position(spec, t)
    v = (_position(spec, t + h) - _position(spec, t - h)) / (2 * h)
    a = (_position(spec, t + h) - 2 * p + _position(spec, t - h)) / (h * h)
    return p, v, a


def _attitude(spec: SyntheticSpec, t: np.ndarray) -> np.ndarray:
    """q_nav_body: body z along (a - g) (a quadrotor's thrust), heading ``yaw0 + 0.4 sin(0.1 t)`` airborne."""
    _, _, a = _derivatives(spec, t)
    z = a - GRAVITY
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    airborne = _blend(t, spec.static_s, spec.static_s + spec.takeoff_s)
    yaw = np.radians(spec.yaw0_deg) + 0.4 * np.sin(0.1 * t) * airborne
    xc = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=-1)
    y = np.cross(z, xc)
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, z)
    R = np.stack([x, y, z], axis=-1)  # columns: body axes in nav
    return rot.matrix_to_quat(R)


def _rates(spec: SyntheticSpec, t: np.ndarray, h: float = 1e-4) -> np.ndarray:
    """Body angular rate from the attitude: ``2 vec(q^-1 (x) dq/dt)`` by central differences."""
    qm, qp = _attitude(spec, t - h), _attitude(spec, t + h)
    dq = rot.quat_mul(rot.quat_conj(qm), qp)
    dq *= np.sign(dq[:, 3:4])
    return rot.quat_log(dq) / (2 * h)


def truth_at(spec: SyntheticSpec, t: np.ndarray):
    """True position, velocity, attitude, body rate and specific force (body) at times ``t``."""
    p, v, a = _derivatives(spec, t)
    q = _attitude(spec, t)
    w = _rates(spec, t)
    f = rot.quat_rotate(rot.quat_conj(q), a - GRAVITY)
    return p, v, q, w, f


def _write(path: Path, header: str, rows: np.ndarray, fmt) -> None:
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt=fmt)


def make_log(directory, seed: int = 0, spec: SyntheticSpec | None = None, profile=None) -> dict:
    """Write a synthetic log into ``directory`` (created); returns the true biases and the NLOS anchor.

    ``profile`` (a :class:`swarm.sensors.profile.SensorProfile`, None: the model above, sample for sample
    as before profiles existed) replaces the range error model and the IMU's noise by the profile's
    (:mod:`swarm.logs.phenomena`): per-anchor offsets ``offset_m`` spread by ``offset_spread_m``, a step
    ``takeoff_step_m`` (spread ``takeoff_step_spread_m``) from the take-off on (``t >= static_s``, the
    rotors spin up and the vehicle leaves the pad), white noise ``ground_sigma_m`` before and ``sigma_m``
    after, a Gauss-Markov multipath error, NLOS episodes and isolated outliers in flight, the IMU's white
    noise densities and its vibration in flight. The scene stays the spec's: the trajectory, the range
    rate, losses and jitter, the slow walk of the airborne biases, the one NLOS anchor. The main stream's
    draws are the same with or without a profile, so a profile changes only what it models."""
    spec = spec or SyntheticSpec()
    rng = np.random.default_rng(seed)
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    T = spec.duration_s
    imu_p = profile.imu if profile is not None else None
    accel_noise = spec.accel_noise if imu_p is None else imu_p.accel_noise_m_s2_rthz
    gyro_noise = spec.gyro_noise if imu_p is None else imu_p.gyro_noise_rad_s_rthz

    # IMU: jittered sample times, a gap, biases with a random walk
    n = int(T * spec.imu_rate_hz)
    dt = 1.0 / spec.imu_rate_hz
    t_imu = np.arange(n) * dt + rng.uniform(-spec.imu_jitter_s, spec.imu_jitter_s, n)
    t_imu[0] = 0.0
    keep = ~((t_imu >= spec.imu_gap_at_s) & (t_imu < spec.imu_gap_at_s + spec.imu_gap_s))
    t_imu = t_imu[keep]
    _, _, _, w, f = truth_at(spec, t_imu)
    ba0 = rng.uniform(-spec.accel_bias_m_s2, spec.accel_bias_m_s2, 3)
    bg0 = rng.uniform(-spec.gyro_bias_rad_s, spec.gyro_bias_rad_s, 3)
    steps = np.diff(t_imu, prepend=0.0)[:, None]
    ba = ba0 + np.cumsum(rng.normal(size=(len(t_imu), 3)) * spec.accel_bias_rw * np.sqrt(steps), axis=0)
    bg = bg0 + np.cumsum(rng.normal(size=(len(t_imu), 3)) * spec.gyro_bias_rw * np.sqrt(steps), axis=0)
    gyro = w + bg + rng.normal(size=w.shape) * gyro_noise * math.sqrt(spec.imu_rate_hz)
    acc = f + ba + rng.normal(size=f.shape) * accel_noise * math.sqrt(spec.imu_rate_hz)
    if imu_p is not None:
        vib_g, vib_a = ph.vibration(seed, imu_p, t_imu >= spec.static_s)
        gyro, acc = gyro + vib_g, acc + vib_a
    _write(
        d / "imu.csv",
        "t_s,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,acc_x_m_s2,acc_y_m_s2,acc_z_m_s2",
        np.column_stack([t_imu, gyro, acc]),
        "%.6f",
    )

    # UWB: round robin over the anchors, biases that step once airborne and drift, losses, one NLOS anchor
    m = len(ANCHORS)
    k = np.arange(int(T * spec.range_rate_hz))
    t_rng = np.sort(k / spec.range_rate_hz + rng.uniform(0.0, spec.range_jitter_s, len(k)))
    anchor = k % m
    p, _, q, _, _ = truth_at(spec, t_rng)
    tag = p + rot.quat_rotate(q, np.broadcast_to(np.array(spec.lever_arm_m), p.shape))
    true_range = np.linalg.norm(tag - ANCHORS[anchor], axis=1)
    uwb_p = profile.uwb if profile is not None else None
    if uwb_p is None:
        b0 = rng.uniform(*spec.range_bias_m, m)
        step = rng.uniform(-spec.range_bias_step_m, spec.range_bias_step_m, m)
    else:  # the same draws (uniform(a, b, m) is a + (b - a) times m doubles), spread as the profile says
        b0 = ph.spread_draw(uwb_p.offset_m, uwb_p.offset_spread_m, rng.uniform(0.0, 1.0, m))
        step = ph.spread_draw(uwb_p.takeoff_step_m, uwb_p.takeoff_step_spread_m, rng.uniform(0.0, 1.0, m))
    airborne = t_rng >= spec.static_s + spec.takeoff_s
    walk = np.zeros((len(t_rng), m))
    walk[1:] = np.cumsum(
        rng.normal(size=(len(t_rng) - 1, m)) * spec.range_bias_rw * np.sqrt(np.diff(t_rng))[:, None], axis=0
    )
    walk -= walk[np.searchsorted(t_rng, spec.static_s + spec.takeoff_s).clip(0, len(t_rng) - 1)]
    walk[~airborne] = 0.0
    white = rng.normal(size=len(t_rng))
    episodes: list[ph.Episode] = []
    range_outliers = np.zeros(len(t_rng), dtype=bool)
    if uwb_p is None:
        bias = b0[anchor] + airborne * (step[anchor] + walk[np.arange(len(t_rng)), anchor])
        z = true_range + bias + white * spec.range_sigma_m
    else:
        lifted = t_rng >= spec.static_s
        bias = b0[anchor] + lifted * step[anchor] + airborne * walk[np.arange(len(t_rng)), anchor]
        sigma = np.where(lifted, uwb_p.sigma_m, uwb_p.ground_sigma_m)
        extra, episodes, range_outliers = ph.range_errors(seed, uwb_p, t_rng, anchor, lifted, m, T)
        z = true_range + bias + white * sigma + extra
    nlos = (anchor == spec.nlos_anchor) & airborne & (rng.random(len(t_rng)) < spec.nlos_probability)
    z[nlos] += rng.exponential(spec.nlos_excess_m, nlos.sum())
    lost = rng.random(len(t_rng)) < spec.range_loss
    if spec.nlos_episode is not None:
        a_ep, t0_ep, dur_ep, excess_ep = spec.nlos_episode
        forced = ph.Episode(int(a_ep), float(t0_ep), float(t0_ep + dur_ep), float(excess_ep))
        z += ph.episode_excess(t_rng, anchor, [forced])
        episodes = [*episodes, forced]
    z[lost] = np.nan  # a lost reply: the logger writes nan, the reader skips and counts the row
    rows = np.column_stack([t_rng, anchor, z])
    if spec.blackout is not None:
        b_from, b_for = spec.blackout
        rows = rows[~((t_rng >= b_from) & (t_rng < b_from + b_for))]
    if (
        spec.tdoa
    ):  # a passive tag: no two-way ranges (the draws above are kept: the rest of the log is the same)
        rows = rows[:0]
    _write(d / "uwb.csv", "t_s,anchor_id,range_m", rows, ["%.6f", "%d", "%.6f"])
    _write(
        d / "anchors.csv",
        "anchor_id,x_m,y_m,z_m",
        np.column_stack([np.arange(m), ANCHORS]),
        ["%d"] + ["%.4f"] * 3,
    )

    t_truth = np.arange(0.0, T, 0.01)
    pt, _, qt, _, _ = truth_at(spec, t_truth)
    _write(d / "truth.csv", "t_s,x_m,y_m,z_m,qx,qy,qz,qw", np.column_stack([t_truth, pt, qt]), "%.7f")

    extra_toml, baro_drift = _write_height_baro(d, seed, spec)
    tdoa = None
    if spec.tdoa:
        from swarm.logs.reader import LogConfig
        from swarm.logs.synth_tdoa import write_tdoa

        tdoa = write_tdoa(d, seed, spec, profile, ANCHORS, b0, step, truth_at)
        if "tdoa" in LogConfig.__dataclass_fields__:
            # its anchors carry constant offsets of 0.2-0.5 m (range_bias_m): the filter's offset states
            # (off by default in a TDoA log, [tdoa] offsets)
            extra_toml += f"\n[tdoa]\nsigma_m = {tdoa['sigma_m']:g}\noffsets = true\n"
    vision_toml = ""
    outliers = np.zeros(0, dtype=np.int64)
    if spec.vision_rate_hz > 0:
        outliers = _write_vision(d, spec, rng)
        cam = ", ".join(f"{v:g}" for v in spec.camera_position_m)
        vision_toml = f"""
[vision]
camera_position_m = [{cam}]
camera_quaternion = [1.0, 0.0, 0.0, 0.0]   # camera +z along body -z: looking down
"""
    pad = ", ".join(f"{v:g}" for v in spec.pad_m)
    lever = ", ".join(f"{v:g}" for v in spec.lever_arm_m)
    (
        d / "log.toml"
    ).write_text(f"""# Synthetic flight (swarm synth-log --seed {seed}): {T:g} s, {m} anchors, anchor {spec.nlos_anchor} NLOS.
name = "synthetic flight, seed {seed}"{"" if profile is None else f"  # sensor profile {profile.name!r}"}

[estimator]
accel_noise = {_flight_density(accel_noise, imu_p and imu_p.accel_vibration_m_s2, spec):g}
gyro_noise = {_flight_density(gyro_noise, imu_p and imu_p.gyro_vibration_rad_s, spec):g}
accel_bias_rw = {max(spec.accel_bias_rw, 1e-4):g}
gyro_bias_rw = {max(spec.gyro_bias_rw, 1e-6):g}
range_bias = true
range_bias_rw = {max(spec.range_bias_rw, 1e-3):g}
gravity_nav = [0.0, 0.0, -9.81]
lever_arm_m = [{lever}]

[calibration]
until_s = {spec.static_s:g}
position_m = [{pad}]

[initial]
# the pad is surveyed: the first position is known to ~2 cm
sigma_position_m = 0.02
yaw_deg = {spec.yaw0_deg:g}
sigma_range_bias_m = {max(spec.range_bias_step_m, 0.03) if uwb_p is None else max(abs(uwb_p.takeoff_step_m) + uwb_p.takeoff_step_spread_m, 0.03):g}
{vision_toml}{extra_toml}""")  # noqa: E501
    return {
        "accel_bias": ba0,
        "gyro_bias": bg0,
        "range_bias_static": b0,
        "range_bias_step": step,
        "nlos_anchor": spec.nlos_anchor,
        "range_bias_final": b0 + step + walk[-1],
        "nlos_t": t_rng[nlos & ~lost],
        "vision_outliers": outliers,
        "profile": None if profile is None else profile.name,
        "takeoff_s": spec.static_s,
        "nlos_episodes": episodes,
        "range_outliers_t": t_rng[range_outliers & ~lost],
        "baro_drift_final_m": baro_drift,
        "tdoa": tdoa,
    }


def _flight_density(density: float, vibration: float | None, spec: SyntheticSpec) -> float:
    """The white noise density a filter should assume in flight: the sensor's own and the vibration's
    spread ``v`` per sample at the IMU rate ``r`` as a density ``v / sqrt(r)``, added in power."""
    return math.hypot(density, (vibration or 0.0) / math.sqrt(spec.imu_rate_hz))


def _write_height_baro(d: Path, seed: int, spec: SyntheticSpec) -> tuple[str, float | None]:
    """``height.csv`` and ``baro.csv`` when the spec asks for them (:mod:`swarm.logs.phenomena`), and their
    log.toml tables (written only once log.toml knows them: the reader refuses an unknown table). Returns
    the tables' text and the barometer's final drift (None without a barometer)."""
    from swarm.logs.reader import LogConfig

    known = LogConfig.__dataclass_fields__
    toml, drift = "", None
    if spec.height_rate_hz > 0:
        t = np.arange(0.0, spec.duration_s, 1.0 / spec.height_rate_hz)
        p, _, q, _, _ = truth_at(spec, t)
        cos_tilt = 1.0 - 2.0 * (q[:, 0] ** 2 + q[:, 1] ** 2)  # R_22 of body -> nav
        _write(d / "height.csv", "t_s,range_m", ph.height_rows(seed, t, p[:, 2], cos_tilt, spec), "%.6f")
        if "height" in known:
            toml += (
                f"\n[height]\nsigma_m = {spec.height_sigma_m:g}\nmax_range_m = {spec.height_max_range_m:g}\n"
                f"min_cos_tilt = {spec.height_min_cos_tilt:g}\nground_z_m = {spec.height_ground_z_m:g}\n"
            )
    if spec.baro_rate_hz > 0:
        t = np.arange(0.0, spec.duration_s, 1.0 / spec.baro_rate_hz)
        p, _, _, _, _ = truth_at(spec, t)
        rows, walk = ph.baro_rows(seed, t, p[:, 2], spec)
        _write(d / "baro.csv", "t_s,height_m", rows, "%.6f")
        drift = float(walk[-1])
        if "baro" in known:
            toml += f"\n[baro]\nsigma_m = {spec.baro_sigma_m:g}\n"
    return toml, drift


def _write_vision(d: Path, spec: SyntheticSpec, rng: np.random.Generator) -> np.ndarray:
    """``markers.csv`` and ``vision.csv``: every marker in the camera's field of view at each frame. Returns
    the rows (from 0, after the header) that are misdetections."""
    mk = markers(spec)
    t = np.arange(0.0, spec.duration_s, 1.0 / spec.vision_rate_hz)
    p, _, q, _, _ = truth_at(spec, t)
    R = rot.quat_to_matrix(q)  # (n, 3, 3) body to nav
    cam = np.asarray(spec.camera_position_m)
    # t_c = R_bc^T (R^T (m - p) - c) for every frame and marker
    rel = mk[None, :, :] - p[:, None, :]
    body = np.einsum("nji,nmj->nmi", R, rel) - cam
    tc = body @ R_BODY_CAM  # row-vector form of R_bc^T b
    z = tc[..., 2]
    off_axis = np.degrees(np.arctan2(np.linalg.norm(tc[..., :2], axis=-1), z))
    seen = (z > 0.3) & (z < spec.vision_max_range_m) & (off_axis < spec.fov_half_deg)
    frame, marker = np.nonzero(seen)
    zc = z[frame, marker]
    lateral = zc * spec.pixel_sigma / spec.focal_px
    depth = zc * zc * spec.pixel_sigma / (spec.focal_px * spec.marker_size_m)
    sig = np.column_stack([lateral, lateral, depth])
    meas = tc[frame, marker] + rng.normal(size=sig.shape) * sig
    wrong = rng.random(len(frame)) < spec.outlier_probability
    direction = rng.normal(size=(int(wrong.sum()), 3))
    meas[wrong] += spec.outlier_m * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    _write(
        d / "markers.csv",
        "marker_id,x_m,y_m,z_m",
        np.column_stack([np.arange(len(mk)), mk]),
        ["%d"] + ["%.4f"] * 3,
    )
    header, cols = "t_s,marker_id,x_m,y_m,z_m", [t[frame], marker, meas]
    if spec.vision_sigma_columns:
        header, cols = header + ",sigma_x_m,sigma_y_m,sigma_z_m", [*cols, sig]
    rows = np.column_stack(cols)
    _write(d / "vision.csv", header, rows, ["%.6f", "%d"] + ["%.6f"] * (rows.shape[1] - 2))
    return np.flatnonzero(wrong)
