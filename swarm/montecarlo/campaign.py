"""Paired Monte Carlo campaigns of any mission's scenario (paper section V-C, Table II; VI-B) on any executor.

The runner is the same for every mission; a mission gives only its :class:`CampaignMission`: how to load
its scenario, how to fly one seeded run of one policy and reduce it to ``runs.csv`` rows, which columns
those rows have, and how to write its report from the directory. The runner takes it as an argument; the
mission registry (:data:`swarm.missions.MISSIONS`, a layer above) gives each mission's.

Design:

* **Paired runs.** Run ``i`` of every policy uses the same seed, :func:`run_seed` ``(root, i)``, an integer
  derived from the root seed with ``SeedSequence.spawn``; every random quantity of a run (initial
  estimate errors, sensor noise, the ``[dispersions]`` of :mod:`swarm.kinds.dispersions`) is drawn
  from that seed inside the mission's simulator, whatever the policy. So the policies see the
  same dispersions run by run and their difference is a paired comparison; and ``swarm sim
  DIR/scenario.toml --policy P --seed S`` re-runs any single run exactly.
* **Any executor.** The runs are tasks of one picklable function, the mission's ``run_one``, submitted to a
  :class:`concurrent.futures.Executor`: a :class:`~concurrent.futures.ProcessPoolExecutor` with
  ``workers`` processes by default, or one the caller brings, e.g. from a ``dask.distributed`` cluster::

      from dask.distributed import Client
      client = Client("tcp://scheduler:8786")
      run_campaign(spec, "mc-out", executor=client.get_executor())

  (the workers need this package installed; an executor passed in is not shut down).
* **Saved run by run.** ``DIR/runs.csv`` gets the rows of each (run, policy) as it finishes (one per
  vehicle that the mission reports), with the trajectories in ``DIR/trajectories.jsonl``;
  ``DIR/campaign.json`` holds the mission, the root seed, the seed rule and the policies (and, once runs
  are done, the wall time and workers of the last session), ``DIR/scenario.toml`` the scenario as run. An
  interrupted or killed campaign keeps every finished run; ``resume=True`` runs only what is missing,
  after checking that the mission, scenario, seed and policies are those of ``DIR``. When every run is
  done, both files are rewritten in run order (policies in their order), so a campaign's files do not
  depend on which run finished first, on how many workers, nor on an interruption.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import importlib
import json
import logging
import math
import os
import pkgutil
import signal
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarm.config import dump_toml, to_mapping
from swarm.errors import ConfigError

log = logging.getLogger(__name__)

POLICIES = ("fixed", "mdp")
SEED_RULE = "seed_i = numpy.random.SeedSequence(root_seed).spawn(runs)[i].generate_state(1)[0]"
"""How run ``i``'s seed derives from the root seed (recorded in ``campaign.json``)."""
MANIFEST, SCENARIO_FILE, RUNS_FILE, TRAJ_FILE = (
    "campaign.json",
    "scenario.toml",
    "runs.csv",
    "trajectories.jsonl",
)


def run_seed(root_seed: int, run: int) -> int:
    """The seed of run ``run`` (:data:`SEED_RULE`): ``SeedSequence(root_seed).spawn(n)[run]`` has spawn key
    ``(run,)`` whatever ``n``, so a campaign extended to more runs keeps the seeds it had."""
    child = np.random.SeedSequence(int(root_seed), spawn_key=(int(run),))
    return int(child.generate_state(1)[0])


# -------------------------------------------------------------------------------------- what a mission gives


@dataclass(frozen=True)
class CampaignMission:
    """What the runner asks of a mission, given it by the mission registry (:meth:`swarm.missions.Mission.
    campaign`): beside its name, functions, each a callable or named ``"package.module:function"`` and
    imported when called (so a mission's campaign part imports no simulator, and ``run_one`` pickles by
    reference)."""

    name: str
    """The mission (``campaign.json``'s ``mission``): ``docking``, ``landing``."""
    load: str | Callable
    """``(scenario, overrides=None) -> scenario``: a scenario file or bundled name, ``--set`` applied; a
    ConfigError for one the campaign cannot run. Reads ``DIR/scenario.toml`` back too."""
    columns: str | Callable
    """``(scenario) -> {column: type}``: the ``runs.csv`` columns (types: ``int``, ``float``, ``bool``,
    ``str``; ``float?`` may be empty). Every row has ``run`` and ``policy``."""
    run_one: str | Callable
    """``(scenario, policy, run, seed, trajectory_period_s) -> (rows, trajectories)``: run ``run`` of
    ``policy`` flown from ``seed``, in a worker; each trajectory is a JSON object with ``run`` and
    ``policy``."""
    report: str | Callable
    """``(out_dir, figures=True) -> record``: the report written from the directory's files alone."""
    summary: str | Callable
    """``(record) -> str``: what ``swarm montecarlo`` prints of the record."""
    preload: str = ""
    """A module imported in the parent before a local pool forks (loaded and compiled once)."""

    def entry(self, what: str) -> Callable:
        """The function field ``what`` gives."""
        f = getattr(self, what)
        return f if callable(f) else pkgutil.resolve_name(f)


DOCKING = CampaignMission(
    name="docking",
    load="swarm.scenario:load_scenario",
    columns="swarm.montecarlo.run:fields_for",
    run_one="swarm.montecarlo.run:run_one",
    report="swarm.montecarlo.report:campaign_report",
    summary="swarm.montecarlo.report:summary_text",
    preload="swarm.sim.docking",
)
"""The docking's campaign part: the mission of a directory whose ``campaign.json`` names none (as before
missions), so the runner's default. Every mission's part is given by its entry in
:data:`swarm.missions.MISSIONS`."""


# ------------------------------------------------------------------------------------------- the campaign


@dataclass(frozen=True)
class CampaignSpec:
    """What to run: ``runs`` paired runs of each policy of ``scenario`` from ``root_seed``."""

    scenario: object
    policies: tuple[str, ...] = POLICIES
    runs: int = 500
    root_seed: int = 0
    mission: CampaignMission = DOCKING
    """Whose scenario it is (:meth:`swarm.missions.Mission.campaign`)."""

    def __post_init__(self) -> None:
        if not (isinstance(self.runs, int) and self.runs >= 1):
            raise ConfigError(f"--runs must be a positive integer, got {self.runs!r}")
        if not self.policies:
            raise ConfigError("--policy must be given at least once, got none")
        for p in self.policies:
            if p not in POLICIES:
                raise ConfigError(f"--policy must be one of {list(POLICIES)}, got {p!r}")
        if len(set(self.policies)) != len(self.policies):
            raise ConfigError(f"--policy must not repeat a policy, got {list(self.policies)!r}")
        if not (isinstance(self.root_seed, int) and self.root_seed >= 0):
            raise ConfigError(f"--seed must be a non-negative integer, got {self.root_seed!r}")


@dataclass
class CampaignOutcome:
    """What :func:`run_campaign` did."""

    out_dir: Path
    total: int
    """Tasks of the campaign (runs x policies)."""
    done_before: int
    """Tasks already in the directory when it started (resume)."""
    done: int
    """Tasks in the directory now."""
    wall_s: float
    workers: int | None = None
    """Processes of the runner's own pool; None for an executor passed in."""
    interrupted: bool = False
    failures: list[str] = field(default_factory=list)


def read_manifest(out_dir: Path) -> dict:
    try:
        return json.loads((Path(out_dir) / MANIFEST).read_text())
    except FileNotFoundError:
        raise ConfigError(
            f"--resume {str(out_dir)!r}: no {MANIFEST} there, not a campaign directory"
        ) from None
    except (OSError, json.JSONDecodeError) as exc:
        raise ConfigError(f"--resume {str(out_dir)!r}: cannot read {MANIFEST}: {exc}") from None


def _differences(a, b, path: str = "") -> list[str]:
    """Dotted paths where two ``to_mapping`` trees differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append(f"{path}.{k}".lstrip("."))
            else:
                out += _differences(a[k], b[k], f"{path}.{k}")
        return out
    return [] if a == b else [path.lstrip(".")]


def _prepare_dir(spec: CampaignSpec, out_dir: Path, resume: bool) -> None:
    """Create ``out_dir`` (new campaign) or check it holds this very campaign (resume)."""
    scen = to_mapping(spec.scenario)
    if resume:
        man = read_manifest(out_dir)
        was = man.get("mission", DOCKING.name)
        if was != spec.mission.name:
            raise ConfigError(
                f"--resume {str(out_dir)!r}: a {was} campaign, the scenario given is a {spec.mission.name} "
                f"one; resume with {str(out_dir / SCENARIO_FILE)!r}"
            )
        try:
            saved = to_mapping(spec.mission.entry("load")(out_dir / SCENARIO_FILE))
        except ConfigError as exc:
            raise ConfigError(f"--resume {str(out_dir)!r}: cannot load its {SCENARIO_FILE}: {exc}") from None
        diff = _differences(saved, scen)
        if diff:
            shown = ", ".join(repr(d) for d in diff[:3]) + (
                f" and {len(diff) - 3} more" if len(diff) > 3 else ""
            )
            raise ConfigError(
                f"--resume {str(out_dir)!r}: the scenario differs from the one the campaign ran in "
                f"{shown}; resume with {str(out_dir / SCENARIO_FILE)!r} (and the same --set overrides)"
            )
        if man["root_seed"] != spec.root_seed:
            raise ConfigError(
                f"--seed {spec.root_seed} differs from the campaign's root seed {man['root_seed']}"
            )
        if tuple(man["policies"]) != tuple(spec.policies):
            raise ConfigError(
                f"--policy {list(spec.policies)} differs from the campaign's policies {man['policies']}"
            )
        man["runs"] = max(int(man["runs"]), spec.runs)
    else:
        if out_dir.exists() and any(out_dir.iterdir()):
            raise ConfigError(
                f"--out {str(out_dir)!r} exists and is not empty; continue that campaign with "
                f"--resume {str(out_dir)!r} or choose another --out"
            )
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(f"--out {str(out_dir)!r}: cannot create it: {exc.strerror or exc}") from None
        (out_dir / SCENARIO_FILE).write_text(dump_toml(spec.scenario))
        man = {
            "mission": spec.mission.name,
            "scenario": spec.scenario.name,
            "root_seed": spec.root_seed,
            "seed_rule": SEED_RULE,
            "policies": list(spec.policies),
            "runs": spec.runs,
            "created_unix_s": time.time(),
        }
    (out_dir / MANIFEST).write_text(json.dumps(man, indent=1) + "\n")


def _parse(value: str, kind: str):
    if kind.endswith("?") and value == "":
        return None
    kind = kind.rstrip("?")
    if kind == "int":
        return int(value)
    if kind == "float":
        return float(value)
    if kind == "bool":
        if value not in ("True", "False"):
            raise ValueError(f"not a bool: {value!r}")
        return value == "True"
    return value


def _format(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(float(value))  # shortest text that reads back to the same float (numpy's too)
    return str(value)


def read_runs(out_dir: Path, scenario=None, mission: CampaignMission = DOCKING) -> list[dict]:
    """The typed rows of ``DIR/runs.csv`` (the ``mission``'s ``columns`` of the campaign's scenario,
    ``DIR/scenario.toml`` unless given), in file order. A last line cut short (a campaign killed mid-write)
    is dropped; any other malformed line is an error, and so is a directory of another mission."""
    path = Path(out_dir) / RUNS_FILE
    if not path.exists():
        return []
    was = read_manifest(out_dir).get("mission", DOCKING.name)
    if was != mission.name:
        raise ConfigError(f"{Path(out_dir) / MANIFEST}: a {was} campaign, read as a {mission.name} one")
    if scenario is None:
        scenario = mission.entry("load")(Path(out_dir) / SCENARIO_FILE)
    fields = mission.entry("columns")(scenario)
    text = path.read_text()
    lines = text.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines = lines[:-1]
    reader = csv.DictReader(lines)
    if reader.fieldnames is not None and list(reader.fieldnames) != list(fields):
        raise ConfigError(f"{path}: its columns are not those of this version ({len(fields)} expected)")
    rows = []
    for n, raw in enumerate(reader, start=2):
        try:
            rows.append({k: _parse(raw[k], kind) for k, kind in fields.items()})
        except (ValueError, TypeError, KeyError) as exc:
            raise ConfigError(f"{path}: line {n} is malformed: {exc}") from None
    return rows


def read_trajectories(out_dir: Path) -> list[dict]:
    """Every complete line of ``DIR/trajectories.jsonl``."""
    path = Path(out_dir) / TRAJ_FILE
    if not path.exists():
        return []
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            continue  # a line cut short by a kill: its run is redone or has no trajectory
    return out


def _truncate_partial_line(path: Path) -> None:
    """Drop a last line without its newline (the run it belonged to is redone)."""
    if not path.exists():
        return
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        path.write_bytes(data[: data.rfind(b"\n") + 1])


def _init_worker() -> None:
    """Start of a default pool's worker: Ctrl-C is the parent's (it stops submitting and keeps the finished
    runs), and BLAS gets one thread. A run is single-threaded Python and numba; OpenBLAS's own threads
    only spin on the other cores (measured: 0.32 s of CPU per 0.22 s run, the same wall time with one
    thread), which halves what a second worker can add."""
    from threadpoolctl import threadpool_limits

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    global _BLAS_LIMIT
    _BLAS_LIMIT = threadpool_limits(limits=1)


_BLAS_LIMIT = None  # kept alive for the worker's lifetime


def default_workers() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def run_campaign(
    spec: CampaignSpec,
    out_dir: str | os.PathLike,
    *,
    executor: cf.Executor | None = None,
    workers: int | None = None,
    resume: bool = False,
    progress: bool = True,
    trajectory_period_s: float = 1.0,
) -> CampaignOutcome:
    """Run (or finish) a campaign into ``out_dir`` (module docstring); see :class:`CampaignOutcome`.

    Args:
        spec: mission, scenario, policies, number of runs, root seed.
        out_dir: campaign directory: created (must be empty or absent), or continued with ``resume``.
        executor: where the runs go; default a ProcessPoolExecutor with ``workers`` processes.
        workers: processes of the default executor (default: the cores available).
        resume: continue the campaign in ``out_dir`` (same scenario, seed and policies; more runs allowed).
        progress: show a tqdm progress bar with ETA on stderr.
        trajectory_period_s: sampling period of the saved trajectories [s].

    Raises:
        ConfigError: bad spec or flags, or ``out_dir`` not usable as asked.
    """
    out_dir = Path(out_dir)
    if workers is not None and not (isinstance(workers, int) and workers >= 1):
        raise ConfigError(f"--workers must be a positive integer, got {workers!r}")
    _prepare_dir(spec, out_dir, resume)
    runs = int(read_manifest(out_dir)["runs"]) if resume else spec.runs
    runs_path, traj_path = out_dir / RUNS_FILE, out_dir / TRAJ_FILE
    _truncate_partial_line(runs_path)
    _truncate_partial_line(traj_path)
    fields = spec.mission.entry("columns")(spec.scenario)
    run_one = spec.mission.entry("run_one")
    done_keys = {(r["run"], r["policy"]) for r in read_runs(out_dir, spec.scenario, spec.mission)}
    todo = [
        (i, p) for i in range(runs) for p in spec.policies if (i, p) not in done_keys
    ]  # paired runs side by side: an interrupted campaign leaves few unpaired runs
    total = runs * len(spec.policies)
    done_before = total - len(todo)
    own = executor is None
    outcome = CampaignOutcome(
        out_dir, total, done_before, done_before, 0.0, (workers or default_workers()) if own else None
    )
    if not todo:
        return outcome
    if own:
        if spec.mission.preload:  # loaded (and compiled) once here, inherited by forked workers
            importlib.import_module(spec.mission.preload)
        executor = cf.ProcessPoolExecutor(max_workers=outcome.workers, initializer=_init_worker)
    new_file = not runs_path.exists() or runs_path.stat().st_size == 0
    t0 = time.perf_counter()
    bar = _progress(total, done_before, progress)
    futures: dict[cf.Future, tuple[int, str]] = {}
    written: set[cf.Future] = set()
    with runs_path.open("a", newline="") as fr, traj_path.open("a") as ft:
        writer = csv.DictWriter(fr, fieldnames=list(fields))
        if new_file:
            writer.writeheader()
            fr.flush()

        def harvest(fut: cf.Future) -> None:
            written.add(fut)
            i, p = futures[fut]
            try:
                rows, trajs = fut.result()
            except Exception as exc:  # a run that crashed is reported, the others go on
                outcome.failures.append(f"run {i} {p}: {type(exc).__name__}: {exc}")
                log.error("run %d (%s) failed: %s", i, p, exc)
                return
            for tr in trajs:
                ft.write(json.dumps(tr, separators=(",", ":")) + "\n")
            ft.flush()
            for row in rows:
                writer.writerow({k: _format(row[k]) for k in fields})
            fr.flush()  # the row is the record that the run is done: written last
            outcome.done += 1
            bar.update(1)

        try:
            for i, p in todo:
                seed = run_seed(spec.root_seed, i)
                futures[executor.submit(run_one, spec.scenario, p, i, seed, trajectory_period_s)] = (i, p)
            for fut in cf.as_completed(futures):
                harvest(fut)
        except KeyboardInterrupt:
            outcome.interrupted = True
            for fut in futures:
                fut.cancel()
            if own:
                executor.shutdown(wait=True, cancel_futures=True)  # the runs in flight finish
            for fut in futures:
                if fut not in written and fut.done() and not fut.cancelled():
                    harvest(fut)
        finally:
            bar.close()
            if own:
                executor.shutdown(wait=True, cancel_futures=True)
    outcome.wall_s = time.perf_counter() - t0
    man = read_manifest(out_dir)
    man["wall_s"], man["workers"] = outcome.wall_s, outcome.workers  # this session's, for the report
    (out_dir / MANIFEST).write_text(json.dumps(man, indent=1) + "\n")
    if outcome.done == total:
        _in_run_order(out_dir, spec.policies)
    return outcome


def _in_run_order(out_dir: Path, policies: tuple[str, ...]) -> None:
    """Rewrite a finished campaign's ``runs.csv`` and ``trajectories.jsonl`` in run order, the policies in
    their order (each line's text kept; a task's own lines keep theirs). Of trajectory lines written twice
    (a run redone after a kill that came between its trajectory and its row) the last is kept."""
    order = {p: k for k, p in enumerate(policies)}
    runs_path, traj_path = out_dir / RUNS_FILE, out_dir / TRAJ_FILE
    header, *lines = runs_path.read_bytes().decode().splitlines(keepends=True)  # the csv module's \r\n kept
    names = next(csv.reader([header]))
    i_run, i_pol = names.index("run"), names.index("policy")
    cells = list(csv.reader(lines))
    rows = sorted(zip(cells, lines, strict=True), key=lambda cl: (int(cl[0][i_run]), order[cl[0][i_pol]]))
    _replace(runs_path, header + "".join(line for _, line in rows))
    if traj_path.exists():
        last: dict[tuple, tuple[dict, str]] = {}
        for line in traj_path.read_bytes().decode().splitlines(keepends=True):
            try:
                tr = json.loads(line)
            except json.JSONDecodeError:
                continue  # as read_trajectories
            last[(tr["run"], tr["policy"], tr.get("chaser"))] = (tr, line)
        ordered = sorted(last.values(), key=lambda tl: (tl[0]["run"], order[tl[0]["policy"]]))
        _replace(traj_path, "".join(line for _, line in ordered))


def _replace(path: Path, text: str) -> None:
    """Write ``path`` whole or not at all (a kill leaves the old file)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(text.encode())
    os.replace(tmp, path)


def _progress(total: int, initial: int, enabled: bool):
    from tqdm import tqdm

    tqdm.monitor_interval = 0  # no monitor thread: worker processes may be forked after the bar exists
    return tqdm(
        total=total,
        initial=initial,
        unit="run",
        desc="montecarlo",
        disable=not enabled,
        smoothing=0.05,
        dynamic_ncols=True,
        mininterval=0.5,
    )


def complete_pairs(rows: Iterable[dict], policies: tuple[str, ...]) -> list[int]:
    """Run indices that every policy has finished (the paired sample)."""
    have: dict[int, set[str]] = {}
    for r in rows:
        have.setdefault(r["run"], set()).add(r["policy"])
    return sorted(i for i, ps in have.items() if set(policies) <= ps)


def finite(values: Iterable) -> np.ndarray:
    """The finite values of ``values`` (None and NaN dropped) as a float array."""
    return np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
