"""In-process closed loop: world, mothership radio network and every agent stepped in one process.

The order of one tick ``k`` is the contract the distributed swarm (issue 4) follows as well:

1. every agent takes its sensor frame of tick ``k`` (gyro predict, AHRS, the UWB range the mothership
   produced from the truth at ``t_k``, vision), a chaser using its target's estimate of tick ``k - 1``;
2. every agent publishes its estimate of tick ``k``; at control ticks it runs guidance + control and
   returns nozzle thrusts, which the world holds until the next control tick;
3. the world checks contact and the keep-out sphere on the truth, then steps to tick ``k + 1``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from swarm.core import rotations as rot
from swarm.core.agent import VehicleAgent
from swarm.core.faults import FaultSchedule
from swarm.core.guidance import CORRIDOR_MODES, Mode
from swarm.core.world import UwbNetwork, World, stream
from swarm.kinds.dispersions import apply_dispersion, draw_dispersion
from swarm.sim._fastloop import CONTACT, SENSORS_DONE, run_ticks
from swarm.sim.referee import judge

NO_VISION = object()
"""Marker for 'this tick's samples are in the world's arrays and no camera sees anything'."""


def _has_vision(frames) -> bool:
    return any(fr.vision is not None for fr in frames.values())


def initial_estimate(sc, vehicle_index: int, x_true: np.ndarray, seed: int):
    """Initial estimate of a vehicle: truth plus N(0, sigma^2) from its ``init`` stream (also P0)."""
    sig = sc.initial.sigmas
    e = stream(seed, vehicle_index, "init").normal(size=9) * sig
    p0 = x_true[0:3] + e[0:3]
    v0 = x_true[3:6] + e[3:6]
    q0 = rot.multiplicative_reset(x_true[6:10], -e[6:9])
    return p0, v0, q0, sig**2


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


@dataclass
class ChaserOutcome:
    """What happened to one chaser (DESIGN.md section 8 field names in :meth:`as_dict`)."""

    docked: bool = False
    collided: bool = False
    docking_time_s: float | None = None
    total_impulse_ns: float = 0.0
    position_error_m: float | None = None
    attitude_error_rad: float | None = None
    contact: dict | None = None
    keepout_violated: bool = False
    modes: list[dict] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    series: dict[str, list] = field(default_factory=dict)


def _new_series() -> dict[str, list]:
    keys = (
        "t_s",
        "p_true_nav",
        "p_est_nav",
        "q_true_nav_body",
        "q_est_nav_body",
        "cov_pos",
        "mode",
        "relative_nav",
    )
    return {k: [] for k in keys}


class DockingSim:
    """One run of a scenario in-process; :meth:`run` returns the JSON-ready summary."""

    def __init__(
        self,
        scenario,
        policy: str | None = None,
        seed: int = 0,
        record_series: bool = True,
        fast: bool = True,
    ):
        self.sc = scenario
        self.policy = policy or scenario.policy
        self.seed = int(seed)
        self.record_series = record_series
        self.fast = fast  # False: every tick through the per-object Python path (the reference)
        self.world = World(scenario, self.seed)
        self.dispersion = draw_dispersion(scenario, self.seed)  # [dispersions]: all off -> nominal
        apply_dispersion(self.world, scenario, self.dispersion)
        self.network = UwbNetwork(scenario, self.seed)
        self.agents: dict[str, VehicleAgent] = {}
        for i, vid in enumerate(scenario.vehicles):
            p0, v0, q0, cov0 = initial_estimate(scenario, i, self.world.x[vid], self.seed)
            self.agents[vid] = VehicleAgent(scenario, vid, p0, v0, q0, cov0, self.policy)
        self.outcomes = {c: ChaserOutcome(series=_new_series()) for c in scenario.chasers}
        self.done: set[str] = set()
        # faults (swarm.core.faults): the world and the network hold the fixed windows already; the
        # schedule adds the mode-triggered ones after the control tick of the mode change
        self.faults = FaultSchedule(scenario.faults, scenario.dt_s, scenario.chasers)
        self.world.camera_loss = self.faults.camera  # the same lists: windows opened later reach the world
        self._mode_faults = scenario.faults.mode_triggered
        self._bind_storage()

    def run(self) -> dict:
        sc = self.sc
        dt = sc.dt_s
        control_every = sc.every(sc.translation_control.rate_hz)
        control_dt = control_every * dt
        vision_every = sc.every(sc.camera.rate_hz)
        series_every = sc.sim.series_every if self.record_series else 0
        max_k = round(sc.sim.max_duration_s / dt)
        watched = {sc.vehicles[c].target for c in sc.chasers}
        frames = None  # tick k's sensor frames; NO_VISION: they are in the world's arrays, no camera frame
        wall0 = time.perf_counter()
        k = 0
        while k <= max_k:
            t = k * dt
            python_tick = (
                not self.fast
                or frames is None
                or k % control_every == 0
                or (series_every and k % series_every == 0)
                or (frames is not NO_VISION and any(fr.vision is not None for fr in frames.values()))
            )
            if not python_tick:
                # compiled ticks up to the next one that needs Python (control, series, camera)
                camera = self._camera  # decided at the last Python tick, margins cover one control period
                k_end = k + 1
                while k_end <= max_k and not (
                    k_end % control_every == 0
                    or (series_every and k_end % series_every == 0)
                    or (camera and k_end % vision_every == 0)
                ):
                    k_end += 1
                k_stop, code = self._fast(k, min(k_end, max_k + 1))
                if code == CONTACT:  # tick k_stop's sensors are in; finish it here
                    k = k_stop
                    t = k * dt
                    self._check_truth(k, t)
                    if len(self.done) == len(self.outcomes):
                        break
                    frames = self.world.step()
                    k += 1
                else:
                    k = k_stop
                    camera_tick = k % vision_every == 0 and self._camera
                    frames = self.world.frames() if camera_tick else NO_VISION
                continue
            snap = {vid: self.agents[vid].estimate() for vid in watched}  # estimates of tick k - 1
            for cid in sc.chasers:
                self.agents[cid].set_target_estimate(snap[sc.vehicles[cid].target])
            if frames is NO_VISION or (self.fast and frames is not None and not _has_vision(frames)):
                self._fast(k, k + 1, sensors_only=True)  # the same sensor steps, compiled
            elif frames is not None:
                ranges = self.network.step(k, t, self.world.x)
                for vid, agent in self.agents.items():
                    fr = frames[vid]
                    agent.on_imu(t, dt, fr.gyro_body, fr.q_ahrs_nav_body)
                    if vid in ranges:
                        agent.on_uwb(ranges[vid].anchor_id, ranges[vid].range_m)
                    if fr.vision is not None:
                        agent.on_vision(t, fr.vision_kind, fr.vision)
            if k % control_every == 0:
                for vid, agent in self.agents.items():
                    if vid in self.done:
                        continue
                    cmd = agent.control(t, control_dt)
                    self.world.set_command(vid, cmd.thrusts_n)
                    if vid in self.outcomes:
                        self._log_events(vid, cmd.events)
                if self._mode_faults:
                    self._update_faults(t)
            self._check_truth(k, t)
            if len(self.done) == len(self.outcomes):
                break
            self._camera = self._camera_possible()
            build = not self.fast or ((k + 1) % vision_every == 0 and self._camera)
            frames = self.world.step(build_frames=build)
            if frames is None:
                frames = NO_VISION
            k += 1
        wall = time.perf_counter() - wall0
        return self._summary(min(k, max_k) * dt, wall)

    def _bind_storage(self) -> None:
        """Stack every agent's filter and health arrays (views stay with the agents) so the compiled
        loop sees all vehicles at once."""
        agents = list(self.agents.values())
        self.AX = np.ascontiguousarray(np.concatenate([a.est.X for a in agents]))
        self.AP = np.ascontiguousarray(np.concatenate([a.est.P for a in agents]))
        self.AC = np.ascontiguousarray(np.concatenate([a.est.counts for a in agents]))
        self.AB = np.ascontiguousarray(np.concatenate([a.est.book for a in agents]))
        self.Hok = np.stack([a.h_ok for a in agents])
        self.Hd2 = np.stack([a.h_d2 for a in agents])
        self.Hmeta = np.stack([a.h_meta for a in agents])
        self.Fb = np.stack([a.f_body for a in agents])
        self.Wb = np.stack([a.w_body for a in agents])
        for b, a in enumerate(agents):
            a.est.X, a.est.P = self.AX[b : b + 1], self.AP[b : b + 1]
            a.est.counts, a.est.book = self.AC[b : b + 1], self.AB[b : b + 1]
            a.h_ok, a.h_d2, a.h_meta = self.Hok[b], self.Hd2[b], self.Hmeta[b]
            a.f_body, a.w_body = self.Fb[b], self.Wb[b]
        index = {vid: i for i, vid in enumerate(self.agents)}
        self.pairs = np.array(
            [[index[c], index[self.sc.vehicles[c].target]] for c in self.sc.chasers], dtype=np.int64
        )
        self.pairs = self.pairs.reshape(-1, 2)
        self.t_agent = np.zeros(len(agents))
        self._lv = np.zeros(len(agents))
        self._df = np.zeros(len(agents), dtype=np.bool_)
        self._done = np.zeros(len(self.pairs), dtype=np.bool_)
        self._docking = np.zeros(len(self.pairs), dtype=np.bool_)
        self._camera = True
        self._corridor_cos = self.sc.guidance.corridor_cos
        self._cam_axis_body = rot.quat_rotate(
            np.asarray(self.sc.camera.q_body_cam, dtype=float), np.array([0.0, 0.0, 1.0])
        )
        self.ko_flag = np.zeros(len(self.pairs), dtype=np.bool_)
        self.ko_t = np.zeros(len(self.pairs))
        self.ko_r = np.zeros(len(self.pairs))
        # closest true centre distance outside the corridor modes, per chaser
        self.closest = np.full(len(self.pairs), np.inf)

    def _camera_possible(self) -> bool:
        """Whether any chaser could see its target before the next control tick (then camera ticks need
        Python): a necessary condition on the truth, with margins for the motion within a control
        period: the target within the camera's range (plus a cube's diagonal and 5 cm) and within its
        field-of-view cone (plus 5 deg)."""
        cam = self.sc.camera
        reach = cam.max_range_m + 4.0 * self.sc.guidance.half_size_m + 0.05
        cos_fov = np.cos(np.radians(min(cam.fov_half_angle_deg + 5.0, 180.0)))
        X = self.world.X
        for c, t in self.pairs:
            d = X[t, 0:3] - X[c, 0:3]
            dist2 = d.dot(d)
            if dist2 > reach * reach:
                continue
            axis_nav = rot.quat_rotate(X[c, 6:10], self._cam_axis_body)
            if axis_nav.dot(d) >= cos_fov * np.sqrt(dist2):
                return True
        return False

    def _fast(self, k0: int, k1: int, sensors_only: bool = False) -> tuple[int, int]:
        """Run ticks ``k0 .. k1 - 1`` compiled (:func:`swarm.sim._fastloop.run_ticks`)."""
        sc, w, net = self.sc, self.world, self.network
        g, ag = sc.guidance, sc.agent
        agents = list(self.agents.values())
        first = agents[0]
        w.reserve_noise(k1 - k0)
        net.reserve_noise((k1 - k0) // net.every + 1)
        last_vision, dock_flag, done, docking = self._lv, self._df, self._done, self._docking
        for b, a in enumerate(agents):
            last_vision[b] = a._last_vision_s
            dock_flag[b] = a.mode in (Mode.DOCK, Mode.DOCKED) and a._last_vision_s > -np.inf
        chasers = sc.chasers
        for c, cid in enumerate(chasers):
            done[c] = cid in self.done
            docking[c] = self.agents[cid].mode in CORRIDOR_MODES
        ko_before = self.ko_flag.copy()
        k_stop, code = run_ticks(
            k0, k1, sc.dt_s, net.every, w.ahrs_every, sc.ahrs.enabled,
            w.X, w.wrench, w.thrust_sum, w.attached_arr, w.impulse, w.bias, w.gyro_noise, w.gi, w.ahrs_noise,
            w.ai, w.prm, w.gyro_out, w.ahrs_out, w.gyro_step_t, w.gyro_step,
            net.lever, net.anchors, net.drift, net.prm, net.next_anchor, net.noise, net.ui, net.lost,
            net.anchor_id, net.range_m, net.outlier,
            self.AX, self.AP, self.AC, self.AB, first.est._prm, self.Fb, self.Wb, first.mass_kg,
            first._ahrs_cov, first._gate_1d, first._gate_3d, first._sigma_range,
            self.Hok, self.Hd2, self.Hmeta,
            last_vision, dock_flag, ag.vision_recent_s, ag.uwb_with_vision, self.t_agent,
            self.pairs, done, docking, g.face_normal_target, g.q_target_chaser_docked, g.half_size_m,
            g.keepout_radius_m, self._corridor_cos, g.contact_distance_m,
            self.ko_flag, self.ko_t, self.ko_r, self.closest, sensors_only,
        )  # fmt: skip
        for b, a in enumerate(agents):
            a.t_s = float(self.t_agent[b])
        if code != SENSORS_DONE:
            w.k = k_stop  # the world's state is that of tick k_stop
        for c, cid in enumerate(chasers):
            if self.ko_flag[c] and not ko_before[c]:
                out = self.outcomes[cid]
                out.keepout_violated = True
                self.ko_flag[self.sc.chasers.index(cid)] = True
                ev = {
                    "t_s": float(self.ko_t[c]),
                    "keepout_violation": True,
                    "mode": self.agents[cid].mode.value,
                }
                out.events.append(ev | {"range_m": float(self.ko_r[c])})
        return k_stop, code

    def _update_faults(self, t: float) -> None:
        """After the control tick at ``t``: open (or close) the mode-triggered fault windows; they start
        at the next tick at the earliest, so no sample already taken is affected, and the compiled
        stretches that follow check them tick by tick (:mod:`swarm.core.faults`)."""
        changed = False
        for cid in self.sc.chasers:
            changed |= self.faults.on_mode(t, cid, self.agents[cid].mode.value)
        if changed:
            self.network.set_fault_windows(self.faults.uwb_dropout, self.faults.nlos)

    def _log_events(self, cid: str, events: list[dict]) -> None:
        out = self.outcomes[cid]
        for ev in events:
            out.events.append(ev)
            out.modes.append(
                {"mode": ev["to"], "t_s": ev["t_s"], "range_m": ev["range_m"], "reason": ev["reason"]}
            )

    def _check_truth(self, k: int, t: float) -> None:
        sc, g = self.sc, self.sc.guidance
        for cid, out in self.outcomes.items():
            agent = self.agents[cid]
            tid = sc.vehicles[cid].target
            if self.record_series and k % sc.sim.series_every == 0 and cid not in self.done:
                s = out.series
                s["t_s"].append(t)
                s["p_true_nav"].append(self.world.x[cid][0:3].tolist())
                s["p_est_nav"].append(agent.est.p_nav[0].tolist())
                s["q_true_nav_body"].append(self.world.x[cid][6:10].tolist())
                s["q_est_nav_body"].append(agent.est.q_nav_body[0].tolist())
                s["cov_pos"].append(agent.est.P[0, :3, :3].tolist())
                s["mode"].append(agent.mode.value)
                s["relative_nav"].append(bool(agent.relative_nav))
            if cid in self.done:
                continue
            call = judge(self.world, g, cid, tid, agent.mode in CORRIDOR_MODES, t)
            if agent.mode not in CORRIDOR_MODES:
                c = sc.chasers.index(cid)
                self.closest[c] = min(self.closest[c], call.centre_m)
            if call.keepout:
                if not out.keepout_violated:
                    out.events.append(
                        {
                            "t_s": t,
                            "keepout_violation": True,
                            "mode": agent.mode.value,
                            "range_m": call.centre_m,
                        }
                    )
                out.keepout_violated = True
            ct = call.contact
            if ct is not None:
                out.docked, out.collided = ct.docked, not ct.docked
                out.contact = ct.contact
                out.docking_time_s = t
                out.position_error_m = ct.position_error_m
                out.attitude_error_rad = ct.attitude_error_rad
                self.world.attach(cid, tid)
                self.done.add(cid)
                self._log_events(cid, [ct.event(agent.mode.value)])

    def _summary(self, t_end: float, wall: float) -> dict:
        chasers = {}
        for cid, out in self.outcomes.items():
            agent = self.agents[cid]
            out.total_impulse_ns = self.world.impulse_ns[cid]
            sw = agent.switcher
            d = {
                "docked": out.docked,
                "collided": out.collided,
                "docking_time_s": out.docking_time_s,
                "total_impulse_ns": out.total_impulse_ns,
                "position_error_m": out.position_error_m,
                "attitude_error_rad": out.attitude_error_rad,
                "final_mode": agent.mode.value,
                "modes": out.modes,
                "r1_m": sw.r1_m,
                "r2_m": sw.r2_m,
                "keepout_violated": out.keepout_violated,
                "closest_approach_m": _finite_or_none(self.closest[self.sc.chasers.index(cid)]),
                "contact": out.contact,
                "estimator": {
                    "rejected_ranges": int(agent.est.count(0, "rejected")[0]),
                    "accepted_ranges": int(agent.est.count(0, "accepted")[0]),
                    "accepted_vision": int(
                        agent.est.count(1, "accepted")[0] + agent.est.count(2, "accepted")[0]
                    ),
                },
            }
            if self.policy == "mdp":
                d["decisions"] = [dec.as_dict() for dec in sw.decisions]
            if self.record_series:
                d["series"] = out.series
            if self.sc.faults.enabled:
                d["faults"] = {
                    "events": [ev for ev in self.faults.events if ev["chaser"] == cid],
                    "uwb_dropout_s": self.faults.dropout_windows() + list(self.sc.uwb.dropout_windows_s),
                    "camera_loss_s": [tuple(w) for w in self.faults.camera[cid]],
                    "nlos_burst_s": [tuple(w) for w in self.faults.nlos],
                }
            chasers[cid] = d
        return {
            "scenario": self.sc.name,
            "policy": self.policy,
            "seed": self.seed,
            "sim_time_s": t_end,
            "wall_s": wall,
            "realtime_factor": t_end / wall if wall > 0 else None,
            "target_impulse_ns": {v: self.world.impulse_ns[v] for v in self.sc.vehicles if v not in chasers},
            "chasers": chasers,
        }


def run_docking(scenario, policy: str | None = None, seed: int = 0, record_series: bool = True) -> dict:
    """Run one docking in-process and return its summary (DESIGN.md section 8 fields per chaser)."""
    return DockingSim(scenario, policy, seed, record_series).run()
