"""``swarm compile``: every chain's entry points run (against the cache ``make test`` filled), bad flags are
refused naming the value, and (``--runslow``) a fresh cache filled by it leaves a docking and a landing
nothing to compile."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from swarm.cli.compile import CHAINS
from swarm.cli.main import main


def test_every_chain_runs_its_entry_points_in_parallel_processes(capsys):
    # a chain whose calls no longer fit the API it warms raises in its process, and main() with it
    assert main(["compile", "--jobs", "2"]) == 0
    out = capsys.readouterr().out
    for name in CHAINS:
        assert f"  {name}: " in out
    assert "(2 at once)" in out and "compiled in " in out


def test_one_job_and_a_subset_run_in_this_process(capsys):
    assert main(["compile", "--jobs", "1", "--only", "filters"]) == 0
    out = capsys.readouterr().out
    assert "  filters: " in out and "  docking: " not in out and "(1 at once)" in out


def test_a_failing_chain_is_named_the_others_still_compile_and_the_exit_status_is_1(monkeypatch, capsys):
    from swarm.cli import compile as cc

    def broken() -> None:
        raise RuntimeError("scenario missing")

    monkeypatch.setitem(cc.CHAINS, "docking", (broken, "broken on purpose"))
    assert main(["compile", "--jobs", "1", "--only", "docking,filters"]) == 1
    out, err = capsys.readouterr()
    assert "chain 'docking' failed: RuntimeError: scenario missing" in err
    assert "  filters: " in out and "failed: docking" in out


@pytest.mark.parametrize(
    "argv, named",
    [
        (["--jobs", "0"], "--jobs must be an integer > 0, got '0'"),
        (["--jobs", "two"], "--jobs must be an integer > 0, got 'two'"),
        (["--only", "docking,nope"], "--only: chains are docking, landing, filters; got 'docking,nope'"),
        (["--only", ","], "got ','"),
    ],
)
def test_bad_flags_are_refused_naming_the_value(argv, named, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["compile", *argv])
    assert exc.value.code == 2
    assert named in capsys.readouterr().err


_COUNT = """
import sys
from numba.core import event
n = [0]
class L(event.Listener):
    def on_start(self, ev): n[0] += 1
    def on_end(self, ev): pass
event.register("numba:compile", L())
from swarm.cli.main import main
for argv in (["sim", "docking", "--no-series"], ["sim", "landing"]):
    main(argv)
print("COMPILES", n[0])
"""


@pytest.mark.slow
def test_a_fresh_cache_filled_by_compile_leaves_a_docking_and_a_landing_nothing_to_compile(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    subprocess.run([sys.executable, "-m", "swarm.cli.main", "compile"], env=env, check=True, timeout=900)
    out = subprocess.run([sys.executable, "-c", _COUNT], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "COMPILES 0" in out.stdout, out.stdout[-2000:]
