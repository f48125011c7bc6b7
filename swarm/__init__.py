"""TPODS swarm: robust proximity operations with Markov-model guidance switching."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path


def _numba_cache_dir() -> None:
    """Point numba's on-disk cache at a directory keyed by the kernels' sources.

    numba invalidates a cached function when *its own* file changes, not when a function it calls (and
    compiles in) changes in another file, so an edit of, say, ``_rot_nb.py`` would leave stale machine
    code in the estimator's cache. Keying the cache directory by every source file of the package avoids
    that. A ``NUMBA_CACHE_DIR`` set by the user wins. Must run before numba is imported.
    """
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    root = Path(__file__).resolve().parent
    h = hashlib.sha1()
    for path in sorted(root.rglob("*.py")):
        st = path.stat()
        h.update(f"{path.relative_to(root)}:{st.st_size}:{st.st_mtime_ns}".encode())
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "tpods-swarm" / "numba"
    os.environ["NUMBA_CACHE_DIR"] = str(base / h.hexdigest()[:16])


_numba_cache_dir()
