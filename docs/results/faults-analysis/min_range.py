"""Throwaway: closest true approach to the (stationary) target before DOCK, per run, from a campaign's
trajectories.jsonl (1 s samples of the chaser's true position) and runs.csv (t_dock_s)."""

from __future__ import annotations

import csv
import json
import sys

import numpy as np

d = sys.argv[1]
P_T = np.array([1.0, 2.0, 1.0])  # the paper's target station (no position dispersion in docking-faults)
rows = {(r["policy"], int(r["run"])): r for r in csv.DictReader(open(f"{d}/runs.csv"))}
res = {}
for line in open(f"{d}/trajectories.jsonl"):
    tr = json.loads(line)
    r = rows[(tr["policy"], tr["run"])]
    if float(r["target_impulse_ns"]) > 0:
        continue  # target moved: its station is not its position
    t = np.array(tr["t_s"])
    p = np.array(tr["p_ms"])
    t_dock = float(r["t_dock_s"]) if r["t_dock_s"] else np.inf
    m = t < t_dock
    res.setdefault(tr["policy"], []).append(float(np.min(np.linalg.norm(p[m] - P_T, axis=1))))
for pol, v in sorted(res.items()):
    v = 1e3 * np.array(v)
    print(
        f"{pol}: {len(v)} runs; closest approach before DOCK [mm]: min {v.min():.1f}, 1 % {np.percentile(v, 1):.1f},"
        f" 5 % {np.percentile(v, 5):.1f}, median {np.median(v):.1f}; below 150 mm: {(v < 150).sum()},"
        f" below 155 mm: {(v < 155).sum()}, below 160 mm: {(v < 160).sum()}"
    )
