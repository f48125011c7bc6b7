"""The landing campaign runs through the docking campaign's runner (swarm.montecarlo.campaign): a campaign
killed part-way and resumed writes the same files, byte for byte, as one never interrupted; ``--dask``
gives the same rows; the committed campaign's first runs come out as committed; a landing directory is not
resumed as a docking one.

One uninterrupted campaign (5 paired runs from a start 12 m out, in this process) is made once per module
and is the oracle of the others.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
from pathlib import Path

import pytest

import swarm.montecarlo.campaign as campaign
from swarm.cli.main import main
from swarm.errors import ConfigError
from swarm.landing_scenario import load_landing
from swarm.missions import MISSIONS
from swarm.montecarlo.campaign import CampaignSpec, read_runs, run_campaign
from swarm.montecarlo.landing import write_report
from swarm.scenario import load_scenario

LANDING = MISSIONS["landing"].campaign()
SHORT = {"vehicle.start_m": [12.0, 3.0, 5.0]}  # 13-17 s flights instead of 15-18 s
RUNS, ROOT, POLICIES = 5, 3, ("fixed", "mdp")
COMMITTED = Path(__file__).resolve().parents[2] / "docs" / "results" / "landing-500-seed0"


def _spec(runs: int = RUNS) -> CampaignSpec:
    return CampaignSpec(load_landing("landing", SHORT), POLICIES, runs, ROOT, LANDING)


@pytest.fixture(scope="module")
def whole(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("landing") / "whole"
    with cf.ThreadPoolExecutor(1) as ex:
        outcome = run_campaign(_spec(), out, executor=ex, progress=False)
    assert outcome.done == outcome.total == 2 * RUNS and not outcome.failures
    write_report(out, figures=False)
    return out


def test_a_killed_landing_campaign_resumes_to_the_same_files(whole, tmp_path, monkeypatch):
    out = tmp_path / "killed"
    real = cf.as_completed
    k = 3

    def killed_after_k(futures):  # k runs finish, in reverse order as on several workers, then Ctrl-C
        it = real(futures)
        yield from reversed([next(it) for _ in range(k)])
        raise KeyboardInterrupt

    monkeypatch.setattr(campaign.cf, "as_completed", killed_after_k)
    with cf.ThreadPoolExecutor(1) as ex:
        first = run_campaign(_spec(), out, executor=ex, progress=False)
    assert first.interrupted and k <= first.done < first.total
    # what a kill in the middle of a write leaves: the last row cut short (its trajectory line complete)
    text = (out / "runs.csv").read_bytes()
    (out / "runs.csv").write_bytes(text[: len(text) - 30])
    kept = len(read_runs(out, mission=LANDING))
    assert kept == first.done - 1
    monkeypatch.setattr(campaign.cf, "as_completed", real)
    with cf.ThreadPoolExecutor(1) as ex:
        again = run_campaign(_spec(), out, executor=ex, resume=True, progress=False)
    assert (again.done_before, again.done, again.total) == (kept, 2 * RUNS, 2 * RUNS)
    for name in ("runs.csv", "trajectories.jsonl"):  # the redone run's trajectory is not there twice
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
    got, want = write_report(out, figures=False), json.loads((whole / "stats.json").read_text())
    for rec in (got, want):
        rec.pop("wall_s"), rec.pop("workers")
    assert json.loads(json.dumps(got)) == want


def test_resuming_a_landing_campaign_as_docking_names_both(whole):
    with pytest.raises(ConfigError, match="a landing campaign, the scenario given is a docking one"):
        run_campaign(CampaignSpec(load_scenario("docking"), POLICIES, 1, ROOT), whole, resume=True)


def test_the_committed_landing_campaign_s_first_rows_come_out_byte_for_byte(tmp_path):
    """docs/results/landing-500-seed0 re-run from its scenario.toml and campaign.json: its first three
    paired runs are its first lines (the full 500 are re-made by the command in docs/results/README.md)."""
    man = json.loads((COMMITTED / "campaign.json").read_text())
    sc = load_landing(COMMITTED / "scenario.toml")
    with cf.ThreadPoolExecutor(1) as ex:
        run_campaign(CampaignSpec(sc, tuple(man["policies"]), 3, man["root_seed"], LANDING), tmp_path / "c",
                     executor=ex, progress=False)  # fmt: skip
    got = (tmp_path / "c" / "runs.csv").read_bytes().splitlines(keepends=True)
    want = (COMMITTED / "runs.csv").read_bytes().splitlines(keepends=True)
    assert len(got) == 1 + 3 * len(man["policies"])
    assert got == want[: len(got)]


def test_a_landing_campaign_on_a_dask_cluster_gives_the_local_rows(whole, tmp_path):
    """``--dask``: a scheduler and one worker thread in this process, reached over loopback TCP."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=None) as cluster:  # fmt: skip
        out = tmp_path / "dask"
        start = f"vehicle.start_m={json.dumps(SHORT['vehicle.start_m'])}"
        argv = ["montecarlo", "landing", "--set", start, "--runs", "2", "--seed", str(ROOT), "--dask",
                cluster.scheduler_address, "--out", str(out), "--no-figures", "--no-progress"]  # fmt: skip
        assert main(argv) == 0
    lines = (out / "runs.csv").read_bytes().splitlines(keepends=True)
    assert lines == (whole / "runs.csv").read_bytes().splitlines(keepends=True)[: 1 + 2 * 2]
    assert json.loads((out / "campaign.json").read_text())["workers"] is None
    assert "on a cluster" in (out / "report.md").read_text()
