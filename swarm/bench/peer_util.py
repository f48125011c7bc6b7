"""The UTIL dataset authors' error-state filter on one of our log folders: ``swarm bench peer``.

Their filter (``scripts/estimation/eskf_class.py`` of utiasDSL/util-uwb-dataset; Zhao, Goudar, Qiao &
Schoellig, "UTIL: An ultra-wideband time-difference-of-arrival indoor localization dataset", IJRR 2024) is
imported from the user's own checkout (``--util-eskf DIR``) and run as it is: nothing of it is copied here.
This module converts one log folder (``docs/logs.md``) into the inputs their ``main.py`` gives it, drives it
step by step as that script does, and scores its estimate with the metrics of ``swarm replay``
(:mod:`swarm.logs.replay`): 3-D and per-axis RMSE against ``truth.csv`` interpolated at each estimate, the
position NEES against its 95 % chi-square(3) band, and the filter's wall time.

What their code takes (``main.py`` and ``eskf_class.py``, commit fef243a):

* ``ESKF(X0, q0, P0, K)``: ``X0`` (6, 1) position [m] and velocity [m/s] in the anchors' frame (z up,
  gravity ``-9.81 e3``); ``q0`` a ``pyquaternion.Quaternion`` body -> nav (scalar first); ``P0`` (9, 9) over
  ``(dp, dv, dtheta)``; ``K`` the number of time steps (its arrays ``Xpo``, ``Ppo``, ``q_list`` are
  preallocated, one row per step).
* ``predict(imu, dt, imu_check, k)``: ``imu`` (6,) = specific force [g] then angular rate [deg/s], body
  frame (the Crazyflie's: x forward, z up, which is ours); with ``imu_check`` false the last sample is held.
* ``UWB_correct(uwb, anchor_position, k)``: ``uwb`` (3,) = ``(idA, idB, |p - a_B| - |p - a_A|)`` [m] (the
  firmware's ``distanceDiff``, our ``tdoa.csv`` ``ddist_m``); ``anchor_position`` (n, 3) rows indexed by
  anchor id. TDoA only: there is no two-way-range update.
* ``main.py``'s driver: the IMU and each TDoA stream downsampled by 8 (``downsamp``: three halvings); in
  TDoA2 only the 8 consecutive pairs ``(7,0), (0,1) .. (6,7)`` (``extract_tdoa_meas``), in TDoA3 every row;
  one time base, the sorted union of the two; at step ``k`` predict with the IMU sample of ``t[k-1]`` over
  ``t[k] - t[k-1]`` and correct with the TDoA row of ``t[k-1]``. ``X0 = (1.25, 0, 0.07, 0, 0, 0)``, ``q0``
  identity, every initial sigma 0.1.
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from types import ModuleType

import numpy as np
from scipy.stats import chi2

from swarm.core import rotations as rot
from swarm.errors import ConfigError, LogError
from swarm.logs.reader import Log, read_log

ESKF_FILE = "eskf_class.py"
"""Their filter's module; ``--util-eskf`` names its folder or the repository's root."""
ESKF_SUBDIR = ("scripts", "estimation")

DOWNSAMPLE = 8
"""``main.py``'s ``downsamp``: ``data[0::2]`` three times, i.e. every 8th sample of each stream."""
RING = 8
"""TDoA2 anchors in their TDMA ring: ``extract_tdoa_meas`` keeps the pairs ``(i, (i + 1) mod 8)``."""
TDOA2_RING_SHARE = 0.9
"""``mode = auto``: a log is TDoA2 when at least this share of its rows are ring pairs (measured on the
UTIL flights: 0.96-0.99 in TDoA2, 0.16-0.18 in TDoA3, whose anchors pair with any other)."""
AUTHORS_X0_M = (1.25, 0.0, 0.07)
"""``main.py``'s initial position [m] (its ``X0``)."""
AUTHORS_SIGMA0 = 0.1
"""``main.py``'s initial standard deviation of every error state (m, m/s, rad)."""
BAND = 0.95
"""Two-sided probability of the NEES band (as :data:`swarm.logs.replay.BAND`)."""
DIVERGED_M = 1.0
"""An estimate whose error exceeds this [m] for :data:`DIVERGED_S` in all is called diverged (the UTIL
flights stay within ~3 x 3 x 2 m: an error of 1 m held for seconds is a lost estimate, not a noisy one)."""
DIVERGED_S = 2.0
"""Total time [s] above :data:`DIVERGED_M` that makes a run diverged."""
AIRBORNE_M = 0.2
"""``span = airborne``: the log is cut to where the truth is this far above its first height [m]. On the
UTIL flights the TDoA rows of a vehicle standing on the floor are off by ~3 m (median absolute residual
against the truth below 0.1 m of height; 0.4-0.6 m at 0.1-0.2 m; 0.1-0.3 m above): this span shows the
filter without them."""
VELOCITY_DT_S = 0.05
"""Half-width of the truth's central difference for the initial velocity of an airborne span [s]."""


@dataclass(frozen=True)
class PeerConfig:
    """How ``swarm bench peer`` feeds their filter."""

    mode: str = "auto"
    """``tdoa2``, ``tdoa3`` or ``auto`` (:data:`TDOA2_RING_SHARE`)."""
    downsample: int = DOWNSAMPLE
    """Keep every n-th IMU sample and every n-th row of each TDoA stream (``main.py``: 8)."""
    initial: str = "truth"
    """``truth``: ``X0`` at the truth's first position (the pad's position, which our replay is given too);
    ``authors``: ``main.py``'s :data:`AUTHORS_X0_M`. Velocity zero, attitude identity, sigmas 0.1 both
    ways."""
    span: str = "full"
    """``full``: the whole log, as their ``main.py`` runs a flight; ``airborne``: from the first to the last
    truth sample :data:`AIRBORNE_M` above the first one, ``X0`` the truth's position and velocity there
    (attitude identity and sigmas 0.1 as ``main.py``; needs ``initial = truth``)."""

    def __post_init__(self) -> None:
        if self.mode not in ("auto", "tdoa2", "tdoa3"):
            raise ConfigError(f"--mode must be auto, tdoa2 or tdoa3, got {self.mode!r}")
        if not (isinstance(self.downsample, int) and self.downsample >= 1):
            raise ConfigError(f"--downsample must be an integer >= 1, got {self.downsample!r}")
        if self.initial not in ("truth", "authors"):
            raise ConfigError(f"--initial must be truth or authors, got {self.initial!r}")
        if self.span not in ("full", "airborne"):
            raise ConfigError(f"--span must be full or airborne, got {self.span!r}")
        if self.span == "airborne" and self.initial != "truth":
            raise ConfigError("--span airborne starts from the truth: it needs --initial truth")


@dataclass(frozen=True)
class PeerInputs:
    """A log converted to what their ``main.py`` hands the filter (module docstring)."""

    mode: str
    """``tdoa2`` or ``tdoa3``."""
    t0_s: float
    """The log time of ``t == 0`` (``main.py`` resets the time base to the first sample) [s]."""
    t_s: np.ndarray
    """(K,) the filter's time steps: the sorted union of ``imu_t_s`` and ``uwb_t_s`` [s from t0]."""
    imu_t_s: np.ndarray
    """(N,) IMU sample times [s from t0]."""
    imu: np.ndarray
    """(N, 6) specific force [g] then angular rate [deg/s], body frame (x forward, z up)."""
    uwb_t_s: np.ndarray
    """(M,) TDoA times [s from t0], sorted."""
    uwb: np.ndarray
    """(M, 3) anchor id A, anchor id B, ``|p - a_B| - |p - a_A|`` [m]."""
    anchor_position: np.ndarray
    """(max id + 1, 3) anchor antenna positions [m], row = anchor id (NaN for an id the log lacks)."""
    tdoa_rows: int
    """TDoA rows in the log, before the pair selection and the downsampling."""


# --------------------------------------------------------------------------------------- their module


def find_eskf(directory: str | Path) -> Path:
    """Their ``eskf_class.py`` in ``directory`` or in its ``scripts/estimation``."""
    d = Path(directory)
    for candidate in (d / ESKF_FILE, d.joinpath(*ESKF_SUBDIR, ESKF_FILE)):
        if candidate.is_file():
            return candidate
    raise ConfigError(
        f"--util-eskf {str(d)!r}: no {ESKF_FILE} in it or in {'/'.join(ESKF_SUBDIR)} (give a checkout of "
        "utiasDSL/util-uwb-dataset or its scripts/estimation folder)"
    )


def load_eskf(directory: str | Path) -> ModuleType:
    """Their ``eskf_class`` module, imported from its file (under a private name, so that no other
    ``eskf_class`` on ``sys.path`` is taken). It imports ``pyquaternion`` (the ``bench`` extra)."""
    path = find_eskf(directory)
    spec = importlib.util.spec_from_file_location("util_eskf_peer", path)
    if spec is None or spec.loader is None:
        raise ConfigError(f"--util-eskf: cannot import {path}")
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except ImportError as exc:
        raise ConfigError(
            f"--util-eskf: {path} needs {exc.name!r}, not installed (pip install '.[bench]')"
        ) from exc
    for name in ("ESKF", "Quaternion"):
        if not hasattr(module, name):
            raise ConfigError(f"--util-eskf: {path} defines no {name} (not the UTIL authors' ESKF?)")
    return module


def _units(module: ModuleType) -> tuple[float, float]:
    """Their ``GRAVITY_MAGNITUDE`` [m/s^2 per g] and ``DEG_TO_RAD``: dividing by them gives their filter,
    once it multiplies back, exactly the SI values of our ``imu.csv``."""
    return float(getattr(module, "GRAVITY_MAGNITUDE", 9.81)), float(
        getattr(module, "DEG_TO_RAD", math.pi / 180)
    )


# ------------------------------------------------------------------------------------------- inputs


def anchor_table(ids: np.ndarray, anchors_nav: np.ndarray) -> np.ndarray:
    """Anchor positions (max id + 1, 3) with row ``i`` = anchor id ``i`` (their ``an_pos`` is indexed by
    id: ``anchor_position[int(uwb[0])]``); NaN rows for ids the log lacks."""
    ids = np.asarray(ids, dtype=int)
    table = np.full((int(ids.max()) + 1, 3), np.nan)
    table[ids] = anchors_nav
    return table


def detect_mode(a_ids: np.ndarray, b_ids: np.ndarray) -> str:
    """``tdoa2`` if at least :data:`TDOA2_RING_SHARE` of the pairs are ring pairs, else ``tdoa3``."""
    ring = np.mean((np.asarray(a_ids) + 1) % RING == np.asarray(b_ids)) if len(a_ids) else 0.0
    return "tdoa2" if ring >= TDOA2_RING_SHARE else "tdoa3"


def airborne_window(lg: Log) -> tuple[float, float]:
    """The first and last truth times :data:`AIRBORNE_M` above the truth's first height [s]."""
    if lg.truth_t is None:
        raise LogError(f"{lg.path}: --span airborne needs a truth.csv")
    up = np.flatnonzero(lg.truth_p[:, 2] > lg.truth_p[0, 2] + AIRBORNE_M)
    if len(up) < 2:
        raise LogError(f"{lg.path}: the truth never rises {AIRBORNE_M} m above its start: no airborne span")
    return float(lg.truth_t[up[0]]), float(lg.truth_t[up[-1]])


def window(lg: Log, cfg: PeerConfig) -> tuple[float, float]:
    """The span of log time the filter runs on [s] (:attr:`PeerConfig.span`)."""
    return airborne_window(lg) if cfg.span == "airborne" else (-math.inf, math.inf)


def peer_inputs(lg: Log, module: ModuleType, cfg: PeerConfig = PeerConfig()) -> PeerInputs:
    """``lg`` as their ``main.py`` feeds the filter (module docstring). Raises ConfigError for a log
    without TDoA (their filter has no two-way-range update)."""
    n_td = 0 if lg.tdoa_t is None else len(lg.tdoa_t)
    if n_td == 0:
        raise ConfigError(
            f"{lg.path}: no tdoa.csv rows ({len(lg.uwb_t)} two-way ranges in uwb.csv): the UTIL authors' "
            "ESKF fuses TDoA only (UWB_correct models d_B - d_A), so it cannot run on this log"
        )
    g, deg = _units(module)
    n = cfg.downsample
    ids = lg.anchor_ids.astype(int)
    a_id, b_id = ids[lg.tdoa_a], ids[lg.tdoa_b]
    mode = detect_mode(a_id, b_id) if cfg.mode == "auto" else cfg.mode
    t_a, t_b = window(lg, cfg)
    keep = (lg.tdoa_t >= t_a) & (lg.tdoa_t <= t_b)
    rows = np.column_stack([lg.tdoa_t, a_id, b_id, lg.tdoa_ddist])[keep]
    a_id, b_id = a_id[keep], b_id[keep]
    if mode == "tdoa2":  # extract_tdoa_meas: one stream per ring pair, each downsampled
        parts = [rows[(a_id == i) & (b_id == (i + 1) % RING)][::n] for i in (RING - 1, *range(RING - 1))]
        rows = np.concatenate(parts, axis=0)
        rows = rows[np.argsort(rows[:, 0], kind="stable")]
    else:
        rows = rows[::n]
    i_keep = (lg.imu_t >= t_a) & (lg.imu_t <= t_b)
    if len(rows) == 0 or not i_keep.any():
        raise LogError(f"{lg.path}: no TDoA or no IMU sample in the span {t_a:g}..{t_b:g} s")
    t_truth = lg.truth_t[0] if lg.truth_t is not None and cfg.span == "full" else math.inf
    t0 = float(min(rows[0, 0], lg.imu_t[i_keep][0], t_truth))
    imu = np.column_stack([lg.acc / g, lg.gyro / deg])[i_keep][::n]
    imu_t = lg.imu_t[i_keep][::n] - t0
    uwb_t = rows[:, 0] - t0
    return PeerInputs(
        mode=mode,
        t0_s=t0,
        t_s=np.unique(np.concatenate([imu_t, uwb_t])),
        imu_t_s=imu_t,
        imu=imu,
        uwb_t_s=uwb_t,
        uwb=rows[:, 1:4].copy(),
        anchor_position=anchor_table(ids, lg.anchors_nav),
        tdoa_rows=n_td,
    )


def initial_state(lg: Log, cfg: PeerConfig, t0_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``X0`` (6, 1) and ``P0`` (9, 9) at log time ``t0_s`` (:attr:`PeerConfig.initial`,
    :attr:`PeerConfig.span`; ``main.py``'s zero velocity and sigmas for a whole log)."""
    X0 = np.zeros((6, 1))
    if cfg.initial == "authors":
        X0[0:3, 0] = AUTHORS_X0_M
    elif lg.truth_p is None:
        raise LogError(f"{lg.path}: --initial truth needs a truth.csv")
    else:
        tt, pp = lg.truth_t, lg.truth_p
        X0[0:3, 0] = [np.interp(t0_s, tt, pp[:, k]) for k in range(3)]
        if cfg.span == "airborne":  # central difference of the truth
            lo, hi = t0_s - VELOCITY_DT_S, t0_s + VELOCITY_DT_S
            X0[3:6, 0] = [
                (np.interp(hi, tt, pp[:, k]) - np.interp(lo, tt, pp[:, k])) / (hi - lo) for k in range(3)
            ]
    return X0, np.eye(9) * AUTHORS_SIGMA0**2


# ------------------------------------------------------------------------------------------- driving


def drive(module: ModuleType, inp: PeerInputs, X0: np.ndarray, P0: np.ndarray):
    """Their filter over ``inp``, stepped as ``main.py`` does; returns the filter, the wall time of the
    loop [s], its CPU time [s] (the figure to read on a shared machine) and the number of TDoA rows their
    innovation test rejected (seen as ``Ppo[k]`` left equal to ``Ppr[k]``). ``main.py``'s ``isin`` takes the
    first row at a time; so does this."""
    t = inp.t_s
    K = len(t)
    eskf = module.ESKF(X0, module.Quaternion([1.0, 0.0, 0.0, 0.0]), P0, K)
    i_imu = np.searchsorted(inp.imu_t_s, t)
    has_imu = (i_imu < len(inp.imu_t_s)) & (inp.imu_t_s[np.minimum(i_imu, len(inp.imu_t_s) - 1)] == t)
    i_uwb = np.searchsorted(inp.uwb_t_s, t)
    has_uwb = (i_uwb < len(inp.uwb_t_s)) & (inp.uwb_t_s[np.minimum(i_uwb, len(inp.uwb_t_s) - 1)] == t)
    i_imu = np.where(has_imu, i_imu, 0)  # main.py passes row 0 when there is none (then unused)
    rejected = 0
    start, cpu = time.perf_counter(), time.process_time()
    for k in range(1, K):
        eskf.predict(inp.imu[i_imu[k - 1]], t[k] - t[k - 1], bool(has_imu[k - 1]), k)
        if has_uwb[k - 1]:
            eskf.UWB_correct(inp.uwb[i_uwb[k - 1]], inp.anchor_position, k)
            rejected += bool(np.array_equal(eskf.Ppo[k], eskf.Ppr[k]))
    return eskf, time.perf_counter() - start, time.process_time() - cpu, rejected


# ------------------------------------------------------------------------------------------- scoring


def score(t_s, p_nav, P_pos, q_wxyz, truth_t, truth_p, truth_q) -> dict:
    """The metrics of ``swarm replay`` (:meth:`swarm.logs.replay.ReplayResult.summary`): position error
    against the truth linearly interpolated at each estimate inside the truth's span; 3-D and per-axis
    RMSE, the largest error, the attitude error against the nearest truth sample, the position NEES
    ``e^T P^-1 e`` (Bar-Shalom, Li & Kirubarajan 2001 sec. 5.4.2) against the two-sided :data:`BAND` of
    chi-square(3). ``q_wxyz`` is scalar first (their ``q_list``), ``truth_q`` scalar last."""
    inside = (t_s >= truth_t[0]) & (t_s <= truth_t[-1])
    t = t_s[inside]
    p_true = np.column_stack([np.interp(t, truth_t, truth_p[:, k]) for k in range(3)])
    e = p_nav[inside] - p_true
    err = np.linalg.norm(e, axis=1)
    nearest = np.clip(np.searchsorted(truth_t, t), 0, len(truth_t) - 1)
    q_est = np.asarray(q_wxyz)[inside][:, [1, 2, 3, 0]]
    dq = rot.quat_mul(rot.quat_conj(truth_q[nearest]), q_est / np.linalg.norm(q_est, axis=1)[:, None])
    angle = np.linalg.norm(rot.quat_log(dq), axis=1)
    nees = np.einsum("ni,ni->n", e, np.linalg.solve(P_pos[inside], e[..., None])[..., 0])
    lo, hi = chi2.ppf([(1 - BAND) / 2, (1 + BAND) / 2], 3)
    dt = np.diff(t, append=t[-1])
    over = float(np.sum(dt[err > DIVERGED_M]))
    return {
        "estimates": len(t),
        "rmse_m": float(np.sqrt(np.mean(err * err))),
        "rmse_axis_m": np.sqrt(np.mean(e * e, axis=0)).tolist(),
        "max_error_m": float(err.max()),
        "final_error_m": float(err[-1]),
        "attitude_rmse_deg": float(np.degrees(np.sqrt(np.mean(angle * angle)))),
        "nees_mean": float(nees.mean()),
        "nees_band": [float(lo), float(hi)],
        "nees_in_band_share": float(((nees >= lo) & (nees <= hi)).mean()),
        "error_over_1m_s": over,
        "diverged": over >= DIVERGED_S,
    }


def run_peer(log_dir: str | Path, util_eskf: str | Path, cfg: PeerConfig = PeerConfig()) -> dict:
    """Their filter on the log in ``log_dir``: the JSON of ``swarm bench peer`` (module docstring)."""
    module = load_eskf(util_eskf)
    lg = read_log(log_dir)
    if lg.truth_t is None:
        raise LogError(f"{lg.path}: no truth.csv; the comparison scores against it")
    inp = peer_inputs(lg, module, cfg)
    X0, P0 = initial_state(lg, cfg, inp.t0_s)
    eskf, wall, cpu, rejected = drive(module, inp, X0, P0)
    path = find_eskf(util_eskf)
    record = {
        "log": str(lg.path),
        "name": lg.config.name,
        "peer": {
            "file": str(path),
            "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
            "settings": _settings(module, eskf),
        },
        "config": asdict(cfg),
        "mode": inp.mode,
        "duration_s": float(inp.t_s[-1] - inp.t_s[0]),
        "imu_samples": len(inp.imu_t_s),
        "tdoa_rows": inp.tdoa_rows,
        "tdoa_used": len(inp.uwb_t_s),
        "tdoa_rejected_share": rejected / max(len(inp.uwb_t_s), 1),
        "initial_position_m": X0[0:3, 0].tolist(),
        "initial_velocity_m_s": X0[3:6, 0].tolist(),
        "start_s": inp.t0_s,
        "steps": len(inp.t_s),
        "wall_s": wall,
        "cpu_s": cpu,
        "step_us": 1e6 * wall / max(len(inp.t_s) - 1, 1),
        "step_cpu_us": 1e6 * cpu / max(len(inp.t_s) - 1, 1),
    }
    record.update(
        score(
            inp.t_s + inp.t0_s, eskf.Xpo[:, 0:3], eskf.Ppo[:, 0:3, 0:3], eskf.q_list,
            lg.truth_t, lg.truth_p, lg.truth_q,
        )
    )  # fmt: skip
    return record


def _settings(module: ModuleType, eskf) -> dict:
    """Their noise settings as their code holds them (module constants and the instance's)."""
    out = {}
    for name in ("w_accxyz", "w_gyro_rpy", "GRAVITY_MAGNITUDE"):
        if hasattr(module, name):
            out[name] = float(getattr(module, name))
    if hasattr(eskf, "std_uwb_tdoa"):
        out["std_uwb_tdoa_m"] = float(eskf.std_uwb_tdoa)
    if hasattr(eskf, "t_uv"):
        out["t_uv_m"] = np.asarray(eskf.t_uv, dtype=float).ravel().tolist()
    return out


def format_report(r: dict) -> str:
    """The printed summary."""
    ax = ", ".join(f"{v:.3f}" for v in r["rmse_axis_m"])
    lines = [
        f"UTIL authors' ESKF on {r['name'] or r['log']} ({r['mode']}, {r['duration_s']:.1f} s)",
        f"  inputs: {r['imu_samples']} IMU samples, {r['tdoa_used']} of {r['tdoa_rows']} TDoA rows "
        f"(1 in {r['config']['downsample']}), {100 * r['tdoa_rejected_share']:.1f} % rejected by its test",
        f"  3-D RMSE {r['rmse_m']:.3f} m  (x, y, z: {ax})  max {r['max_error_m']:.3f} m",
        f"  NEES mean {r['nees_mean']:.2f} (3 expected), "
        f"{100 * r['nees_in_band_share']:.0f} % in its 95 % band",
        f"  attitude RMS {r['attitude_rmse_deg']:.2f} deg",
        f"  wall {r['wall_s']:.2f} s, CPU {r['cpu_s']:.2f} s ({r['steps']} steps, {r['step_us']:.0f} us each)"
        + ("  DIVERGED" if r["diverged"] else ""),
    ]
    return "\n".join(lines)
