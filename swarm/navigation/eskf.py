"""The ``"eskf"`` navigator: the IMU-driven error-state filter (:mod:`swarm.core.imu_filter`, kernels
:mod:`swarm.core._imu_nb`; Sola 2017) behind :class:`~swarm.navigation.base.Navigator`.

Specific force and rate drive it, with accelerometer and gyro biases and gravity in its model, so it needs
an IMU that measures both. The landing agent (:mod:`swarm.step.landing`) builds it with
:meth:`~swarm.core.imu_filter.ImuFilter.create` and runs its compiled steps on ``X`` and ``P``. The docking
runners do not fly it yet (:meth:`Eskf.for_docking`).
"""

from __future__ import annotations

import math

import numpy as np

from swarm.core import _imu_nb as nb
from swarm.core.imu_filter import ImuFilter, chi2_gate
from swarm.navigation.base import Fused, Navigator, NavState, check_docking_navigator

_NO_INDEX = np.full(3, -1, dtype=np.int64)


class Eskf(ImuFilter, Navigator):
    """An :class:`~swarm.core.imu_filter.ImuFilter` with the navigation interface on its filter 0. Its camera
    (for :meth:`fuse_landmark`) is ``cam_pos_body_m`` and ``R_body_cam``, set by the caller that has the
    vehicle's mounts; a downward camera at the centre of mass until then. :meth:`propagate` predicts over the
    interval it is given and advances ``t`` by it: a caller uses either the interface or the time-stamped
    :meth:`~swarm.core.imu_filter.ImuFilter.imu` and ``update_*`` of the class (which predict to each
    sample's time with the held IMU sample), not both on one object."""

    name = "eskf"
    needs = frozenset({"gyro", "accelerometer"})
    summary = (
        "the IMU-driven error-state filter: gyro and accelerometer, IMU biases (swarm/core/imu_filter.py)"
    )
    cam_pos_body_m = np.zeros(3)
    R_body_cam = np.diag([1.0, -1.0, -1.0])
    landmark_gate_probability = 0.9995
    """The chi-square probability of :meth:`fuse_landmark`'s gate (that of the landing's pad update)."""

    docking_missing = (
        "the docking world's IMU sample has no specific force, and the docking agent's compiled steps "
        "(swarm/step/agent.py, swarm/step/tick.py) drive the MEKF's arrays"
    )

    @classmethod
    def for_docking(cls, scenario, vehicle_id: str, p0_nav, v0_nav, q0_nav_body, cov0) -> Eskf:
        """Refused (:attr:`docking_missing`)."""
        check_docking_navigator(vehicle_id, cls)
        raise AssertionError("unreachable")  # pragma: no cover

    def _fused(self, res) -> Fused:
        status = int(res[0])
        return Fused(status, float(res[1]) if status != nb.REFUSED else math.nan)

    def propagate(self, dt_s: float, gyro_body, accel_body=None, a_known_nav=None) -> int:
        if accel_body is None:
            raise ValueError("the eskf navigator needs the specific force accel_body [m/s^2]")
        w = np.ascontiguousarray(gyro_body, dtype=np.float64)
        f = np.ascontiguousarray(accel_body, dtype=np.float64)
        ok = nb.predict_one(self.X[0], self.P[0], w, f, float(dt_s), self.prm)
        self.t += float(dt_s)
        return 0 if ok else 2

    def fuse_range(self, anchor: int, range_m: float, sigma_m: float) -> Fused:
        res = np.empty(3)
        i = self.ridx[anchor]
        nb.update_range3(self.X[0], self.P[0], self.anchors[anchor], i[0], i[1], i[2], float(range_m),
                         float(sigma_m), self.prm, self._work, res)  # fmt: skip
        return self._fused(res)

    def fuse_tdoa(self, anchor_a: int, anchor_b: int, diff_m: float, sigma_m: float) -> Fused:
        res = np.empty(4)
        nb.update_tdoa(self.X[0], self.P[0], self.anchors[anchor_a], self.anchors[anchor_b],
                       self.ridx[anchor_a], self.ridx[anchor_b], float(diff_m), float(sigma_m), self.prm,
                       self._work, res)  # fmt: skip
        return self._fused(res)

    def fuse_landmark(self, p_nav, f_cam_m, sigma_m: float) -> Fused:
        res = np.empty(2)
        cam = np.asarray(self.cam_pos_body_m, float)
        nb.update_pad_one(self.X[0], self.P[0], np.asarray(p_nav, float), cam,
                          np.ascontiguousarray(self.R_body_cam, float), np.asarray(f_cam_m, float),
                          np.eye(3) * float(sigma_m) ** 2, chi2_gate(self.landmark_gate_probability, 3),
                          res)  # fmt: skip
        return self._fused(res)

    def state(self) -> NavState:
        return NavState(self.p_nav[0].copy(), self.v_nav[0].copy(), self.q_nav_body[0].copy())

    def covariance(self) -> np.ndarray:
        return self.P[0, :9, :9].copy()
