"""Throwaway: one line per trace.py output: the DOCK phase split at vision loss (camera markers leave the
image at ~8 cm gap): target true displacement perpendicular to the face normal during the blind phase,
the chaser's relative-estimate lateral error at contact, the true lateral offset at contact."""

from __future__ import annotations

import json
import sys

import numpy as np

from swarm.core import rotations as rot
from swarm.core.guidance import GuidanceParams

G = GuidanceParams()
print(
    "file | outcome | DOCK s | vision lost at gap mm | blind s | lateral at vision loss mm (true/est) |"
    " docking point moved in blind phase, lateral mm (face normal turned deg) | same minus its velocity at vision loss x blind time, lateral mm | target moved in DOCK mm | lateral at end mm (true/est) |"
    " rel. estimate lateral error at end mm"
)
for path in sys.argv[1:]:
    d = json.load(open(path))
    c = d["summary"]["chasers"]["chaser"]
    dock = [r for r in d["trace"] if r["mode"] == "DOCK"]
    if not dock:
        print(path, "no DOCK")
        continue
    i = next((j for j, r in enumerate(dock) if r["vis_age"] > 0.5), None)
    a, e = dock[i] if i is not None else dock[-1], dock[-1]
    n = rot.quat_rotate(np.array(e["qt_true"]), G.face_normal_target)
    n_a = rot.quat_rotate(np.array(a["qt_true"]), G.face_normal_target)
    # where the chaser must be when docked (the target's port + a cube), at vision loss and at the end
    dpt = (np.array(e["pt_true"]) + 2 * G.half_size_m * n) - (
        np.array(a["pt_true"]) + 2 * G.half_size_m * n_a
    )
    lat_move = np.linalg.norm(dpt - (dpt @ n) * n)
    # the vision-relative velocity estimate at vision loss carries the target's velocity then, so only the
    # target's motion beyond that constant velocity (its thrust in the blind phase) is unseen
    dacc = dpt - np.array(a["vt_true"]) * (e["t"] - a["t"])
    lat_acc = np.linalg.norm(dacc - (dacc @ n) * n)
    rot_deg = np.degrees(np.arccos(np.clip(n @ n_a, -1, 1)))
    rel_t = np.array(e["pc_true"]) - np.array(e["pt_true"])
    rel_e = np.array(e["pc_est"]) - np.array(e["pt_latched"])
    err = rel_e - rel_t
    out = "docked" if c["docked"] else ("collided" if c["collided"] else c["final_mode"])
    out += " +keep-out" if c["keepout_violated"] else ""
    moved = np.linalg.norm(np.array(e["pt_true"]) - np.array(dock[0]["pt_true"]))
    print(
        f"{path.split('/')[-1]} | {out} | {e['t'] - dock[0]['t']:.1f} | {1e3 * a['true_geom']['gap_m']:.0f} | "
        f"{e['t'] - a['t']:.1f} | {1e3 * a['true_geom']['lateral_m']:.1f}/{1e3 * a['est_geom']['lateral_m']:.1f} | "
        f"{1e3 * lat_move:.1f} ({rot_deg:.1f}) | {1e3 * lat_acc:.1f} | {1e3 * moved:.1f} | {1e3 * e['true_geom']['lateral_m']:.1f}/"
        f"{1e3 * e['est_geom']['lateral_m']:.1f} | {1e3 * np.linalg.norm(err - (err @ n) * n):.1f}"
    )
