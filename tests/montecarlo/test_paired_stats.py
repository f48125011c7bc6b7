"""The one paired comparison of every campaign (:func:`swarm.montecarlo.stats.paired`) against a hand
computation: the differences 1, 2, 3, 4 of four runs that both policies finished.

By hand: mean 2.5, sample standard deviation sqrt(5/3), t = 2.5 / (sqrt(5/3) / 2) = sqrt(15) on 3 degrees of
freedom; the 95 % interval 2.5 +- t_{0.975,3} sqrt(5/3) / 2 with t_{0.975,3} = 3.182446 (Student's table);
the two-sided p of the t-test from the closed-form CDF of t with 3 degrees of freedom,
F(t) = 1/2 + (theta + sin(theta) cos(theta)) / pi, theta = atan(t / sqrt(3)); the exact Wilcoxon signed-rank
p with four positive differences, 2 / 2^4 (only one of the 16 sign patterns has W+ = 10, doubled).
"""

from __future__ import annotations

import math

import pytest

from swarm.montecarlo.stats import paired, success

T_975_3 = 3.182446  # Student's t table, 0.975 quantile, 3 degrees of freedom


def _landing_rows() -> list[dict]:
    """Rows as a landing campaign has them (no ``chaser`` column): four complete pairs and three that are
    not pairs for ``paired``."""
    rows = []
    for run, base in enumerate((10.0, 20.0, 30.0, 40.0)):
        rows.append({"run": run, "policy": "fixed", "landed": True, "energy_j": base})
        rows.append({"run": run, "policy": "mdp", "landed": True, "energy_j": base + run + 1.0})
    rows.append({"run": 4, "policy": "fixed", "landed": False, "energy_j": 1.0})  # one did not land
    rows.append({"run": 4, "policy": "mdp", "landed": True, "energy_j": 900.0})
    rows.append({"run": 5, "policy": "fixed", "landed": True, "energy_j": 1.0})  # no mdp run yet
    rows.append({"run": 6, "policy": "fixed", "landed": True, "energy_j": None})  # no value
    rows.append({"run": 6, "policy": "mdp", "landed": True, "energy_j": 900.0})
    return rows[::-1]  # file order does not matter


def test_paired_equals_the_hand_computation():
    d = paired(_landing_rows(), "fixed", "mdp", "energy_j", key="landed")
    sd = math.sqrt(5.0 / 3.0)
    assert d["n"] == 4
    assert d["mean_diff"] == pytest.approx(2.5, rel=1e-15)
    assert d["std_diff"] == pytest.approx(sd, rel=1e-15)
    half = T_975_3 * sd / 2.0
    assert d["ci95"] == pytest.approx([2.5 - half, 2.5 + half], rel=1e-6)  # the table's 7 digits
    assert d["relative"] == pytest.approx(2.5 / 25.0, rel=1e-15)  # against the mean of 10, 20, 30, 40
    theta = math.atan(math.sqrt(15.0) / math.sqrt(3.0))
    p_hand = 1.0 - 2.0 / math.pi * (theta + math.sin(theta) * math.cos(theta))
    assert d["p_value"] == pytest.approx(p_hand, rel=1e-9)
    assert d["wilcoxon_p_value"] == pytest.approx(2.0 / 16.0, rel=1e-12)


def test_paired_pairs_each_chaser_with_itself():
    """Docking rows carry a chaser: run 0's chaser b pairs with run 0's chaser b, never with a."""
    rows = [
        {"run": 0, "chaser": "a", "policy": "fixed", "docked": True, "t": 1.0},
        {"run": 0, "chaser": "b", "policy": "fixed", "docked": True, "t": 100.0},
        {"run": 0, "chaser": "a", "policy": "mdp", "docked": True, "t": 2.0},
        {"run": 0, "chaser": "b", "policy": "mdp", "docked": True, "t": 104.0},
    ]
    d = paired(rows, "fixed", "mdp", "t")  # docked is the default success key
    assert d["n"] == 2 and d["mean_diff"] == 2.5  # (1 + 4) / 2; a cross pairing would give +-51.5


def test_success_counts_under_the_mission_s_key_with_the_exact_interval():
    rows = _landing_rows()
    s = success(rows, "landed")
    assert (s["n"], s["landed"], s["rate"]) == (13, 12, 12 / 13)
    # Clopper-Pearson: the upper bound of k of n is the Beta(k + 1, n - k) quantile 0.975; Beta(13, 1)
    # has the CDF x^13, so for 12 of 13 it is 0.975^(1/13)
    assert s["ci95"][1] == pytest.approx(0.975 ** (1.0 / 13.0), rel=1e-9)
    assert 0.0 < s["ci95"][0] < 12 / 13
