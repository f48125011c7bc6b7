"""Throwaway: distribution of the true lateral port offset at contact, per policy, split by whether the
target fired its thrusters during the run (runs.csv of a campaign)."""

from __future__ import annotations

import csv
import sys

import numpy as np

for path in sys.argv[1:]:
    rows = [r for r in csv.DictReader(open(path)) if r["contact_lateral_m"]]
    print(path)
    for pol in ("fixed", "mdp"):
        for fired in (False, True):
            v = np.array(
                [
                    1e3 * float(r["contact_lateral_m"])
                    for r in rows
                    if r["policy"] == pol and (float(r["target_impulse_ns"]) > 0) == fired
                ]
            )
            if len(v):
                print(
                    f"  {pol:5s} target fired={fired!s:5s}: {len(v):3d} contacts, lateral [mm] median "
                    f"{np.median(v):.1f}, 95 % {np.percentile(v, 95):.1f}, max {v.max():.1f}, > 20 mm: {(v > 20).sum()}"
                )
