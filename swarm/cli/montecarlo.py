"""``swarm montecarlo SCENARIO``: paired Monte Carlo campaign of several policies (paper Table II, Figs. 5-6).

Runs ``--runs`` paired runs of each ``--policy`` on ``--workers`` processes, or on an existing
dask.distributed cluster with ``--dask tcp://HOST:8786``, saves them run by run in ``--out DIR`` (Ctrl-C
keeps the finished runs, ``--resume DIR`` continues), then writes ``DIR/report.md`` with the statistics and
figures; ``--json FILE`` gets the swarm/step/outcome.py record. The library entry point, which takes any
``concurrent.futures`` executor, is :func:`swarm.montecarlo.campaign.run_campaign`.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

from swarm.args import add_output_file, add_scenario_args, seed
from swarm.errors import ConfigError

log = logging.getLogger(__name__)


def _int(flag: str):
    def parse(text: str) -> int:
        try:
            return int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} must be an integer, got {text!r}") from None

    return parse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "montecarlo",
        help="paired Monte Carlo campaign of switching policies (paper Table II, Figs. 5-6)",
        description=__doc__.split("\n\n")[1],
    )
    add_scenario_args(p)
    p.add_argument("--runs", type=_int("--runs"), default=None, help="paired runs per policy (default 500)")
    p.add_argument(
        "--policy",
        dest="policies",
        action="append",
        default=None,
        metavar="POLICY",
        help="fixed or mdp; repeat to compare (default: both); the first is the baseline",
    )
    p.add_argument("--workers", type=_int("--workers"), default=None, help="processes (default: the cores)")
    p.add_argument(
        "--dask",
        default=None,
        metavar="ADDRESS",
        help="run on the dask.distributed scheduler at ADDRESS (tcp://HOST:PORT; extra 'dask'), not locally",
    )
    p.add_argument(
        "--dask-timeout",
        type=float,
        default=10.0,
        metavar="S",
        help="seconds to wait for the dask scheduler to answer (default 10)",
    )
    p.add_argument("--seed", type=seed, default=None, help="root seed (default 0)")
    p.add_argument(
        "--out", type=Path, default=None, metavar="DIR", help="campaign directory (default mc-SCENARIO-seedS)"
    )
    p.add_argument("--resume", type=Path, default=None, metavar="DIR", help="continue the campaign in DIR")
    add_output_file(p, "--json", "write the statistics as JSON")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-figures", action="store_true", help="report.md without the PNG figures (faster)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """``swarm montecarlo SCENARIO``: the paired campaign of the scenario's mission, its campaign part
    (:meth:`swarm.missions.Mission.campaign`) handed to the one runner: the same flags, directory, resume
    and ``--dask`` for every mission; the mission's report and summary."""
    from swarm.missions import mission_of, overrides_of
    from swarm.montecarlo.campaign import CampaignSpec, read_manifest, run_campaign
    from swarm.montecarlo.report import finite_or_null

    plan = mission_of(args.scenario).campaign()
    sc = plan.entry("load")(args.scenario, overrides_of(args))
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers must be a positive integer, got {args.workers}")
    if args.resume is not None:
        if args.out is not None and args.out.resolve() != args.resume.resolve():
            raise ConfigError(
                f"--out {str(args.out)!r} and --resume {str(args.resume)!r} name different directories"
            )
        man = read_manifest(args.resume)
        runs = args.runs if args.runs is not None else int(man["runs"])
        seed = args.seed if args.seed is not None else int(man["root_seed"])
        policies = tuple(args.policies) if args.policies else tuple(man["policies"])
        out = args.resume
    else:
        runs = 500 if args.runs is None else args.runs
        seed = 0 if args.seed is None else args.seed
        policies = tuple(args.policies) if args.policies else ("fixed", "mdp")
        out = args.out if args.out is not None else Path(f"mc-{sc.name}-seed{seed}")
    spec = CampaignSpec(sc, policies, runs, seed, plan)
    if args.dask is not None:
        if args.workers is not None:
            raise ConfigError("--workers and --dask: choose one (the cluster has its own workers)")
        from swarm.montecarlo.cluster import dask_executor

        if not (0.1 <= args.dask_timeout <= 600.0):
            raise ConfigError(
                f"--dask-timeout must be a number of seconds in 0.1..600, got {args.dask_timeout}"
            )
        with dask_executor(args.dask, timeout_s=args.dask_timeout) as executor:
            outcome = run_campaign(
                spec, out, executor=executor, resume=args.resume is not None, progress=not args.no_progress
            )
    else:
        outcome = run_campaign(
            spec, out, workers=args.workers, resume=args.resume is not None, progress=not args.no_progress
        )
    for failure in outcome.failures:
        log.error("%s", failure)
    if outcome.interrupted:
        print(
            f"interrupted: {outcome.done} of {outcome.total} runs kept in {out}; continue with "
            f"swarm montecarlo {args.scenario} --resume {out}"
        )
        return 130
    rec = plan.entry("report")(out, figures=not args.no_figures)
    print(plan.entry("summary")(rec))
    print(f"report: {out / 'report.md'}")
    if args.json is not None:
        try:
            args.json.write_text(json.dumps(finite_or_null(rec), indent=1) + "\n")
        except OSError as exc:
            raise ConfigError(f"--json: cannot write {str(args.json)!r}: {exc.strerror or exc}") from None
        print(f"statistics written to {args.json}")
    return 0 if not outcome.failures else 1
