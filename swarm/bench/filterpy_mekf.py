"""FilterPy's ``ExtendedKalmanFilter`` running the compounded filter's model, for ``swarm bench estimator``.

FilterPy is an optional extra (``pip install .[bench]``): nothing here imports it at module level, and
:func:`filterpy_available` says whether it can be used. ``tests/test_bench_estimator.py`` checks that this
model and the compiled compounded filter (``swarm.core._ekf_nb``) give the same state and covariance to
1e-9, so the bench compares like with like.
"""

from __future__ import annotations

import numpy as np

from swarm.core import rotations as rot
from swarm.core.estimator import EstimatorParams

FILTERPY_MISSING = "filterpy not installed (pip install .[bench])"


def filterpy_available() -> bool:
    """True when ``filterpy.kalman`` imports."""
    try:
        import filterpy.kalman  # noqa: F401
    except ImportError:
        return False
    return True


class FilterPyMekf:
    """FilterPy's ``ExtendedKalmanFilter`` (dim_x=9, dim_z=1) running the compounded filter's model.

    The state is the error state ``(p, v, d_theta)`` around a reference quaternion ``q_nav_body`` that is
    propagated with the gyro outside FilterPy (paper eq. 3). Per step: ``F = [[I, dt I, 0], [0, I, 0],
    [0, 0, Phi]]`` with ``Phi = R(exp(w dt))^T`` (Crassidis & Junkins 2011 sec. 7.2.4), the known
    acceleration through ``B = [dt^2/2 I; dt I; 0]``, ``Q`` the white-noise-acceleration blocks
    ``q dt^3/3, q dt^2/2, q dt`` plus ``psd dt I`` on attitude; then ``ekf.update`` with the range model of
    ``_ekf_nb.range_model`` (``h = |p + R(q) P1 - a|``, ``H = [u^T, 0, -u^T R(q) [P1 x]]``) and the
    multiplicative reset ``q <- q (x) exp(d_theta)``, ``P <- T P T^T``, ``T = I - 1/2 [d_theta x]`` on
    the attitude block (Markley 2003; Mueller, Hehn & D'Andrea 2016). ``d_theta`` is zero before every
    update, so ``h`` and ``H`` are evaluated at the reference attitude, as in the compiled kernel.
    ``F`` changes with the gyro each step; ``Q`` and ``B`` depend only on ``dt`` and are built once.
    FilterPy has no gate: with every range accepted both filters do the same algebra.

    Arguments: ``p_nav`` (3,) [m] and ``v_nav`` (3,) [m/s] in frame c, ``q_nav_body`` (4,) scalar-last,
    ``cov0`` (9, 9) of ``(d_p, d_v, d_theta)``, ``dt_s`` the fixed step [s].
    """

    def __init__(self, params: EstimatorParams, p_nav, v_nav, q_nav_body, cov0, dt_s: float) -> None:
        from filterpy.kalman import ExtendedKalmanFilter

        self.ekf = ExtendedKalmanFilter(dim_x=9, dim_z=1)
        self.ekf.x = np.concatenate([p_nav, v_nav, np.zeros(3)]).reshape(9, 1)
        self.ekf.P = np.array(cov0, dtype=float)
        self.q_nav_body = np.array(q_nav_body, dtype=float)
        self.dt_s = dt_s
        self.sigma_range_m = params.sigma_range_m
        self.lever_body_m = np.asarray(params.lever_arm_body_m, dtype=float)
        self._skew_lever = rot.skew(self.lever_body_m)
        eye3, q_acc = np.eye(3), params.accel_psd_m2_s3
        Q = np.zeros((9, 9))
        Q[:3, :3] = q_acc * dt_s**3 / 3.0 * eye3
        Q[:3, 3:6] = Q[3:6, :3] = q_acc * dt_s**2 / 2.0 * eye3
        Q[3:6, 3:6] = q_acc * dt_s * eye3
        Q[6:, 6:] = (params.gyro_arw_rad_rts**2 + params.attitude_rw_extra_rad_rts**2) * dt_s * eye3
        self.ekf.Q = Q
        self.ekf.B = np.vstack([0.5 * dt_s**2 * eye3, dt_s * eye3, np.zeros((3, 3))])
        self._F = np.eye(9)
        self._F[:3, 3:6] = dt_s * eye3
        self._R_nav_body = rot.quat_to_matrix(self.q_nav_body)

    def _tag_offset(self, x: np.ndarray, anchor_nav: np.ndarray) -> np.ndarray:
        return x[:3, 0] + self._R_nav_body @ self.lever_body_m - anchor_nav

    def _hx(self, x: np.ndarray, anchor_nav: np.ndarray) -> np.ndarray:
        d = self._tag_offset(x, anchor_nav)
        return np.array([[np.sqrt(d @ d)]])

    def _h_jacobian(self, x: np.ndarray, anchor_nav: np.ndarray) -> np.ndarray:
        d = self._tag_offset(x, anchor_nav)
        u = d / np.sqrt(d @ d)
        H = np.zeros((1, 9))
        H[0, :3] = u
        H[0, 6:] = -(u @ self._R_nav_body) @ self._skew_lever
        return H

    def step(self, w_body: np.ndarray, a_nav: np.ndarray, anchor_nav: np.ndarray, range_m: float) -> None:
        """One predict with gyro ``w_body`` [rad/s] and acceleration ``a_nav`` [m/s^2], then one range
        ``range_m`` [m] to the anchor at ``anchor_nav`` (frame c)."""
        ekf = self.ekf
        dq = rot.rotvec_exp(w_body * self.dt_s)
        self.q_nav_body = rot.quat_normalize(rot.quat_mul(self.q_nav_body, dq))
        self._R_nav_body = rot.quat_to_matrix(self.q_nav_body)
        self._F[6:, 6:] = rot.quat_to_matrix(dq).T
        ekf.F = self._F
        ekf.predict(u=a_nav.reshape(3, 1))
        ekf.update(
            np.array([range_m]), self._h_jacobian, self._hx, R=self.sigma_range_m**2,
            args=(anchor_nav,), hx_args=(anchor_nav,),
        )  # fmt: skip
        dth = ekf.x[6:, 0].copy()
        self.q_nav_body = rot.multiplicative_reset(self.q_nav_body, dth)
        self._R_nav_body = rot.quat_to_matrix(self.q_nav_body)
        x, y, z = 0.5 * dth
        T = np.eye(9)
        T[6:, 6:] = ((1.0, z, -y), (-z, 1.0, x), (y, -x, 1.0))  # I - [dth x] / 2 (rot.skew is slow)
        ekf.P = T @ ekf.P @ T.T
        ekf.x[6:] = 0.0
