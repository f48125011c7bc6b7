"""Throwaway: list the failed runs (keep-out violation or collision) of a campaign's runs.csv."""

from __future__ import annotations

import csv
import sys

for path in sys.argv[1:]:
    rows = list(csv.DictReader(open(path)))
    fail = [r for r in rows if r["collided"] == "True" or r["keepout_violated"] == "True"]
    print(
        path,
        f"{len(rows)} runs, {len(fail)} failed,",
        f"target fired (impulse > 0) in {sum(float(r['target_impulse_ns']) > 0 for r in rows)}",
    )
    for r in sorted(fail, key=lambda r: (r["policy"], int(r["run"]))):
        lat = r["contact_lateral_m"]
        print(
            f"  {r['policy']:5s} run {int(r['run']):3d} seed {r['seed']:>10s} collided={r['collided']:5s} "
            f"keepout={r['keepout_violated']:5s} final={r['final_mode']:7s} "
            f"lateral={1e3 * float(lat) if lat else float('nan'):5.1f} mm "
            f"target_impulse={float(r['target_impulse_ns']):.4f} N s"
        )
