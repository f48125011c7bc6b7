"""TPODS swarm: robust proximity operations with Markov-model guidance switching."""

from __future__ import annotations

import hashlib
import os
import shutil
import time
from pathlib import Path

KERNEL_SOURCES: tuple[str, ...] = (
    "__init__.py", "config.py", "errors.py", "core", "kinds", "navigation", "step", "logs", "sim/__init__.py",
    "sim/estimation.py", "transport/_codec_nb.py", "bench/__init__.py", "bench/estimator.py",
    "bench/filterpy_mekf.py", "bench/replay.py",
)  # fmt: skip
"""The sources (files, or directories of ``*.py``, relative to this package) whose text the compiled
kernels depend on: every module that defines a numba kernel and every module those import, directly or
not (a kernel freezes the globals it reads, constants of another module included, into its machine code).
``tests/test_numba_cache.py`` derives that set from the imports and fails naming a module left out. An edit
elsewhere (the CLI, the transport, the world process, the dashboard) compiles nothing again."""

CACHE_KEEP = 16
"""Kernel caches kept, the one in use included: the most recently used (each is ~15 MB)."""
_CACHE_GRACE_S = 3600.0  # a cache used within the hour is never removed (another checkout may be running)


def _kernel_key(root: Path) -> str:
    """A digest of the package's path and the text of :data:`KERNEL_SOURCES` (their content, not their
    times: a ``git checkout`` of the same sources finds the same cache; ~1.5 ms). The path is in it because
    numba keeps each source directory's functions apart by its full path anyway: a clone elsewhere compiles
    its own, and under a key of its own the pruning bounds them (one key per checkout, not one directory
    growing by ~15 MB with every fresh clone)."""
    h = hashlib.sha1(f"{root}\0".encode())
    for name in KERNEL_SOURCES:
        path = root / name
        for f in sorted(path.rglob("*.py")) if path.is_dir() else [path]:
            h.update(f"{f.relative_to(root)}\0".encode())
            h.update(f.read_bytes())
            h.update(b"\0")
    return h.hexdigest()[:16]


def prune_kernel_caches(base: Path, keep: int = CACHE_KEEP, grace_s: float = _CACHE_GRACE_S) -> list[Path]:
    """Remove the kernel caches under ``base`` beyond the ``keep`` most recently used, those not used for
    ``grace_s`` [s]; returns what it removed. A cache in use has its time set at every start
    (:func:`_numba_cache_dir`). Never raises: a cache that cannot be removed stays."""
    try:
        dirs = [(d.stat().st_mtime, d) for d in base.iterdir() if d.is_dir() and not d.is_symlink()]
    except OSError:
        return []
    dirs.sort(reverse=True)
    now, removed = time.time(), []
    for mtime, d in dirs[keep:]:
        if now - mtime > grace_s:
            shutil.rmtree(d, ignore_errors=True)
            removed.append(d)
    return removed


BLAS_CORETYPE = "Haswell"
"""The OpenBLAS kernels pinned on every x86-64 CPU with AVX2 and FMA (:func:`_pin_blas_kernels`)."""


def _cpu_flags() -> set[str]:
    """The CPU's feature flags as Linux lists them (empty elsewhere, or if unreadable)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("flags"):
                    return set(line.partition(":")[2].split())
    except OSError:
        pass
    return set()


def _pin_blas_kernels() -> None:
    """Make numpy's linear algebra give the same bits on every x86-64 machine with AVX2 and FMA.

    The OpenBLAS inside numpy and scipy picks its kernels by the CPU it finds (``DYNAMIC_ARCH``): on a CPU
    with AVX-512 it takes its SkylakeX kernels, elsewhere Haswell's, and the two round differently in the
    last bit. A run's numbers then depended on the machine: the committed campaign's closest approach came
    out 0.24174180619520322 m instead of 0.24174180619520144 m on an AVX-512 EPYC. ``OPENBLAS_CORETYPE``
    pins the kernels when it is set before OpenBLAS loads, at numpy's import: hence here, before anything
    of this package imports numpy (``tests/test_reproducible.py`` checks that every entry point imports this
    package first). A CPU without AVX2 and FMA (Haswell's kernels would not run on it) keeps OpenBLAS's own
    choice, as does a value the user set. Our matrices are 3x3 to 15x15: the kernels' speed does not show.
    """
    if "OPENBLAS_CORETYPE" in os.environ:
        return
    if {"avx2", "fma"} <= _cpu_flags():
        os.environ["OPENBLAS_CORETYPE"] = BLAS_CORETYPE


def _numba_cache_dir() -> None:
    """Point numba's on-disk cache at a directory keyed by the kernels' sources.

    numba invalidates a cached function when *its own* file changes, not when a function it calls (and
    compiles in) changes in another file, so an edit of, say, ``_rot_nb.py`` would leave stale machine
    code in the estimator's cache. Keying the cache directory by the text of every kernel source
    (:data:`KERNEL_SOURCES`, and the package's path: :func:`_kernel_key`) avoids that. A new key (a kernel
    changed, another checkout) removes the caches of older keys beyond :data:`CACHE_KEEP`
    (:func:`prune_kernel_caches`): without it, every edit left ~15 MB behind.
    A ``NUMBA_CACHE_DIR`` set by the user wins. Must run before numba is imported.
    """
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "tpods-swarm" / "numba"
    cache = base / _kernel_key(Path(__file__).resolve().parent)
    try:
        if cache.is_dir():
            os.utime(cache)  # used now: the pruning keeps the most recently used
        else:
            cache.mkdir(parents=True, exist_ok=True)
            prune_kernel_caches(base)
    except OSError:
        pass  # a read-only home: numba says so itself when it cannot write its cache
    os.environ["NUMBA_CACHE_DIR"] = str(cache)


_pin_blas_kernels()
_numba_cache_dir()
