"""A run gives the same bits on every x86-64 machine with AVX2 and FMA: numpy's OpenBLAS kernels are pinned
(``swarm._pin_blas_kernels``), which works only if this package is imported before numpy. Every package's
``__init__`` imports ``swarm`` first, so any process of the project has the pin before numpy loads; the test
process too (its conftest imports swarm first). The committed campaign's rows
(``tests/montecarlo/test_campaign.py``) are the end-to-end check: on an AVX-512 EPYC they differed in the
last bit before the pinning."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import swarm

# every process starts in one of these packages (`swarm`, `python -m agents|mothership|swarm.world|dashboard`,
# the landing agents): importing any module of one runs the package's __init__ first, which imports swarm
PACKAGES = ("swarm", "agents", "mothership", "dashboard")

_PROBE = (
    "import importlib, os, sys; importlib.import_module(sys.argv[1]); print(repr(('swarm' in sys.modules, "
)
_PROBE += "'numpy' in sys.modules, os.environ.get('OPENBLAS_CORETYPE'))))"


@pytest.mark.parametrize("package", PACKAGES)
def test_every_package_pins_the_kernels_before_numpy_loads(package):
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    r = subprocess.run([sys.executable, "-c", _PROBE, package], capture_output=True, text=True, timeout=120,
                       env=env)  # fmt: skip
    assert r.returncode == 0, r.stderr
    swarm_in, numpy_in, coretype = eval(r.stdout.strip().splitlines()[-1])
    assert swarm_in and not numpy_in, f"importing {package} must import swarm, and numpy not yet"
    pinned = {"avx2", "fma"} <= swarm._cpu_flags()
    assert coretype == (swarm.BLAS_CORETYPE if pinned else None)


def test_openblas_runs_the_pinned_kernels_here_and_in_a_child():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    if not {"avx2", "fma"} <= swarm._cpu_flags():
        pytest.skip("no AVX2 and FMA on this CPU: OpenBLAS keeps its own choice")
    import numpy  # noqa: F401  (loads OpenBLAS, if nothing did yet)

    arch = {i.get("architecture") for i in threadpoolctl.threadpool_info() if i["internal_api"] == "openblas"}
    assert arch == {swarm.BLAS_CORETYPE}  # this test process: the conftest imported swarm first
    code = ("import agents.process, threadpoolctl; print(sorted({i.get('architecture') for i in "
            "threadpoolctl.threadpool_info() if i['internal_api'] == 'openblas'}))")  # fmt: skip
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == repr([swarm.BLAS_CORETYPE])


def test_a_coretype_the_user_set_is_kept():
    code = "import os, swarm; print(os.environ['OPENBLAS_CORETYPE'])"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "OPENBLAS_CORETYPE": "Sandybridge"})  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "Sandybridge"
