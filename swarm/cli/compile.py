"""``swarm compile [--jobs N]``: compile every numba kernel into the cache before the first run, in parallel.

The kernels (the tick, the filters, the landing, the IMU filter) are compiled by numba on their first call
and kept in its cache, one per checkout (``swarm/__init__.py``). On a fresh checkout that first call costs
minutes on one core: ~2 min for the docking tick and everything it calls, ~1 min for the landing's, tens of
seconds for the rest. Without this command the first ``swarm sim``, test or launched process pays it, and a
launch's processes compile the same kernels side by side. ``swarm compile`` runs the same code paths on
scratch objects, the independent chains in ``--jobs`` processes at once (longest first), so the cache is
full when the work starts; with a full cache it only loads it (a few seconds). ``make test`` and
``make demo`` run it first. A chain that fails is named on stderr, the others still compile, and the exit
status is 1.

Each chain runs the entry points a run calls, with the argument types a run passes (numba caches one
machine code per type signature): the in-process run, then the processes' per-tick paths.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

from swarm.missions import MISSIONS, resolve


def docking_kernels() -> None:
    """The docking tick compiled whole (``swarm sim``, campaigns), then the world and agent processes'."""
    from agents.process import warm_up as warm_agent
    from swarm.scenario import load_scenario
    from swarm.sim.docking import run_docking
    from swarm.world.process import warm_up as warm_world

    sc = load_scenario("docking", {"sim.max_duration_s": 1.0})
    run_docking(sc, sc.policy, 0, record_series=True)
    warm_world(sc, 0)
    for vid in sc.vehicles:
        warm_agent(sc, 0, vid, sc.policy)


def landing_kernels() -> None:
    """The landing compiled whole (``swarm sim landing``), then the landing agent process's tick."""
    from agents.landing import warm_up
    from swarm.sim.landing import load_landing, run_landing

    sc = load_landing("landing")
    run_landing(sc, sc.policy, 0)
    warm_up(sc, 0, 0, sc.policy)


def _filters() -> None:
    """The batched pose estimator (``PoseEstimator``: every measurement kind) and the IMU-driven filter over
    a short synthetic log (``swarm replay``, ``swarm navigate``)."""
    import numpy as np

    from swarm.core.estimator import EstimatorParams, PoseEstimator
    from swarm.logs.reader import read_log
    from swarm.logs.replay import replay_log
    from swarm.logs.synthetic import SyntheticSpec, make_log

    q = np.array([1.0, 0.0, 0.0, 0.0])
    est = PoseEstimator.create(EstimatorParams(), np.zeros((2, 3)), np.zeros(3), q, np.full(9, 1e-2))
    est.predict(np.zeros(3), np.zeros(3), 0.01)
    est.update_range(np.array([1.0, 0.0, 0.0]), np.ones(2))
    est.update_features(np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 1.0]]), np.ones((2, 2, 3)))
    est.update_pose(np.array([0.0, 0.0, 1.0]), q, np.array([0.0, 0.0, 1.0]), q, np.eye(6) * 1e-4)
    est.update_attitude(q, np.eye(3) * 1e-4)
    _ = est.sigma_pos_max_m
    with tempfile.TemporaryDirectory(prefix="swarm-compile-") as d:
        make_log(d, 0, SyntheticSpec(duration_s=12.0, imu_gap_at_s=10.0))
        replay_log(read_log(d))


CHAINS: dict[str, tuple[Callable[[], None], str]] = {
    **{m.name: (resolve(m.compile_entry), m.name) for m in MISSIONS.values() if m.compile_entry},
    "filters": (_filters, "the batched estimator and the IMU-driven filter (~20 s cold)"),
}
"""The chains, longest first: each registered mission's (:attr:`swarm.missions.Mission.compile_entry`:
docking ~2 min on one core cold, landing ~1 min), then the filters. Chains share only small helpers, so
they compile in parallel; within a chain the order matters (the processes' paths reuse what the in-process
run compiled)."""


def _run_chain(name: str) -> float:
    t0 = time.perf_counter()
    CHAINS[name][0]()
    return time.perf_counter() - t0


def add_parser(sub: argparse._SubParsersAction) -> None:
    from swarm.args import positive_int

    p = sub.add_parser(
        "compile",
        help="compile the numba kernels into the cache before the first run (parallel)",
        description=__doc__.split("\n\n")[1],
    )
    p.add_argument(
        "--jobs", type=positive_int("--jobs"), default=min(os.cpu_count() or 1, len(CHAINS)),
        help=f"processes compiling at once (default: the cores, at most {len(CHAINS)}: one per chain)",
    )  # fmt: skip
    p.add_argument("--only", type=_chains, default=tuple(CHAINS), metavar="CHAIN,CHAIN",
                   help=f"compile only these chains (of {', '.join(CHAINS)})")  # fmt: skip
    p.set_defaults(func=run)


def _chains(text: str) -> tuple[str, ...]:
    names = tuple(t.strip() for t in text.split(",") if t.strip())
    bad = [n for n in names if n not in CHAINS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"--only: chains are {', '.join(CHAINS)}; got {text!r}")
    return names


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    names = [n for n in CHAINS if n in args.only]
    print(f"compiling {len(names)} kernel chains into {os.environ.get('NUMBA_CACHE_DIR')} "
          f"({min(args.jobs, len(names))} at once)", flush=True)  # fmt: skip
    failed = []

    def report(name: str, result: Callable[[], float]) -> None:
        try:
            print(f"  {name}: {result():.1f} s", flush=True)
        except Exception as exc:  # one chain's failure (a bug, a killed worker) leaves the others' caches
            failed.append(name)
            print(f"swarm compile: chain {name!r} failed: {type(exc).__name__}: {exc}", file=sys.stderr,
                  flush=True)  # fmt: skip

    if args.jobs == 1:
        for n in names:
            report(n, lambda n=n: _run_chain(n))
    else:
        ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: nothing inherited half-compiled
        with ProcessPoolExecutor(max_workers=min(args.jobs, len(names)), mp_context=ctx) as pool:
            pending = {pool.submit(_run_chain, n): n for n in names}
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    report(pending.pop(f), f.result)
    print(f"compiled in {time.perf_counter() - t0:.1f} s"
          + (f"; failed: {', '.join(failed)}" if failed else ""), flush=True)  # fmt: skip
    return 1 if failed else 0
