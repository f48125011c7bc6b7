"""The fault campaign's reductions (:mod:`swarm.montecarlo.faults`): which samples the position NEES
counts, and the per-time chi-square band against synthetic NEES of known distribution."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from swarm.montecarlo.faults import nees_consistency, nees_samples


def _series(rel: list[bool]) -> dict:
    """A series at 1 s with an error of (1, 0, 0) m and identity covariance: NEES 1 at every sample."""
    n = len(rel)
    return {
        "t_s": [float(i) for i in range(n)],
        "p_est_nav": [[1.0, 0.0, 0.0]] * n,
        "p_true_nav": [[0.0, 0.0, 0.0]] * n,
        "cov_pos": [np.eye(3).tolist()] * n,
        "relative_nav": rel,
    }


def test_nees_samples_leave_out_the_dropout_and_everything_after_the_first_vision():
    # vision at 6-7 s, then lost again at 8 s: the estimate is still the vision-relative one
    rel = [False] * 6 + [True, True] + [False] * 4
    nees, used = nees_samples(_series(rel), list(range(12)), [(2.0, 4.0)])
    assert nees == [1.0] * 12
    assert used == [True, True, False, False, True, True] + [False] * 6


def test_nees_samples_count_every_sample_of_a_run_without_vision_or_dropout():
    _, used = nees_samples(_series([False] * 5), list(range(5)), [])
    assert used == [True] * 5


def _trajs(nees: np.ndarray) -> list[dict]:
    """One trajectory per row of ``nees`` (runs, times), every sample counted."""
    t = [float(k) for k in range(nees.shape[1])]
    return [{"t_s": t, "nees_pos": list(row), "nees_used": [True] * len(t)} for row in nees]


@pytest.mark.parametrize(("scale", "expect_inside"), [(1.0, True), (0.8, False)])
def test_nees_band_holds_95_percent_of_times_for_a_consistent_filter_only(scale, expect_inside):
    """Independent chi-square(3) NEES (closed-form oracle: a consistent filter) are inside the per-time
    band at a binomial(times, 0.95) fraction of the times; a filter whose covariance is 25 % too large
    (NEES x 0.8) is inside at few."""
    runs, times = 200, 400
    rng = np.random.default_rng(7)
    nees = scale * rng.chisquare(3, size=(runs, times))
    out = nees_consistency(_trajs(nees))
    assert out["samples"] == runs * times and out["times"] == times
    lo, hi = binom.ppf([0.0005, 0.9995], times, 0.95) / times  # 99.9 % interval of the inside fraction
    if expect_inside:
        assert lo <= out["fraction_times_inside_95"] <= hi
        assert out["mean_nees"] == pytest.approx(3.0, abs=0.03)
    else:
        assert out["fraction_times_inside_95"] < 0.1
        assert out["times_below"] > 0.9 * times
