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

import numpy as np

from swarm.landing_scenario import (  # noqa: F401  (the scenario's names, where the runner's users look)
    SCENARIO_DIR,
    FleetUav,
    LandingScenario,
    load_landing,
)
from swarm.step import landing_nb as lnb
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
    compiled: bool = True,
    faults=(),
) -> dict:
    """Fly every UAV of the scenario (module docstring): ``{"uavs": {id: summary}, ...}``, or the first
    UAV's summary alone with ``only_first``. ``tap`` (``swarm sim --mcap``) sees the run as the processes
    would publish it: ``tap.start(world, policy)``, then per tick ``tap.world(k, world, inputs)`` and
    ``tap.agent(uid, agent, command)`` for each UAV, and ``tap.end(world, agents, k, wall_s)``.

    With the corner-projection camera, two-way ranging and no tap, each UAV flies in compiled code
    (:func:`fly_compiled`); otherwise, or with ``compiled=False``, tick by tick on the objects the processes
    run, with the same result to the bit. A TDoA radio (``uwb.mode`` tdoa2/tdoa3) always runs tick by tick:
    it hands a tag a varying number of differences a tick, from one channel every tag shares, which the
    compiled per-UAV loop does not carry (as the docking simulation's fast path does not). ``faults``:
    ``(kind, start_s, duration_s, uav_ids)`` windows opened on the world before
    the run (:meth:`~swarm.step.landing.LandingWorld.add_fault`), as a run-time ``swarm fault`` does in a
    launched swarm."""
    policy = policy or sc.policy
    world = LandingWorld(sc, seed)
    for kind, start_s, duration_s, uav_ids in faults:
        world.add_fault(kind, start_s, duration_s, uav_ids)
    uavs = sc.uavs()[:1] if only_first else sc.uavs()
    if only_first:
        for extra in sc.uavs()[1:]:
            world.uavs[extra.id].done = True
    agents = {u.id: LandingAgent(sc, seed, u.index, policy) for u in uavs}
    n_ticks = round(sc.max_duration_s / sc.dt_s)
    if tap is not None:
        tap.start(world, policy)
    t0_wall = time.perf_counter()
    if compiled and tap is None and sc.camera.mode == "corners" and sc.uwb.mode == "twr":
        k = max(fly_compiled(world, agents[u.id], u.id, n_ticks, record_series) for u in uavs)
    else:
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


def fly_compiled(
    world: LandingWorld, agent: LandingAgent, uid: str, n_ticks: int, record_series: bool
) -> int:
    """UAV ``uid``'s run, ticks ``1 .. n_ticks``, in compiled code (:func:`swarm.step.landing_nb.
    run_landing_ticks`), back in Python only to refill its draws and to turn its records into the guidance's
    modes and decisions and the agent's series; the tick at which it ended."""
    u = world.uavs[uid]
    wa, aa, ga = world.arrays(u), agent.arrays(), agent.guidance_arrays()
    ctl = (agent.cs, agent.cp, agent.u, agent.act)
    SER, SER_n = np.zeros((256, lnb.SER_N)), np.zeros(1, dtype=np.int64)
    every = lnb.SERIES_EVERY if record_series else 0
    k = 1
    while True:
        world.ensure_draws(u)
        noise = (u.noise.Z, u.noise.pos, world.draws)
        code, k = lnb.run_landing_ticks(k, n_ticks + 1, wa, aa, ga, ctl, *noise, SER, SER_n, every)
        agent.guidance.drain()
        for row in SER[: SER_n[0]]:
            agent.series.add(row)
        SER_n[0] = 0
        if code == lnb.RUN_DONE:
            return k


def summary(sc: LandingScenario, policy: str, seed: int, world: LandingWorld, agent: LandingAgent, uid: str,
            wall: float, record_series: bool = True) -> dict:  # fmt: skip
    """One UAV's summary (``swarm sim landing --json``): the world's half (where it ended) and the agent's."""
    out = landing_summary(sc, policy, seed, world.outcome(uid), agent.outcome(), world.uavs[uid].end_k, wall)
    if record_series:
        out["series"] = dict(agent.series.__dict__)
    return out
