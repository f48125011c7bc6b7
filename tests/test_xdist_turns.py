"""tests/xdist_turns.py under a real ``pytest -n 2``: a test marked ``alone`` overlaps no other test, the
others do run side by side, and the costly files are handed out first.

Oracle: each test of a small suite written here appends its worker and its start and end times to a file;
the intervals are compared. The suite imports only the plugin (no swarm), so the run takes a few seconds.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("xdist")

ROOT = Path(__file__).resolve().parents[1]

RECORD = """
import os, time
from pathlib import Path

def record(name, hold_s):
    t0 = time.monotonic()
    time.sleep(hold_s)
    with open(Path(__file__).parent / "log.txt", "a") as f:
        f.write(f"{name} {os.environ['PYTEST_XDIST_WORKER']} {t0:.4f} {time.monotonic():.4f}\\n")
"""

SHARED = """
import pytest
from record import record

@pytest.mark.parametrize("i", range(8))
def test_shared(i):
    record(f"shared{i}", 0.15)
"""

ALONE = """
import pytest
from record import record

@pytest.mark.alone
@pytest.mark.parametrize("i", range(3))
def test_alone(i):
    record(f"alone{i}", 0.3)

@pytest.mark.parametrize("i", range(4))
def test_beside(i):
    record(f"beside{i}", 0.15)
"""


def _run_two_workers(tmp_path: Path, modules: dict[str, str]) -> list[list[str]]:
    """The test ``modules`` (file name -> text) with the plugin, run by a real ``pytest -n 2`` in
    ``tmp_path``; the rows each test wrote (name, worker, start, end)."""
    (tmp_path / "conftest.py").write_text('pytest_plugins = ["tests.xdist_turns"]\n')
    (tmp_path / "pytest.ini").write_text("[pytest]\nmarkers =\n    alone: nothing beside it\n")
    (tmp_path / "record.py").write_text(RECORD)
    for name, text in modules.items():
        (tmp_path / name).write_text(text)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}  # (this run may be a worker)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(tmp_path)])
    args = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "2", "--dist", "loadfile",
            "--no-loadscope-reorder", "--basetemp", str(tmp_path / "base")]  # fmt: skip
    run = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    rows = [line.split() for line in (tmp_path / "log.txt").read_text().splitlines()]
    return rows


def test_an_alone_test_runs_with_nothing_beside_it_and_the_others_run_side_by_side(tmp_path):
    rows = _run_two_workers(tmp_path, {"test_a_shared.py": SHARED, "test_b_alone.py": ALONE})
    spans = {name: (worker, float(t0), float(t1)) for name, worker, t0, t1 in rows}
    assert len(spans) == 15 and {w for w, _, _ in spans.values()} == {"gw0", "gw1"}, spans

    def overlap(a: str, b: str) -> bool:
        return spans[a][1] < spans[b][2] and spans[b][1] < spans[a][2]

    alone = [n for n in spans if n.startswith("alone")]
    for a in alone:
        beside = [b for b in spans if b != a and overlap(a, b)]
        assert beside == [], (a, beside, spans)
    # without the lock's exclusive turns, the two files' tests do overlap (each worker has one file)
    others = [n for n in spans if not n.startswith("alone")]
    assert any(overlap(a, b) for a in others for b in others if spans[a][0] != spans[b][0]), spans


def test_the_costly_files_go_first_under_xdist_and_a_serial_run_keeps_pytests_order():
    from types import SimpleNamespace

    from tests.xdist_turns import FILE_COST_S, pytest_collection_modifyitems

    def item(rel: str, name: str):
        return SimpleNamespace(path=ROOT / rel, name=name)

    launch, stop = "tests/transport/test_launch.py", "tests/transport/test_launch_stop.py"
    collected = [
        item("tests/test_a.py", "a1"),
        item(stop, "stop1"),
        item("tests/test_b.py", "b1"),
        item(launch, "launch1"),
        item(launch, "launch2"),
        item("tests/test_a2.py", "a2"),
    ]
    serial = list(collected)
    pytest_collection_modifyitems(SimpleNamespace(rootpath=ROOT), serial)
    assert serial == collected  # no worker: pytest's order
    worker = list(collected)
    pytest_collection_modifyitems(SimpleNamespace(rootpath=ROOT, workerinput={}), worker)
    assert [i.name for i in worker] == ["launch1", "launch2", "stop1", "a1", "b1", "a2"]
    assert FILE_COST_S[launch] > FILE_COST_S[stop]


BROWSER = """
import pytest
from record import record

@pytest.fixture(scope="module")
def page():  # a module's browser and swarm: set up in the first test, torn down after the last
    record("{name}-setup", 0.1)
    yield
    record("{name}-teardown", 0.1)

@pytest.mark.parametrize("i", range(3))
def test_page(page, i):
    record(f"{name}{{i}}", 0.15)
"""


def test_two_browser_modules_never_run_side_by_side_from_setup_to_teardown(tmp_path):
    modules = {f"test_browser_{name}.py": BROWSER.replace("{name}", name) for name in ("one", "two")}
    rows = _run_two_workers(tmp_path, modules)
    span = {}
    for name, worker, t0, t1 in rows:
        module = "one" if name.startswith("one") else "two"
        _, a, b = span.get(module, (worker, float(t0), float(t1)))
        span[module] = (worker, min(a, float(t0)), max(b, float(t1)))
    assert {w for w, _, _ in span.values()} == {"gw0", "gw1"}, span  # one module a worker
    (_, a0, a1), (_, b0, b1) = span["one"], span["two"]
    assert a1 <= b0 or b1 <= a0, span  # without the browser lock both start at once
