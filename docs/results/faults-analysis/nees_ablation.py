"""Ablation of the chaser filter's tuning against its position NEES and the campaign's safety (issue 7).

usage (from the repository root; ``PYTHONPATH=.`` so that this checkout's ``swarm`` is the one imported):
    PYTHONPATH=. python docs/results/faults-analysis/nees_ablation.py SCENARIO RUNS OUT_DIR LABEL [K=V ...]
    PYTHONPATH=. python docs/results/faults-analysis/nees_ablation.py --table OUT_DIR

Runs ``RUNS`` paired runs of both policies (root seed 0, 2 workers) of ``SCENARIO`` with the overrides
``K=V`` (as ``swarm montecarlo --set``) into ``OUT_DIR/LABEL``, and writes ``OUT_DIR/LABEL.json``: per policy
the outcome classes and NEES of :func:`swarm.montecarlo.faults.fault_summary`, plus the mean docking time,
impulse and position error. ``--table`` prints every ``OUT_DIR/*.json`` as one Markdown table.

A fault-free scenario (``docking``) gets a UWB dropout window after the end of every run
(``faults.uwb_dropout.windows_s=[[1000, 1001]]``): it turns the runner's NEES bookkeeping on and changes
nothing else (the same seed gives the same run bit for bit).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np


def run(scenario: str, runs: int, out_dir: Path, label: str, sets: list[str]) -> None:
    from swarm.config import parse_override
    from swarm.montecarlo.campaign import CampaignSpec, read_runs, read_trajectories, run_campaign
    from swarm.montecarlo.faults import fault_summary
    from swarm.scenario import load_scenario

    over = dict(parse_override(a) for a in sets)
    sc = load_scenario(scenario, over)
    if not sc.faults.enabled:
        over["faults.uwb_dropout.windows_s"] = [[1000.0, 1001.0]]
        sc = load_scenario(scenario, over)
    out = out_dir / label
    outcome = run_campaign(CampaignSpec(sc, ("fixed", "mdp"), runs, 0), out, workers=2, progress=False)
    rows, trajs = read_runs(out), read_trajectories(out)
    summ = fault_summary(rows, trajs)
    for pol, s in summ.items():
        mine = [r for r in rows if r["policy"] == pol]
        for key in ("docking_time_s", "total_impulse_ns", "position_error_m"):
            v = np.array([r[key] for r in mine if r[key] is not None], dtype=float)
            s[key] = float(v.mean()) if v.size else None
    rec = {"scenario": scenario, "runs": runs, "sets": sets, "wall_s": outcome.wall_s, "policies": summ}
    (out_dir / f"{label}.json").write_text(json.dumps(rec, indent=1) + "\n")
    print(table([(label, rec)]))


def table(recs) -> str:
    lines = [
        "| config | scenario | policy | safe | KO viol. | coll. | HOLD | closest [mm] | NEES mean | median "
        "| inside 95 % | above | below | dock time [s] | impulse [N s] | pos. err [mm] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, rec in recs:
        for pol, s in rec["policies"].items():
            n = s["nees"]
            ca = s.get("closest_approach_m")
            lines.append(
                f"| {label} | {rec['scenario']} | {pol} | {s['docked'] + s['aborted']}/{s['n_runs']} "
                f"({s['aborted']} ab.) | {s['keepout_violations']} | {s['collisions']} | "
                f"{s['runs_with_hold']} | "
                f"{1e3 * ca['min'] if ca else float('nan'):.1f} | {n['mean_nees']:.2f} | "
                f"{n['median_nees']:.2f} | {100 * n['fraction_times_inside_95']:.0f} % of {n['times']} | "
                f"{n['times_above']} | {n['times_below']} | {s['docking_time_s']:.2f} | "
                f"{s['total_impulse_ns']:.4f} | {1000 * s['position_error_m']:.2f} |"
            )
    return "\n".join(lines)


def main(argv) -> None:
    if argv[0] == "--table":
        d = Path(argv[1])
        recs = [(p.stem, json.loads(p.read_text())) for p in sorted(d.glob("*.json"))]
        print(table(recs))
        return
    scenario, runs, out_dir, label = argv[0], int(argv[1]), Path(argv[2]), argv[3]
    out_dir.mkdir(parents=True, exist_ok=True)
    run(scenario, runs, out_dir, label, argv[4:])


if __name__ == "__main__":
    main(sys.argv[1:])
