"""The import layers of docs/architecture.md, checked by import-linter (`.importlinter`): the real tree keeps
them, and a copy of it with one core module importing the transport is refused, so the check can fail."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

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


def test_a_core_module_importing_the_transport_breaks_the_layers(tmp_path):
    _copy_tree(tmp_path)
    victim = tmp_path / "swarm" / "core" / "rotations.py"
    victim.write_text(victim.read_text() + "\nfrom swarm.transport import keys  # noqa: E402\n")
    r = _lint(tmp_path)
    assert r.returncode != 0, r.stdout
    assert "swarm.core.rotations -> swarm.transport.keys" in r.stdout, r.stdout


def test_an_in_process_runner_importing_zenoh_breaks_the_purity_contract(tmp_path):
    _copy_tree(tmp_path)
    victim = tmp_path / "swarm" / "sim" / "plot.py"
    victim.write_text(victim.read_text() + "\nimport zenoh  # noqa: E402\n")
    r = _lint(tmp_path)
    assert r.returncode != 0, r.stdout
    assert "swarm.sim.plot -> zenoh" in r.stdout, r.stdout


def test_a_mission_importing_another_mission_breaks_the_independence_contract(tmp_path):
    _copy_tree(tmp_path)
    victim = tmp_path / "swarm" / "missions" / "docking.py"
    victim.write_text(victim.read_text() + "\nfrom swarm.missions import landing  # noqa: E402,F401\n")
    r = _lint(tmp_path)
    assert r.returncode != 0, r.stdout
    assert "swarm.missions.docking -> swarm.missions.landing" in r.stdout, r.stdout


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
