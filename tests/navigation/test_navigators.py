"""The navigation registry: the choice of a vehicle's filter from its IMU (and a scenario's override,
refused when unknown or when the IMU lacks what the filter needs), and both filters behind one interface
solving the same problem: a vehicle at rest among four anchors, ranges, a distance difference, a landmark."""

from __future__ import annotations

import numpy as np
import pytest

from swarm.core.estimator import EstimatorParams, PoseEstimator, UpdateStatus
from swarm.core.imu_filter import ImuFilterParams
from swarm.errors import ConfigError
from swarm.navigation import NAVIGATORS, Eskf, Mekf, Navigator, navigator_name
from swarm.scenario import load_scenario

ANCHORS = np.array([[2.0, -1.0, 1.5], [2.0, 1.5, -1.0], [-2.0, 1.0, -1.5], [-1.5, -2.0, 1.0]])
P_TRUE = np.array([0.3, -0.2, 0.5])
P_START = P_TRUE + np.array([0.15, -0.1, 0.1])
SIGMAS0 = np.r_[np.full(3, 0.3**2), np.full(3, 0.05**2), np.full(3, 0.02**2)]
LEVEL = np.array([0.0, 0.0, 0.0, 1.0])
G = 9.81
DT = 0.01


def test_the_registry_holds_the_two_filters():
    assert sorted(NAVIGATORS) == ["eskf", "mekf"]
    assert all(issubclass(n, Navigator) for n in NAVIGATORS.values())


def test_the_filter_follows_the_imu_and_an_override_is_checked():
    assert navigator_name({"gyro"}) == "mekf"
    assert navigator_name({"gyro", "accelerometer"}) == "eskf"
    assert navigator_name({"gyro", "accelerometer"}, "mekf") == "mekf"  # a gyro is all the MEKF needs
    with pytest.raises(
        ConfigError, match=r"vehicles\.c\.navigation must be one of \['eskf', 'mekf'\], got 'ukf'"
    ):
        navigator_name({"gyro"}, "ukf", "vehicles.c")
    with pytest.raises(
        ConfigError, match=r"vehicles\.c\.navigation = 'eskf' needs an IMU that measures accel"
    ):
        navigator_name({"gyro"}, "eskf", "vehicles.c")


def _mekf() -> Mekf:
    est = Mekf.create(EstimatorParams(), P_START, np.zeros(3), LEVEL, SIGMAS0, n_anchors=4)
    est.anchors = ANCHORS
    return est


def _eskf() -> Eskf:
    prm = ImuFilterParams(range_bias=False, range_common_offset=False, range_gm=False)
    return Eskf.create(prm, ANCHORS, P_START, np.zeros(3), LEVEL, 0.0, 0.02,
                       (0.3, 0.05, 0.02, 0.05, 0.005, 0.1))  # fmt: skip


def _lever(nav) -> np.ndarray:
    return np.asarray(nav.params.lever_arm_body_m if isinstance(nav, Mekf) else nav.params.lever_arm_m)


@pytest.mark.parametrize("make", [_mekf, _eskf], ids=["mekf", "eskf"])
def test_both_filters_converge_through_the_interface(make):
    """4 s at rest at 100 Hz, one 2 cm range a tick round-robin: the estimate within 5 cm of the truth (it
    starts 20 cm off) and its position sigma below 3 cm (it starts at 30 cm; each filter's process noise
    holds it at 0.6-2 cm with these anchors, and the errors, 1-2 cm, are within it); then a distance
    difference and a landmark are accepted, and a range 1 m long is rejected by the gate."""
    nav = make()
    rng = np.random.default_rng(0)
    tag = P_TRUE + _lever(nav)  # level attitude: the tag is the lever arm off the centre of mass
    for k in range(400):
        assert (
            nav.propagate(DT, np.zeros(3), accel_body=np.array([0.0, 0.0, G]), a_known_nav=np.zeros(3)) == 0
        )
        a = k % 4
        r = np.linalg.norm(tag - ANCHORS[a]) + 0.02 * rng.standard_normal()
        assert nav.fuse_range(a, r, 0.02).status in (UpdateStatus.ACCEPTED, UpdateStatus.REJECTED_OUTLIER)
    s = nav.state()
    assert np.linalg.norm(s.p_nav - P_TRUE) < 0.05, s.p_nav
    P = nav.covariance()
    assert P.shape == (9, 9) and np.sqrt(np.max(np.diag(P)[:3])) < 0.03
    d = np.linalg.norm(tag - ANCHORS[2]) - np.linalg.norm(tag - ANCHORS[0])
    assert nav.fuse_tdoa(0, 2, d, 0.05).status == UpdateStatus.ACCEPTED
    R_bc = np.diag([1.0, -1.0, -1.0])  # both default cameras look down body -z
    cam = np.asarray(nav.params.camera_pos_body_m if isinstance(nav, Mekf) else nav.cam_pos_body_m)
    p_mark = P_TRUE + np.array([0.1, 0.05, -1.0])
    f = R_bc.T @ (p_mark - P_TRUE - cam)
    fused = nav.fuse_landmark(p_mark, f, 0.005)
    assert fused.status == UpdateStatus.ACCEPTED and fused.d2 < 20.0, fused
    far = nav.fuse_range(1, np.linalg.norm(tag - ANCHORS[1]) + 1.0, 0.02)
    assert far.status == UpdateStatus.REJECTED_OUTLIER and far.d2 > 100.0, (
        far
    )  # 1 m against a ~2 cm innovation sigma


def test_the_eskf_needs_the_specific_force():
    with pytest.raises(ValueError, match="specific force"):
        _eskf().propagate(DT, np.zeros(3))


def test_the_docking_mekf_is_the_pose_estimator_it_replaces():
    """Bit for bit: the registry's docking filter has the arrays ``PoseEstimator.create`` gave the agent."""
    sc = load_scenario("docking")
    p0, q0, cov0 = np.array([1.0, 0.5, -0.2]), np.array([0.1, 0.0, 0.0, 0.99498743710662]), np.full(9, 1e-3)
    nav = NAVIGATORS[sc.navigation("chaser")].for_docking(sc, "chaser", p0, np.zeros(3), q0, cov0)
    ref = PoseEstimator.create(
        sc.estimator_for("chaser"), p0, np.zeros(3), q0, cov0, n_anchors=len(sc.anchors_m)
    )
    assert isinstance(nav, Mekf)
    for name in ("X", "P", "counts", "book", "_prm", "_cam_pos", "_R_bc", "_q_bc"):
        assert np.array_equal(getattr(nav, name), getattr(ref, name)), name
    with pytest.raises(
        ConfigError, match=r"vehicles\.chaser\.navigation = 'eskf': the docking runners cannot"
    ):
        Eskf.for_docking(sc, "chaser", p0, np.zeros(3), q0, cov0)


def test_a_scenario_names_a_vehicle_navigator_and_a_bad_one_is_refused_naming_the_file(tmp_path):
    from tests.test_scenario import load_variant

    assert load_variant(tmp_path, "vehicles.chaser", "navigation", '"mekf"').navigation("chaser") == "mekf"
    assert load_scenario("docking").navigation("target") == "mekf"  # a cube's gyro-only IMU: the MEKF
    with pytest.raises(ConfigError) as err:
        load_variant(tmp_path, "vehicles.chaser", "navigation", '"ukf"')
    msg = str(err.value)
    assert ".toml: vehicles.chaser.navigation must be one of ['eskf', 'mekf'], got 'ukf'" in msg, msg
    assert "(at line " in msg, msg
    # a cube with the IMU-driven filter: its IMU has no accelerometer (and the docking runners run the MEKF)
    with pytest.raises(
        ConfigError, match=r"vehicles\.chaser\.navigation = 'eskf' needs an IMU that measures"
    ):
        load_variant(tmp_path, "vehicles.chaser", "navigation", '"eskf"')
