"""Suite-wide options: ``--runslow`` enables the tests marked ``slow`` (long statistical runs, and launches
whose claim the default suite already checks in another launch)."""

from __future__ import annotations

import pytest

import swarm  # noqa: F401  (first: it pins numpy's BLAS kernels before any test module imports numpy)

pytest_plugins = ["tests.hard_timeout"]  # the last resort against a hang no signal reaches


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--runslow", action="store_true", default=False, help="run tests marked slow")


SLOW_TIMEOUT_S = 3600.0
"""A ``slow`` test's hang limit under ``--runslow`` (the default's 300 s, ``pyproject.toml``, is for the
default suite: a full statistical run may take longer than that and is not hung)."""


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
