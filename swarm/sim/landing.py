"""UAV precision landing in-process (paper section VI-B; ``swarm sim landing``, ``swarm sim landing-swarm``).

Quadrotors (:mod:`swarm.kinds.quadrotor`) start far from their pads and fly the landing guidance of
:mod:`swarm.core.landing` on their own estimates: the IMU-driven error-state filter
(:mod:`swarm.core.imu_filter`) propagated by a 6-axis IMU (biases, noise), corrected by GNSS, by UWB ranges to
the anchors around the pads when in reach, and by the pad's pose from the downward camera
(:mod:`swarm.core.pad_vision`: the rendered image and ArUco detection, or the corner-projection mode)
whenever the pad is in view. Each tick is the landing tick of :mod:`swarm.step.landing` (world step, agent
step, hold), the same that the landing world and agent processes run. The scenario is its own TOML file
(``swarm/scenarios/landing.toml``, :class:`swarm.landing_scenario.LandingScenario`).
"""

from __future__ import annotations

import time

from swarm.landing_scenario import (  # noqa: F401  (the scenario's names, where the runner's users look)
    SCENARIO_DIR,
    FleetUav,
    LandingScenario,
    is_landing_scenario,
    load_landing,
)
from swarm.step.landing import LandingAgent, LandingWorld, landing_summary


def run_landing(
    sc: LandingScenario, policy: str | None = None, seed: int = 0, record_series: bool = True
) -> dict:
    """Fly one landing (the scenario's first UAV); the summary of ``swarm sim landing --json``."""
    return run_landing_fleet(sc, policy, seed, record_series, only_first=True)


def run_landing_fleet(
    sc: LandingScenario,
    policy: str | None = None,
    seed: int = 0,
    record_series: bool = True,
    only_first: bool = False,
    tap=None,
) -> dict:
    """Fly every UAV of the scenario (module docstring): ``{"uavs": {id: summary}, ...}``, or the first
    UAV's summary alone with ``only_first``. ``tap`` (``swarm sim --mcap``) sees the run as the processes
    would publish it: ``tap.start(world, policy)``, then per tick ``tap.world(k, world, inputs)`` and
    ``tap.agent(uid, agent, command)`` for each UAV, and ``tap.end(world, agents, k, wall_s)``."""
    policy = policy or sc.policy
    world = LandingWorld(sc, seed)
    uavs = sc.uavs()[:1] if only_first else sc.uavs()
    if only_first:
        for extra in sc.uavs()[1:]:
            world.uavs[extra.id].done = True
    agents = {u.id: LandingAgent(sc, seed, u.index, policy) for u in uavs}
    n_ticks = round(sc.max_duration_s / sc.dt_s)
    if tap is not None:
        tap.start(world, policy)
    t0_wall = time.perf_counter()
    k = 0
    for k in range(1, n_ticks + 1):
        inputs = world.step(k)
        if not inputs:
            k -= 1
            break
        if tap is not None:
            tap.world(k, world, inputs)
        for uid, inp in inputs.items():
            cmd = agents[uid].tick(inp, world.uavs[uid].x[0:3] if record_series else None)
            if tap is not None:
                tap.agent(uid, agents[uid], cmd)
            world.hold(uid, cmd)
    wall = time.perf_counter() - t0_wall
    for uid in agents:
        if not world.uavs[uid].done:
            world.uavs[uid].end_k = k
    if tap is not None:
        tap.end(world, agents, k, wall)
    out = {u.id: summary(sc, policy, seed, world, agents[u.id], u.id, wall, record_series) for u in uavs}
    if only_first:
        return out[uavs[0].id]
    return {
        "scenario": sc.name,
        "policy": policy,
        "seed": seed,
        "camera_mode": sc.camera.mode,
        "landed": sum(1 for v in out.values() if v["landed"]),
        "uavs": out,
        "sim_time_s": round(k * sc.dt_s, 4),
        "wall_s": wall,
    }


def summary(sc: LandingScenario, policy: str, seed: int, world: LandingWorld, agent: LandingAgent, uid: str,
            wall: float, record_series: bool = True) -> dict:  # fmt: skip
    """One UAV's summary (``swarm sim landing --json``): the world's half (where it ended) and the agent's."""
    out = landing_summary(sc, policy, seed, world.outcome(uid), agent.outcome(), world.uavs[uid].end_k, wall)
    if record_series:
        out["series"] = dict(agent.series.__dict__)
    return out
