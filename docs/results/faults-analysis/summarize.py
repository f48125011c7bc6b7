"""Throwaway: print the DOCK-phase numbers of a trace.py output (issue-7 analysis)."""

from __future__ import annotations

import json
import sys

import numpy as np

from swarm.core import rotations as rot
from swarm.core.guidance import GuidanceParams

G = GuidanceParams()


def face_n(q):
    return rot.quat_rotate(np.asarray(q), G.face_normal_target)


def angle_deg(rel, n):
    return np.degrees(np.arccos(np.clip(rel @ n / np.linalg.norm(rel), -1, 1)))


def lateral(rel, n):
    return np.linalg.norm(rel - (rel @ n) * n)


def summarize(path):
    d = json.load(open(path))
    c = d["summary"]["chasers"]["chaser"]
    tr = d["trace"]
    out = {
        "outcome": "docked" if c["docked"] else ("collided" if c["collided"] else c["final_mode"]),
        "keepout": c["keepout_violated"],
        "contact": c["contact"],
        "events": [e for e in c.get("events", [])] if "events" in c else None,
    }
    dock = [r for r in tr if r["mode"] == "DOCK"]
    if not dock:
        return out
    e0, e1 = dock[0], dock[-1]
    for tag, r in (("dock_entry", e0), ("last_dock", e1)):
        pc, pt, pce, ptl = (np.array(r[k]) for k in ("pc_true", "pt_true", "pc_est", "pt_latched"))
        nt, nl = face_n(r["qt_true"]), face_n(r["qt_latched"])
        rel_t, rel_e = pc - pt, pce - ptl
        out[tag] = {
            "t": r["t"],
            "vis_age_s": r["vis_age"],
            "range_true_m": float(np.linalg.norm(rel_t)),
            "angle_true_deg": float(angle_deg(rel_t, nt)),  # chaser off the true face normal
            "angle_est_deg": float(angle_deg(rel_e, nl)),  # what guidance sees
            "lat_true_mm": 1e3 * float(lateral(rel_t - 0.1 * nt, nt)),
            "lat_est_mm": 1e3 * float(lateral(rel_e - 0.1 * nl, nl)),
            "rel_err_mm": (1e3 * (rel_e - rel_t)).round(1).tolist(),
            "rel_err_lat_mm": 1e3 * float(lateral(rel_e - rel_t, nt)),
            "target_latch_err_mm": (1e3 * (ptl - pt)).round(1).tolist(),
            "target_normal_err_deg": float(np.degrees(np.arccos(np.clip(nt @ nl, -1, 1)))),
            "sig_c_mm": 1e3 * r["sig_c"],
            "true_geom": r["true_geom"],
            "est_geom": r["est_geom"],
        }
    pts = np.array([r["pt_true"] for r in dock])
    out["target_moved_in_dock_mm"] = 1e3 * float(np.linalg.norm(pts[-1] - pts[0]))
    ages = np.array([r["vis_age"] for r in dock])
    rngs = np.array([r["true_geom"]["gap_m"] for r in dock])
    lost = np.where(ages > 0.5)[0]
    out["vision_lost_at_gap_mm"] = 1e3 * float(rngs[lost[0]]) if len(lost) else None
    out["dock_duration_s"] = dock[-1]["t"] - dock[0]["t"]
    return out


if __name__ == "__main__":
    for p in sys.argv[1:]:
        print(p)
        print(json.dumps(summarize(p), indent=1, default=float))
