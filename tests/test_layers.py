"""The import layers of docs/architecture.md, checked by import-linter (`.importlinter`): the real tree keeps
them, and a copy of it with one core module importing the transport is refused, so the check can fail."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("swarm", "agents", "mothership", "dashboard")
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(root: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(root))
    return subprocess.run(
        [str(LINT), "--no-cache"], cwd=root, env=env, capture_output=True, text=True, timeout=300
    )


def _copy_tree(dst: Path) -> None:
    for pkg in PACKAGES:
        shutil.copytree(REPO / pkg, dst / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.toml"))
    shutil.copy(REPO / ".importlinter", dst / ".importlinter")


def test_the_tree_keeps_its_import_layers():
    r = _lint(REPO)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 broken" in r.stdout, r.stdout


@pytest.mark.parametrize(
    ("victim", "line", "broken"),
    [
        # a core module importing the transport breaks the layers
        ("swarm/core/rotations.py", "from swarm.transport import keys  # noqa: E402",
         "swarm.core.rotations -> swarm.transport.keys"),
        # an in-process runner importing zenoh breaks the purity contract
        ("swarm/sim/plot.py", "import zenoh  # noqa: E402", "swarm.sim.plot -> zenoh"),
        # a mission importing another mission breaks the independence contract
        ("swarm/missions/docking.py", "from swarm.missions import landing  # noqa: E402,F401",
         "swarm.missions.docking -> swarm.missions.landing"),
        # so does a mission module added to the package (.importlinter lists swarm.missions.*, not names)
        ("swarm/missions/toy.py", "from swarm.missions import landing  # noqa: E402,F401",
         "swarm.missions.toy -> swarm.missions.landing"),
        # a navigator reaching into the kinds (its sibling layer: it picks by the IMU it is told of)
        ("swarm/navigation/mekf.py", "from swarm.kinds import base  # noqa: E402,F401",
         "swarm.navigation.mekf -> swarm.kinds.base"),
    ],
)  # fmt: skip
def test_an_import_across_a_contract_breaks_it(tmp_path, victim, line, broken):
    _copy_tree(tmp_path)
    path = tmp_path / victim
    path.write_text((path.read_text() if path.exists() else "") + f"\n{line}\n")
    r = _lint(tmp_path)
    assert r.returncode != 0, r.stdout
    assert broken in r.stdout, r.stdout


def _cycles(graph, modules: list[str]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan 1972, iterative)."""
    succ = {m: sorted(x for x in graph.find_modules_directly_imported_by(m) if x in modules) for m in modules}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out = []
    for root in modules:
        if root in index:
            continue
        work = [(root, iter(succ[root]))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(succ[w])))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_no_module_imports_itself_through_others():
    """No import cycle, counting the imports inside functions too (grimp reads every import statement)."""
    import grimp

    graph = grimp.build_graph(*PACKAGES, cache_dir=None)
    assert _cycles(graph, sorted(graph.modules)) == []


def test_the_cycle_finder_finds_a_cycle():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}

    class Graph:
        def find_modules_directly_imported_by(self, m):
            return edges[m]

    assert _cycles(Graph(), ["a", "b", "c", "d"]) == [["a", "b", "c"]]
