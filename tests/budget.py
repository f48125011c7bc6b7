"""How many examples a property test draws: the full count under ``--runslow``, a quarter (at least 25)
in the default suite (tests/conftest.py sets :data:`FULL_ENV` from the flag before any test module is
imported). The default suite draws new examples each run (Hypothesis is not derandomised), so CI runs
sample the space between them; ``--runslow`` is the exhaustive pass."""

from __future__ import annotations

import os

FULL_ENV = "TPODS_FULL_EXAMPLES"
"""Set to 1 by ``--runslow``."""


def examples(n: int) -> int:
    """``n`` examples under ``--runslow``; ``max(n // 4, 25)`` (never more than ``n``) otherwise."""
    return n if os.environ.get(FULL_ENV) == "1" else min(n, max(n // 4, 25))
