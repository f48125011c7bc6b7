"""Throwaway: re-run one docking-faults run with extra per-tick records (issue-7 analysis).

usage: python docs/results/faults-analysis/trace.py SCENARIO POLICY SEED OUT.json [--set K=V ...]
Records at the series ticks (plus every control tick in ALIGN/DOCK): truth of chaser and target, the
chaser's estimate, the target estimate the chaser uses (latched), the target's own estimate, the
guidance reference, the time since the last accepted vision update, and the true/estimated port geometry.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from swarm.core.guidance import contact_state
from swarm.scenario import load_scenario
from swarm.sim.docking import DockingSim


def main(argv):
    scen, policy, seed, out = argv[0], argv[1], int(argv[2]), argv[3]
    from swarm.config import parse_override

    sc = load_scenario(scen, dict(parse_override(a) for a in argv[4:]))
    sim = DockingSim(sc, policy, seed, record_series=True)
    g = sc.guidance
    cid = sc.chasers[0]
    tid = sc.vehicles[cid].target
    rec = []
    orig_control = sim.agents[cid].control
    last_ref = {}

    def control(t, dt):
        cmd = orig_control(t, dt)
        last_ref["p"] = cmd.reference.p_ms.copy()
        return cmd

    sim.agents[cid].control = control
    orig_check = sim._check_truth

    def check(k, t):
        a = sim.agents[cid]
        ta = sim.agents[tid]
        if (
            cid not in sim.done
            and a.target is not None
            and (a.mode.value in ("REORIENT", "ALIGN", "DOCK") or k % 100 == 0)
        ):
            xc, xt = sim.world.x[cid], sim.world.x[tid]
            ct = contact_state(g, xc[0:3], xc[3:6], xc[6:10], xt[0:3], xt[6:10], xt[3:6])
            ce = contact_state(
                g, a.est.p_ms[0], a.est.v_ms[0], a.est.q_ms_body[0], a.target.p_ms, a.target.q_ms_body
            )
            rec.append(
                {
                    "t": t,
                    "mode": a.mode.value,
                    "vis_age": t - a._last_vision_s,
                    "rel_nav": bool(a.relative_nav),
                    "pc_true": xc[0:3].tolist(),
                    "vc_true": xc[3:6].tolist(),
                    "qc_true": xc[6:10].tolist(),
                    "pt_true": xt[0:3].tolist(),
                    "qt_true": xt[6:10].tolist(),
                    "vt_true": xt[3:6].tolist(),
                    "pc_est": a.est.p_ms[0].tolist(),
                    "qc_est": a.est.q_ms_body[0].tolist(),
                    "pt_latched": a.target.p_ms.tolist(),
                    "qt_latched": a.target.q_ms_body.tolist(),
                    "pt_own": ta.est.p_ms[0].tolist(),
                    "sig_c": float(a.sigma_pos_max_m),
                    "ref": last_ref.get("p", np.full(3, np.nan)).tolist(),
                    "true_geom": ct,
                    "est_geom": ce,
                }
            )
        orig_check(k, t)

    sim._check_truth = check
    res = sim.run()
    c = res["chasers"][cid]
    c.pop("series", None)
    json.dump({"summary": res, "trace": rec}, open(out, "w"), default=float)
    print(
        seed,
        policy,
        "docked" if c["docked"] else ("collided" if c["collided"] else "no contact"),
        "keepout" if c["keepout_violated"] else "",
        c["contact"],
    )


if __name__ == "__main__":
    main(sys.argv[1:])
