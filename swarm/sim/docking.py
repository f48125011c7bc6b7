"""In-process closed loop: the world, the radio network and every agent stepped in one process.

The runner calls the one tick of docs/architecture.md ("The one tick"), the very steps the processes call:
for tick ``k``

1. every agent takes its inputs of tick ``k`` (:meth:`swarm.step.agent.VehicleAgent.tick`): a chaser its
   target's estimate of tick ``k - 1``, then the gyro (+ AHRS), the UWB range the radio step produced from
   the truth at ``t_k``, the camera; on its control ticks guidance and its kind's controller;
2. the world holds the commands and hands the chasers' modes to its fault schedule
   (:meth:`swarm.step.world.World.take_commands`);
3. the referee judges contact and the keep-out sphere on the truth (:class:`swarm.step.referee.Referee`),
   then the world steps to tick ``k + 1``.

Ticks that need no Python (no control, no camera frame, no time-series sample) run compiled, many at a
time (:func:`swarm.step.tick.run_ticks`): the same compiled steps in the same order.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from swarm.step.agent import AgentInputs, VehicleAgent
from swarm.step.initial import initial_estimate
from swarm.step.outcome import chaser_summary, run_summary
from swarm.step.radio import UwbNetwork
from swarm.step.referee import Referee
from swarm.step.tick import (
    CONTACT,
    SENSORS_DONE,
    agent_arrays,
    radio_arrays,
    referee_arrays,
    run_ticks,
    world_arrays,
)
from swarm.step.world import World

NO_VISION = object()
"""Marker for 'this tick's samples are in the world's arrays and no camera sees anything'."""


def _has_vision(frames) -> bool:
    return any(fr.vision is not None for fr in frames.values())


@dataclass
class ChaserOutcome:
    """What happened to one chaser (DESIGN.md section 8 field names in its summary)."""

    docked: bool = False
    collided: bool = False
    docking_time_s: float | None = None
    position_error_m: float | None = None
    attitude_error_rad: float | None = None
    contact: dict | None = None
    keepout_violated: bool = False
    modes: list[dict] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)
    series: dict[str, list] = field(default_factory=dict)


SERIES_KEYS = ("t_s", "p_true_nav", "p_est_nav", "q_true_nav_body", "q_est_nav_body", "cov_pos", "mode",
               "relative_nav")  # fmt: skip


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
        sc = scenario
        self.sc = sc
        self.policy = policy or sc.policy
        self.seed = int(seed)
        self.record_series = record_series
        self.fast = fast  # False: every tick through the per-object Python path (the reference)
        self.world = World(sc, self.seed)  # draws and applies the run's dispersions, owns its faults
        self.dispersion = self.world.dispersion
        self.network = UwbNetwork(sc, self.seed)
        self.agents: dict[str, VehicleAgent] = {}
        for i, vid in enumerate(sc.vehicles):
            p0, v0, q0, cov0 = initial_estimate(sc, i, self.world.x[vid], self.seed)
            self.agents[vid] = VehicleAgent(sc, vid, p0, v0, q0, cov0, self.policy)
        self.referee = Referee(sc)
        self.outcomes = {c: ChaserOutcome(series={k: [] for k in SERIES_KEYS}) for c in sc.chasers}
        self.done: set[str] = set()
        self.control_periods = sorted({a.control_every for a in self.agents.values()})
        self._bind_storage()

    # ---- set-up ------------------------------------------------------------------------------------
    def _bind_storage(self) -> None:
        """Stack every agent's filter and health arrays (views stay with the agents) so the compiled
        loop sees all vehicles at once."""
        agents = list(self.agents.values())
        self.AX = np.ascontiguousarray(np.concatenate([a.est.X for a in agents]))
        self.AP = np.ascontiguousarray(np.concatenate([a.est.P for a in agents]))
        self.AC = np.ascontiguousarray(np.concatenate([a.est.counts for a in agents]))
        self.AB = np.ascontiguousarray(np.concatenate([a.est.book for a in agents]))
        self.PRMS = np.stack([a.est._prm for a in agents])
        self.Hok = np.stack([a.h_ok for a in agents])
        self.Hd2 = np.stack([a.h_d2 for a in agents])
        self.Hmeta = np.stack([a.h_meta for a in agents])
        self.Fb = np.stack([a.f_body for a in agents])
        self.Wb = np.stack([a.w_body for a in agents])
        self.plane = np.stack([a.plane for a in agents])
        self.mass = np.array([a.mass_kg for a in agents])
        for b, a in enumerate(agents):
            a.est.X, a.est.P = self.AX[b : b + 1], self.AP[b : b + 1]
            a.est.counts, a.est.book = self.AC[b : b + 1], self.AB[b : b + 1]
            a.est._prm = self.PRMS[b]
            a.h_ok, a.h_d2, a.h_meta = self.Hok[b], self.Hd2[b], self.Hmeta[b]
            a.f_body, a.w_body, a.plane = self.Fb[b], self.Wb[b], self.plane[b]
        self.t_agent = np.zeros(len(agents))
        self.last_vision = np.zeros(len(agents))
        self.dock_flag = np.zeros(len(agents), dtype=np.bool_)
        sc, first = self.sc, agents[0]
        self._cfg = (
            sc.dt_s, self.network.every, self.world.ahrs_every, sc.ahrs.enabled, first._ahrs_cov,
            first._gate_1d, first._gate_3d, first._sigma_range, sc.agent.vision_recent_s,
            sc.agent.uwb_with_vision,
        )  # fmt: skip
        self._camera = True
        self._cam_axis_body = {c: sc.kind(c).mounts.camera_axis_body for c in sc.chasers}

    def _is_control(self, k: int) -> bool:
        return any(k % e == 0 for e in self.control_periods)

    # ---- the run -----------------------------------------------------------------------------------
    def run(self) -> dict:
        sc = self.sc
        dt = sc.dt_s
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
                or self._is_control(k)
                or (series_every and k % series_every == 0)
                or (frames is not NO_VISION and _has_vision(frames))
            )
            if not python_tick:
                # compiled ticks up to the next one that needs Python (control, series, camera)
                camera = self._camera  # decided at the last Python tick, margins cover one control period
                k_end = k + 1
                while k_end <= max_k and not (
                    self._is_control(k_end)
                    or (series_every and k_end % series_every == 0)
                    or (camera and k_end % vision_every == 0)
                ):
                    k_end += 1
                k_stop, code = self._fast(k, min(k_end, max_k + 1))
                if code == CONTACT:  # tick k_stop's sensors are in; finish it here
                    k = k_stop
                    self._check_truth(k, k * dt)
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
            targets = {cid: snap[sc.vehicles[cid].target] for cid in sc.chasers}
            commands = {}
            if frames is NO_VISION or (self.fast and frames is not None and not _has_vision(frames)):
                for cid, est in targets.items():
                    self.agents[cid].set_target_estimate(est)
                self._fast(k, k + 1, sensors_only=True)  # the same sensor steps, compiled
                for vid, agent in self.agents.items():
                    if k % agent.control_every == 0 and vid not in self.done:
                        commands[vid] = agent.control(t, agent.control_dt)
            elif frames is not None:
                ranges = self.network.step(k, t, self.world.X, *self.world.radio_env(t))
                for vid, agent in self.agents.items():
                    fr = frames[vid]
                    r = ranges.get(vid)
                    inp = AgentInputs(
                        k, t, dt, fr.gyro_body, fr.q_ahrs_nav_body,
                        None if r is None else (r.anchor_id, r.range_m),
                        None if fr.vision is None else (fr.vision_kind, fr.vision), targets.get(vid),
                        control=vid not in self.done,  # a docked chaser's filter runs on; it commands nothing
                    )  # fmt: skip
                    cmd = agent.tick(inp)
                    if cmd is not None:
                        commands[vid] = cmd
            else:  # tick 0: no sample yet
                for cid, est in targets.items():
                    self.agents[cid].set_target_estimate(est)
                for vid, agent in self.agents.items():
                    commands[vid] = agent.control(t, agent.control_dt)
            for vid, cmd in commands.items():
                if vid in self.outcomes:
                    self._log_events(vid, cmd.events)
            self.world.take_commands(k, {v: (c.u, self.agents[v].mode.value) for v, c in commands.items()})
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

    def _camera_possible(self) -> bool:
        """Whether any chaser could see its target before the next control tick (then camera ticks need
        Python): a necessary condition on the truth, with margins for the motion within a control
        period: the target within the camera's range (plus a body's diagonal and 5 cm) and within its
        field-of-view cone (plus 5 deg)."""
        from swarm.core import rotations as rot

        cam = self.sc.camera
        reach = cam.max_range_m + 4.0 * self.sc.guidance.half_size_m + 0.05
        cos_fov = np.cos(np.radians(min(cam.fov_half_angle_deg + 5.0, 180.0)))
        X = self.world.X
        for c, (ic, it) in enumerate(self.referee.pairs):
            d = X[it, 0:3] - X[ic, 0:3]
            dist2 = d.dot(d)
            if dist2 > reach * reach:
                continue
            axis_nav = rot.quat_rotate(X[ic, 6:10], self._cam_axis_body[self.referee.chasers[c]])
            if axis_nav.dot(d) >= cos_fov * np.sqrt(dist2):
                return True
        return False

    def _fast(self, k0: int, k1: int, sensors_only: bool = False) -> tuple[int, int]:
        """Run ticks ``k0 .. k1 - 1`` compiled (:func:`swarm.step.tick.run_ticks`)."""
        w, net, ref = self.world, self.network, self.referee
        w.reserve_noise(k1 - k0)
        net.reserve_noise((k1 - k0) // net.every + 1)
        for b, a in enumerate(self.agents.values()):
            self.last_vision[b] = a._last_vision_s
            self.dock_flag[b] = a.docking_on_vision
        ref.set_modes({c: self.agents[c].mode for c in ref.chasers})
        ko_before = ref.ko_flag.copy()
        k_stop, code = run_ticks(
            k0, k1, self._cfg, world_arrays(w), radio_arrays(net), agent_arrays(self), referee_arrays(ref),
            sensors_only,
        )  # fmt: skip
        for b, a in enumerate(self.agents.values()):
            a.t_s = float(self.t_agent[b])
        if code != SENSORS_DONE:
            w.k = k_stop  # the world's state is that of tick k_stop
        for c, cid in enumerate(ref.chasers):
            if ref.ko_flag[c] and not ko_before[c]:
                self._keepout(cid, float(ref.ko_t[c]), float(ref.ko_r[c]))
        return k_stop, code

    def _keepout(self, cid: str, t: float, range_m: float) -> None:
        out = self.outcomes[cid]
        if not out.keepout_violated:
            out.events.append(
                {"t_s": t, "keepout_violation": True, "mode": self.agents[cid].mode.value, "range_m": range_m}
            )
        out.keepout_violated = True

    def _log_events(self, cid: str, events: list[dict]) -> None:
        out = self.outcomes[cid]
        for ev in events:
            out.events.append(ev)
            out.modes.append(
                {"mode": ev["to"], "t_s": ev["t_s"], "range_m": ev["range_m"], "reason": ev["reason"]}
            )

    def _check_truth(self, k: int, t: float) -> None:
        sc = self.sc
        if self.record_series and k % sc.sim.series_every == 0:
            for cid, out in self.outcomes.items():
                if cid in self.done:
                    continue
                agent, x = self.agents[cid], self.world.x[cid]
                s = out.series
                s["t_s"].append(t)
                s["p_true_nav"].append(x[0:3].tolist())
                s["p_est_nav"].append(agent.est.p_nav[0].tolist())
                s["q_true_nav_body"].append(x[6:10].tolist())
                s["q_est_nav_body"].append(agent.est.q_nav_body[0].tolist())
                s["cov_pos"].append(agent.est.P[0, :3, :3].tolist())
                s["mode"].append(agent.mode.value)
                s["relative_nav"].append(bool(agent.relative_nav))
        keepouts, contacts = self.referee.judge(
            self.world.X, t, {c: self.agents[c].mode for c in self.referee.chasers}
        )
        for cid, range_m in keepouts:
            self._keepout(cid, t, range_m)
        for cid, ct in contacts:
            out = self.outcomes[cid]
            out.docked, out.collided = ct.docked, not ct.docked
            out.contact = ct.contact
            out.docking_time_s = t
            out.position_error_m = ct.position_error_m
            out.attitude_error_rad = ct.attitude_error_rad
            self.world.attach(cid, sc.vehicles[cid].target)
            self.done.add(cid)
            self._log_events(cid, [ct.event(self.agents[cid].mode.value)])

    def _summary(self, t_end: float, wall: float) -> dict:
        sc = self.sc
        chasers = {}
        for cid, out in self.outcomes.items():
            agent = self.agents[cid]
            sw = agent.switcher
            d = chaser_summary(
                sc, cid, docked=out.docked, collided=out.collided, docking_time_s=out.docking_time_s,
                effort=self.world.effort_by_vehicle[cid], position_error_m=out.position_error_m,
                attitude_error_rad=out.attitude_error_rad, final_mode=agent.mode.value, modes=out.modes,
                r1_m=sw.r1_m, r2_m=sw.r2_m, keepout_violated=out.keepout_violated,
                closest_approach_m=self.referee.closest_approach(cid), contact=out.contact,
                estimator={
                    "rejected_ranges": int(agent.est.count(0, "rejected")[0]),
                    "accepted_ranges": int(agent.est.count(0, "accepted")[0]),
                    "accepted_vision": int(
                        agent.est.count(1, "accepted")[0] + agent.est.count(2, "accepted")[0]
                    ),
                },
            )  # fmt: skip
            if self.policy == "mdp":
                d["decisions"] = [dec.as_dict() for dec in sw.decisions]
            if self.record_series:
                d["series"] = out.series
            if sc.faults.enabled:
                f = self.world.faults
                d["faults"] = {
                    "events": [ev for ev in f.events if ev["chaser"] == cid],
                    "uwb_dropout_s": f.dropout_windows(),
                    "camera_loss_s": [tuple(w) for w in f.camera[cid]],
                    "nlos_burst_s": [tuple(w) for w in f.nlos],
                }
            chasers[cid] = d
        return run_summary(sc, self.policy, self.seed, t_end, wall, self.world.effort_by_vehicle, chasers)


def run_docking(scenario, policy: str | None = None, seed: int = 0, record_series: bool = True) -> dict:
    """Run one docking in-process and return its summary (DESIGN.md section 8 fields per chaser)."""
    return DockingSim(scenario, policy, seed, record_series).run()
