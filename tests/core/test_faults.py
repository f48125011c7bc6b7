"""Tests of swarm.core.faults and of the fault hooks of the sensor models (UWB exchange, world gyro and
camera): parameters, mode triggers, and each fault's footprint on the samples."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from swarm.core.faults import FaultParams, FaultSchedule, FaultWindows
from swarm.core.sensors import uwb_exchange
from swarm.errors import ConfigError
from swarm.scenario import Scenario
from swarm.step.radio import UwbNetwork, radio_env
from swarm.step.world import World

DT = 0.01


# ---- parameters -------------------------------------------------------------------------------------


def test_faults_are_off_by_default():
    assert not FaultParams().enabled and not FaultParams().mode_triggered


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"windows_s": ((2.0, 1.0),)}, "windows_s"),
        ({"windows_s": ((-1.0, 1.0),)}, "windows_s"),
        ({"on_mode": "DOCKING"}, "on_mode"),
        ({"delay_s": -1.0}, "delay_s"),
        ({"on_mode": "ALIGN", "duration_s": 0.0}, "duration_s"),
    ],
)
def test_bad_fault_window_names_the_field(kwargs, field):
    with pytest.raises(ConfigError, match=field):
        FaultWindows(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"nlos_burst_probability": 1.5}, "nlos_burst_probability"),
        ({"gyro_bias_step_t_s": -2.0}, "gyro_bias_step_t_s"),
        ({"gyro_bias_step_deg_s": (0.0, math.nan, 0.0)}, "gyro_bias_step_deg_s"),
    ],
)
def test_bad_fault_params_name_the_field(kwargs, field):
    with pytest.raises(ConfigError, match=field):
        FaultParams(**kwargs)


# ---- mode triggers ----------------------------------------------------------------------------------


def test_mode_window_opens_at_the_tick_after_the_mode_change():
    p = FaultParams(uwb_dropout=FaultWindows(on_mode="REORIENT", delay_s=1.0, duration_s=5.0))
    s = FaultSchedule(p, DT, ["c"])
    assert not s.on_mode(10.0, "c", "APPROACH")
    assert s.on_mode(20.0, "c", "REORIENT")
    assert s.dropout_windows() == [pytest.approx((21.01, 26.01))]
    assert not s.on_mode(20.1, "c", "REORIENT")  # no change, no new window


def test_window_while_in_mode_closes_when_the_mode_ends():
    p = FaultParams(camera_loss=FaultWindows(on_mode="ALIGN", duration_s=100.0, while_in_mode=True))
    s = FaultSchedule(p, DT, ["c"])
    s.on_mode(30.0, "c", "ALIGN")
    assert s.camera_lost("c", 31.0)
    assert s.on_mode(40.0, "c", "DOCK")
    assert s.camera["c"] == [pytest.approx([30.01, 40.01])]
    assert s.camera_lost("c", 40.0) and not s.camera_lost("c", 40.01)


def test_first_entry_only_triggers_once_and_every_entry_triggers_again():
    once = FaultSchedule(FaultParams(uwb_dropout=FaultWindows(on_mode="REORIENT")), DT, ["c"])
    every = FaultSchedule(
        FaultParams(uwb_dropout=FaultWindows(on_mode="REORIENT", first_entry_only=False)), DT, ["c"]
    )
    for s in (once, every):
        for t, mode in ((1.0, "REORIENT"), (2.0, "HOLD"), (3.0, "REORIENT")):
            s.on_mode(t, "c", mode)
    assert len(once.dropout_windows()) == 1 and len(every.dropout_windows()) == 2


# ---- UWB exchange -----------------------------------------------------------------------------------


def _exchange(prm, t, z, drop=(), nlos=()):
    """One exchange at ``t`` in the radio environment of the dropout windows ``drop`` and NLOS bursts
    ``nlos`` (:func:`swarm.step.radio.radio_env`, what the world hands the radio step)."""
    lost, p = radio_env(
        t, np.array(drop, dtype=float).reshape(-1, 2), np.array(nlos, dtype=float).reshape(-1, 3)
    )
    return uwb_exchange(t, np.zeros(3), np.array([1.0, 0.0, 0.0]), z, 0.0, prm, lost, p)


def test_a_clear_channel_is_the_fault_free_exchange():
    prm = UwbNetwork(Scenario(), 0).prm
    z = np.array([0.3, 0.0, 1.0, 0.0])
    assert radio_env(0.5, np.zeros((0, 2)), np.zeros((0, 3))) == (False, 0.0)
    assert _exchange(prm, 0.5, z) == uwb_exchange(
        0.5, np.zeros(3), np.array([1.0, 0.0, 0.0]), z, 0.0, prm, False, 0.0
    )


def test_dropout_window_loses_every_reply_inside_and_none_outside():
    prm = UwbNetwork(Scenario(), 0).prm
    z = np.zeros(4)
    w = [(1.0, 2.0)]
    assert _exchange(prm, 1.0, z, w)[0] and _exchange(prm, 1.99, z, w)[0]
    assert not _exchange(prm, 0.99, z, w)[0] and not _exchange(prm, 2.0, z, w)[0]


def test_overlapping_nlos_bursts_take_the_largest_probability():
    nlos = np.array([[0.0, 10.0, 0.2], [5.0, 8.0, 0.6], [9.0, 12.0, 0.4]])
    assert radio_env(6.0, np.zeros((0, 2)), nlos) == (False, 0.6)
    assert radio_env(9.5, np.zeros((0, 2)), nlos) == (False, 0.4)
    assert radio_env(12.0, np.zeros((0, 2)), nlos) == (False, 0.0)


def test_nlos_burst_makes_outliers_at_its_probability_only_inside_the_window():
    prm = UwbNetwork(Scenario(), 0).prm
    rng = np.random.default_rng(3)
    zs = rng.standard_normal((4000, 4))
    burst = [(10.0, 20.0, 0.3)]
    inside = np.mean([_exchange(prm, 15.0, z, nlos=burst)[2] for z in zs])
    outside = np.mean([_exchange(prm, 25.0, z, nlos=burst)[2] for z in zs])
    # binomial(4000, 0.3): sigma = 0.0072, so +-0.03 is a > 4-sigma band
    assert inside == pytest.approx(0.3, abs=0.03)
    assert outside == 0.0


def test_nlos_burst_changes_no_random_draw_of_an_inlier():
    """Common random numbers: an exchange that is no outlier returns the very range of the fault-free one."""
    prm = UwbNetwork(Scenario(), 0).prm
    z = np.array([0.3, 0.0, 1.0, 0.0])  # the outlier uniform Phi(1) = 0.84 > 0.5: no outlier
    assert _exchange(prm, 0.5, z, nlos=[(0.0, 1.0, 0.5)]) == _exchange(prm, 0.5, z)


# ---- world: gyro step and camera loss ---------------------------------------------------------------


def test_gyro_bias_step_adds_exactly_the_step_from_its_time_on():
    step = (0.5, -0.2, 1.0)
    sc = Scenario()
    faulty = replace(sc, faults=FaultParams(gyro_bias_step_t_s=0.5, gyro_bias_step_deg_s=step))
    a, b = World(sc, 4), World(faulty, 4)
    for k in range(100):
        fa, fb = a.step()["chaser"], b.step()["chaser"]
        diff = fb.gyro_body - fa.gyro_body
        if (
            k + 1
        ) * DT <= 0.5 + 1e-9:  # the sample of tick k+1 averages [t_k, t_k+1]: stepped once t_k >= 0.5
            assert np.array_equal(diff, np.zeros(3)), k
        else:
            np.testing.assert_allclose(diff, np.radians(step), rtol=0, atol=1e-12)
        assert np.array_equal(b.gyro_out[1], a.gyro_out[1])  # the target has no step


def test_camera_loss_window_drops_frames_without_touching_the_camera_stream():
    from swarm.scenario import load_scenario

    sc = load_scenario("docking")
    # put the chaser right in front of the target's docking face, where it sees the markers
    lost = replace(sc, faults=FaultParams(camera_loss=FaultWindows(windows_s=((0.0, 0.06),))))
    worlds = [World(s, 1) for s in (sc, lost)]
    for w in worlds:
        xt = w.x["target"]
        from swarm.core.guidance import docking_geometry

        n_nav, _, q_dock = docking_geometry(sc.guidance, xt[0:3], xt[6:10])
        w.x["chaser"][0:3] = xt[0:3] + 0.3 * n_nav
        w.x["chaser"][6:10] = q_dock
    seen = [[], []]
    for _ in range(10):
        for j, w in enumerate(worlds):
            fr = w.step()["chaser"]
            if w.k % w.vision_every == 0:
                seen[j].append(fr.vision)
    assert all(v is not None for v in seen[0])
    assert seen[1][0] is None and worlds[1].camera_frames_lost == 1  # t = 0.05: lost
    assert np.array_equal(seen[1][1], seen[0][1])  # t = 0.10: back, the same noise as without the fault
