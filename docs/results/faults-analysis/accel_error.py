"""The chaser's unmodelled acceleration in the closed loop: what the filter's process noise must cover.

usage (from the repository root; ``PYTHONPATH=.`` so that this checkout's ``swarm`` is the one imported):
    PYTHONPATH=. python docs/results/faults-analysis/accel_error.py SCENARIO RUNS [POLICY] [K=V ...]

The truth (swarm/core/dynamics.py) accelerates by ``R(q_true) F_body / m``: the nozzles' wrench ``B f``,
with no noise, quantisation or misalignment (``[dispersions]`` off), no gravity, no drag. The filter
predicts with the same achieved force (``VehicleAgent.f_body``, the allocation's ``B f``, which the world
applies unchanged) turned by its *estimated* attitude and divided by the nominal mass,
``R(q_est) F_body / m`` (``agent_imu``). With the dispersions off the only unmodelled acceleration is
therefore the thrust-direction error of the attitude estimate error ``dtheta`` (body frame):

    a_err = (R(q_true) - R(q_est)) F_body / m  ~=  -R(q_est) [F_body x] dtheta / m.

It is measured exactly, tick by tick (``fast=False``): ``a_err = dv_true / dt - a_filter``, the true
velocity change over the tick against the acceleration the filter's predict used for it, over the ticks
on which the chaser navigates on UWB (not relative to the target), and reduced to:

* ``sigma_a``: RMS per axis [m/s^2];
* ``q_white = sigma_a^2 dt``: the PSD if ``a_err`` were independent from tick to tick;
* ``q_diffusion_T``: the diffusion rate of its integral, ``E[(int_0^T a_err dt)^2] / T`` per axis over
  non-overlapping windows of ``T`` s. A white acceleration of PSD ``q`` (the filter's model, Bar-Shalom,
  Li & Kirubarajan 2001 sec. 6.2) gives ``E[dv^2] = q T`` for every ``T``; for a correlated one this
  is ``int R_a(tau) dtau = S_a(0)`` once ``T`` exceeds the correlation time, the value the filter's
  ``q`` must match. Reported over whole runs and without the first 5 s (the initial 2 deg attitude
  error while the controller accelerates dominates the whole-run value).
"""

from __future__ import annotations

import json
import sys

import numpy as np

from swarm.core import rotations as rot
from swarm.scenario import load_scenario
from swarm.sim.docking import DockingSim

WINDOWS_S = (2.0, 5.0, 10.0, 20.0)
SKIP_S = 5.0


def one_run(sc, policy: str, seed: int) -> np.ndarray:
    """``a_err`` (ticks, 3) [m/s^2] of the chaser of one run, on the ticks it navigates on UWB."""
    sim = DockingSim(sc, policy, seed, record_series=False, fast=False)
    cid = sc.chasers[0]
    agent, world = sim.agents[cid], sim.world
    step = world.step
    rec = []

    def logged_step(**kw):
        v0 = world.x[cid][3:6].copy()
        a_filter = rot.quat_rotate(agent.est.q_ms_body[0], agent.f_body) / agent.mass_kg
        uwb_nav = not agent.relative_nav and cid not in sim.done
        out = step(**kw)
        if uwb_nav:
            rec.append((world.x[cid][3:6] - v0) / sc.dt_s - a_filter)
        return out

    world.step = logged_step
    sim.run()
    return np.asarray(rec).reshape(-1, 3)


def diffusion(a: np.ndarray, dt: float, window_s: float) -> float:
    """``E[(int a dt)^2] / T`` over non-overlapping windows of ``window_s`` = T, averaged over the axes
    [m^2/s^3]; nan when the record is shorter than one window."""
    n = round(window_s / dt)
    k = a.shape[0] // n
    if k < 1:
        return float("nan")
    integ = a[: k * n].reshape(k, n, 3).sum(axis=1) * dt
    return float(np.mean(integ**2) / window_s)


def reduce(recs: list[np.ndarray], dt: float) -> dict:
    a = np.concatenate(recs)
    sigma_a = float(np.sqrt(np.mean(a**2)))
    out = {"ticks": int(a.shape[0]), "sigma_a_m_s2": sigma_a, "q_white_m2_s3": sigma_a**2 * dt}
    for w in WINDOWS_S:
        out[f"q_diffusion_{w:g}s_m2_s3"] = float(np.nanmean([diffusion(r, dt, w) for r in recs]))
    return out


def main(argv) -> None:
    from swarm.config import parse_override

    scen, runs = argv[0], int(argv[1])
    rest = argv[2:]
    policy = rest.pop(0) if rest and "=" not in rest[0] else "fixed"
    sc = load_scenario(scen, dict(parse_override(a) for a in rest))
    recs = [one_run(sc, policy, 1000 + i) for i in range(runs)]
    skip = round(SKIP_S / sc.dt_s)
    out = {
        "scenario": scen,
        "policy": policy,
        "runs": runs,
        "overrides": rest,
        "whole_run": reduce(recs, sc.dt_s),
        f"after_{SKIP_S:g}s": reduce([r[skip:] for r in recs], sc.dt_s),
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
