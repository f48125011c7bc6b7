"""Pad vision (swarm.core.pad_vision): the rendered image is what a camera would see (the detector finds the
markers where the scenario says and nowhere else), the PnP covariance matches the pose error, and the cheap
corner mode agrees with the rendered one in distribution."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from swarm.core import rotations as rot
from swarm.core.pad_vision import (
    PadBoardParams,
    PadCameraParams,
    Renderer,
    corner_frame,
    detect,
    estimate_pose,
    make_detector,
    pose_error,
    project_corners,
)
from swarm.errors import ConfigError

BOARD = PadBoardParams()
CAM = PadCameraParams()


@pytest.fixture(scope="module")
def renderer():
    return Renderer(BOARD, CAM)


@pytest.fixture(scope="module")
def detector():
    return make_detector(BOARD)


def above(alt_m, tilt_deg=0.0, yaw_deg=0.0, offset_m=(0.0, 0.0)):
    """The pad's pose in a downward camera at ``alt_m`` above the point ``offset_m`` of the pad, tilted
    about its x axis and turned about the vertical: ``(t_cam_m, q_cam_pad)``."""
    down = rot.quat_mul(np.array([1.0, 0.0, 0.0, 0.0]), rot.rotvec_exp(np.radians([tilt_deg, 0.0, 0.0])))
    q_pad_cam = rot.quat_mul(rot.rotvec_exp(np.radians([0.0, 0.0, yaw_deg])), down)
    q_cam_pad = rot.quat_conj(q_pad_cam)
    return -rot.quat_rotate(q_cam_pad, np.array([offset_m[0], offset_m[1], alt_m])), q_cam_pad


def random_pose(rng, lo, hi):
    alt = rng.uniform(lo, hi)
    return above(alt, rng.uniform(-15, 15), rng.uniform(0, 360), rng.uniform(-0.15, 0.15, 2) * alt)


def test_every_marker_is_found_with_its_id_close_up(renderer, detector):
    rng = np.random.default_rng(0)
    t, q = above(1.0, 5.0, 20.0)
    ids, corners = detect(renderer.render(t, q, rng), BOARD, detector)
    assert sorted(ids.tolist()) == sorted(BOARD.markers[0].tolist())  # the four and the centre marker
    truth = project_corners(BOARD, CAM, t, q)
    index = {int(i): k for k, i in enumerate(BOARD.markers[0])}
    err = np.concatenate([corners[k] - truth[index[int(i)]] for k, i in enumerate(ids)])
    assert np.sqrt(np.mean(err**2)) < 0.4  # sub-pixel: the corners are where the projection puts them


def test_the_markers_are_detected_over_the_claimed_range_and_not_outside_the_frustum(renderer, detector):
    """Claimed: the board is detected from 0.5 m to 7 m with up to 15 deg of tilt (the corner mode's
    min_marker_px = 12 is a 0.2 m marker at 8.3 m)."""
    rng = np.random.default_rng(1)
    for lo, hi in ((0.5, 2.0), (2.0, 4.0), (4.0, 7.0)):
        seen_r = seen_c = 0
        for _ in range(15):
            t, q = random_pose(rng, lo, hi)
            seen_r += len(detect(renderer.render(t, q, rng), BOARD, detector)[0]) > 0
            seen_c += len(corner_frame(BOARD, CAM, t, q, rng)[0]) > 0
        assert seen_r >= 14 and seen_c >= 14, (lo, hi, seen_r, seen_c)
    for t, q in (
        above(2.0, offset_m=(2.0, 0.0)),  # 45 deg off the axis: outside the 65 deg lens
        above(2.0, tilt_deg=60.0),  # looking away
        above(20.0),
    ):  # too far: 5 px markers
        assert len(detect(renderer.render(t, q, rng), BOARD, detector)[0]) == 0
        assert len(corner_frame(BOARD, CAM, t, q, rng)[0]) == 0
    t, q = above(-2.0)  # the pad behind the camera
    assert len(corner_frame(BOARD, CAM, t, q, rng)[0]) == 0


def _nees(frames, mode, renderer, detector, rng):
    out, errs = [], []
    for t, q in frames:
        if mode == "rendered":
            ids, corners = detect(renderer.render(t, q, rng), BOARD, detector)
        else:
            ids, corners = corner_frame(BOARD, CAM, t, q, rng)
        est = estimate_pose(ids, corners, BOARD, CAM)
        if est is None:
            continue
        e = pose_error(est, t, q)
        out.append(float(e @ np.linalg.solve(est.cov_cam, e)))
        errs.append(e)
    return np.array(out), np.array(errs)


@pytest.mark.parametrize("mode", ["rendered", "corners"])
def test_the_pnp_pose_error_matches_its_covariance(mode, renderer, detector):
    """60 frames from 0.5 to 4 m: the mean 6-dof NEES of a consistent estimate is chi-square(360) / 60, whose
    99 % band is [4.7, 7.5]; the rendered mode's corner noise is a fitted model (its residual misfit and
    the pose's nonlinearity at range), so its band is widened to [4, 8.5]."""
    rng = np.random.default_rng(2)
    frames = [random_pose(rng, 0.5, 4.0) for _ in range(60)]
    nees, _ = _nees(frames, mode, renderer, detector, rng)
    assert len(nees) >= 57
    lo, hi = chi2.ppf([0.005, 0.995], 6 * len(nees)) / len(nees)
    if mode == "rendered":
        lo, hi = 4.0, 8.5
    assert lo <= nees.mean() <= hi


def test_the_corner_mode_agrees_with_the_rendered_one_in_distribution(renderer, detector):
    """The same 80 poses from 1 to 4 m in both modes. Their NEES samples are one distribution (two-sample
    Kolmogorov-Smirnov, p > 0.01: measured 0.08-0.56 over four seeds); the translation error spreads
    (robust: 1.4826 MAD) agree within a factor 1.6 (the ratio of two 80-sample MADs spreads +-30 % at
    95 %); and both detect the board in the same frames but for a few. Not asserted, and said in the
    module docstring: the rendered attitude errors are smaller than the white-noise corner model makes them
    (a detected marker's four corners err together), so the corner mode is conservative in attitude."""
    from scipy.stats import ks_2samp

    rng = np.random.default_rng(3)
    frames = [random_pose(rng, 1.0, 4.0) for _ in range(80)]
    nr, er = _nees(frames, "rendered", renderer, detector, rng)
    nc, ec = _nees(frames, "corners", renderer, detector, rng)
    assert ks_2samp(nr, nc).pvalue > 0.01

    def mad(e):
        return 1.4826 * np.median(np.abs(e - np.median(e, axis=0)), axis=0)

    ratio = mad(er[:, :3]) / mad(ec[:, :3])
    assert np.all((ratio > 1 / 1.6) & (ratio < 1.6)), ratio
    assert abs(len(er) - len(ec)) <= 3


def test_a_bad_board_or_camera_is_refused_naming_the_field():
    with pytest.raises(ConfigError, match=r"^pad\.pitch_m must exceed marker_size_m"):
        PadBoardParams(pitch_m=0.1)
    with pytest.raises(ConfigError, match=r"^pad\.dictionary"):
        PadBoardParams(dictionary="DICT_NOPE")
    with pytest.raises(ConfigError, match=r"^pad_camera\.distortion"):
        PadCameraParams(distortion=(0.0, 0.0))
