"""``swarm montecarlo --dask``: a campaign on a real dask.distributed cluster on loopback.

The scheduler and two workers are separate processes (``dask scheduler`` / ``dask worker``, each worker under
its nanny), reached over ``tcp://127.0.0.1:<free port>``; every process is killed at the end, even on
failure. Oracle: the same campaign run locally (a ProcessPoolExecutor): a run's seed depends on the root seed
and its index only, so every row but the wall time must be equal, whichever worker ran it, even when one of
the two workers is SIGKILLed mid-campaign (the scheduler gives its runs to the other).
"""

from __future__ import annotations

import csv
import subprocess
import sys
import time
from pathlib import Path

import pytest

from swarm.montecarlo.campaign import CampaignSpec, run_campaign
from swarm.scenario import load_scenario
from swarm.sim.docking import run_docking
from tests.transport.procs import Procs, free_port, wait_until

distributed = pytest.importorskip("distributed")

RUNS = 40  # 80 dockings of ~60 ms: ~2.5 s on two workers, long enough to kill one of them mid-way
SEED = 7
BIN = Path(sys.executable).parent


def _rows(out: Path) -> dict[tuple[str, str], dict]:
    with (out / "runs.csv").open() as f:
        return {
            (r["run"], r["policy"]): {k: v for k, v in r.items() if k != "wall_s"} for r in csv.DictReader(f)
        }


def _lines(path: Path) -> int:
    try:
        return max(0, len(path.read_text().splitlines()) - 1)
    except FileNotFoundError:
        return 0


@pytest.fixture(scope="module")
def local(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("local") / "campaign"
    outcome = run_campaign(CampaignSpec(load_scenario("docking"), ("fixed", "mdp"), RUNS, SEED), out,
                           workers=2, progress=False)  # fmt: skip
    assert outcome.done == 2 * RUNS and not outcome.failures
    return out


def test_a_campaign_on_a_dask_cluster_gives_the_local_rows_even_when_a_worker_is_killed(local, tmp_path):
    run_docking(load_scenario("docking"), seed=0, record_series=False)  # numba's cache warm for the workers
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {"OMP_NUM_THREADS": "1", "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    with Procs() as procs:
        procs.start([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                     "--no-dashboard"], env=env)  # fmt: skip
        worker = [str(BIN / "dask"), "worker", address, "--nworkers", "1", "--nthreads", "1",
                  "--host", "127.0.0.1", "--no-dashboard"]  # fmt: skip
        workers = [procs.start(worker, env=env) for _ in range(2)]
        client = None
        deadline = time.monotonic() + 60.0
        while client is None:  # the scheduler takes a second or two to listen
            try:
                client = distributed.Client(address, timeout=5, set_as_default=False)
            except OSError:
                assert time.monotonic() < deadline, "the dask scheduler did not come up"
                time.sleep(0.5)
        with client:
            client.wait_for_workers(2, timeout=60)
        out = tmp_path / "campaign"
        campaign = procs.start([sys.executable, "-m", "swarm.cli.main", "montecarlo", "docking", "--runs",
                                str(RUNS), "--seed", str(SEED), "--dask", address, "--out", str(out),
                                "--no-figures", "--no-progress"])  # fmt: skip
        # a quarter of the runs done: kill one worker (its nanny and its worker process, the whole group)
        wait_until(lambda: _lines(out / "runs.csv") >= RUNS // 2 or campaign.popen.poll() is not None, 120.0,
                   "a quarter of the runs", poll_s=0.005)  # fmt: skip
        done_at_kill = _lines(out / "runs.csv")
        workers[0].kill_group()
        rc = campaign.wait(180.0)
    text = campaign.output()
    assert rc == 0, text
    assert done_at_kill < 2 * RUNS, (
        f"the campaign ended ({done_at_kill} runs) before the kill: nothing tested"
    )
    got, want = _rows(out), _rows(local)
    assert len(got) == 2 * RUNS
    assert got == want
    assert "Traceback" not in text


@pytest.mark.parametrize(
    ("flags", "expect"),
    [
        (
            ["--dask", "localhost"],
            "--dask must be a scheduler address such as tcp://HOST:8786, got 'localhost'",
        ),
        (["--dask", "tcp://127.0.0.1:99999"], "--dask: port 99999 out of range 1..65535"),
        (["--dask", "tcp://127.0.0.1:8786", "--workers", "2"], "--workers and --dask: choose one"),
    ],
)
def test_bad_dask_flags_give_one_clear_error(flags, expect, tmp_path):
    args = [sys.executable, "-m", "swarm.cli.main", "montecarlo", "docking", "--runs", "1",
            "--out", str(tmp_path / "c"), *flags]  # fmt: skip
    r = subprocess.run(args, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2, r.stderr
    assert expect in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_an_unreachable_scheduler_is_named_within_the_timeout(tmp_path):
    address = f"tcp://127.0.0.1:{free_port()}"  # nobody listens there
    t0 = time.monotonic()
    args = [sys.executable, "-m", "swarm.cli.main", "montecarlo", "docking", "--runs", "1",
            "--out", str(tmp_path / "c"), "--dask", address, "--dask-timeout", "2"]  # fmt: skip
    r = subprocess.run(args, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert f"--dask: cannot reach the scheduler at {address}" in r.stderr, r.stderr
    assert time.monotonic() - t0 < 30.0  # the 2 s timeout, plus the interpreter's start
    assert "Traceback" not in r.stderr
