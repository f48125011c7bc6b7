"""``swarm bench tdoa``: two-way ranging over TDMA against TDoA3 as the swarm grows (issue 45).

For N vehicles, each tag's measurement rate with TWR-TDMA (:func:`swarm.core.tdoa_radio.twr_tdma_rate_hz`:
one exchange per frame of the smallest power of two >= N slots of 4.2 ms, at most the 50 Hz UWB tick:
~238/N) and with TDoA3 (the closed form :func:`~swarm.core.tdoa_radio.expected_rates` and a simulation of
N tags on one channel, :class:`~swarm.core.tdoa_radio.TdoaRadio`); then the position RMSE of ``swarm
replay`` (:func:`swarm.logs.replay.replay_log`) at that rate on one synthetic flight
(:mod:`swarm.logs.synthetic`, 8 anchors):

* TWR: the flight's 80 Hz round-robin ranges thinned to the per-tag rate, the round robin kept (the
  ``j``-th range kept is the first of anchor ``j mod 8`` at or after ``j / rate``);
* TDoA3: the same flight's ``tdoa.csv`` (``swarm synth-log --tdoa tdoa3``): its rate does not depend on N,
  so it is replayed once and its row repeats.

Both logs miss the same share of packets (``range_loss``, 5 %), have the same per-anchor biases and the
same NLOS anchor (3: in flight 60 % of its ranges, or packets, long by an exponential of mean 1 m); the TWR
log's airborne biases also walk slowly, the TDoA log's do not (:mod:`swarm.logs.synth_tdoa`).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

FULL = {"vehicles": (2, 8, 32, 128), "duration_s": 60.0, "seed": 1, "sim_s": 10.0}
QUICK = {"vehicles": (2, 8), "duration_s": 20.0, "seed": 1, "sim_s": 3.0}


def thin_ranges(rows: np.ndarray, rate_hz: float, n_anchors: int) -> np.ndarray:
    """``uwb.csv`` rows ``(t_s, anchor_id, range_m)`` (round robin) thinned to ``rate_hz``, the round robin
    kept: the ``j``-th kept row is the first of anchor ``j mod n_anchors`` at or after ``j / rate_hz``."""
    t, a = rows[:, 0], rows[:, 1].astype(int)
    by_anchor = [np.flatnonzero(a == i) for i in range(n_anchors)]
    keep = []
    for j in range(int((t[-1] - t[0]) * rate_hz)):
        idx = by_anchor[j % n_anchors]
        k = np.searchsorted(t[idx], t[0] + j / rate_hz)
        if k < len(idx):
            keep.append(idx[k])
    return rows[np.unique(np.asarray(keep, dtype=np.int64))]


def _replay(folder: Path) -> dict:
    from swarm.logs.reader import read_log
    from swarm.logs.replay import replay_log

    s = replay_log(read_log(folder)).summary()
    out = {k: s.get(k) for k in ("rmse_m", "nees_mean", "nees_in_band_share", "replay_wall_s")}
    out["resets"] = sum(1 for e in s["events"] if e["kind"] == "estimator_reset")
    return out


def run(cfg: dict) -> dict:
    """The table (module docstring) as a JSON-ready dict."""
    from swarm.core import tdoa_radio as tr
    from swarm.logs.synthetic import ANCHORS, SyntheticSpec, make_log

    t0 = time.perf_counter()
    spec = SyntheticSpec(duration_s=cfg["duration_s"])
    params = tr.TdoaParams(tag_loss=spec.range_loss, sigma_m=float(np.sqrt(2) * spec.range_sigma_m))
    model = tr.expected_rates(params, len(ANCHORS))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        twr_dir, tdoa_dir = Path(tmp) / "twr", Path(tmp) / "tdoa3"
        make_log(twr_dir, cfg["seed"], spec)
        tdoa_spec = SyntheticSpec(
            duration_s=cfg["duration_s"], tdoa="tdoa3", tdoa_nlos_anchor=spec.nlos_anchor
        )
        make_log(tdoa_dir, cfg["seed"], tdoa_spec)
        ranges = np.loadtxt(twr_dir / "uwb.csv", delimiter=",", skiprows=1)
        tdoa_rows = sum(1 for _ in (tdoa_dir / "tdoa.csv").open()) - 1
        tdoa = _replay(tdoa_dir)
        rng = np.random.default_rng(cfg["seed"])
        for n in cfg["vehicles"]:
            twr_hz = tr.twr_tdma_rate_hz(n)
            thin_dir = Path(tmp) / f"twr{n}"
            shutil.copytree(twr_dir, thin_dir)
            kept = thin_ranges(ranges, twr_hz, len(ANCHORS))
            np.savetxt(thin_dir / "uwb.csv", kept, delimiter=",", header="t_s,anchor_id,range_m", comments="",
                       fmt=["%.6f", "%d", "%.6f"])  # fmt: skip
            twr = _replay(thin_dir)
            radio = tr.TdoaRadio(params, ANCHORS, n, cfg["sim_s"], seed=cfg["seed"])
            pos = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-2, 2, n), rng.uniform(0.5, 2, n)])
            radio.step(cfg["sim_s"], pos)
            per_tag = radio.counts["rows"] / cfg["sim_s"]
            sent, lost = radio.channel.counts(0.0, cfg["sim_s"], len(ANCHORS))
            rows.append(
                {
                    "vehicles": int(n),
                    "twr_hz": twr_hz,
                    "twr_log_hz": len(kept) / cfg["duration_s"],
                    "tdoa3_model_hz": model.measurements_per_tag_hz,
                    "tdoa3_sim_hz": float(per_tag.mean()),
                    "tdoa3_sim_min_hz": float(per_tag.min()),
                    "tdoa3_sim_max_hz": float(per_tag.max()),
                    "tdoa3_log_hz": tdoa_rows / cfg["duration_s"],
                    "anchors_sim_hz": float(sent.sum() / cfg["sim_s"]),
                    "collision_share_sim": float(lost.sum() / max(sent.sum(), 1)),
                    "twr_rmse_m": twr["rmse_m"],
                    "twr_nees_mean": twr["nees_mean"],
                    "twr_resets": twr["resets"],
                    "tdoa3_rmse_m": tdoa["rmse_m"],
                    "tdoa3_nees_mean": tdoa["nees_mean"],
                    "tdoa3_resets": tdoa["resets"],
                }
            )
    return {
        "config": {k: list(v) if isinstance(v, tuple) else v for k, v in cfg.items()},
        "anchors": len(ANCHORS),
        "model": {
            "anchors_hz": model.total_hz,
            "per_anchor_hz": float(model.per_anchor_hz[0]),
            "airtime_s": params.airtime,
            "collision_share": model.collision_share,
            "aloha_collision": model.aloha_collision,
            "received_per_tag_hz": model.received_per_tag_hz,
            "measurements_per_tag_hz": model.measurements_per_tag_hz,
        },
        "rows": rows,
        "wall_s": time.perf_counter() - t0,
    }


def format_report(r: dict) -> str:
    """The table as text."""
    m, c = r["model"], r["config"]

    def f(v, fmt):
        return "-" if v is None else format(v, fmt)

    lines = [
        f"TDoA for swarms: per-tag measurement rate and swarm replay's position RMSE ({c['duration_s']:g} s "
        f"synthetic flight, seed {c['seed']}, {r['anchors']} anchors)",
        f"TDoA3 model: {m['per_anchor_hz']:.0f} packets/s per anchor, {m['anchors_hz']:.0f} in all, air time "
        f"{m['airtime_s'] * 1e3:.3f} ms, {100 * m['collision_share']:.1f} % collide (pure ALOHA "
        f"{100 * m['aloha_collision']:.1f} %), a tag receives {m['received_per_tag_hz']:.0f}/s and forms "
        f"{m['measurements_per_tag_hz']:.0f} differences/s, for any number of tags",
        "",
        "vehicles | TWR-TDMA [Hz] | TDoA3 model [Hz] | TDoA3 sim [Hz] (min-max) | TWR RMSE [m] "
        "| TDoA3 RMSE [m] | TWR NEES | TDoA3 NEES | resets TWR / TDoA3",
        "---:|---:|---:|---:|---:|---:|---:|---:|---:",
    ]
    for row in r["rows"]:
        sim = f"{row['tdoa3_sim_hz']:.0f} ({row['tdoa3_sim_min_hz']:.0f}-{row['tdoa3_sim_max_hz']:.0f})"
        lines.append(
            f"{row['vehicles']} | {row['twr_hz']:.2f} | {row['tdoa3_model_hz']:.0f} | {sim} | "
            f"{f(row['twr_rmse_m'], '.3f')} | {f(row['tdoa3_rmse_m'], '.3f')} | "
            f"{f(row['twr_nees_mean'], '.2f')} | {f(row['tdoa3_nees_mean'], '.2f')} | "
            f"{row['twr_resets']} / {row['tdoa3_resets']}"
        )
    lines.append(f"({r['wall_s']:.0f} s)")
    return "\n".join(lines)
