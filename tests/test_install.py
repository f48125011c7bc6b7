"""A non-editable install runs every bundled scenario: the scenarios are package data.

A fresh venv gets ``pip install --no-deps .`` (a wheel built from the checkout, copied into the venv's
site-packages, not a link back to it); its dependencies come from the test's own environment through a
``.pth`` path entry, which adds that site-packages to ``sys.path`` without running the ``.pth`` files in it,
so this checkout's editable finder stays out. ``swarm sim`` then runs from a directory outside the checkout.

The installed copy's kernels are new to numba's cache: compiling them costs ~3 min of CPU on the 2-core VM.
By default both scenarios run half a simulated second with the JIT off (the same code, interpreted); with
``--runslow`` each runs to its docking, compiled.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize(
    "full", [False, pytest.param(True, marks=pytest.mark.slow)], ids=["short", "docking"]
)
def test_a_non_editable_install_runs_swarm_sim_on_the_bundled_scenarios(tmp_path, full):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()  # fmt: skip
    (Path(site) / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    pip = [str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-cache-dir"]
    r = subprocess.run([*pip, str(REPO)], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    where = subprocess.run([str(py), "-c", "import swarm; print(swarm.__file__)"], capture_output=True,
                           text=True, check=True, cwd=tmp_path).stdout  # fmt: skip
    assert where.startswith(site), where  # the installed copy, not this checkout
    assert (Path(site) / "swarm" / "scenarios" / "ground-docking.toml").is_file()
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    env.pop("PYTHONPATH", None)
    extra = [] if full else ["--set", "sim.max_duration_s=0.5"]
    if not full:
        env["NUMBA_DISABLE_JIT"] = "1"
    for scenario in ("docking", "ground-docking"):
        r = subprocess.run([str(venv / "bin" / "swarm"), "sim", scenario, "--no-series", *extra],
                           capture_output=True, text=True, timeout=900, cwd=tmp_path, env=env)  # fmt: skip
        assert "Traceback" not in r.stderr, r.stderr
        assert f"scenario {scenario}  policy mdp  seed 0" in r.stdout, r.stdout
        if full:
            assert r.returncode == 0 and "chaser: DOCKED" in r.stdout, (scenario, r.stdout, r.stderr)
        else:  # half a second: the run ends undocked (exit 1), having stepped every part of the tick
            assert r.returncode == 1 and "not docked (APPROACH)" in r.stdout, (scenario, r.stdout, r.stderr)
