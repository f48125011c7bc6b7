"""The "pose" camera model (swarm.core.camera.pose_frame): an on-board PnP's pose and covariance.

Oracles: the pixel Jacobian (itself checked against OpenCV's projectPoints in test_camera.py) for the
covariance, chi-square bounds for the seeded Monte Carlo consistency of the draws (Bar-Shalom, Li &
Kirubarajan 2001, sec. 5.4), and OpenCV's solvePnP on noisy pixels (the "pnp" model) for what the
first-order model stands in for.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from swarm.core._noise_nb import noise_key
from swarm.core.camera import (
    POSE_N,
    CameraModel,
    CameraParams,
    MarkerParams,
    face_normal,
    pixel_jacobian,
    pose_frame,
    project_markers,
    relative_pose,
    solve_pnp,
)
from tests.core.test_camera import _rotation_error_rad, _scene

CAM = CameraParams(model=CameraModel.POSE)
MARKERS = MarkerParams()
KEY = np.uint64(noise_key(11, 1, 3))


def _frame(scene, counter, face="+z"):
    p_cam, q_cam, p_t, q_t = scene
    n = face_normal(face)
    out = np.full(POSE_N, np.nan)
    ok = pose_frame(MARKERS.markers(face), MARKERS.half_size_m * n, n, p_t, q_t, p_cam, q_cam,
                    np.array(CAM.visibility_vector), CAM.pixel_sigma_px, KEY, counter, out)  # fmt: skip
    return ok, out


def test_a_frame_reports_the_first_order_pnp_covariance_at_the_true_pose():
    scene = _scene(0.4, (0.2, -0.1, 0.3), (0.02, -0.01))
    ok, out = _frame(scene, 0)
    assert ok
    t_true, q_true = relative_pose(*scene)
    J = pixel_jacobian(MARKERS.markers("+z"), t_true, q_true, CAM)
    expected = CAM.pixel_sigma_px**2 * np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(out[7:].reshape(6, 6), expected, rtol=1e-9, atol=1e-15)
    assert out[6] >= 0.0 and abs(np.linalg.norm(out[3:7]) - 1.0) < 1e-12


def test_the_draws_are_consistent_with_the_reported_covariance():
    """Errors of 2000 frames at 0.4 m: mean zero and average NEES inside the two-sided 99 % chi-square(6 N)
    / N interval (a wrong perturbation side or a missing Cholesky factor moves it far outside)."""
    scene = _scene(0.4, (0.3, 0.1, -0.2), (0.03, 0.02))
    t_true, q_true = relative_pose(*scene)
    runs = 2000
    err = np.empty((runs, 6))
    nees = np.empty(runs)
    for k in range(runs):
        ok, out = _frame(scene, k)
        assert ok
        err[k] = np.r_[out[0:3] - t_true, _rotation_error_rad(out[3:7], q_true)]
        nees[k] = err[k] @ np.linalg.solve(out[7:].reshape(6, 6), err[k])
    lo, hi = chi2.ppf([0.005, 0.995], 6 * runs) / runs
    assert lo < nees.mean() < hi, f"average NEES {nees.mean():.2f} outside [{lo:.2f}, {hi:.2f}]"
    sd = np.sqrt(np.diag(out[7:].reshape(6, 6)))
    assert np.all(np.abs(err.mean(axis=0)) < 4 * sd / np.sqrt(runs))  # unbiased within 4 sigma


def test_the_pose_model_matches_solvepnp_on_noisy_pixels_where_the_first_order_model_holds():
    """The point of the model: at 0.3 m (the ground docking's vision range) the spread of OpenCV's PnP
    on 0.5 px pixels is the spread the pose model draws: each axis's standard deviation within 15 % (400
    runs: the sampling error of a standard deviation is 3.5 %, so 15 % is over 4 sigma of both)."""
    scene = _scene(0.3, (0.2, -0.1, 0.0))
    t_true, q_true = relative_pose(*scene)
    m = MARKERS.markers("+z")
    p_cam, q_cam, p_t, q_t = scene
    clean = project_markers(m, p_t, q_t, p_cam, q_cam, CAM, None)
    rng = np.random.default_rng(5)
    runs = 400
    e_pnp = np.empty((runs, 6))
    e_pose = np.empty((runs, 6))
    for k in range(runs):
        res = solve_pnp(clean + CAM.pixel_sigma_px * rng.standard_normal(clean.shape), m, CAM)
        e_pnp[k] = np.r_[res.t_cam_m - t_true, _rotation_error_rad(res.q_cam_target, q_true)]
        _, out = _frame(scene, k)
        e_pose[k] = np.r_[out[0:3] - t_true, _rotation_error_rad(out[3:7], q_true)]
    ratio = e_pose.std(axis=0) / e_pnp.std(axis=0)
    assert np.all(np.abs(ratio - 1.0) < 0.15), ratio


@pytest.mark.parametrize("case", ["too far", "behind", "face turned away"])
def test_no_frame_when_the_face_is_not_visible(case):
    if case == "too far":
        scene = _scene(CAM.max_range_m + 0.1)
    elif case == "behind":
        p_cam, q_cam, p_t, q_t = _scene(0.3)
        flip = Rotation.from_quat(q_cam) * Rotation.from_rotvec([np.pi, 0.0, 0.0])
        scene = (p_cam, flip.as_quat(), p_t, q_t)
    else:
        p_cam, q_cam, p_t, q_t = _scene(0.3)
        scene = (p_cam, q_cam, p_t, (Rotation.from_quat(q_t) * Rotation.from_rotvec([np.pi, 0, 0])).as_quat())
    ok, out = _frame(scene, 0)
    assert not ok
    assert np.all(np.isnan(out))  # nothing written


def test_frames_of_other_counters_or_keys_differ_and_repeat_exactly():
    scene = _scene(0.4)
    _, a = _frame(scene, 3)
    _, b = _frame(scene, 3)
    _, c = _frame(scene, 4)
    assert np.array_equal(a, b)
    assert not np.array_equal(a[:7], c[:7])
    np.testing.assert_array_equal(a[7:], c[7:])  # the covariance is the geometry's, not the draw's
