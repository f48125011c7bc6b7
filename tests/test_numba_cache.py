"""The numba cache directory (``swarm/__init__.py``): keyed by the text of the kernels' sources, which the
imports must confirm, and pruned to the most recently used."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import time
from pathlib import Path

import swarm
from swarm import KERNEL_SOURCES, _kernel_key, prune_kernel_caches

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("swarm", "agents", "mothership", "dashboard")


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in (REPO / pkg).rglob("*.py"):
            parts = path.relative_to(REPO).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> tuple[set[str], bool]:
    """The package's modules that ``name`` imports (anywhere in it), and whether it imports numba."""
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    named, numba = set(), False
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            named.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            named.add(mod)
            named.update(f"{mod}.{a.name}" for a in node.names)
    found = set()
    for full in named:
        parts = full.split(".")
        numba |= parts[0] == "numba"
        found.update(q for i in range(1, len(parts) + 1) if (q := ".".join(parts[:i])) in modules)
    return found, numba


def _kernel_closure() -> tuple[set[str], dict[str, Path]]:
    modules = _modules()
    graph, kernels = {}, []
    for name, path in modules.items():
        graph[name], numba = _imports(name, path, modules)
        if numba:
            kernels.append(name)
    assert kernels, "no module imports numba: the analysis is broken"
    seen, stack = set(), list(kernels)
    while stack:
        name = stack.pop()
        if name not in seen:
            seen.add(name)
            stack.extend(graph[name])
    return seen, modules


def _covered(path: Path) -> bool:
    root = Path(swarm.__file__).resolve().parent
    try:
        rel = path.resolve().relative_to(root)
    except ValueError:
        return False  # outside the swarm package: not in the key at all
    return any(rel == Path(s) or Path(s) in rel.parents for s in KERNEL_SOURCES)


def test_every_module_a_kernel_depends_on_is_in_the_key():
    closure, modules = _kernel_closure()
    missing = sorted(m for m in closure if not _covered(modules[m]))
    assert not missing, f"add to swarm.KERNEL_SOURCES (their text is compiled into kernels): {missing}"
    # and the key is narrower than the package: these edits compile nothing again
    for name in ("swarm.cli.launch", "swarm.transport.messages", "swarm.world.process", "swarm.scenario"):
        assert name not in closure and not _covered(modules[name]), name


def _tree(tmp_path: Path) -> Path:
    root = tmp_path / "pkg"
    for rel in ("core/a.py", "core/sub/b.py", "config.py", "cli/main.py"):
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(f"# {rel}\n")
    return root


def test_the_key_follows_the_kernel_sources_text_only(tmp_path, monkeypatch):
    monkeypatch.setattr(swarm, "KERNEL_SOURCES", ("core", "config.py"))
    root = _tree(tmp_path)
    key = _kernel_key(root)
    (root / "cli/main.py").write_text("# an edit outside the kernels\n")
    os.utime(root / "core/a.py", (1, 1))  # a checkout: new times, same text
    assert _kernel_key(root) == key
    (root / "core/sub/b.py").write_text("X = 2\n")  # a kernel source, nested
    key2 = _kernel_key(root)
    assert key2 != key
    (root / "config.py").write_text("# changed\n")
    key3 = _kernel_key(root)
    assert key3 not in (key, key2)
    # the same text in another checkout: a key of its own (numba keeps its functions apart by path)
    other = root.rename(tmp_path / "clone")
    assert _kernel_key(other) != key3
    other.rename(root)
    assert _kernel_key(root) == key3


def test_prune_keeps_the_most_recently_used_and_the_fresh(tmp_path):
    now = time.time()
    ages_h = [0.1, 0.5, 2, 5, 10, 30, 50, 0.2]  # hours since last used
    for i, age in enumerate(ages_h):
        d = tmp_path / f"k{i}"
        d.mkdir()
        (d / "f.nbi").write_bytes(b"x")
        os.utime(d, (now - age * 3600, now - age * 3600))
    removed = prune_kernel_caches(tmp_path, keep=3, grace_s=3600)
    # kept: the 3 most recently used (0.1, 0.2, 0.5 h); the others, unused for over an hour, went
    assert sorted(d.name for d in removed) == ["k2", "k3", "k4", "k5", "k6"]
    assert sorted(d.name for d in tmp_path.iterdir()) == ["k0", "k1", "k7"]
    # within the grace, a cache beyond `keep` stays (another checkout may be using it)
    assert prune_kernel_caches(tmp_path, keep=1, grace_s=3600) == []
    assert prune_kernel_caches(tmp_path / "absent") == []


def test_a_fresh_interpreter_uses_and_prunes_the_cache(tmp_path):
    base = tmp_path / "tpods-swarm" / "numba"
    old = time.time() - 86400
    for i in range(swarm.CACHE_KEEP + 3):  # stale caches of other keys, a day old
        (base / f"old{i:02d}").mkdir(parents=True)
        os.utime(base / f"old{i:02d}", (old + i, old + i))
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    code = "import os, swarm; print(os.environ['NUMBA_CACHE_DIR'])"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    cache = Path(out.stdout.strip())
    assert cache.parent == base and cache.is_dir()
    assert cache.name == _kernel_key(Path(swarm.__file__).resolve().parent)
    left = sorted(d.name for d in base.iterdir())
    # the new one and the CACHE_KEEP - 1 most recently used of the old: the four oldest went
    assert left == sorted([cache.name] + [f"old{i:02d}" for i in range(4, swarm.CACHE_KEEP + 3)])
    # a second start finds it and removes nothing
    out2 = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out2.stdout.strip() == str(cache) and sorted(d.name for d in base.iterdir()) == left
