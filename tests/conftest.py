"""Suite-wide options: ``--runslow`` enables the tests marked ``slow`` (long statistical runs, and launches
whose claim the default suite already checks in another launch)."""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

import swarm  # noqa: F401  (first: it pins numpy's BLAS kernels before any test module imports numpy)
from tests.budget import FULL_ENV, examples

# the last resort against a hang no signal reaches; who runs beside whom under `pytest -n 2` (make test)
pytest_plugins = ["tests.hard_timeout", "tests.xdist_turns"]


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--runslow", action="store_true", default=False, help="run tests marked slow")


SLOW_TIMEOUT_S = 3600.0
"""A ``slow`` test's hang limit under ``--runslow`` (the default's 300 s, ``pyproject.toml``, is for the
default suite: a full statistical run may take longer than that and is not hung)."""


def pytest_configure(config: pytest.Config) -> None:
    # property tests: Hypothesis' own 100 examples under --runslow, a quarter by default (tests/budget.py);
    # before collection, so that the modules' @settings(max_examples=examples(n)) read it
    full = bool(config.getoption("--runslow"))
    os.environ[FULL_ENV] = "1" if full else "0"
    # no per-example deadline: on a shared 2-core machine an example's wall time says nothing about the code
    # (a VisionBatch round trip failed once under load, then passed 14 reruns); speed is the benchmarks' job
    settings.register_profile("suite", max_examples=examples(100), deadline=None)
    settings.load_profile("suite")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--runslow"):
        for item in items:
            if "slow" in item.keywords and item.get_closest_marker("timeout") is None:
                item.add_marker(pytest.mark.timeout(SLOW_TIMEOUT_S))
        return
    skip = pytest.mark.skip(reason="long run: use --runslow (a smaller version or a sibling runs by default)")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
