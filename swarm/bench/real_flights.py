"""``swarm bench real-flights LOG [LOG ...]``: the IMU-driven filter on recorded flights with a truth, as a
new user would run it: nothing tuned but what a user knows of the flight.

For each log folder (``swarm import`` output), what its ``log.toml`` does not say is taken from the
truth, as a user reads it off the motion-capture record: the pad is the truth's first position, the
heading its first yaw, and the static segment ends 1 s before the truth first rises 5 cm, but only if the
gyro is quiet there (no axis turning faster than ``QUIET_GYRO_RAD_S`` on average nor spreading more than
``QUIET_GYRO_SPREAD_RAD_S``; the UTIL TDoA logs start with the rotors already spinning, yawing at
0.09 rad/s and spreading 0.15, so they have none, and the pad is then the first position). Every other key
is the default. The report: 3-D and per-axis RMSE over the whole log and over its airborne span, position
NEES (mean, share in its 95 % band), resets, rejected shares, and the replay's time per 60 s of log (reading
the files included).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from swarm.logs.cfusd import CF_TWR_SIGMA_M
from swarm.logs.prior import given_keys
from swarm.logs.reader import read_log
from swarm.logs.replay import replay_log

QUIET_GYRO_RAD_S = 0.02
"""Largest mean rate of a static segment on any axis [rad/s] (a MEMS gyro's bias is a few mrad/s)."""
QUIET_GYRO_SPREAD_RAD_S = 0.1
"""Largest per-axis gyro spread of a static segment [rad/s] (a Crazyflie standing: ~0.003; a raw 1 kHz
MEMS gyro of 0.002 rad/s/sqrt(Hz): 0.06)."""
RISE_M = 0.05
"""The truth's rise that marks the take-off [m]."""
AIRBORNE_M = 0.2
"""The airborne span of a flight: where the truth is this high over its start [m] (the UTIL authors' filter
is scored on it too, ``swarm bench peer --span airborne``)."""


def user_keys(log_dir: Path) -> dict[str, object]:
    """What a user would write in log.toml from the truth (module docstring), for keys it does not give."""
    log = read_log(log_dir)
    if log.truth_t is None:
        raise ValueError(f"{log_dir}: no truth.csv: a real-flight benchmark needs one")
    given = given_keys(Path(log_dir) / "log.toml")
    p0 = [round(float(v), 4) for v in log.truth_p[0]]
    yaw = float(np.degrees(Rotation.from_quat(log.truth_q[0]).as_euler("ZYX")[0]))
    rise = np.flatnonzero(log.truth_p[:, 2] > log.truth_p[0, 2] + RISE_M)
    until = float(log.truth_t[rise[0]] - 1.0) if len(rise) else 0.0
    seg = log.gyro[log.imu_t < until]
    quiet = (
        len(seg) > 100
        and float(np.abs(seg.mean(axis=0)).max()) < QUIET_GYRO_RAD_S
        and float(seg.std(axis=0).max()) < QUIET_GYRO_SPREAD_RAD_S
    )
    keys: dict[str, object] = {"initial.yaw_deg": round(yaw, 2)}
    if quiet:
        keys.update({"calibration.until_s": round(until, 3), "calibration.position_m": p0})
    else:
        keys.update({"calibration.until_s": 0.0, "initial.position_m": p0})
        if len(log.uwb_t):  # no segment to calibrate the ranges' noise: the Crazyflie firmware's
            keys["uwb.sigma_m"] = CF_TWR_SIGMA_M
    return {k: v for k, v in keys.items() if k not in given}


def run_flight(log_dir: Path, overrides: dict[str, object] | None = None) -> dict:
    """One flight's row (module docstring)."""
    keys = {**user_keys(log_dir), **(overrides or {})}
    t0 = time.perf_counter()
    log = read_log(log_dir, keys)
    r = replay_log(log)
    wall = time.perf_counter() - t0
    s = r.summary()
    inside, e, _ = r.errors()
    z_true = np.interp(r.t[inside], log.truth_t, log.truth_p[:, 2])
    air = z_true > log.truth_p[0, 2] + AIRBORNE_M
    rmse_air = float(np.sqrt(np.mean(np.sum(e[air] ** 2, axis=1)))) if air.any() else None
    duration = float(log.imu_t[-1] - log.imu_t[0])
    gated = r.counts[:, 0] + r.counts[:, 1]
    row = {
        "log": str(log_dir),
        "mode": "tdoa" if s.get("tdoa") else "twr",
        "duration_s": duration,
        "keys_from_truth": keys,
        "rmse_m": s.get("rmse_m"),
        "rmse_axis_m": s.get("rmse_axis_m"),
        "rmse_airborne_m": rmse_air,
        "nees_mean": s.get("nees_mean"),
        "nees_in_band_share": s.get("nees_in_band_share"),
        "resets": sum(e["kind"] == "estimator_reset" for e in s["events"]),
        "rejected_share": float(r.counts[:, 1].sum() / gated.sum()) if gated.sum() else None,
        "wall_s": wall,
        "wall_per_60_s": wall * 60.0 / duration if duration > 0 else math.nan,
    }
    if s.get("tdoa"):
        row["rejected_share"] = s["tdoa"]["rejected_share"]
    return row


def run(logs: list[Path], overrides: dict[str, object] | None = None) -> tuple[dict, str]:
    rows = [run_flight(Path(d), overrides) for d in logs]
    lines = [
        "| flight | mode | 3-D RMSE [m] | x / y / z [m] | airborne [m] | NEES mean | in 95 % band | resets "
        "| rejected | s per 60 s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for w in rows:
        ax = " / ".join(f"{v:.3f}" for v in w["rmse_axis_m"]) if w["rmse_axis_m"] else "-"
        lines.append(
            f"| {Path(w['log']).name} | {w['mode']} | {w['rmse_m']:.3f} | {ax} | "
            f"{'-' if w['rmse_airborne_m'] is None else format(w['rmse_airborne_m'], '.3f')} | "
            f"{w['nees_mean']:.2f} | "
            f"{w['nees_in_band_share']:.0%} | {w['resets']} | "
            f"{'-' if w['rejected_share'] is None else format(w['rejected_share'], '.1%')} | "
            f"{w['wall_per_60_s']:.2f} |"
        )
    return {"flights": rows}, "\n".join(lines)
