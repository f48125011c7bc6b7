"""The simulated world: truth dynamics of every vehicle and their on-board sensors (gyro, AHRS, camera),
and the mothership's simulated UWB radio network.

Like :class:`swarm.core.agent.VehicleAgent`, these objects do no I/O: the world process and the
mothership process (issue 4) wrap them, and the in-process simulation calls them directly, in the same
order, with the same random streams (:func:`stream`), so one seed is one trajectory in either runner.

Tick ``k`` is time ``t_k = k dt``. :meth:`World.step` applies each vehicle's held nozzle thrusts over
``[t_k, t_k+1]`` (paper eq. 1-2, :func:`swarm.core.dynamics.propagate`) and returns the sensor samples
of tick ``k + 1``: the gyro reports the mean body rate over the step (the delta-angle an IMU integrates)
plus noise and bias; the camera, at its rate, what the chaser sees of its target's docking face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarm.core import rotations as rot
from swarm.core.camera import camera_pose_ms, feature_vectors, project_markers, visible
from swarm.core.dynamics import propagate
from swarm.core.guidance import contact_state, docking_geometry
from swarm.core.sensors import UwbRadio, ahrs_sample, gyro_init_bias, gyro_sample
from swarm.core.thrusters import allocation_matrix

STREAMS = ("init", "gyro", "ahrs", "camera", "uwb")


def stream(seed: int, vehicle_index: int, name: str) -> np.random.Generator:
    """The random stream ``name`` of vehicle ``vehicle_index`` for root ``seed``: independent streams from
    one ``SeedSequence`` (spawn keys), the same in every process that asks for them."""
    key = (int(vehicle_index), STREAMS.index(name))
    return np.random.default_rng(np.random.SeedSequence(entropy=int(seed), spawn_key=key))


@dataclass
class SensorFrame:
    """The on-board sensor samples of one vehicle at one tick."""

    t_s: float
    gyro_body: np.ndarray
    q_ahrs_ms_body: np.ndarray | None = None
    vision_kind: str | None = None  # "features" or "pixels"
    vision: np.ndarray | None = None


class World:
    """Truth of every vehicle of a scenario and their on-board sensors (module docstring)."""

    def __init__(self, scenario, seed: int) -> None:
        sc = scenario
        self.sc = sc
        self.ids = list(sc.vehicles)
        self.dt = sc.dt_s
        self.k = 0
        self.mass = sc.dynamics.mass_kg
        self.inertia = np.asarray(sc.dynamics.inertia_diag_kgm2, dtype=float)
        self.h_max = sc.dynamics.integration_step_s
        self.B = allocation_matrix(sc.thrusters)
        self.x: dict[str, np.ndarray] = {}
        self.thrusts: dict[str, np.ndarray] = {}
        self.bias: dict[str, np.ndarray] = {}
        self.rng: dict[tuple[str, str], np.random.Generator] = {}
        self.impulse_ns: dict[str, float] = {}
        self._wrench: dict[str, np.ndarray] = {}
        self._thrust_sum: dict[str, float] = {}
        self.attached: dict[str, bool] = {}
        for i, vid in enumerate(self.ids):
            spec = sc.vehicles[vid]
            x = np.zeros(13)
            x[0:3] = spec.position_m
            x[6:10] = sc.q0(vid)
            self.x[vid] = x
            self.thrusts[vid] = np.zeros(self.B.shape[1])
            self._wrench[vid] = np.zeros(6)
            self._thrust_sum[vid] = 0.0
            for name in ("gyro", "ahrs", "camera"):
                self.rng[vid, name] = stream(seed, i, name)
            self.bias[vid] = gyro_init_bias(sc.gyro, self.rng[vid, "gyro"])
            self.impulse_ns[vid] = 0.0
            self.attached[vid] = False
        self.markers_target = sc.markers.markers(sc.guidance.docking_face)
        self.vision_every = sc.every(sc.camera.rate_hz)
        self.ahrs_every = sc.every(sc.ahrs.rate_hz)

    @property
    def t_s(self) -> float:
        return self.k * self.dt

    def set_command(self, vehicle_id: str, thrusts_n) -> None:
        """Nozzle thrusts [N] to hold from now on (clipped to the nozzles' range: a command cannot make a
        nozzle pull or exceed its maximum)."""
        f = np.clip(np.asarray(thrusts_n, dtype=float), 0.0, self.sc.thrusters.max_thrust_n)
        self.thrusts[vehicle_id] = np.where(np.isfinite(f), f, 0.0)
        self._wrench[vehicle_id] = self.B @ self.thrusts[vehicle_id]
        self._thrust_sum[vehicle_id] = float(np.sum(self.thrusts[vehicle_id]))

    def step(self) -> dict[str, SensorFrame]:
        """Advance every vehicle by one tick and return the sensor frames of the new tick."""
        dt = self.dt
        frames: dict[str, SensorFrame] = {}
        k1 = self.k + 1
        for vid in self.ids:
            x0 = self.x[vid]
            if self.attached[vid]:
                x1 = x0.copy()
            else:
                wrench = self._wrench[vid]
                x1 = propagate(x0, wrench[:3], wrench[3:], dt, self.mass, self.inertia, self.h_max)
                self.impulse_ns[vid] += self._thrust_sum[vid] * dt  # thrusts are >= 0: sum |f| dt
            self.x[vid] = x1
            w_mean = rot.quat_log(rot.quat_mul(rot.quat_conj(x0[6:10]), x1[6:10])) / dt
            gyro, self.bias[vid] = gyro_sample(
                w_mean, self.bias[vid], dt, self.sc.gyro, self.rng[vid, "gyro"]
            )
            frame = SensorFrame(k1 * dt, gyro)
            if self.sc.ahrs.enabled and k1 % self.ahrs_every == 0:
                frame.q_ahrs_ms_body = ahrs_sample(x1[6:10], self.sc.ahrs, self.rng[vid, "ahrs"])
            frames[vid] = frame
        self.k = k1
        if k1 % self.vision_every == 0:
            for vid in self.ids:
                spec = self.sc.vehicles[vid]
                if spec.role == "chaser":
                    self._vision(vid, spec.target, frames[vid])
        return frames

    def _vision(self, chaser: str, target: str, frame: SensorFrame) -> None:
        cam = self.sc.camera
        xc, xt = self.x[chaser], self.x[target]
        p_cam, q_cam = camera_pose_ms(xc[0:3], xc[6:10], cam)
        if not visible(p_cam, q_cam, xt[0:3], xt[6:10], self.sc.guidance.docking_face, cam, self.sc.markers):
            return
        rng = self.rng[chaser, "camera"]
        if cam.model == "pnp":
            frame.vision_kind = "pixels"
            frame.vision = project_markers(self.markers_target, xt[0:3], xt[6:10], p_cam, q_cam, cam, rng)
        else:
            frame.vision_kind = "features"
            frame.vision = feature_vectors(self.markers_target, xt[0:3], xt[6:10], p_cam, q_cam, cam, rng)

    # ---- truth-side metrics -------------------------------------------------------------------------
    def contact(self, chaser: str, target: str) -> dict:
        """Port-to-port geometry of a pair on the truth (:func:`swarm.core.guidance.contact_state`)."""
        xc, xt = self.x[chaser], self.x[target]
        return contact_state(self.sc.guidance, xc[0:3], xc[3:6], xc[6:10], xt[0:3], xt[6:10], xt[3:6])

    def keepout_violated(self, chaser: str, target: str, docking: bool) -> bool:
        """The chaser's centre inside the target's keep-out sphere, outside the docking corridor (or
        inside it while not docking)."""
        g = self.sc.guidance
        xc, xt = self.x[chaser], self.x[target]
        rel = xc[0:3] - xt[0:3]
        r = float(np.linalg.norm(rel))
        if r >= g.keepout_radius_m:
            return False
        n_ms, _, _ = docking_geometry(g, xt[0:3], xt[6:10])
        in_corridor = rel @ n_ms >= r * np.cos(np.radians(g.corridor_half_angle_deg))
        return not (docking and in_corridor)

    def attach(self, chaser: str, target: str) -> None:
        """Docked: the chaser rides with the target from now on (no further propagation)."""
        self.attached[chaser] = True
        self.set_command(chaser, np.zeros_like(self.thrusts[chaser]))


class UwbNetwork:
    """The mothership's simulated radio network: one round-robin UWB radio per agent (paper sec. III)."""

    def __init__(self, scenario, seed: int) -> None:
        self.sc = scenario
        self.anchors = np.asarray(scenario.anchors_m, dtype=float)
        self.lever = np.asarray(scenario.tag_lever_arm_body_m, dtype=float)
        self.radios = {vid: UwbRadio(self.anchors, scenario.uwb) for vid in scenario.vehicles}
        self.rng = {vid: stream(seed, i, "uwb") for i, vid in enumerate(scenario.vehicles)}
        self.every = scenario.every(scenario.uwb.rate_hz)

    def step(self, k: int, t_s: float, truth: dict[str, np.ndarray]) -> dict[str, object]:
        """Ranges of tick ``k`` from the truth states (13,) of each vehicle: ``{id: UwbSample}``; a
        vehicle is missing when it has no exchange this tick or the reply was lost."""
        out: dict[str, object] = {}
        if k % self.every:
            return out
        for vid, x in truth.items():
            tag = x[0:3] + rot.quat_rotate(x[6:10], self.lever)
            sample = self.radios[vid].sample(t_s, tag, self.rng[vid])
            if sample is not None:
                out[vid] = sample
        return out
