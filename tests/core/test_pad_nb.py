"""The compiled pad camera and pose solve (swarm.core._pad_nb) against their OpenCV references in
swarm.core.pad_vision.

Oracles: ``cv2.projectPoints`` and ``cv2.undistortPoints`` for the camera model; :func:`corner_frame` fed the
same seeded draws for the corner mode; for the pose, :func:`estimate_pose` (OpenCV's IPPE + Levenberg-
Marquardt) and, because OpenCV's LM stops at a relative step of FLT_EPSILON and converges only linearly in a
far board's weak tilt direction (it ends up to ~1e-4 m and ~1e-3 rad, rarely 0.1 rad, from its own
minimum), the same function with its refinement carried to convergence by Newton's method on OpenCV's own
gradient (``cv2.projectPoints``' Jacobian) with a finite-difference Hessian: an independent minimiser of
the same cost, whose covariance is then ``estimate_pose``'s own code at the exact minimum.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from swarm.core import _pad_nb as nb
from swarm.core import _pnp_nb as pnp
from swarm.core import pad_vision as pv
from swarm.core import rotations as rot
from swarm.core.pad_vision import PadBoardParams, PadCameraParams, corner_frame, estimate_pose
from swarm.landing_scenario import load_landing

_SC = load_landing("landing")
SETUPS = {
    "landing.toml": (_SC.pad.board, _SC.camera.intrinsics),
    "defaults": (PadBoardParams(), PadCameraParams()),
}
# every distortion term non-zero, for the camera model's tests
SKEWED = PadCameraParams(fx_px=480.0, fy_px=510.0, cx_px=325.0, cy_px=236.0,
                         distortion=(-0.12, 0.05, 0.002, -0.0015, -0.01))  # fmt: skip
_CV_REFINE_LM = cv2.solvePnPRefineLM


def pose_above(rng, alt_lo=0.3, alt_hi=7.0, tilt_max_deg=35.0, offset_frac=0.5):
    """A downward camera ``alt`` above a point of the pad up to ``offset_frac * alt`` off its centre,
    tilted up to ``tilt_max_deg`` about a random horizontal axis and turned by any yaw: the pad's pose in
    the camera ``(t_cam_m, q_cam_pad)``."""
    alt = rng.uniform(alt_lo, alt_hi)
    off = rng.uniform(-offset_frac, offset_frac, 2) * alt
    tilt = np.radians(rng.uniform(0.0, tilt_max_deg))
    axis = rng.uniform(0.0, 2 * np.pi)
    down = rot.quat_mul(
        np.array([1.0, 0.0, 0.0, 0.0]), rot.rotvec_exp(tilt * np.array([np.cos(axis), np.sin(axis), 0.0]))
    )
    q_pad_cam = rot.quat_mul(rot.rotvec_exp(np.array([0.0, 0.0, rng.uniform(0.0, 2 * np.pi)])), down)
    q_cam_pad = rot.quat_conj(q_pad_cam)
    return -rot.quat_rotate(q_cam_pad, np.array([off[0], off[1], alt])), q_cam_pad


def rot_diff(R1, R2) -> float:
    """Angle [rad] of ``R1 R2^T``, exact for small angles (``cv2.Rodrigues`` returns 0 below 1e-5)."""
    c = np.clip((np.trace(R1 @ R2.T) - 1.0) / 2.0, -1.0, 1.0)
    D = R1 @ R2.T
    s = 0.5 * np.linalg.norm([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]])
    return float(np.arctan2(s, c))


class Frames:
    """Preallocated arrays for one board, as a compiled loop holds them."""

    def __init__(self, board: PadBoardParams, cam: PadCameraParams) -> None:
        self.board, self.cam = board, cam
        self.cv = nb.camera_vector(cam)
        self.corners = np.ascontiguousarray(board.corners)
        m = len(self.corners)
        self.idx = np.empty(m, dtype=np.int64)
        self.px = np.empty((m, 4, 2))
        self.obj = np.empty((4 * m, 3))
        self.img = np.empty((4 * m, 2))
        self.var = np.empty(4 * m)
        self.t = np.empty(3)
        self.R = np.empty((3, 3))
        self.cov = np.empty((6, 6))

    def detect(self, t, q, Z, pos=0):
        R = rot.quat_to_matrix(q)
        K, pos = nb.corner_frame_nb(self.corners, R, np.asarray(t, float), self.cv, Z, pos, self.idx, self.px)
        return K, pos

    def solve(self, K):
        n = nb.pack_frame_nb(self.corners, self.idx, self.px, K, self.cv, self.obj, self.img, self.var)
        return n, pnp.solve_pose_nb(self.obj, self.img, self.var, n, self.cv, self.t, self.R, self.cov)

    def cost(self, n, R, t):
        return pnp._cost(self.obj, self.img, n, self.cv, R, np.asarray(t, float))


def _converged_refine(obj, img, K, dist, rvec, tvec, *args, **kwargs):
    """``cv2.solvePnPRefineLM``, then Newton's method on its cost ``|r|^2 / 2`` in ``(rvec, tvec)``: the
    gradient ``J^T r`` from ``cv2.projectPoints``, the Hessian by central differences of it, until the
    step is below 1e-13."""
    rvec, tvec = _CV_REFINE_LM(obj, img, K, dist, rvec, tvec, *args, **kwargs)
    obs = np.asarray(img, float).reshape(-1)

    def grad(x):
        p, J = cv2.projectPoints(obj, x[:3], x[3:], K, dist)
        return J[:, :6].T @ (p.reshape(-1) - obs)

    x = np.r_[rvec.ravel(), tvec.ravel()]
    for _ in range(30):
        H = np.empty((6, 6))
        for j in range(6):
            e = np.zeros(6)
            e[j] = 1e-6
            H[:, j] = (grad(x + e) - grad(x - e)) / 2e-6
        step = -np.linalg.solve(0.5 * (H + H.T), grad(x))
        x = x + step
        if np.linalg.norm(step) < 1e-13:
            break
    return x[:3].reshape(3, 1), x[3:].reshape(3, 1)


@pytest.fixture
def estimate_pose_converged(monkeypatch):
    """:func:`estimate_pose` with its LM refinement carried to convergence (module docstring)."""

    def run(ids, corners_px, board, cam):
        with monkeypatch.context() as m:
            m.setattr(pv.cv2, "solvePnPRefineLM", _converged_refine)
            return estimate_pose(ids, corners_px, board, cam)

    return run


# ---- the camera model -------------------------------------------------------------------------------------


def test_camera_vector_follows_the_layout():
    c = PadCameraParams(width_px=800, height_px=600, fx_px=1.0, fy_px=2.0, cx_px=3.0, cy_px=4.0,
                        distortion=(5.0, 6.0, 7.0, 8.0, 9.0), corner_sigma_px=10.0, corner_sigma_k_px2=11.0,
                        min_marker_px=12.0)  # fmt: skip
    v = nb.camera_vector(c)
    assert v.shape == (nb.CAM_N,) and v.dtype == np.float64
    expect = {nb.CAM_FX: 1, nb.CAM_FY: 2, nb.CAM_CX: 3, nb.CAM_CY: 4, nb.CAM_K1: 5, nb.CAM_K2: 6,
              nb.CAM_P1: 7, nb.CAM_P2: 8, nb.CAM_K3: 9, nb.CAM_WIDTH: 800, nb.CAM_HEIGHT: 600,
              nb.CAM_MIN_MARKER: 12, nb.CAM_SIGMA: 10, nb.CAM_SIGMA_K: 11}  # fmt: skip
    assert sorted(expect) == list(range(nb.CAM_N))
    assert all(v[i] == x for i, x in expect.items())


def test_project_point_matches_cv2_project_points():
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-1, 1, (2000, 2)), np.ones(2000)]) * rng.uniform(0.1, 10.0, (2000, 1))
    for cam in (SKEWED, PadCameraParams()):
        ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, cam.dist)
        mine = np.array([nb.project_point(nb.camera_vector(cam), *p) for p in pts])
        # the same polynomial in double precision: rounding is ~1e-13 px
        assert np.abs(mine - ref.reshape(-1, 2)).max() < 1e-9


def test_undistort_point_is_cv2_undistort_points_iteration():
    rng = np.random.default_rng(1)
    px = np.column_stack([rng.uniform(0, 639, 2000), rng.uniform(0, 479, 2000)])
    for cam in (SKEWED, PadCameraParams()):
        cv = nb.camera_vector(cam)
        mine = np.array([nb.undistort_point(cv, u, v) for u, v in px])
        crit = (cv2.TERM_CRITERIA_COUNT, nb.UNDISTORT_ITERS, 0.0)
        same = cv2.undistortPoints(px.reshape(-1, 1, 2), cam.K, cam.dist, None, None, None, crit)
        assert np.abs(mine - same.reshape(-1, 2)).max() < 1e-14  # the same iteration, step for step
        conv = cv2.undistortPoints(px.reshape(-1, 1, 2), cam.K, cam.dist, None, None, None,
                                   (cv2.TERM_CRITERIA_COUNT, 100, 0.0))  # fmt: skip
        assert np.abs(mine - conv.reshape(-1, 2)).max() < 1e-9  # converged, as far as it matters
        back = np.array([nb.project_point(cv, x, y, 1.0) for x, y in mine])
        assert np.abs(back - px).max() < 1e-6


# ---- the corner mode ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("setup", SETUPS)
def test_corner_frame_nb_equals_corner_frame_with_the_same_draws(setup):
    board, cam = SETUPS[setup]
    f = Frames(board, cam)
    ids = board.markers[0]
    rng = np.random.default_rng(2)
    seen = {"none": 0, "some": 0, "all": 0, "centre only": 0}
    for k in range(600):
        close = k % 3 == 0  # a third close to the pad, where markers leave the image
        t, q = pose_above(rng, 0.3, 0.6, 20.0, 0.3) if close else pose_above(rng)
        seed = int(rng.integers(2**31))
        ref_ids, ref_px = corner_frame(board, cam, t, q, np.random.default_rng(seed))
        Z = np.random.default_rng(seed).standard_normal(1000)
        K, pos = f.detect(t, q, Z)
        assert pos == 8 * K
        assert np.array_equal(ids[f.idx[:K]], ref_ids)
        if K:
            assert np.abs(f.px[:K] - ref_px).max() < 1e-9  # ~1e-13 seen
        seen["none" if K == 0 else "all" if K == len(ids) else "some"] += 1
        seen["centre only"] += K == 1 and f.idx[0] == len(ids) - 1
    assert min(seen.values()) >= 10, seen  # every case was exercised


def test_corner_frame_nb_continues_the_draw_stream():
    board, cam = SETUPS["defaults"]
    f = Frames(board, cam)
    rng = np.random.default_rng(3)
    poses = [pose_above(rng, 1.0, 3.0, 10.0, 0.1) for _ in range(5)]
    ref_rng = np.random.default_rng(42)
    Z = np.random.default_rng(42).standard_normal(500)
    pos = total = 0
    for t, q in poses:
        ref_ids, ref_px = corner_frame(board, cam, t, q, ref_rng)
        K, pos = f.detect(t, q, Z, pos)
        assert K == len(ref_ids) > 0
        assert np.abs(f.px[:K] - ref_px).max() < 1e-9
        total += K
    assert pos == 8 * total


def test_corner_frame_nb_refuses_a_short_draw_array():
    board, cam = SETUPS["defaults"]
    f = Frames(board, cam)
    t, q = pose_above(np.random.default_rng(4), 2.0, 2.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="fewer than"):
        f.detect(t, q, np.zeros(8 * len(f.corners) - 1))


def test_pack_frame_builds_estimate_poses_rows():
    board, cam = SETUPS["defaults"]
    f = Frames(board, cam)
    t, q = pose_above(np.random.default_rng(5), 1.5, 1.5, 5.0, 0.0)
    K, _ = f.detect(t, q, np.random.default_rng(6).standard_normal(100))
    n = nb.pack_frame_nb(f.corners, f.idx, f.px, K, f.cv, f.obj, f.img, f.var)
    assert n == 4 * K and K == len(f.corners)
    assert np.array_equal(f.obj[:n], board.corners[f.idx[:K]].reshape(-1, 3))
    assert np.array_equal(f.img[:n], f.px[:K].reshape(-1, 2))
    expect = np.repeat(cam.corner_sigma(pv._sides(f.px[:K])) ** 2, 4)  # estimate_pose's, per corner
    assert np.allclose(f.var[:n], expect, rtol=1e-14, atol=0)


# ---- the pose solve ---------------------------------------------------------------------------------------


def test_the_newton_system_is_the_costs_gradient_and_hessian():
    """``J^T r`` and ``J^T J + S`` against central differences of the cost pulled back through the
    retraction, with residuals large enough (30 px) that ``S`` matters."""
    board, cam = PadBoardParams(), SKEWED
    cv = nb.camera_vector(cam)
    obj = np.ascontiguousarray(board.corners.reshape(-1, 3))
    n = len(obj)
    t, q = pose_above(np.random.default_rng(7), 1.0, 1.0, 30.0, 0.1)
    R = rot.quat_to_matrix(q)
    img = np.array([nb.project_point(cv, *(R @ p + t)) for p in obj])
    img += np.random.default_rng(8).normal(0.0, 30.0, img.shape)
    A, b, B, S = np.empty((6, 6)), np.empty(6), np.empty((6, 6)), np.empty((6, 6))
    pnp._normal_equations(obj, img, np.empty(0), n, cv, R, t, A, b, B, S)

    def f(d):
        R2, t2 = np.empty((3, 3)), np.empty(3)
        pnp._retract(R, t, d, 1.0, R2, t2)
        return 0.5 * pnp._cost(obj, img, n, cv, R2, t2)

    h = 1e-5
    E = np.eye(6) * h
    g = np.array([(f(E[j]) - f(-E[j])) / (2 * h) for j in range(6)])
    H = np.array([[(f(E[j] + E[k]) - f(E[j] - E[k]) - f(E[k] - E[j]) + f(-E[j] - E[k])) / (4 * h * h)
                   for k in range(6)] for j in range(6)])  # fmt: skip
    assert np.abs(-b - g).max() < 1e-7 * np.abs(g).max()
    # the differences' error is ~1e-8 of the Hessian; S is ~1e-2 of it here
    assert np.abs(S).max() > 1e-3 * np.abs(A + S).max()
    assert np.abs(A + S - H).max() < 1e-6 * np.abs(H).max()


def _compare(f, K, ids, estimate_pose_converged):
    """solve_pose_nb against estimate_pose (plain and converged) on f's frame: the figures the tests
    check (both refuse nowhere in the envelope)."""
    board, cam = f.board, f.cam
    n, ok = f.solve(K)
    est = estimate_pose(ids, f.px[:K], board, cam)
    conv = estimate_pose_converged(ids, f.px[:K], board, cam)
    assert ok and est is not None and conv is not None
    R_est, R_conv = rot.quat_to_matrix(est.q_cam_pad), rot.quat_to_matrix(conv.q_cam_pad)
    return {
        "conv_dt": np.abs(f.t - conv.t_cam_m).max(),
        "conv_dr": rot_diff(f.R, R_conv),
        "conv_cov": np.linalg.norm(f.cov - conv.cov_cam) / np.linalg.norm(conv.cov_cam),
        "est_dt": np.abs(f.t - est.t_cam_m).max(),
        "est_dr": rot_diff(f.R, R_est),
        "cost": f.cost(n, f.R, f.t),
        "est_cost": f.cost(n, R_est, est.t_cam_m),
        "conv_cost": f.cost(n, R_conv, conv.t_cam_m),
        "rms": pnp.reproj_rms_nb(f.obj, f.img, n, f.cv, f.R, f.t),
        "conv_rms": conv.reproj_rms_px,
    }


def _check(rows):
    """The agreement a set of frames must show (thresholds: module docstring and the comments)."""
    conv = [r for r in rows if r["conv_dr"] < 1e-2]  # the minimum converged OpenCV found
    other = [r for r in rows if r["conv_dr"] >= 1e-2]  # OpenCV's IPPE ranked the other planar solution first
    # both minimise the same cost, to steps of 1e-12 (ours) and 1e-13 (Newton on OpenCV's gradient): seen
    # <= 1e-13 m and 1e-11 rad over 14000 frames
    assert max(r["conv_dt"] for r in conv) < 1e-9
    assert max(r["conv_dr"] for r in conv) < 1e-9
    # the same first-order covariance at the same pose from two Jacobians (OpenCV's in (rvec, tvec) mapped
    # through the left Jacobian, ours in (dt, dphi) directly): seen <= 2e-12 relative
    assert max(r["conv_cov"] for r in conv) < 1e-8
    assert max(abs(r["rms"] - r["conv_rms"]) for r in conv) < 1e-9
    # never a worse minimum than OpenCV's: where they differ ours has the lower cost (the planar ambiguity's
    # other minimum, which OpenCV's IPPE ranked first; ~0.15 % of the envelope's frames); the tolerance is
    # the costs' rounding (a 4-point fit's cost is ~1e-3 px^2)
    assert all(r["cost"] <= min(r["est_cost"], r["conv_cost"]) * (1 + 1e-9) + 1e-12 for r in rows)
    assert all(r["cost"] < r["conv_cost"] for r in other)
    assert len(other) <= 0.01 * len(rows)
    return conv


@pytest.mark.parametrize("setup", SETUPS)
def test_solve_pose_nb_matches_estimate_pose_over_the_landing_envelope(setup, estimate_pose_converged):
    board, cam = SETUPS[setup]
    f = Frames(board, cam)
    ids = board.markers[0]
    rng = np.random.default_rng(9)
    rows = []
    while len(rows) < 300:
        t, q = pose_above(rng)
        K, _ = f.detect(t, q, rng.standard_normal(8 * len(ids)))
        if K:
            rows.append(_compare(f, K, ids[f.idx[:K]], estimate_pose_converged))
    conv = _check(rows)
    # plain estimate_pose ends up to ~1e-4 m and ~1e-3 rad from the minimum: loose, but the same basin
    assert np.median([r["est_dt"] for r in conv]) < 1e-5


def test_solve_pose_nb_with_the_centre_marker_alone(estimate_pose_converged):
    board, cam = SETUPS["landing.toml"]
    f = Frames(board, cam)
    ids = board.markers[0]
    rng = np.random.default_rng(10)
    rows = []
    while len(rows) < 60:
        t, q = pose_above(rng, 0.3, 0.45, 20.0, 0.15)
        K, _ = f.detect(t, q, rng.standard_normal(8 * len(ids)))
        if K == 1 and f.idx[0] == len(ids) - 1:
            rows.append(_compare(f, K, ids[f.idx[:K]], estimate_pose_converged))
    _check(rows)


def _mirrored(R, t):
    """The pose whose plane normal is ``R``'s reflected about the line of sight to the pad's centre, which
    stays put: the planar ambiguity's other solution, to first order (Collins & Bartoli 2014 sec. 4)."""
    d = t / np.linalg.norm(t)
    n1 = R[:, 2]
    n2 = 2.0 * (n1 @ d) * d - n1
    axis = np.cross(n1, n2)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return R.copy()
    return rot.quat_to_matrix(rot.rotvec_exp(axis / s * np.arctan2(s, n1 @ n2))) @ R


def test_solve_pose_nb_takes_the_lower_of_the_two_planar_minima():
    """One far marker, where the planar ambiguity's two minima are closest in cost: the solve's cost is
    never above the minima reached from the truth and from its mirror image, and IPPE's first-ranked
    solution alone (OpenCV's choice) refines to the higher minimum in some frames (1.4 % in 2000)."""
    board, cam = SETUPS["defaults"]
    f = Frames(board, cam)
    rng = np.random.default_rng(11)
    out = (np.empty(3), np.empty((3, 3)), np.empty((6, 6)))
    Rs, ts, costs = np.empty((2, 3, 3)), np.empty((2, 3)), np.empty(2)

    def minimum(n, R0, t0):
        if not pnp.refine_pose_nb(f.obj, f.img, f.var, n, f.cv, R0, np.asarray(t0, float), *out):
            return np.inf
        return f.cost(n, out[1], out[0])

    frames = two_minima = missed = 0
    while frames < 500:
        t, q = pose_above(rng, 4.0, 7.0)
        K, _ = f.detect(t, q, rng.standard_normal(8 * len(f.corners)))
        if K != 1:
            continue
        frames += 1
        n, ok = f.solve(K)
        assert ok
        cost = f.cost(n, f.R, f.t)
        tol = cost * 1e-9 + 1e-12  # a fit of 4 points has costs ~1e-3 px^2, their rounding ~1e-14
        R = rot.quat_to_matrix(q)
        c_truth, c_mirror = minimum(n, R, t), minimum(n, _mirrored(R, np.asarray(t)), t)
        assert cost <= min(c_truth, c_mirror) + tol
        two_minima += abs(c_truth - c_mirror) > tol
        assert pnp.ippe_poses_nb(f.obj, f.img, n, f.cv, Rs, ts, costs) and costs[0] <= costs[1]
        missed += minimum(n, Rs[0], ts[0]) > cost + tol
    assert two_minima > frames / 2
    assert missed >= 1


def test_refine_pose_nb_from_a_nearby_pose_gives_the_solve():
    board, cam = SETUPS["defaults"]
    f = Frames(board, cam)
    t, q = pose_above(np.random.default_rng(12), 2.0, 2.0, 20.0, 0.2)
    K, _ = f.detect(t, q, np.random.default_rng(13).standard_normal(100))
    n, ok = f.solve(K)
    assert ok
    t2, R2, cov2 = np.empty(3), np.empty((3, 3)), np.empty((6, 6))
    R0 = rot.quat_to_matrix(rot.quat_mul(rot.rotvec_exp(np.array([0.02, -0.01, 0.03])), q))
    assert pnp.refine_pose_nb(f.obj, f.img, f.var, n, f.cv, R0, np.asarray(t) + 0.05, t2, R2, cov2)
    assert np.abs(t2 - f.t).max() < 1e-12 and rot_diff(R2, f.R) < 1e-12
    assert np.abs(cov2 - f.cov).max() < 1e-9 * np.abs(f.cov).max()


# ---- refusals: where estimate_pose returns None ---------------------------------------------------------


@pytest.fixture
def frame():
    """A good frame of the default board: (Frames, n)."""
    board, cam = SETUPS["defaults"]
    f = Frames(board, cam)
    t, q = pose_above(np.random.default_rng(14), 2.0, 2.0, 10.0, 0.1)
    K, _ = f.detect(t, q, np.random.default_rng(15).standard_normal(100))
    n, ok = f.solve(K)
    assert ok and K == len(f.corners)
    return f, n


def _solve(f, n, obj=None, img=None, var=None):
    obj = f.obj if obj is None else obj
    img = f.img if img is None else img
    var = f.var if var is None else var
    return pnp.solve_pose_nb(obj, img, var, n, f.cv, f.t, f.R, f.cov)


def test_fewer_than_four_points_are_refused(frame):
    f, _ = frame
    assert not _solve(f, 3)
    assert _solve(f, 4)  # one marker is enough


def test_a_non_finite_pixel_is_refused(frame):
    f, n = frame
    for bad in (np.nan, np.inf):
        img = f.img.copy()
        img[5, 1] = bad
        assert not _solve(f, n, img=img)
        ids = f.board.markers[0][f.idx[: n // 4]]
        assert estimate_pose(ids, img[:n].reshape(-1, 4, 2), f.board, f.cam) is None


def test_a_degenerate_geometry_is_refused(frame):
    """Collinear corners: the homography and ``J^T J`` are singular (a rotation about the line moves
    nothing)."""
    f, n = frame
    obj = f.obj.copy()
    obj[:n, 1] = 0.0
    img = np.array([nb.project_point(f.cv, *(f.R @ p + f.t)) for p in obj[:n]])
    assert not _solve(f, n, obj=obj, img=img)
    t2, R2, cov2 = np.empty(3), np.empty((3, 3)), np.empty((6, 6))
    assert not pnp.refine_pose_nb(obj, img, f.var, n, f.cv, f.R.copy(), f.t.copy(), t2, R2, cov2)


def test_a_non_positive_or_non_finite_covariance_is_refused(frame):
    f, n = frame
    assert not _solve(f, n, var=np.zeros_like(f.var))
    var = f.var.copy()
    var[2] = np.nan
    assert not _solve(f, n, var=var)


def test_a_pad_behind_the_camera_is_refused():
    """A marker in front of the camera on a pad whose centre is behind it (seen edge-on, 1 m off the
    centre): the solve finds that pose, t_z = -0.1 m, and refuses it, as estimate_pose does."""
    board = PadBoardParams(grid=2, marker_size_m=0.2, pitch_m=2.0, centre_size_m=0.0)
    cam = PadCameraParams()
    f = Frames(board, cam)
    # pad x -> camera z, pad y -> camera x, pad z -> camera y: the marker at pad (1, 1) is 0.8-1.0 m ahead
    R = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    t = np.array([-1.0, 0.3, -0.1])
    K, _ = nb.corner_frame_nb(f.corners, R, t, f.cv, np.zeros(100), 0, f.idx, f.px)
    assert K == 1 and board.markers[0][f.idx[0]] == 1
    n = nb.pack_frame_nb(f.corners, f.idx, f.px, K, f.cv, f.obj, f.img, f.var)
    assert not _solve(f, n)
    assert estimate_pose(board.markers[0][f.idx[:K]], f.px[:K], board, cam) is None
    # the refinement alone finds it: refused by the t_z check, not for want of a pose
    R2, t2 = R.copy(), t.copy()
    cost, status = pnp._refine(f.obj, f.img, n, f.cv, R2, t2, np.empty((5, 6, 6)), 40, R, np.full(3, np.nan))
    assert status == pnp._CONVERGED and cost < 1e-20 and t2[2] < 0
    assert not pnp.refine_pose_nb(f.obj, f.img, f.var, n, f.cv, R, t, t2, R2, np.empty((6, 6)))
