"""Faults in the closed loop (issue 7): each fault's footprint on a docking run, the compiled fast path
honouring mode-triggered faults bit for bit, and a small Monte Carlo of the issue's fault set ending
docked or safely aborted, never with a keep-out violation."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.montecarlo.campaign import CampaignSpec, read_runs, read_trajectories, run_campaign
from swarm.montecarlo.faults import classify, fault_summary
from swarm.scenario import load_scenario
from swarm.sim.docking import DockingSim

SEED = 3
# the camera lost for the whole of ALIGN (the bundled scenario loses it for its first 10 s only, in which
# the target may not come into view at all), and DOCK allowed without vision, so that frames with the
# target in view are really dropped and the run still goes on to DOCK
OVERRIDES = {"faults.camera_loss.duration_s": 400.0, "guidance.dock_requires_vision": False}


def _logged_sim(sc, seed: int) -> tuple[DockingSim, list[float], list[float]]:
    """A per-tick (``fast=False``) sim whose UWB ranges and accepted vision updates of the chaser are
    logged by time."""
    sim = DockingSim(sc, "mdp", seed, record_series=True, fast=False)
    ranges, vision = [], []
    net_step = sim.network.step

    def step(k, t, truth, *env):
        out = net_step(k, t, truth, *env)
        if "chaser" in out:
            ranges.append(t)
        return out

    sim.network.step = step
    agent = sim.agents["chaser"]
    on_vision = agent.on_vision

    def vision_update(t, kind, data):
        status = on_vision(t, kind, data)
        vision.append(t)
        return status

    agent.on_vision = vision_update
    return sim, ranges, vision


@pytest.fixture(scope="module")
def faulty_run():
    sc = load_scenario("docking-faults", OVERRIDES)
    sim, ranges, vision = _logged_sim(sc, SEED)
    res = sim.run()["chasers"]["chaser"]
    return sim, res, np.asarray(ranges), np.asarray(vision)


def test_no_range_arrives_during_the_dropout_that_reorient_triggered(faulty_run):
    _, res, ranges, _ = faulty_run
    t_reorient = next(m["t_s"] for m in res["modes"] if m["mode"] == "REORIENT")
    (start, end), *_ = res["faults"]["uwb_dropout_s"]
    assert start == pytest.approx(t_reorient + 0.01) and end == pytest.approx(start + 5.0)
    assert not np.any((ranges >= start) & (ranges < end))
    # the chaser ranges at 50 Hz round robin on either side of the window (NLOS outliers are ranges too)
    assert np.sum((ranges >= start - 1.0) & (ranges < start)) >= 45
    assert np.sum((ranges >= end) & (ranges < end + 1.0)) >= 45


def test_the_position_covariance_grows_through_the_dropout(faulty_run):
    _, res, _, _ = faulty_run
    s = res["series"]
    (start, end), *_ = res["faults"]["uwb_dropout_s"]
    t = np.asarray(s["t_s"])
    tr = np.trace(np.asarray(s["cov_pos"]), axis1=1, axis2=2)
    inside = tr[(t >= start + 0.05) & (t < end)]
    assert np.all(np.diff(inside) > 0)  # prediction only: the covariance can only grow


def test_no_vision_update_while_the_camera_is_lost_in_align(faulty_run):
    sim, res, _, vision = faulty_run
    (start, end), *_ = res["faults"]["camera_loss_s"]
    modes = [(m["mode"], m["t_s"]) for m in res["modes"]]
    t_align = next(t for m, t in modes if m == "ALIGN")
    t_next = next(t for m, t in modes if t > t_align)
    # from the tick after ALIGN began until the tick after it ended (OVERRIDES: longer than ALIGN)
    assert start == pytest.approx(t_align + 0.01) and end == pytest.approx(t_next + 0.01)
    assert not np.any((vision >= start) & (vision < end))
    assert sim.world.camera_frames_lost > 0  # the target was in view: frames were really dropped
    assert np.any(vision >= end)  # the camera is back for DOCK


def test_fast_path_gives_the_per_tick_run_with_mode_triggered_faults(faulty_run):
    _, slow, _, _ = faulty_run
    sc = load_scenario("docking-faults", OVERRIDES)
    fast = DockingSim(sc, "mdp", SEED, record_series=True, fast=True).run()["chasers"]["chaser"]
    for key in ("docked", "docking_time_s", "total_impulse_ns", "modes", "estimator", "faults"):
        assert fast[key] == slow[key], key
    for key in ("p_true_nav", "p_est_nav", "cov_pos"):
        assert np.array_equal(np.asarray(fast["series"][key]), np.asarray(slow["series"][key])), key


def test_gyro_bias_step_in_the_closed_loop_matches_per_tick_and_changes_the_run():
    over = {"faults.gyro_bias_step_t_s": 20.0, "faults.gyro_bias_step_deg_s": [0.0, 0.0, 0.5]}
    sc = load_scenario("docking", {**over, "sim.max_duration_s": 40.0})
    fast = DockingSim(sc, "mdp", 1, record_series=True, fast=True).run()["chasers"]["chaser"]
    slow = DockingSim(sc, "mdp", 1, record_series=True, fast=False).run()["chasers"]["chaser"]
    nominal = DockingSim(load_scenario("docking", {"sim.max_duration_s": 40.0}), "mdp", 1).run()
    q = np.asarray(fast["series"]["q_est_nav_body"])
    assert np.array_equal(q, np.asarray(slow["series"]["q_est_nav_body"]))
    t = np.asarray(fast["series"]["t_s"])
    q_nom = np.asarray(nominal["chasers"]["chaser"]["series"]["q_est_nav_body"])
    assert np.array_equal(q[t <= 20.0], q_nom[t <= 20.0])  # bit for bit before the step
    assert not np.array_equal(q[t > 20.0], q_nom[t > 20.0])


def test_small_campaign_of_the_issue_fault_set_docks_or_aborts_safely(tmp_path):
    """8 seeded runs of the issue's fault set (10 % NLOS, 5 s dropout in REORIENT, camera lost in ALIGN):
    every one docks or aborts without a keep-out violation or collision (the requirement is 100 %, so the
    threshold is every run), and the NEES is computed over the samples outside the dropout."""
    sc = load_scenario("docking-faults")
    run_campaign(CampaignSpec(sc, ("mdp",), 8, 0), tmp_path / "c", workers=2, progress=False)
    rows, trajs = read_runs(tmp_path / "c"), read_trajectories(tmp_path / "c")
    assert len(rows) == 8
    assert all(classify(r) in ("docked", "aborted") for r in rows)
    assert not any(r["keepout_violated"] or r["collided"] for r in rows)
    summary = fault_summary(rows, trajs)["mdp"]
    assert summary["failed"] == 0 and summary["docked"] + summary["aborted"] == 8
    # each trajectory excludes its dropout samples from the NEES
    for tr in trajs:
        (a, b), *_ = tr["faults"]["uwb_dropout_s"]
        inside = [u for t, u in zip(tr["t_s"], tr["nees_used"], strict=True) if a <= t < b]
        assert inside and not any(inside)
    assert summary["nees"]["samples"] > 100


# ---- consistency of the chaser's position estimate in the closed loop -------------------------------------


def _run_means_t_test(means: np.ndarray, dof: int = 3, alpha: float = 1e-3) -> tuple[float, float]:
    """``(mean, half-width)``: the mean over independent runs of each run's time-averaged NEES and the
    two-sided ``1 - alpha`` Student-t half-width around it. The runs are independent (one seed each),
    so the t-test of "expected NEES = dof" is exact up to the central limit theorem, whereas the samples
    inside one run are strongly correlated (the error of a filter with a small process noise decorrelates
    over tens of seconds), which is why the run, not the sample, is the unit here."""
    from scipy.stats import t as student

    n = means.size
    half = float(student.ppf(1 - alpha / 2, n - 1) * means.std(ddof=1) / np.sqrt(n))
    return float(means.mean()), half


def test_chaser_position_nees_is_consistent_in_the_closed_loop_on_uwb():
    """32 seeded runs of the fault-free docking, the first 40 s (APPROACH on UWB, no vision): the mean of
    the runs' time-averaged position NEES is 3 (the chi-square mean for 3 dof) within a 99.9 % t-interval
    of the run-to-run spread. Measured: 3.09 +- 0.65 (s = 1.01 over runs); the tuning before issue 7
    (accel_psd 1e-6, a covariance ~25 % too large) gives 2.39 +- 0.27 (s = 0.42) and fails."""
    sc = load_scenario("docking", {"sim.max_duration_s": 40.0})
    means = []
    for k in range(32):
        s = DockingSim(sc, "fixed", 100 + k).run()["chasers"]["chaser"]["series"]
        assert not any(s["relative_nav"])  # UWB navigation throughout
        e = np.asarray(s["p_est_nav"]) - np.asarray(s["p_true_nav"])
        nees = np.einsum("ki,ki->k", e, np.linalg.solve(np.asarray(s["cov_pos"]), e[..., None])[..., 0])
        means.append(nees[::10].mean())  # 1 s samples
    mean, half = _run_means_t_test(np.asarray(means))
    assert abs(mean - 3.0) <= half, f"mean NEES {mean:.2f} +- {half:.2f} excludes 3"


@pytest.mark.slow
def test_fault_campaign_is_safe_and_its_nees_consistent_outside_the_dropout(tmp_path):
    """The issue's campaign at 80 runs per policy: every run docked or aborted safely, and the position
    NEES (UWB navigation before the first vision update, outside the dropout) consistent: the mean of the
    runs' time-averaged NEES is 3 within a 99.9 % t-interval (see the fast test), and the ensemble mean
    inside its 95 % chi-square band at >= 75 % of the sample times. 95 % of the times is what a consistent
    filter gives on average, but neighbouring times 1 s apart are strongly correlated, so the observed
    fraction scatters widely around it (tests/core/test_estimator_statistics.py uses the same 75 %);
    measured at 100 runs: 92 % (fixed) and 92 % (mdp), against 28 % for the tuning before issue 7."""
    sc = load_scenario("docking-faults")
    run_campaign(CampaignSpec(sc, ("fixed", "mdp"), 80, 0), tmp_path / "c", workers=2, progress=False)
    rows, trajs = read_runs(tmp_path / "c"), read_trajectories(tmp_path / "c")
    summary = fault_summary(rows, trajs)
    for pol, s in summary.items():
        assert s["failed"] == 0 and s["docked"] + s["aborted"] == 80, pol
        assert s["nees"]["fraction_times_inside_95"] >= 0.75, (pol, s["nees"])
        means = []
        for tr in trajs:
            if tr["policy"] == pol:
                used = [v for v, u in zip(tr["nees_pos"], tr["nees_used"], strict=True) if u]
                means.append(np.mean(used))
        mean, half = _run_means_t_test(np.asarray(means))
        assert abs(mean - 3.0) <= half, f"{pol}: mean NEES {mean:.2f} +- {half:.2f} excludes 3"
