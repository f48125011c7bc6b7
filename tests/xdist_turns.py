"""Two test workers on two cores (``make test`` runs ``pytest -n 2``, pytest-xdist): who runs beside whom, and
in which order (a plugin of ``tests/conftest.py``; without xdist it changes nothing).

- **Alone.** A test marked ``alone`` asserts wall-clock timing of a launched swarm: a stall told within a
  second, a killed process seen lost and restarted while the run is still on, late ticks counted against a
  free-running clock. Beside another worker's launch those margins are the machine's, not the code's (two
  such tests failed that way under ``-n 2``, BENCHMARKS.md "Test time"). It takes this run's turn lock
  exclusively: the other worker finishes its current test and waits. Every other test holds the lock
  shared, so the two workers run side by side otherwise. The lock is a file lock (``fcntl.flock``) in the
  run's temporary directory; a turnstile in front of it lets an ``alone`` test in even while the other
  worker goes from test to test (a shared lock is never held across tests).
- **One browser at a time.** A ``tests/dashboard/test_browser*.py`` module holds a browser lock from its
  first test to its last: another worker reaching a browser module waits for it.
- **Order.** xdist hands out whole files (``--dist loadfile``) in collection order. The files that launch
  swarms, dashboards and browsers take minutes; started last, one of them would keep one worker busy while
  the other idles at the end. :data:`FILE_COST_S` moves them to the front, longest first; the rest keep
  pytest's order. The figures only order the files: a file missing from the table runs after them, a
  renamed one likewise.
"""

from __future__ import annotations

import contextlib
import fcntl
from collections.abc import Iterator
from pathlib import Path

import pytest

FILE_COST_S: dict[str, float] = {
    "tests/transport/test_launch.py": 111.0,
    "tests/transport/test_landing_launch.py": 71.0,
    "tests/dashboard/test_browser_landing.py": 68.0,
    "tests/dashboard/test_browser.py": 46.0,
    "tests/transport/test_launch_stop.py": 41.0,
    "tests/dashboard/test_browser_secure.py": 40.0,
    "tests/transport/test_recording.py": 36.0,
    "tests/transport/test_security.py": 28.5,
    "tests/test_cpu_latency.py": 25.6,
    "tests/dashboard/test_browser_playback.py": 23.0,
    "tests/transport/test_launch_kinds.py": 21.8,
    "tests/dashboard/test_browser_ground.py": 16.6,
    "tests/test_bench_swarm.py": 15.9,
    "tests/montecarlo/test_dask.py": 14.5,
    "tests/test_bench_record.py": 14.0,
    "tests/dashboard/test_browser_landing_moving.py": 13.1,
    "tests/dashboard/test_app.py": 12.3,
    "tests/logs/test_replay.py": 11.2,
    "tests/transport/test_messages.py": 10.5,
}
"""Seconds per file in a serial run of the suite (a fresh clone at 08ff0cd, load 1.4-4, ``--durations=0``
summed per file): only the order of the files is taken from them."""


def _lock_dir(config: pytest.Config) -> Path | None:
    """The run's shared directory (the controller's ``basetemp``: xdist gives each worker a ``basetemp``
    inside it, and pytest removes old ones); None outside an xdist worker."""
    if getattr(config, "workerinput", None) is None or not config.option.basetemp:
        return None
    return Path(config.option.basetemp).parent


def _lock_paths(lock_dir: Path) -> tuple[Path, Path]:
    return lock_dir / "xdist-turnstile.lock", lock_dir / "xdist-turn.lock"


@contextlib.contextmanager
def _turn(lock_dir: Path, alone: bool) -> Iterator[None]:
    """Hold this run's turn lock, exclusively for an ``alone`` test, shared otherwise (a readers-writer
    lock with a turnstile: a waiting writer holds the turnstile, so no new reader passes it)."""
    turnstile_path, turn_path = _lock_paths(lock_dir)
    with open(turnstile_path, "a") as turnstile, open(turn_path, "a") as turn:
        fcntl.flock(turnstile, fcntl.LOCK_EX)
        try:
            fcntl.flock(turn, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        finally:
            fcntl.flock(turnstile, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(turn, fcntl.LOCK_UN)


_BROWSER: dict[str, object] = {}
"""The open browser lock file of the browser module this worker is in (by module path)."""


def _browser_module(item: pytest.Item | None) -> str | None:
    """The path of ``item``'s module if it drives Chromium (``tests/dashboard/test_browser*.py``)."""
    if item is None:
        return None
    path = Path(str(item.path))
    return str(path) if path.name.startswith("test_browser") else None


def _browser_turn(lock_dir: Path, item: pytest.Item, nextitem: pytest.Item | None) -> None:
    """Before a browser module's first test: take the browser lock exclusively (two Chromiums and their
    launched swarms side by side missed the page's timeouts on two cores, BENCHMARKS.md "Test time"); it is
    held across the module (its swarm and browser are module fixtures) and taken before the turn lock, so
    the two locks are always taken in one order."""
    module = _browser_module(item)
    if module is not None and module not in _BROWSER:
        fh = open(lock_dir / "xdist-browser.lock", "a")  # held across the module's tests
        fcntl.flock(fh, fcntl.LOCK_EX)
        _BROWSER[module] = fh


def _browser_release(item: pytest.Item, nextitem: pytest.Item | None) -> None:
    """After a browser module's last test (its module fixtures torn down in that test's teardown)."""
    module = _browser_module(item)
    if module is not None and _browser_module(nextitem) != module and module in _BROWSER:
        fh = _BROWSER.pop(module)
        fcntl.flock(fh, fcntl.LOCK_UN)
        fh.close()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    lock_dir = _lock_dir(item.config)
    if lock_dir is None:
        yield
        return
    _browser_turn(lock_dir, item, nextitem)
    try:
        with _turn(lock_dir, alone=item.get_closest_marker("alone") is not None):
            yield
    finally:
        _browser_release(item, nextitem)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under xdist, the costly files first, longest first (a stable sort: each file's tests keep their
    order); a serial run keeps pytest's order."""
    if getattr(config, "workerinput", None) is None:
        return
    root = Path(str(config.rootpath))

    def cost(item: pytest.Item) -> float:
        try:
            rel = Path(str(item.path)).relative_to(root).as_posix()
        except ValueError:
            return 0.0
        return FILE_COST_S.get(rel, 0.0)

    items.sort(key=lambda item: -cost(item))
