"""The in-process runner's compiled inner loop changes nothing but speed."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.scenario import load_scenario
from swarm.sim.docking import DockingSim


@pytest.mark.parametrize(("policy", "seed"), [("fixed", 4), ("mdp", 5)])
def test_compiled_inner_loop_gives_the_per_tick_run_bit_for_bit(policy, seed):
    sc = load_scenario("docking")
    fast = DockingSim(sc, policy, seed, record_series=True, fast=True).run()
    slow = DockingSim(sc, policy, seed, record_series=True, fast=False).run()
    a, b = fast["chasers"]["chaser"], slow["chasers"]["chaser"]
    assert a["docked"] and b["docked"]
    for key in (
        "docking_time_s",
        "total_impulse_ns",
        "position_error_m",
        "attitude_error_rad",
        "r1_m",
        "r2_m",
        "closest_approach_m",
    ):
        assert a[key] == b[key], key
    assert a["modes"] == b["modes"]
    assert a["estimator"] == b["estimator"]
    for key in ("p_true_nav", "p_est_nav", "q_est_nav_body", "cov_pos"):
        assert np.array_equal(np.asarray(a["series"][key]), np.asarray(b["series"][key])), key
    assert fast["target_impulse_ns"] == slow["target_impulse_ns"]


def test_compiled_inner_loop_sees_keepout_and_faults_like_the_per_tick_path():
    """With NLOS outliers and dropouts (faults change the UWB path through the compiled exchange) the two
    paths still agree exactly."""
    sc = load_scenario(
        "docking", {"uwb.nlos_probability": 0.1, "uwb.dropout_probability": 0.05, "sim.max_duration_s": 60.0}
    )
    fast = DockingSim(sc, "mdp", 7, record_series=False, fast=True).run()["chasers"]["chaser"]
    slow = DockingSim(sc, "mdp", 7, record_series=False, fast=False).run()["chasers"]["chaser"]
    assert fast["estimator"] == slow["estimator"]
    assert fast["estimator"]["rejected_ranges"] > 0
    assert fast["modes"] == slow["modes"] and fast["total_impulse_ns"] == slow["total_impulse_ns"]


def test_closest_approach_is_the_closest_truth_outside_the_corridor_modes():
    """``closest_approach_m`` is the minimum true centre distance over the ticks flown outside DOCK/DOCKED/
    ABORT: never above the minimum of the recorded truth series over those modes' samples (a subset of the
    ticks), and no more than one series period of approach-speed travel below it."""
    sc = load_scenario("docking")
    res = DockingSim(sc, "mdp", 5, record_series=True, fast=True).run()["chasers"]["chaser"]
    s = res["series"]
    p_t = np.asarray(sc.vehicles["target"].position_m)
    d = np.linalg.norm(np.asarray(s["p_true_nav"]) - p_t, axis=1)
    outside = np.array([m not in ("DOCK", "DOCKED", "ABORT") for m in s["mode"]])
    series_min = d[outside].min()
    step = sc.sim.series_every * sc.dt_s * 2 * sc.guidance.approach_speed_m_s
    assert series_min - step <= res["closest_approach_m"] <= series_min
    assert res["closest_approach_m"] > sc.guidance.keepout_radius_m
