"""The suite's last resort against a hang that pytest-timeout cannot end (a plugin of ``tests/conftest.py``).

pytest-timeout's signal method fails a hung test from a SIGALRM handler, which Python runs only when the
main thread gets back to Python code: a test stuck in a call that never returns (a Zenoh close that
deadlocks in Rust, a blocked signal) would hold the whole suite until a CI job's own limit killed it
without a word. So each test also arms ``faulthandler.dump_traceback_later`` (a watchdog thread in C) at
twice its timeout plus ``hard_timeout_margin`` seconds: past that, every thread's stack is written and the
run exits (status 1), so that CI ends at once and says where it was stuck."""

from __future__ import annotations

import faulthandler
import os
import sys

import pytest


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addini(
        "hard_timeout_margin",
        "seconds past twice a test's timeout after which the whole run dumps every stack and exits",
        default="30",
    )


_STDERR_FD: list[int] = []  # the run's own stderr, kept before a test's capture replaces descriptor 2


def pytest_configure(config: pytest.Config) -> None:
    _STDERR_FD.append(os.dup(sys.stderr.fileno()))  # (as pytest's own faulthandler plugin does)


def pytest_unconfigure(config: pytest.Config) -> None:
    faulthandler.cancel_dump_traceback_later()
    while _STDERR_FD:
        os.close(_STDERR_FD.pop())


def hard_limit_s(item: pytest.Item) -> float | None:
    """Twice the test's pytest-timeout (its ``timeout`` mark, else the ini's) plus the margin; None
    without a timeout."""
    mark = item.get_closest_marker("timeout")
    if mark is not None and mark.args:
        timeout = float(mark.args[0])
    else:
        raw = item.config.getini("timeout")
        timeout = float(raw) if raw not in (None, "") else 0.0
    if timeout <= 0:
        return None
    return 2.0 * timeout + float(item.config.getini("hard_timeout_margin"))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    limit = hard_limit_s(item)
    if limit is not None and _STDERR_FD:
        faulthandler.dump_traceback_later(limit, exit=True, file=_STDERR_FD[0])
    try:
        yield
    finally:
        if limit is not None:
            faulthandler.cancel_dump_traceback_later()
