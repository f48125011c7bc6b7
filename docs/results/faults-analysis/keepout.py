"""Throwaway: where a trace.py run comes closest to the target outside the corridor modes, and why
(true range vs the range the guidance sees; chaser and target estimate errors along the line of sight)."""

from __future__ import annotations

import json
import sys

import numpy as np

for path in sys.argv[1:]:
    tr = json.load(open(path))["trace"]
    best = None
    for r in tr:
        if r["mode"] in ("DOCK", "DOCKED", "ABORT"):
            continue
        pc, pt = np.array(r["pc_true"]), np.array(r["pt_true"])
        d = np.linalg.norm(pc - pt)
        if best is None or d < best[0]:
            best = (d, r)
    d, r = best
    pc, pt, pce, ptl, ref = (np.array(r[k]) for k in ("pc_true", "pt_true", "pc_est", "pt_latched", "ref"))
    u = (pc - pt) / d
    print(path, f"t={r['t']:.1f} mode={r['mode']} vis_age={r['vis_age']:.1f} rel_nav={r['rel_nav']}")
    print(
        f"  true centre distance {1e3 * d:.1f} mm (keep-out 150); estimated {1e3 * np.linalg.norm(pce - ptl):.1f} mm;"
        f" reference {1e3 * np.linalg.norm(ref - ptl):.1f} mm from the target estimate (stop at 180)"
    )
    print(
        f"  chaser estimate error along LOS {1e3 * (pce - pc) @ u:+.1f} mm (|e|={1e3 * np.linalg.norm(pce - pc):.1f}),"
        f" target estimate error along LOS {1e3 * (ptl - pt) @ u:+.1f} mm (|e|={1e3 * np.linalg.norm(ptl - pt):.1f}),"
        f" own target estimate err {1e3 * np.linalg.norm(np.array(r['pt_own']) - pt):.1f} mm;"
        f" chaser tracking (est - ref) along LOS {1e3 * (pce - ref) @ u:+.1f} mm; sigma_c {1e3 * r['sig_c']:.1f} mm"
    )
