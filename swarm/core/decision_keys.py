"""The keys of one Algorithm 1 decision record (a run summary's ``"decisions"``), in a module light enough
for the wire codec to import (no numba, no scipy: ``tests/transport/test_messages.py``)."""

from __future__ import annotations

DECISION_KEYS: tuple[str, ...] = (
    "t_s",
    "r_m",
    "d",
    "qe_vec_norm",
    "sigma_pos_max_m",
    "sigma_uwb_m",
    "r_t_m",
    "r_d_m",
    "A11",
    "A22",
    "A23",
    "A32",
    "A33",
    "pi1",
    "pi2",
    "r1_m",
    "r2_m",
)
"""Keys of one ``"decisions"`` record, in that order."""
