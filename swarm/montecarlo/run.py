"""One run of a campaign as one ``runs.csv`` row per chaser (:data:`FIELDS`) plus its trajectory.

:func:`run_one` is the task a campaign submits to its executor (a picklable top-level function): it runs
:class:`swarm.sim.docking.DockingSim` with the run's seed and reduces the summary to flat columns: the
swarm/step/outcome.py outcome, the entry time and range of each guidance mode, the distance flown in each,
Algorithm 1's record summarised, the initial truth and estimate error, and the drawn dispersions.
"""

from __future__ import annotations

import time

import numpy as np

from swarm.errors import ConfigError

MAIN_MODES = ("APPROACH", "REORIENT", "ALIGN", "DOCK")

# Columns of runs.csv and how each is read back. "float?" may be empty (None: e.g. no docking time when
# the run did not dock).
FIELDS: dict[str, str] = {
    "run": "int",
    "policy": "str",
    "chaser": "str",
    "seed": "int",
    "docked": "bool",
    "collided": "bool",
    "keepout_violated": "bool",
    "closest_approach_m": "float?",
    "final_mode": "str",
    "docking_time_s": "float?",
    "total_impulse_ns": "float",
    "position_error_m": "float?",
    "attitude_error_rad": "float?",
    "r2_m": "float",
    "r1_m": "float",
    "contact_lateral_m": "float?",
    "contact_attitude_rad": "float?",
    "contact_closing_m_s": "float?",
    "target_impulse_ns": "float",
    "t_approach_s": "float?",
    "t_reorient_s": "float?",
    "range_reorient_m": "float?",
    "t_align_s": "float?",
    "range_align_m": "float?",
    "align_by": "str",
    "t_dock_s": "float?",
    "range_dock_m": "float?",
    "path_approach_m": "float?",
    "path_reorient_m": "float?",
    "path_align_m": "float?",
    "path_dock_m": "float?",
    "n_hold": "int",
    "n_abort": "int",
    "n_decisions": "int",
    "r1_fired": "bool",
    "a11_at_r2": "float?",
    "min_pi2": "float?",
    "max_a32": "float?",
    "sigma_pos_reorient_m": "float?",
    "d_reorient": "float?",
    "p0_x_m": "float",
    "p0_y_m": "float",
    "p0_z_m": "float",
    "est0_err_x_m": "float",
    "est0_err_y_m": "float",
    "est0_err_z_m": "float",
    "est0_att_err_rad": "float",
    "disp_pos_x": "float",
    "disp_pos_y": "float",
    "disp_pos_z": "float",
    "disp_vel_x": "float",
    "disp_vel_y": "float",
    "disp_vel_z": "float",
    "disp_att_x": "float",
    "disp_att_y": "float",
    "disp_att_z": "float",
    "disp_mass_factor": "float",
    "disp_inertia_factor_x": "float",
    "disp_inertia_factor_y": "float",
    "disp_inertia_factor_z": "float",
    "disp_thruster_rms_rad": "float",
    "rejected_ranges": "int",
    "accepted_vision": "int",
    "sim_time_s": "float",
    "wall_s": "float",
}
"""``runs.csv`` columns (the names of swarm/step/outcome.py's summary where it has them) and their types."""
TDOA_FIELDS: dict[str, str] = {"tdoa_accepted": "int", "tdoa_rejected": "int"}
"""The columns a campaign on a TDoA radio (``uwb.mode`` tdoa2/tdoa3) adds after ``accepted_vision``: the
chaser's distance differences its filter accepted and rejected over the run (a difference is counted as a
range, :func:`swarm.step.agent.agent_tdoa`; ``rejected_ranges`` then counts the same rejections). Only
then, so that a two-way-ranging campaign's ``runs.csv`` is the same as before, byte for byte."""


def fields_for(scenario) -> dict[str, str]:
    """The ``runs.csv`` columns of a campaign of ``scenario``: :data:`FIELDS` with its chasers' kind's
    effort (``total_impulse_ns`` and ``target_impulse_ns`` for a cube, as before kinds) and own dispersions
    (``disp_thruster_rms_rad`` for a cube), and on a TDoA radio :data:`TDOA_FIELDS`. A campaign's chasers
    are of one kind."""
    kinds = {scenario.kind(c) for c in scenario.chasers}
    if len({k.name for k in kinds}) != 1:
        raise ConfigError(f"a campaign needs chasers of one kind, got {sorted(k.name for k in kinds)}")
    kind = kinds.pop()
    tdoa = scenario.uwb.mode != "twr"
    out = {}
    for name, typ in FIELDS.items():
        if name == "total_impulse_ns":
            out[kind.effort_key] = typ
        elif name == "target_impulse_ns":
            out[kind.target_effort_key] = typ
        elif name == "disp_thruster_rms_rad":
            out.update(dict.fromkeys(kind.dispersion_columns({}), "float"))
        else:
            out[name] = typ
        if name == "accepted_vision" and tdoa:
            out.update(TDOA_FIELDS)
    return out


def run_one(scenario, policy: str, run: int, seed: int, trajectory_period_s: float = 1.0):
    """Run ``run`` of ``policy`` with ``seed``: ``(rows, trajectories)``, one CSV row (:data:`FIELDS`) and
    one decimated trajectory (``{"run", "policy", "chaser", "t_s", "p_nav"}``, every
    ``trajectory_period_s``, positions rounded to 0.1 mm) per chaser. Runs in a worker process."""
    from swarm.core import rotations as rot
    from swarm.kinds.dispersions import dispersion_columns
    from swarm.sim.docking import DockingSim

    # the rows and the trajectory need the truth's path only; the faults' NEES samples need the rest
    keys = None if scenario.faults.enabled else ("t_s", "p_true_nav")
    sim = DockingSim(scenario, policy, seed, record_series=True, series_keys=keys)
    start = {}
    for cid in scenario.chasers:
        x, est = sim.world.x[cid], sim.agents[cid].est
        start[cid] = (
            x[0:3].copy(),
            est.p_nav[0] - x[0:3],
            float(np.linalg.norm(rot.attitude_error(x[6:10], est.q_nav_body[0]))),
        )
    t0 = time.perf_counter()
    res = sim.run()
    wall = time.perf_counter() - t0
    period = scenario.sim.series_every * scenario.dt_s
    every = max(1, round(trajectory_period_s / period))
    rows, trajs = [], []
    for cid, c in res["chasers"].items():
        kind = scenario.kind(cid)
        p0, err0, att0 = start[cid]
        row = {
            "run": int(run),
            "policy": policy,
            "chaser": cid,
            "seed": int(seed),
            "docked": bool(c["docked"]),
            "collided": bool(c["collided"]),
            "keepout_violated": bool(c["keepout_violated"]),
            "closest_approach_m": c["closest_approach_m"],
            "final_mode": c["final_mode"],
            "docking_time_s": c["docking_time_s"],
            kind.effort_key: c["effort"],
            "position_error_m": c["position_error_m"],
            "attitude_error_rad": c["attitude_error_rad"],
            "r2_m": c["r2_m"],
            "r1_m": c["r1_m"],
            "contact_lateral_m": (c["contact"] or {}).get("lateral_m"),
            "contact_attitude_rad": (c["contact"] or {}).get("attitude_rad"),
            "contact_closing_m_s": (c["contact"] or {}).get("closing_m_s"),
            kind.target_effort_key: res["target_effort"].get(scenario.vehicles[cid].target, 0.0),
            **_mode_columns(c["modes"]),
            **_path_columns(c["series"], c["modes"], c["docking_time_s"]),
            **_decision_columns(c.get("decisions") or [], scenario.mdp),
            "p0_x_m": float(p0[0]),
            "p0_y_m": float(p0[1]),
            "p0_z_m": float(p0[2]),
            "est0_err_x_m": float(err0[0]),
            "est0_err_y_m": float(err0[1]),
            "est0_err_z_m": float(err0[2]),
            "est0_att_err_rad": att0,
            **dispersion_columns(scenario, sim.dispersion, cid),
            "rejected_ranges": c["estimator"]["rejected_ranges"],
            "accepted_vision": c["estimator"]["accepted_vision"],
            "sim_time_s": res["sim_time_s"],
            "wall_s": wall,
        }
        if scenario.uwb.mode != "twr":  # (TDOA_FIELDS)
            row["tdoa_accepted"] = c["estimator"]["accepted_ranges"]
            row["tdoa_rejected"] = c["estimator"]["rejected_ranges"]
        rows.append(row)
        s = c["series"]
        idx = list(range(0, len(s["t_s"]), every))
        if s["t_s"] and idx[-1] != len(s["t_s"]) - 1:
            idx.append(len(s["t_s"]) - 1)  # keep the last sample: the docked position
        traj = {
            "run": int(run),
            "policy": policy,
            "chaser": cid,
            "t_s": [round(s["t_s"][i], 3) for i in idx],
            "p_nav": [[round(v, 4) for v in s["p_true_nav"][i]] for i in idx],
        }
        if "faults" in c:  # [faults] on: the NEES at the saved samples and the windows (montecarlo.faults)
            from swarm.montecarlo.faults import nees_samples

            traj["nees_pos"], traj["nees_used"] = nees_samples(s, idx, c["faults"]["uwb_dropout_s"])
            traj["faults"] = {k: c["faults"][k] for k in ("uwb_dropout_s", "camera_loss_s", "nlos_burst_s")}
        trajs.append(traj)
    return rows, trajs


def _mode_columns(modes: list[dict]) -> dict:
    """First entry time (and range) of each main mode, how ALIGN came about, HOLD and ABORT counts."""
    first: dict[str, dict] = {}
    for m in modes:
        first.setdefault(m["mode"], m)
    out: dict = {}
    for mode in MAIN_MODES:
        m = first.get(mode)
        out[f"t_{mode.lower()}_s"] = m["t_s"] if m else None
        if mode != "APPROACH":
            out[f"range_{mode.lower()}_m"] = m["range_m"] if m else None
    align, dock = first.get("ALIGN"), first.get("DOCK")
    if align is not None:
        out["align_by"] = "stall" if "keep-out boundary" in align["reason"] else "radius"
    elif dock is not None and "ALIGN skipped" in dock["reason"]:
        out["align_by"] = "skipped"
    else:
        out["align_by"] = "none"
    out["n_hold"] = sum(1 for m in modes if m["mode"] == "HOLD")
    out["n_abort"] = sum(1 for m in modes if m["mode"] == "ABORT")
    return out


def _path_columns(series: dict, modes: list[dict], t_end: float | None) -> dict:
    """Distance flown (truth) in each main mode [m], from the recorded series."""
    t = np.asarray(series["t_s"])
    p = np.asarray(series["p_true_nav"]).reshape(-1, 3)
    step = np.r_[0.0, np.linalg.norm(np.diff(p, axis=0), axis=1)]  # step ending at sample k
    entry = {}
    for m in modes:
        entry.setdefault(m["mode"], m["t_s"])
    out = {}
    ends = [entry.get(m) for m in MAIN_MODES[1:]] + [t_end]
    for mode, end in zip(MAIN_MODES, ends, strict=True):
        start = entry.get(mode)
        if start is None:
            out[f"path_{mode.lower()}_m"] = None
            continue
        if end is None:  # a mode never left, or skipped: up to the next mode that was entered, or the end
            later = [entry[m] for m in MAIN_MODES if m in entry and entry[m] > start]
            end = min(later) if later else (t_end if t_end is not None else float(t[-1]) if t.size else start)
        sel = (t > start) & (t <= end)
        out[f"path_{mode.lower()}_m"] = float(step[sel].sum())
    return out


def _decision_columns(decisions: list[dict], mdp) -> dict:
    """Algorithm 1's record summarised: what chose r2, how close pi2 came to its threshold, and the
    inputs of the REORIENT-branch rule (sigma_pos, d) that decide it."""
    a11_at_r2 = None
    for d in decisions:
        if d["A11"] is not None and d["A11"] <= mdp.a11_threshold:
            a11_at_r2 = d["A11"]  # the last one that set r2 (r2 only grows within r_t)
    reo = [d for d in decisions if d["A22"] is not None]
    pis = [d["pi2"] for d in reo if d["pi2"] is not None]
    return {
        "n_decisions": len(decisions),
        "r1_fired": any(p <= mdp.pi2_threshold for p in pis),
        "a11_at_r2": a11_at_r2,
        "min_pi2": min(pis) if pis else None,
        "max_a32": max(d["A32"] for d in reo) if reo else None,
        "sigma_pos_reorient_m": float(np.mean([d["sigma_pos_max_m"] for d in reo])) if reo else None,
        "d_reorient": float(np.mean([d["d"] for d in reo])) if reo else None,
    }
