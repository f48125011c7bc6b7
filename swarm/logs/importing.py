"""What the log importers share (``swarm import``, ``docs/logs.md`` "Importing logs"): the anchors file, the
pairing of separate gyroscope and accelerometer streams into IMU rows, time ordering, and the writing of a
log folder (CSV files with their header, a ``log.toml`` whose comment block says what was imported).

The importers (``swarm/logs/cfusd.py``, ``ulog.py``, ``rosbag.py``) convert units and frames; this module
writes what they hand it, in the columns the reader (``swarm/logs/reader.py``) expects.
"""

from __future__ import annotations

import json
import logging
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarm.errors import LogError
from swarm.logs.reader import (
    ANCHOR_COLUMNS,
    BARO_COLUMNS,
    HEIGHT_COLUMNS,
    IMU_COLUMNS,
    QUAT_NORM_TOL,
    TDOA_COLUMNS,
    TRUTH_COLUMNS,
    UWB_COLUMNS,
    read_anchors,
)

log = logging.getLogger(__name__)

STANDARD_G_M_S2 = 9.81
"""One g [m/s^2] for accelerometers that log in g (the Crazyflie's estAcceleration). 9.81, not the standard
9.80665, because the Crazyflie firmware (``GRAVITY_MAGNITUDE``, ``physicalConstants.h``) and the UTIL
dataset authors' ESKF (``scripts/estimation/eskf_class.py``) both scale by 9.81: the importer undoes the
logger's own conversion. ``swarm import cfusd --g`` overrides it."""

IMU_PAIR_MAX_GAP_S = 0.02
"""Largest gap between the two accelerometer samples around a gyroscope sample for the interpolation to
stand [s] (20 samples of a 1 kHz IMU); a gyroscope sample in a longer accelerometer gap is dropped."""

_UTIL_ANCHOR = re.compile(r"^\s*anchorAnt(\d+)\s*,(.*)$")


@dataclass
class Imported:
    """What an importer did: the figures the CLI prints and ``log.toml``'s comment block keeps."""

    out: Path
    source: str
    """The imported file and its kind, one line."""
    rows: dict[str, int] = field(default_factory=dict)
    """Rows written per file."""
    notes: list[str] = field(default_factory=list)
    """What was imported, converted, dropped (one line each)."""
    warnings: list[str] = field(default_factory=list)
    """Damage that was survived (a file cut mid-write), one line each; also logged as warnings."""

    def warn(self, text: str) -> None:
        self.warnings.append(text)
        log.warning("%s", text)

    def lines(self) -> list[str]:
        """The summary, one line each: source, notes, rows per file, warnings."""
        out = [self.source, *self.notes]
        out.append("rows: " + ", ".join(f"{k} {v}" for k, v in self.rows.items()))
        out += [f"WARNING: {w}" for w in self.warnings]
        return out


def read_anchor_file(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Anchor ids and antenna positions (n, 3) [m] from ``path``: our ``anchors.csv`` (a header with
    ``anchor_id, x_m, y_m, z_m``), or the UTIL dataset's survey (``anchorAnt<id>,x,y,z`` lines give each
    antenna; the other lines, markers on the anchor's case and the dataset's frame, are ignored)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise LogError(f"{p}: cannot read the anchors file: {exc}") from None
    first = next((ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")), "")
    if "anchor_id" in first:
        return read_anchors(p)
    ids, xyz = [], []
    for no, ln in enumerate(text.splitlines(), 1):
        m = _UTIL_ANCHOR.match(ln)
        if not m:
            continue
        parts = m.group(2).split(",")
        try:
            v = [float(x) for x in parts]
        except ValueError:
            raise LogError(
                f"{p.name}, line {no}: not three numbers after anchorAnt{m.group(1)}: {ln!r}"
            ) from None
        if len(v) != 3 or not np.all(np.isfinite(v)):
            raise LogError(f"{p.name}, line {no}: expected anchorAnt<id>,x,y,z with finite x, y, z: {ln!r}")
        aid = int(m.group(1))
        if aid in ids:
            raise LogError(f"{p.name}, line {no}: anchor {aid} is listed twice")
        ids.append(aid)
        xyz.append(v)
    if not ids:
        raise LogError(
            f"{p.name}: no anchors: expected an anchors.csv (anchor_id, x_m, y_m, z_m) or the UTIL survey's "
            "anchorAnt<id>,x,y,z lines"
        )
    order = np.argsort(ids)
    return np.asarray(ids, dtype=np.int64)[order], np.asarray(xyz, dtype=float)[order]


def time_order(t: np.ndarray, strict: bool) -> tuple[np.ndarray, int]:
    """Indices that put ``t`` in time order (stable: equal times keep the log's order) and, when ``strict``,
    keep only the first of equal times; and how many were dropped as duplicates."""
    order = np.argsort(t, kind="stable")
    if not strict or len(order) < 2:
        return order, 0
    ts = t[order]
    keep = np.concatenate(([True], np.diff(ts) > 0.0))
    return order[keep], int((~keep).sum())


def pair_imu(
    gyro_t: np.ndarray,
    gyro: np.ndarray,
    acc_t: np.ndarray,
    acc: np.ndarray,
    max_gap_s: float = IMU_PAIR_MAX_GAP_S,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """IMU rows from separate gyroscope and accelerometer streams: one row at each gyroscope sample's time
    (strictly increasing: a repeated time keeps its first sample), the accelerometer linearly interpolated to
    it between the two accelerometer samples around it. A gyroscope sample before the first or after the
    last accelerometer sample, or between two more than ``max_gap_s`` apart, is dropped. Returns ``(t,
    gyro, acc, dropped)``: times (n,) [s], the two (n, 3) arrays, and the number of gyroscope samples
    dropped (repeats included). Interpolating to the gyroscope's times keeps its samples exact: the
    attitude integrates them, while the specific force is smooth at the ~17 us that separate the two
    streams of a Crazyflie log."""
    g_order, dup = time_order(gyro_t, strict=True)
    a_order, _ = time_order(acc_t, strict=True)
    gt, g = gyro_t[g_order], gyro[g_order]
    at, a = acc_t[a_order], acc[a_order]
    if len(at) < 2 or len(gt) == 0:
        return np.empty(0), np.empty((0, 3)), np.empty((0, 3)), dup + len(gt)
    hi = np.searchsorted(at, gt, side="left")
    inside = (hi > 0) & (hi < len(at))
    exact = (hi < len(at)) & (at[np.minimum(hi, len(at) - 1)] == gt)
    lo = np.clip(hi - 1, 0, len(at) - 1)
    hi_c = np.clip(hi, 0, len(at) - 1)
    gap = at[hi_c] - at[lo]
    keep = exact | (inside & (gap <= max_gap_s))
    gt, g, lo, hi_c = gt[keep], g[keep], lo[keep], hi_c[keep]
    span = at[hi_c] - at[lo]
    w = np.divide(gt - at[lo], span, out=np.ones_like(gt), where=span > 0)
    acc_i = a[lo] + w[:, None] * (a[hi_c] - a[lo])
    return gt, g, acc_i, dup + int((~keep).sum())


def _fmt_rows(columns: list[np.ndarray], formats: list[str]) -> str:
    """The CSV body: one line per row, NaN written as an empty field (a lost reading)."""
    if not columns or len(columns[0]) == 0:
        return ""
    fmt = ",".join(formats)
    arrays = [c.tolist() for c in columns]
    text = "\n".join(fmt % row for row in zip(*arrays, strict=True)) + "\n"
    text = text.replace(",nan", ",")
    return text


class LogFolder:
    """A log folder being written: each ``write_*`` writes one CSV file of ``docs/logs.md``."""

    def __init__(self, out: str | Path, force: bool, report: Imported, time_decimals: int = 6):
        self.out = Path(out)
        self.report = report
        self.t_fmt = f"%.{time_decimals}f"
        if self.out.exists() and not self.out.is_dir():
            raise LogError(f"{self.out}: exists and is not a folder")
        if (self.out / "imu.csv").exists() and not force:
            raise LogError(f"{self.out}: already holds a log (imu.csv); give --force to overwrite it")
        self.out.mkdir(parents=True, exist_ok=True)

    def _write(self, name: str, header: tuple[str, ...], columns: list[np.ndarray], formats: list[str]):
        body = _fmt_rows(columns, formats)
        (self.out / name).write_text(", ".join(header) + "\n" + body, encoding="utf-8")
        self.report.rows[name] = len(columns[0]) if columns else 0

    def write_imu(self, t, gyro_rad_s, acc_m_s2) -> None:
        self._write(
            "imu.csv",
            IMU_COLUMNS,
            [t, *np.asarray(gyro_rad_s).T, *np.asarray(acc_m_s2).T],
            [self.t_fmt] + ["%.9g"] * 6,
        )

    def write_uwb(self, t, anchor_id, range_m) -> None:
        self._write(
            "uwb.csv", UWB_COLUMNS, [np.asarray(t), np.asarray(anchor_id), np.asarray(range_m)],
            [self.t_fmt, "%d", "%.9g"],
        )  # fmt: skip

    def write_anchors(self, ids, xyz) -> None:
        xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
        self._write("anchors.csv", ANCHOR_COLUMNS, [np.asarray(ids), *xyz.T], ["%d"] + ["%.9g"] * 3)

    def write_tdoa(self, t, a, b, ddist_m) -> None:
        self._write(
            "tdoa.csv", TDOA_COLUMNS, [np.asarray(t), np.asarray(a), np.asarray(b), np.asarray(ddist_m)],
            [self.t_fmt, "%d", "%d", "%.9g"],
        )  # fmt: skip

    def write_truth(self, t, p_nav, q_nav_body) -> None:
        """``q_nav_body`` scalar-last; rows whose quaternion is not unit within the reader's tolerance (or
        not finite) are dropped and counted (a motion-capture dropout)."""
        p, q, t = np.asarray(p_nav, float), np.asarray(q_nav_body, float), np.asarray(t, float)
        norm = np.linalg.norm(q, axis=1)
        good = np.isfinite(norm) & (np.abs(norm - 1.0) <= QUAT_NORM_TOL) & np.isfinite(p).all(axis=1)
        if not good.all():
            self.report.notes.append(
                f"truth.csv: {int((~good).sum())} poses without a unit quaternion dropped"
            )
        self._write(
            "truth.csv", TRUTH_COLUMNS, [t[good], *p[good].T, *q[good].T], [self.t_fmt] + ["%.9g"] * 7
        )
        return self.report

    def write_height(self, t, range_m) -> None:
        """``range_m`` NaN for no return: written empty."""
        self._write("height.csv", HEIGHT_COLUMNS, [np.asarray(t), np.asarray(range_m)], [self.t_fmt, "%.9g"])

    def write_baro(self, t, height_m) -> None:
        self._write("baro.csv", BARO_COLUMNS, [np.asarray(t), np.asarray(height_m)], [self.t_fmt, "%.9g"])

    def finish(self, name: str, tables: str = "") -> Imported:
        """``log.toml``: a ``name``, a comment block with the report's lines, and ``tables`` (TOML text the
        importer knows, e.g. the logging system's range noise)."""
        lines = [f"# {ln}" for ln in self.report.lines()]
        text = "\n".join(["# Imported by `swarm import` (docs/logs.md, Importing logs)", *lines])
        text += f"\nname = {json.dumps(name)}\n"
        if tables:
            text += "\n" + tables.strip() + "\n"
        (self.out / "log.toml").write_text(text, encoding="utf-8")
        return self.report
