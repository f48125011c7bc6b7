"""The ``"mekf"`` navigator: the paper's multiplicative EKF (:mod:`swarm.core.estimator`, kernels
:mod:`swarm.core._ekf_nb`) behind :class:`~swarm.navigation.base.Navigator`.

The gyro and the known acceleration of the command in force drive it (paper eq. 3); it needs no
accelerometer. The docking agent (:mod:`swarm.step.agent`) gets it from :func:`Mekf.for_docking` and runs
its compiled steps on the arrays ``X``, ``P``, ``counts``, ``book`` of filter 0, which these methods use too.
"""

from __future__ import annotations

import math

import numpy as np

from swarm.core import _ekf_nb as nb
from swarm.core.estimator import PoseEstimator
from swarm.navigation.base import Fused, Navigator, NavState


class Mekf(PoseEstimator, Navigator):
    """A :class:`~swarm.core.estimator.PoseEstimator` with the navigation interface on its filter 0."""

    name = "mekf"
    needs = frozenset({"gyro"})
    summary = "the paper's multiplicative EKF: gyro and known acceleration (swarm/core/estimator.py)"
    anchors = np.zeros((0, 3))
    """The anchors' positions in nav (M, 3) [m] that :meth:`fuse_range` and :meth:`fuse_tdoa` index."""

    @classmethod
    def for_docking(cls, scenario, vehicle_id: str, p0_nav, v0_nav, q0_nav_body, cov0) -> Mekf:
        """The filter of ``vehicle_id`` of a docking scenario (its ``estimator_for`` tuning, which holds its
        kind's mounts) at the initial estimate ``p0_nav``, ``v0_nav``, ``q0_nav_body`` with covariance
        ``cov0`` (9,)."""
        est = cls.create(scenario.estimator_for(vehicle_id), p0_nav, v0_nav, q0_nav_body, cov0,
                         n_anchors=len(scenario.anchors_m))  # fmt: skip
        est.anchors = np.asarray(scenario.anchors_m, dtype=float)
        return est

    def _fused(self, status: int, kind: int) -> Fused:
        gated = status in (nb.ST_ACCEPTED, nb.ST_REJECTED)
        return Fused(int(status), float(self.book[0, nb.STF_D2 + kind]) if gated else math.nan)

    def propagate(self, dt_s: float, gyro_body, accel_body=None, a_known_nav=None) -> int:
        a = np.zeros(3) if a_known_nav is None else np.ascontiguousarray(a_known_nav, dtype=np.float64)
        w = np.ascontiguousarray(gyro_body, dtype=np.float64)
        return int(nb.predict_one(self.X[0], self.P[0], self.counts[0], self.book[0], w, a, float(dt_s),
                                  self._prm))  # fmt: skip

    def fuse_range(self, anchor: int, range_m: float, sigma_m: float) -> Fused:
        s = nb.update_range_anchor_one(self.X[0], self.P[0], self.counts[0], self.book[0], self._prm,
                                       self.anchors[anchor], int(anchor), float(range_m), float(sigma_m),
                                       self._gate_range)  # fmt: skip
        return self._fused(s, nb.TYPE_RANGE)

    def fuse_tdoa(self, anchor_a: int, anchor_b: int, diff_m: float, sigma_m: float) -> Fused:
        a, b = self.anchors[anchor_a], self.anchors[anchor_b]
        s = nb.update_tdoa_one(self.X[0], self.P[0], self.counts[0], self.book[0], self._prm, a, b,
                               int(anchor_a), int(anchor_b), float(diff_m), float(sigma_m),
                               self._gate_range)  # fmt: skip
        return self._fused(s, nb.TYPE_RANGE)

    def fuse_landmark(self, p_nav, f_cam_m, sigma_m: float) -> Fused:
        from swarm.core.estimator import chi2_gate

        mk = np.ascontiguousarray(np.reshape(p_nav, (1, 3)), dtype=np.float64)
        f = np.ascontiguousarray(np.reshape(f_cam_m, (1, 3)), dtype=np.float64)
        s = nb.update_features_one(self.X[0], self.P[0], self.counts[0], self.book[0], self._prm, mk, f,
                                   float(sigma_m), np.zeros((3, 3)), self._cam_pos, self._R_bc,
                                   chi2_gate(3, self.params.gate_probability))  # fmt: skip
        return self._fused(s, nb.TYPE_FEATURES)

    def state(self) -> NavState:
        return NavState(self.p_nav[0].copy(), self.v_nav[0].copy(), self.q_nav_body[0].copy())

    def covariance(self) -> np.ndarray:
        return self.P[0, :9, :9].copy()
