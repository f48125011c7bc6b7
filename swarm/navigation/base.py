"""The navigation interface (docs/architecture.md, "Navigation"): what an agent step asks of its filter.

A navigator is one vehicle's filter behind five calls: :meth:`Navigator.propagate` over one IMU interval,
:meth:`~Navigator.fuse_range` (a UWB two-way range), :meth:`~Navigator.fuse_tdoa` (a distance difference),
:meth:`~Navigator.fuse_landmark` (vision: a point of known nav position seen by the camera) and the
estimate, :meth:`~Navigator.state` and :meth:`~Navigator.covariance`. Each fusion returns a
:class:`Fused`: the outcome in :class:`swarm.core.estimator.UpdateStatus`'s numbers and the squared
Mahalanobis distance it was gated on (the health window of Algorithm 1 reads it).

The registered navigators (:data:`swarm.navigation.NAVIGATORS`) are the paper's multiplicative EKF
(``"mekf"``, driven by the gyro and the controller's known acceleration) and the IMU-driven error-state
filter (``"eskf"``, driven by gyro and accelerometer, with IMU biases). Each is its filter class
(:class:`~swarm.core.estimator.PoseEstimator`, :class:`~swarm.core.imu_filter.ImuFilter`) with this
interface added on its filter 0, so a runner that batches the filters' arrays keeps doing so.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from swarm.errors import ConfigError


@dataclass(frozen=True)
class Fused:
    """The outcome of one fusion."""

    status: int
    """:class:`swarm.core.estimator.UpdateStatus`: 0 accepted, 1 rejected by the gate, 2-3 refused."""
    d2: float
    """Squared Mahalanobis distance of the innovation (NaN when refused before it was formed)."""


@dataclass(frozen=True)
class NavState:
    """A navigator's estimate (copies)."""

    p_nav: np.ndarray
    """(3,) position of the centre of mass in nav [m]."""
    v_nav: np.ndarray
    """(3,) velocity in nav [m/s]."""
    q_nav_body: np.ndarray
    """(4,) attitude, scalar-last."""


class Navigator(ABC):
    """One vehicle's filter (module docstring)."""

    name: ClassVar[str]
    """Its name in :data:`swarm.navigation.NAVIGATORS` and in a scenario's ``navigation = "..."``."""
    needs: ClassVar[frozenset[str]]
    """What the vehicle's IMU must measure for it (:attr:`swarm.kinds.base.VehicleKind.imu_measures`)."""
    summary: ClassVar[str]
    """One line for error messages and docs."""
    docking_missing: ClassVar[str | None] = None
    """What the docking runners lack to run this filter (:func:`check_docking_navigator`); None: they do."""

    @classmethod
    @abstractmethod
    def for_docking(cls, scenario, vehicle_id: str, p0_nav, v0_nav, q0_nav_body, cov0) -> Navigator:
        """The filter of ``vehicle_id`` of a docking scenario (:class:`swarm.scenario.Scenario`) at the
        initial estimate ``p0_nav``, ``v0_nav``, ``q0_nav_body`` with covariance ``cov0`` (9,)."""

    @abstractmethod
    def propagate(self, dt_s: float, gyro_body, accel_body=None, a_known_nav=None) -> int:
        """Predict over ``dt_s`` [s] with the gyro rate ``gyro_body`` [rad/s] and, as the filter takes them,
        the specific force ``accel_body`` [m/s^2] (body frame) or the known acceleration ``a_known_nav``
        [m/s^2] (nav frame; what the controller commanded). Returns the status (0: done)."""

    @abstractmethod
    def fuse_range(self, anchor: int, range_m: float, sigma_m: float) -> Fused:
        """A two-way range ``range_m`` [m] with noise ``sigma_m`` [m] to anchor index ``anchor``."""

    @abstractmethod
    def fuse_tdoa(self, anchor_a: int, anchor_b: int, diff_m: float, sigma_m: float) -> Fused:
        """A distance difference ``d_b - d_a`` [m] with noise ``sigma_m`` [m] between anchors ``a``, ``b``."""

    @abstractmethod
    def fuse_landmark(self, p_nav, f_cam_m, sigma_m: float) -> Fused:
        """Vision: a point at ``p_nav`` (3,) [m] seen at ``f_cam_m`` (3,) [m] in the camera frame (OpenCV
        axes), each axis with noise ``sigma_m`` [m]; the camera where the vehicle's mounts put it."""

    @abstractmethod
    def state(self) -> NavState:
        """The estimate (copies)."""

    @abstractmethod
    def covariance(self) -> np.ndarray:
        """(9, 9) covariance of the errors of position [m], velocity [m/s] and attitude [rad] (a copy)."""


def check_docking_navigator(vehicle_id: str, nav: type[Navigator]) -> None:
    """ConfigError naming ``vehicles.<vehicle_id>.navigation`` and the filter's name unless the docking
    runners run ``nav`` (:attr:`Navigator.docking_missing` says what they lack)."""
    if nav.docking_missing is not None:
        raise ConfigError(
            f"vehicles.{vehicle_id}.navigation = {nav.name!r}: the docking runners cannot run this filter "
            f"yet: {nav.docking_missing}; use navigation = 'mekf'"
        )
