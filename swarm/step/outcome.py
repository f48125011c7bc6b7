"""A run's outcome as every runner reports it (swarm/step/outcome.py): ``swarm sim`` builds it from the
objects it stepped, ``swarm launch`` from what the world's and the agents' events said; both through
:func:`chaser_summary` and :func:`run_summary`, so the two report the same fields with the same meaning.

Effort is the vehicle kind's own measure (:attr:`swarm.kinds.base.VehicleKind.effort_key`): the total
impulse [N s] of a cube's nozzles (the paper's Table II), the wheel travel [rad] of a wheeled module.
Each chaser's entry carries it under the kind's key (``total_impulse_ns`` for a cube, as before) and as
``effort`` with its ``effort_key`` and ``effort_unit``.
"""

from __future__ import annotations


def chaser_summary(sc, chaser: str, *, effort: float | None, **fields) -> dict:
    """One chaser's entry: ``fields`` (``docked``, ``collided``, ``docking_time_s``, ``position_error_m``,
    ``attitude_error_rad``, ``final_mode``, ``modes``, ``r1_m``, ``r2_m``, ``keepout_violated``,
    ``closest_approach_m``, ``contact``, ``estimator``, ...) in that order, with its kind and effort."""
    kind = sc.kind(chaser)
    d = {"kind": kind.name}
    for name in ("docked", "collided", "docking_time_s"):
        d[name] = fields.pop(name)
    d[kind.effort_key] = effort
    d.update(fields)
    d["effort"] = effort
    d["effort_key"] = kind.effort_key
    d["effort_unit"] = kind.effort_unit
    return d


def run_summary(sc, policy: str, seed: int, t_end: float | None, wall_s: float | None, effort: dict,
                chasers: dict, **extra) -> dict:  # fmt: skip
    """The run's summary: scenario, policy, seed, times, each non-chaser's effort (``target_effort``;
    ``target_impulse_ns`` for the cubes among them, as before) and the chasers' entries."""
    targets = {v: e for v, e in effort.items() if v not in chasers}
    wall = wall_s if wall_s is not None else None
    return {
        "scenario": sc.name, "policy": policy, "seed": seed, "sim_time_s": t_end, "wall_s": wall,
        "realtime_factor": t_end / wall if (t_end is not None and wall) else None, **extra,
        "target_effort": targets,
        "target_impulse_ns": {
            v: e for v, e in targets.items() if sc.kind(v).effort_key == "total_impulse_ns"
        },
        "chasers": chasers,
    }  # fmt: skip
