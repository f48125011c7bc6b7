"""The chaser's unmodelled acceleration in the closed loop: what the filter's process noise must cover.

usage (from the repository root):
    PYTHONPATH=. python docs/results/faults-analysis/accel_error.py SCENARIO RUNS [POLICY] [--set K=V ...]

The truth (swarm/core/dynamics.py) accelerates by ``R(q_true) F_body / m``: the nozzles' wrench, with no
noise, quantisation or misalignment (``[dispersions]`` off), no gravity, no drag. The filter predicts with
the same achieved force (``VehicleAgent.f_body``, the allocation's ``B f``, which the world applies
unchanged) turned by its *estimated* attitude: ``R(q_est) F_body / m`` (``agent_imu``). The only
unmodelled acceleration is therefore

    a_err = (R(q_true) - R(q_est)) F_body / m  ~=  R(q_true) [dtheta x]^T F_body / m,

the thrust-direction error of the attitude error. It is sampled at every control tick (10 Hz; the force
is held for the control period and the attitude error varies over seconds), and reduced to:

* sigma_a: RMS per axis [m/s^2];
* q_white = sigma_a^2 dt_ctrl: the PSD if the samples were independent from one control period to the
  next (Bar-Shalom, Li & Kirubarajan 2001 sec. 6.2: a piecewise-constant white acceleration);
* q_diff: the diffusion rate of its integral, var(int_0^T a_err dt) / T for T = 2-20 s windows, per axis,
  i.e. the low-frequency PSD S_a(0) = int R_a(tau) dtau that a white-noise acceleration model with
  PSD q must match (BLK 2001 sec. 6.2.2; the velocity error of a white acceleration grows as q T);
* the same split by guidance mode.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from swarm.core import rotations as rot
from swarm.scenario import load_scenario
from swarm.sim.docking import DockingSim


def one_run(sc, policy: str, seed: int) -> dict:
    sim = DockingSim(sc, policy, seed, record_series=False)
    cid = sc.chasers[0]
    agent = sim.agents[cid]
    every = sc.every(sc.translation_control.rate_hz)
    rec = {"t": [], "a_err": [], "a_cmd": [], "mode": [], "dth": [], "rel": []}
    orig = sim._check_truth

    def check(k, t):
        if k % every == 0 and cid not in sim.done:
            x = sim.world.x[cid]
            f = agent.f_body.copy()
            m = agent.mass_kg
            a_true = rot.quat_rotate(x[6:10], f) / m
            a_filt = rot.quat_rotate(agent.est.q_ms_body[0], f) / m
            rec["t"].append(t)
            rec["a_err"].append((a_true - a_filt).tolist())
            rec["a_cmd"].append(a_true.tolist())
            rec["mode"].append(agent.mode.value)
            rec["dth"].append(float(np.linalg.norm(rot.attitude_error(x[6:10], agent.est.q_ms_body[0]))))
            rec["rel"].append(bool(agent.relative_nav))
        return orig(k, t)

    sim._check_truth = check
    sim.run()
    return rec


WINDOWS_S = (2.0, 5.0, 10.0, 20.0)


def diffusion(a: np.ndarray, dt: float, window_s: float = 10.0) -> float:
    """var(int a dt) / T over non-overlapping windows of ``window_s`` (per axis, then averaged) [m^2/s^3]."""
    n = round(window_s / dt)
    k = a.shape[0] // n
    if k < 1:
        return float("nan")
    integ = a[: k * n].reshape(k, n, 3).sum(axis=1) * dt
    return float(np.mean(integ**2) / window_s)  # mean square: a_err has no reason to be biased


def main(argv) -> None:
    from swarm.config import parse_override

    scen, runs = argv[0], int(argv[1])
    rest = argv[2:]
    policy = rest.pop(0) if rest and not rest[0].startswith("--") else "fixed"
    sets = [a for a in rest if a != "--set"]
    sc = load_scenario(scen, dict(parse_override(a) for a in sets))
    dt = 1.0 / sc.translation_control.rate_hz
    recs = [one_run(sc, policy, 1000 + i) for i in range(runs)]
    out = {}
    for label, sel in (("all (UWB nav)", None), *((m, m) for m in ("APPROACH", "REORIENT", "ALIGN"))):
        a_all, a_cmd, dth, diff = [], [], [], []
        for r in recs:
            a = np.asarray(r["a_err"])
            keep = ~np.asarray(r["rel"])
            if sel is not None:
                keep &= np.asarray(r["mode"]) == sel
            a_all.append(a[keep])
            a_cmd.append(np.asarray(r["a_cmd"])[keep])
            dth.append(np.asarray(r["dth"])[keep])
            if sel is None:
                diff.append([diffusion(a[keep], dt, w) for w in WINDOWS_S])
        A = np.concatenate(a_all)
        sigma_a = float(np.sqrt(np.mean(A**2)))
        out[label] = {
            "samples": int(A.shape[0]),
            "rms_a_cmd_m_s2": float(np.sqrt(np.mean(np.concatenate(a_cmd) ** 2))),
            "rms_dtheta_deg": float(np.degrees(np.sqrt(np.mean(np.concatenate(dth) ** 2)))),
            "sigma_a_m_s2": sigma_a,
            "q_white_m2_s3": sigma_a**2 * dt,
            **(
                {
                    f"q_diffusion_{w:g}s_m2_s3": float(np.nanmean(np.asarray(diff)[:, i]))
                    for i, w in enumerate(WINDOWS_S)
                }
                if diff
                else {}
            ),
        }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
