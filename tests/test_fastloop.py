"""The in-process runner's compiled inner loop (swarm.step.tick.run_ticks) changes nothing but speed: for
each vehicle kind, with dispersions and faults (fixed and mode-triggered) on, it gives the per-tick run bit
for bit."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.scenario import load_scenario
from swarm.sim.docking import DockingSim

# every dispersion the shared table and each kind declare, and the issue-7 fault set (NLOS over the whole
# run, a dropout opened by REORIENT, the camera lost in ALIGN, a gyro step): runs that exercise every input
# of the step
DISPERSED = {
    "dispersions.position_sigma_m": 0.03, "dispersions.velocity_sigma_m_s": 0.001,
    "dispersions.attitude_sigma_deg": 2.0, "dispersions.mass_sigma_frac": 0.03,
    "dispersions.inertia_sigma_frac": 0.03,
}  # fmt: skip
FAULTS = {
    "uwb.nlos_probability": 0.05,
    "faults.uwb_dropout.on_mode": "REORIENT", "faults.uwb_dropout.duration_s": 4.0,
    "faults.camera_loss.on_mode": "ALIGN", "faults.camera_loss.duration_s": 3.0,
    "faults.gyro_bias_step_t_s": 20.0, "faults.gyro_bias_step_deg_s": [0.05, 0.0, -0.05],
}  # fmt: skip
CASES = {
    "cubesat": ("docking", {}),
    # staggered controller clocks (swarm.stagger_control): the chaser controls on ticks 3, 13, ..., the
    # target on 7, 17, ...; both idle until then
    "cubesat staggered": (
        "docking",
        {"vehicles.chaser.control_phase": 3, "vehicles.target.control_phase": 7},
    ),
    "cubesat dispersed, faults": (
        "docking",
        {
            **DISPERSED,
            **FAULTS,
            "kinds.cubesat.dispersions.thruster_misalignment_deg": 0.5,
            "estimator.accel_psd_m2_s3": 1e-8,
        },
    ),
    "ground": (
        "ground-docking",
        {"vehicles.chaser.position_m": [0.4, 0.3, 0.05], "vehicles.chaser.euler_deg": [0.0, 0.0, 90.0]},
    ),
    "ground pnp": (  # the pixel camera: frames built and PnP solved in Python, between compiled runs
        "ground-docking",
        {
            "camera.model": "pnp",
            "vehicles.chaser.position_m": [0.9, 0.4, 0.05],
            "vehicles.chaser.euler_deg": [0.0, 0.0, 20.0],
        },
    ),
    "ground dispersed, faults": (
        "ground-docking",
        {
            **DISPERSED,
            **FAULTS,
            "kinds.ground.dispersions.wheel_slip_sigma_frac": 0.05,
            "vehicles.chaser.position_m": [0.4, 0.3, 0.05],
            "vehicles.chaser.euler_deg": [0.0, 0.0, 90.0],
        },
    ),
}


# each kind plain and with every input of the step on, both policies and every camera model among them (a
# per-tick docking costs ~10 s of Python here: five cases, not every combination)
@pytest.mark.parametrize(("case", "policy", "seed"), [
    ("cubesat", "fixed", 4), ("cubesat dispersed, faults", "mdp", 6), ("cubesat staggered", "mdp", 1),
    ("ground", "mdp", 5), ("ground pnp", "mdp", 2), ("ground dispersed, faults", "fixed", 6),
])  # fmt: skip
def test_compiled_inner_loop_gives_the_per_tick_run_bit_for_bit(case, policy, seed):
    import warnings

    name, overrides = CASES[case]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the thrust-dispersion advice: heeded (q = 1e-8)
        sc = load_scenario(name, overrides)
    fast = DockingSim(sc, policy, seed, record_series=True, fast=True).run()
    slow = DockingSim(sc, policy, seed, record_series=True, fast=False).run()
    a, b = fast["chasers"]["chaser"], slow["chasers"]["chaser"]
    assert a["docked"] and b["docked"]
    if "faults" in case:  # every fault window opened, the mode-triggered ones included
        assert {e["fault"] for e in a["faults"]["events"]} == {"uwb_dropout", "camera_loss"}
        assert a["faults"] == b["faults"]
    for key in (
        "docking_time_s",
        "effort",
        "position_error_m",
        "attitude_error_rad",
        "r1_m",
        "r2_m",
        "closest_approach_m",
    ):
        assert a[key] == b[key], key
    assert a["modes"] == b["modes"]
    assert a.get("decisions") == b.get("decisions")  # every Algorithm 1 pass, staged or not
    assert a["estimator"] == b["estimator"]
    assert a["estimator"]["accepted_vision"] > 0
    for key in ("p_true_nav", "p_est_nav", "q_est_nav_body", "cov_pos"):
        assert np.array_equal(np.asarray(a["series"][key]), np.asarray(b["series"][key])), key
    assert fast["target_effort"] == slow["target_effort"]


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


def test_compiled_inner_loop_gives_the_per_tick_run_with_the_range_error_model():
    """The MEKF's range-error states (a common offset, per-anchor offsets and Gauss-Markov terms) under the
    real-crazyflie sensor profile: the compiled loop and the per-tick path (the one a launched agent runs)
    agree exactly, series included."""
    model = {"estimator.range_common_offset": True, "estimator.range_bias": True, "estimator.range_gm": True}
    sc = load_scenario("docking", {"sensors.profile": "real-crazyflie", "sim.max_duration_s": 40.0, **model})
    fast = DockingSim(sc, "mdp", 3, record_series=True, fast=True).run()["chasers"]["chaser"]
    slow = DockingSim(sc, "mdp", 3, record_series=True, fast=False).run()["chasers"]["chaser"]
    assert fast["estimator"] == slow["estimator"] and fast["estimator"]["accepted_ranges"] > 0
    assert fast["modes"] == slow["modes"] and fast["total_impulse_ns"] == slow["total_impulse_ns"]
    for key in ("p_est_nav", "cov_pos"):
        assert np.array_equal(np.asarray(fast["series"][key]), np.asarray(slow["series"][key])), key
