"""Tests for swarm.core.mdp: the fixed and Algorithm 1 (MDP) switchers and the stationary distributions.

Oracles: hand-computed Algorithm 1 passes (the arithmetic is in the comments, with the default MdpParams:
r_t = 1.0 m, r_d = 0.12 m, sigma_UWB = 0.02 m, r1 <- 0.1, r2 <- 0.3, thresholds 0.4 / 0.6), the 2-state
closed form, a 3-state chain solved by hand, scipy's eigenvector of A^T for eigenvalue 1, and pi A = pi.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st

from swarm.core.mdp import (
    DECISION_KEYS,
    FixedParams,
    FixedSwitcher,
    MdpParams,
    MdpSwitcher,
    fig4_transition_matrix,
    make_switcher,
    reorient_align_probabilities,
    stationary_2state,
    stationary_distribution,
    steady_state_probabilities,
)
from swarm.errors import ConfigError
from tests.budget import examples

DESIGN_KEYS = {
    "t_s", "r_m", "d", "qe_vec_norm", "sigma_pos_max_m", "sigma_uwb_m", "r_t_m", "r_d_m",
    "A11", "A22", "A23", "A32", "A33", "pi1", "pi2", "r1_m", "r2_m",
}  # fmt: skip  # written by hand from the paper's Algorithm 1, independent of DECISION_KEYS


# ------------------------------------------------------------------------------------------- Algorithm 1


def test_a11_at_most_threshold_sets_r2_to_range():
    # A11 = (r / r_t) * 1 / (1 + d) * 1 / ||q_e|| = (0.62 / 1.0) * (1 / 2) * (1 / 0.8) = 0.62 * 0.625 = 0.3875
    # 0.3875 <= 0.4 -> r2 <- r = 0.62
    sw = MdpSwitcher()
    dec = sw.evaluate(t_s=10.0, r_m=0.62, d=1.0, qe_vec_norm=0.8, sigma_pos_max_m=0.05)
    assert dec is not None
    assert dec.branch == "A11"
    assert dec.A11 == pytest.approx(0.3875, abs=1e-12)
    assert dec.switched == "r2"
    assert sw.r2_m == 0.62 and dec.r2_m == 0.62
    assert sw.r1_m == 0.1
    assert "reorient at r=0.62 m" in dec.reason


def test_a11_exactly_at_threshold_switches():
    # A11 = (0.8 / 1.0) * (1 / 2) * (1 / 1) = 0.4, exact in binary (0.8 / 2 is an exact halving);
    # "<=" switches
    sw = MdpSwitcher()
    dec = sw.evaluate(t_s=0.0, r_m=0.8, d=1.0, qe_vec_norm=1.0, sigma_pos_max_m=0.05)
    assert dec.A11 == 0.4
    assert dec.switched == "r2" and sw.r2_m == 0.8


def test_a11_above_threshold_keeps_r2():
    # A11 = (0.9 / 1.0) * (1 / 2) * (1 / 0.9) = 0.5 > 0.4 -> no switch, r2 stays 0.3
    sw = MdpSwitcher()
    dec = sw.evaluate(t_s=0.0, r_m=0.9, d=1.0, qe_vec_norm=0.9, sigma_pos_max_m=0.05)
    assert dec.A11 == pytest.approx(0.5, abs=1e-12)
    assert dec.switched is None
    assert sw.r2_m == 0.3 and dec.r2_m == 0.3


def test_pi2_at_most_threshold_sets_r1_to_range():
    # r = 0.21 <= r2 = 0.3, d = 0:
    #   A22 = (0.21 / 0.3) * 1 = 0.7, A23 = 0.3
    #   A32 = (0.02 / 0.02) * (0.3 - 0.21) / (0.3 - 0.12) = 1 * 0.09 / 0.18 = 0.5, A33 = 0.5
    #   pi = (A32, A23) / (A23 + A32) = (0.5, 0.3) / 0.8 = (0.625, 0.375); 0.375 <= 0.6 -> r1 <- 0.21
    sw = MdpSwitcher()
    dec = sw.evaluate(t_s=5.0, r_m=0.21, d=0.0, qe_vec_norm=0.1, sigma_pos_max_m=0.02)
    assert dec.branch == "A22"
    np.testing.assert_allclose([dec.A22, dec.A23, dec.A32, dec.A33], [0.7, 0.3, 0.5, 0.5], atol=1e-12)
    np.testing.assert_allclose([dec.pi1, dec.pi2], [0.625, 0.375], atol=1e-12)
    assert dec.switched == "r1"
    assert sw.r1_m == 0.21 and dec.r1_m == 0.21
    assert sw.r2_m == 0.3


def test_pi2_above_threshold_keeps_r1():
    # As above with sigma_pos = 0.004: A32 = 0.2 * 0.5 = 0.1, A33 = 0.9
    #   pi = (0.1, 0.3) / 0.4 = (0.25, 0.75); 0.75 > 0.6 -> no switch, r1 stays 0.1
    sw = MdpSwitcher()
    dec = sw.evaluate(t_s=5.0, r_m=0.21, d=0.0, qe_vec_norm=0.1, sigma_pos_max_m=0.004)
    np.testing.assert_allclose([dec.A32, dec.A33], [0.1, 0.9], atol=1e-12)
    np.testing.assert_allclose([dec.pi1, dec.pi2], [0.25, 0.75], atol=1e-12)
    assert dec.switched is None
    assert sw.r1_m == 0.1


def test_align_branch_uses_the_r2_picked_earlier():
    # First pass: A11 = 0.3875 -> r2 = 0.62 (as above). Second pass at r = 0.37, d = 0.25, sigma_pos = 0.03:
    #   A22 = (0.37 / 0.62) / 1.25 = 0.37 / 0.775 = 74/155, A23 = 81/155
    #   A32 = (0.03 / 0.02) * (0.62 - 0.37) / (0.62 - 0.12) = 1.5 * 0.5 = 0.75, A33 = 0.25
    #   pi2 = A23 / (A23 + A32) = (81/155) / (81/155 + 3/4) = 324 / 789 = 0.41065; <= 0.6 -> r1 <- 0.37
    sw = MdpSwitcher()
    sw.evaluate(t_s=0.0, r_m=0.62, d=1.0, qe_vec_norm=0.8, sigma_pos_max_m=0.05)
    dec = sw.evaluate(t_s=1.0, r_m=0.37, d=0.25, qe_vec_norm=0.2, sigma_pos_max_m=0.03)
    assert dec.A22 == pytest.approx(74 / 155, abs=1e-12)
    assert dec.A32 == pytest.approx(0.75, abs=1e-12)
    assert dec.pi2 == pytest.approx(324 / 789, abs=1e-12)
    assert dec.switched == "r1" and sw.r1_m == 0.37 and sw.r2_m == 0.62


def test_no_decision_beyond_activation_radius():
    sw = MdpSwitcher()
    assert sw.evaluate(t_s=0.0, r_m=1.0001, d=0.0, qe_vec_norm=1.0, sigma_pos_max_m=1.0) is None
    assert sw.decisions == [] and sw.r2_m == 0.3 and sw.r1_m == 0.1


def test_decision_at_exactly_the_activation_radius():
    # "while r <= r_t": r = r_t is evaluated. A11 = 1 * 1 * (1 / 0.5) = 2 -> clipped to 1, no switch
    sw = MdpSwitcher()
    dec = sw.evaluate(t_s=0.0, r_m=1.0, d=0.0, qe_vec_norm=0.5, sigma_pos_max_m=0.0)
    assert dec is not None and dec.A11 == 1.0 and dec.switched is None


def test_no_decision_at_or_inside_r1():
    sw = MdpSwitcher()
    assert sw.evaluate(t_s=0.0, r_m=0.1, d=0.0, qe_vec_norm=1.0, sigma_pos_max_m=1.0) is None  # r == r1
    assert sw.evaluate(t_s=0.0, r_m=0.05, d=0.0, qe_vec_norm=1.0, sigma_pos_max_m=1.0) is None
    assert sw.decisions == []


def test_no_decision_once_inside_the_r1_just_picked():
    sw = MdpSwitcher()
    sw.evaluate(t_s=5.0, r_m=0.21, d=0.0, qe_vec_norm=0.1, sigma_pos_max_m=0.02)  # r1 <- 0.21 (see above)
    assert sw.evaluate(t_s=6.0, r_m=0.2, d=0.0, qe_vec_norm=0.1, sigma_pos_max_m=0.02) is None
    assert len(sw.decisions) == 1


def test_a11_clipped_to_one():
    # d = 0, ||q_e|| = 1e-3: A11 = 0.5 * 1 * 1000 = 500 -> 1
    dec = MdpSwitcher().evaluate(t_s=0.0, r_m=0.5, d=0.0, qe_vec_norm=1e-3, sigma_pos_max_m=0.0)
    assert dec.A11 == 1.0


def test_zero_attitude_error_gives_a11_one_and_no_switch():
    dec = MdpSwitcher().evaluate(t_s=0.0, r_m=0.35, d=50.0, qe_vec_norm=0.0, sigma_pos_max_m=0.0)
    assert dec.A11 == 1.0 and dec.switched is None


def test_a32_clipped_to_one_and_a33_from_clipped_value():
    # r = 0.21: A32 = (0.1 / 0.02) * 0.5 = 2.5 -> 1, A33 = 1 - 1 = 0 (not 1 - 2.5)
    # A22 = 0.7, A23 = 0.3 -> pi = (1, 0.3) / 1.3, pi2 = 0.2308 -> switch
    dec = MdpSwitcher().evaluate(t_s=0.0, r_m=0.21, d=0.0, qe_vec_norm=0.1, sigma_pos_max_m=0.1)
    assert dec.A32 == 1.0 and dec.A33 == 0.0
    assert dec.pi2 == pytest.approx(0.3 / 1.3, abs=1e-12)


def test_every_probability_in_unit_interval_for_extreme_inputs():
    rng = np.random.default_rng(3)
    for _ in range(300):
        sw = MdpSwitcher()
        r = rng.uniform(0.1001, 1.0)
        dec = sw.evaluate(
            t_s=0.0,
            r_m=r,
            d=10.0 ** rng.uniform(-6, 3),
            qe_vec_norm=10.0 ** rng.uniform(-9, 0),
            sigma_pos_max_m=10.0 ** rng.uniform(-6, 1),
        )
        vals = [v for v in (dec.A11, dec.A22, dec.A23, dec.A32, dec.A33, dec.pi1, dec.pi2) if v is not None]
        assert all(0.0 <= v <= 1.0 for v in vals), dec


def test_identity_chain_records_no_pi_and_does_not_switch():
    # r = r2 = 0.3, d = 0: A22 = 1, A23 = 0; A32 = ratio * 0 / 0.18 = 0 -> chain is the identity
    sw = MdpSwitcher()
    dec = sw.evaluate(t_s=0.0, r_m=0.3, d=0.0, qe_vec_norm=0.5, sigma_pos_max_m=0.05)
    assert (dec.A22, dec.A23, dec.A32, dec.A33) == (1.0, 0.0, 0.0, 1.0)
    assert dec.pi1 is None and dec.pi2 is None
    assert dec.switched is None and sw.r1_m == 0.1


def test_nonpositive_reorient_span_takes_full_distance_fraction():
    # r2 - r_d <= 0 cannot happen with validated MdpParams; the helper treats the fraction as 1:
    # A32 = (0.01 / 0.02) * 1 = 0.5
    _, _, a32, a33 = reorient_align_probabilities(0.1, 0.1, 0.0, 0.01, sigma_uwb_m=0.02, r_d_m=0.12)
    assert (a32, a33) == (0.5, 0.5)


def test_invalid_inputs_name_the_argument():
    sw = MdpSwitcher()
    with pytest.raises(ValueError, match="d must be a finite number"):
        sw.evaluate(t_s=0.0, r_m=0.5, d=float("nan"), qe_vec_norm=0.5, sigma_pos_max_m=0.01)
    with pytest.raises(ValueError, match="sigma_pos_max_m must be non-negative"):
        sw.evaluate(t_s=0.0, r_m=0.5, d=0.0, qe_vec_norm=0.5, sigma_pos_max_m=-0.01)


# ----------------------------------------------------------------------------------------------- records


def test_a11_record_has_exactly_design_keys_with_none_for_align_branch():
    dec = MdpSwitcher().evaluate(t_s=1.5, r_m=0.62, d=1.0, qe_vec_norm=0.8, sigma_pos_max_m=0.05)
    rec = dec.as_dict()
    assert set(rec) == DESIGN_KEYS and len(rec) == len(DESIGN_KEYS)
    assert all(rec[k] is None for k in ("A22", "A23", "A32", "A33", "pi1", "pi2"))
    assert rec["A11"] == pytest.approx(0.3875)
    assert rec == {
        **rec,
        "t_s": 1.5, "r_m": 0.62, "d": 1.0, "qe_vec_norm": 0.8, "sigma_pos_max_m": 0.05,
        "sigma_uwb_m": 0.02, "r_t_m": 1.0, "r_d_m": 0.12, "r1_m": 0.1, "r2_m": 0.62,
    }  # fmt: skip


def test_align_record_has_none_for_a11_and_is_json_serialisable():
    dec = MdpSwitcher().evaluate(t_s=5.0, r_m=0.21, d=0.0, qe_vec_norm=0.1, sigma_pos_max_m=0.02)
    rec = dec.as_dict()
    assert set(rec) == DESIGN_KEYS
    assert rec["A11"] is None and rec["pi2"] == pytest.approx(0.375)
    assert json.loads(json.dumps(rec)) == rec


def test_diagnostic_record_adds_branch_switched_reason():
    dec = MdpSwitcher().evaluate(t_s=5.0, r_m=0.21, d=0.0, qe_vec_norm=0.1, sigma_pos_max_m=0.02)
    rec = dec.as_dict(diagnostics=True)
    assert set(rec) == DESIGN_KEYS | {"branch", "switched", "reason"}
    assert (rec["branch"], rec["switched"]) == ("A22", "r1")
    assert rec["reason"] == "pi2=0.375 <= 0.6: align at r=0.21 m"
    assert set(DECISION_KEYS) == DESIGN_KEYS


def test_every_pass_is_recorded_in_order():
    sw = MdpSwitcher()
    ranges = [1.2, 0.95, 0.7, 0.5, 0.25, 0.15, 0.09]  # 1.2 > r_t and 0.09 <= r1: not recorded
    for i, r in enumerate(ranges):
        sw.evaluate(t_s=float(i), r_m=r, d=0.5, qe_vec_norm=0.9, sigma_pos_max_m=0.001)
    assert [dec.t_s for dec in sw.decisions] == [1.0, 2.0, 3.0, 4.0, 5.0]


# ------------------------------------------------------------------------------------ fixed and factory


def test_fixed_switcher_keeps_constant_radii_and_records_nothing():
    sw = FixedSwitcher()
    for r in (1.5, 0.8, 0.5, 0.3, 0.1):
        assert sw.evaluate(t_s=0.0, r_m=r, d=100.0, qe_vec_norm=1.0, sigma_pos_max_m=1.0) is None
        assert (sw.r2_m, sw.r1_m) == (0.8, 0.3)
    assert sw.decisions == []


def test_factory_builds_the_named_policy():
    mdp = MdpParams(r_t_m=1.5)
    fixed = FixedParams(r2_m=0.9, r1_m=0.4)
    s_mdp = make_switcher("mdp", mdp, fixed)
    s_fixed = make_switcher("fixed", mdp, fixed)
    assert isinstance(s_mdp, MdpSwitcher) and s_mdp.params is mdp
    assert isinstance(s_fixed, FixedSwitcher) and (s_fixed.r2_m, s_fixed.r1_m) == (0.9, 0.4)


def test_factory_error_names_the_bad_policy():
    with pytest.raises(ConfigError, match="'markov'"):
        make_switcher("markov", MdpParams(), FixedParams())


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"r_t_m": 0.2}, "mdp.r_t_m"),  # below r2_init = 0.3
        ({"r_d_m": 0.3}, "mdp.r_d_m"),  # not below r2_init
        ({"r1_init_m": 0.3}, "mdp.r1_init_m"),
        ({"a11_threshold": 1.5}, "mdp.a11_threshold"),
        ({"sigma_uwb_m": 0.0}, "mdp.sigma_uwb_m"),
    ],
)
def test_mdp_params_errors_name_the_field(kwargs, field):
    with pytest.raises(ConfigError, match=field):
        MdpParams(**kwargs)


def test_fixed_params_error_names_the_field():
    with pytest.raises(ConfigError, match=r"fixed\.r1_m"):
        FixedParams(r2_m=0.3, r1_m=0.8)


# ------------------------------------------------------------------------------ stationary distributions


def test_three_state_chain_against_hand_solution():
    # pi A = pi for A = [[0.6, 0.4, 0], [0.2, 0.5, 0.3], [0.1, 0, 0.9]]:
    #   column 2: pi2 = 0.4 pi1 + 0.5 pi2        -> pi2 = 0.8 pi1
    #   column 3: pi3 = 0.3 pi2 + 0.9 pi3        -> pi3 = 3 pi2 = 2.4 pi1
    #   column 1: 0.4 pi1 = 0.2 pi2 + 0.1 pi3 = 0.16 pi1 + 0.24 pi1   (consistent)
    #   sum: 4.2 pi1 = 1 -> pi = (5, 4, 12) / 21
    A = [[0.6, 0.4, 0.0], [0.2, 0.5, 0.3], [0.1, 0.0, 0.9]]
    np.testing.assert_allclose(stationary_distribution(A), np.array([5, 4, 12]) / 21, atol=1e-14)


def test_two_state_closed_form_by_hand():
    # a12 = 0.3, a21 = 0.5: pi = (0.5, 0.3) / 0.8 = (0.625, 0.375)
    assert stationary_2state(0.3, 0.5) == pytest.approx((0.625, 0.375), abs=1e-15)


def test_general_solver_matches_two_state_closed_form_on_random_chains():
    rng = np.random.default_rng(7)
    a = rng.uniform(0.0, 1.0, size=(500, 2))
    a[:20, 0] = 0.0  # absorbing state 1 (unique distribution (1, 0)) included on purpose
    for a12, a21 in a:
        if a12 + a21 == 0.0:
            continue
        A = np.array([[1 - a12, a12], [a21, 1 - a21]])
        np.testing.assert_allclose(stationary_distribution(A), stationary_2state(a12, a21), atol=1e-12)


def test_two_state_closed_form_is_none_for_identity():
    assert stationary_2state(0.0, 0.0) is None


@st.composite
def stochastic_matrices(draw: st.DrawFn) -> np.ndarray:
    """Random row-stochastic n x n (n = 1..8), some entries zeroed; kept irreducible by a positive cycle."""
    n = draw(st.integers(1, 8))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    A = rng.dirichlet(np.ones(n), size=n) * (rng.uniform(size=(n, n)) > 0.4)
    A[np.arange(n), (np.arange(n) + 1) % n] += rng.uniform(0.05, 1.0, size=n)  # cycle 0->1->...->0
    return A / A.sum(axis=1, keepdims=True)


@settings(max_examples=examples(200), deadline=None)
@given(stochastic_matrices())
def test_stationary_distribution_is_invariant_and_normalised(A):
    pi = stationary_distribution(A)
    assert np.all(pi >= 0.0)
    assert pi.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(pi @ A, pi, atol=1e-10)


@settings(max_examples=examples(100), deadline=None)
@given(stochastic_matrices())
def test_stationary_distribution_matches_scipy_eigenvector(A):
    w, vl = scipy.linalg.eig(A, left=True, right=False)
    v = np.real(vl[:, np.argmin(np.abs(w - 1.0))])
    np.testing.assert_allclose(stationary_distribution(A), v / v.sum(), atol=1e-9)


def test_transient_state_gets_zero_probability():
    # one closed class {2}; state 1 is transient -> unique pi = (0, 1)
    np.testing.assert_allclose(stationary_distribution([[0.5, 0.5], [0.0, 1.0]]), [0.0, 1.0], atol=1e-15)


def test_periodic_chain_has_unique_distribution():
    np.testing.assert_allclose(stationary_distribution([[0.0, 1.0], [1.0, 0.0]]), [0.5, 0.5], atol=1e-15)


@pytest.mark.parametrize(
    "A",
    [
        np.eye(3),
        [[0.5, 0.5, 0.0, 0.0], [0.5, 0.5, 0.0, 0.0], [0.0, 0.0, 0.2, 0.8], [0.0, 0.0, 0.7, 0.3]],
    ],
    ids=["identity", "two-closed-classes"],
)
def test_reducible_chain_raises(A):
    with pytest.raises(ValueError, match="no unique stationary distribution"):
        stationary_distribution(A)


@pytest.mark.parametrize(
    ("A", "message"),
    [
        ([[0.5, 0.5]], "square"),
        ([[0.5, 0.6], [0.5, 0.5]], "row 0 sums to"),
        ([[1.5, -0.5], [0.5, 0.5]], r"probabilities in \[0, 1\]"),
        ([[np.nan, 1.0], [0.5, 0.5]], "finite"),
    ],
)
def test_invalid_transition_matrix_raises_naming_the_problem(A, message):
    with pytest.raises(ValueError, match=message):
        stationary_distribution(A)


def test_fig4_chain_puts_zero_on_transient_approach():
    # APPROACH leaves for good when A11 < 1; the rest is the Algorithm 1 example above, pi = (0.625, 0.375)
    pi = stationary_distribution(fig4_transition_matrix(0.9, 0.7, 0.5))
    np.testing.assert_allclose(pi, [0.0, 0.625, 0.375], atol=1e-12)


# ------------------------------------------------------------------------------------ section V-D helper


def test_steady_state_probabilities_match_switcher_example():
    # the pi2 <= 0.6 example: r = 0.21, r2 = 0.3, d = 0, sigma_pos = 0.02 -> (0.625, 0.375)
    np.testing.assert_allclose(steady_state_probabilities(0.02, 0.21, 0.3), [0.625, 0.375], atol=1e-12)


def test_steady_state_probabilities_best_vs_worst_case_sigma():
    # best 0.004 m, worst 0.02 m (both from the hand examples): pi_align 0.75 vs 0.375
    pi = steady_state_probabilities(np.array([0.004, 0.02]), 0.21, 0.3)
    assert pi.shape == (2, 2)
    np.testing.assert_allclose(pi[:, 1], [0.75, 0.375], atol=1e-12)


def test_steady_state_probabilities_align_decreases_with_sigma():
    pi_align = steady_state_probabilities(np.linspace(0.0, 0.05, 50), 0.2, 0.5, d=0.3)[:, 1]
    assert np.all(np.diff(pi_align) <= 0.0) and pi_align[-1] < pi_align[0]


def test_steady_state_probabilities_nan_where_not_unique():
    pi = steady_state_probabilities(0.05, 0.3, 0.3, d=0.0)  # the identity chain of the switcher test
    assert np.all(np.isnan(pi))
