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

Ticks that need no Python (everything but a camera frame that may see the target, a guidance mode switch
and a contact) run compiled, many at a time (:func:`swarm.step.tick.run_ticks`): the same compiled steps
in the same order.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from swarm.core.guidance import MODES
from swarm.core.mdp import D_N, DECISION_STAGING
from swarm.step.agent import ROLE_CHASER, AgentInputs, VehicleAgent
from swarm.step.initial import initial_estimate
from swarm.step.outcome import chaser_summary, run_summary
from swarm.step.radio import TdoaSample, UwbNetwork
from swarm.step.referee import Referee
from swarm.step.tick import (
    CONTACT,
    EVENT,
    S_COV,
    S_MODE,
    S_PEST,
    S_PTRUE,
    S_QEST,
    S_QTRUE,
    S_REL,
    S_T,
    SERIES_N,
    STAGING_FULL,
    agent_arrays,
    camera_possible,
    radio_arrays,
    record_series,
    referee_arrays,
    run_ticks,
    world_arrays,
)
from swarm.step.world import World

NO_VISION = object()
"""Marker for 'this tick's samples are in the world's arrays and no camera sees anything'."""

SEGMENT_TICKS = 4096
"""Longest run of compiled ticks per call (the noise drawn ahead of it is sized by it)."""


def _has_vision(frames) -> bool:
    return any(fr.vision is not None for fr in frames.values())


@dataclass
class ChaserOutcome:
    """What happened to one chaser (swarm/step/outcome.py field names in its summary)."""

    docked: bool = False
    collided: bool = False
    docking_time_s: float | None = None
    position_error_m: float | None = None
    attitude_error_rad: float | None = None
    contact: dict | None = None
    keepout_violated: bool = False
    modes: list[dict] = field(default_factory=list)
    events: list[dict] = field(default_factory=list)


SERIES_KEYS = ("t_s", "p_true_nav", "p_est_nav", "q_true_nav_body", "q_est_nav_body", "cov_pos", "mode",
               "relative_nav")  # fmt: skip


def _pad(rows: list[np.ndarray]) -> np.ndarray:
    """Rows of different lengths (each kind's own) stacked, zero-padded to the longest."""
    out = np.zeros((len(rows), max(max(len(r) for r in rows), 1)))
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


class DockingSim:
    """One run of a scenario in-process; :meth:`run` returns the JSON-ready summary."""

    def __init__(
        self,
        scenario,
        policy: str | None = None,
        seed: int = 0,
        record_series: bool = True,
        fast: bool = True,
        series_keys: tuple[str, ...] | None = None,
        tap=None,
    ):
        sc = scenario
        self.sc = sc
        self.policy = policy or sc.policy
        self.seed = int(seed)
        self.record_series = record_series
        # the series keys the summary carries (None: all of them); the compiled loop records every column
        # either way, this only saves turning the others into lists (a campaign needs two of eight)
        self.series_keys = series_keys
        # fast=False: every tick through the per-object Python path (the reference); so with a tap:
        # ``swarm sim --mcap`` (swarm.transport.wire.DockingTap) sees every tick as the processes
        # would publish it: tap.start(sim), then per tick tap.world(sim, k, frames), tap.uwb(sim, k) and
        # tap.agent(sim, vid, k, command or None) of every vehicle, tap.keepout(cid, t, mode, range_m) and
        # tap.contact(cid, t, mode, contact) for the referee's verdicts, and tap.end(sim, k, reason, wall_s)
        # the TDoA radio (uwb.mode tdoa2/tdoa3) hands each tag a variable number of differences a tick: the
        # per-tick path only (the compiled loop carries one range a tick)
        self.fast = fast and tap is None and sc.uwb.mode == "twr"
        self.tap = tap
        self.world = World(sc, self.seed)  # draws and applies the run's dispersions, owns its faults
        self.dispersion = self.world.dispersion
        self.network = UwbNetwork(sc, self.seed)
        self.agents: dict[str, VehicleAgent] = {}
        for i, vid in enumerate(sc.vehicles):
            p0, v0, q0, cov0 = initial_estimate(sc, i, self.world.x[vid], self.seed)
            self.agents[vid] = VehicleAgent(sc, vid, p0, v0, q0, cov0, self.policy)
        self.referee = Referee(sc)
        self.outcomes = {c: ChaserOutcome() for c in sc.chasers}
        self.done: set[str] = set()
        self._bind_storage()

    # ---- set-up ------------------------------------------------------------------------------------
    def _bind_storage(self) -> None:
        """Stack every agent's filter, health and control arrays (views stay with the agents and their
        guidance, switcher and controller objects) so the compiled loop sees all vehicles at once."""
        agents = list(self.agents.values())
        n = len(agents)
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
        # control: roles, periods, targets and every agent's guidance / switcher / controller arrays
        ids = list(self.agents)
        self.role = np.array([a.role_code for a in agents], dtype=np.int64)
        self.every = np.array([a.control_every for a in agents], dtype=np.int64)
        self.phase = np.array([a.control_phase for a in agents], dtype=np.int64)
        self.vdone = np.zeros(n, dtype=np.bool_)
        self.tidx = np.array([ids.index(a.target_id) if a.target_id else -1 for a in agents], dtype=np.int64)
        self.TGT = np.stack([a.TGT for a in agents])
        self.G = np.stack([a.G for a in agents])
        self.GP = np.stack([a.GP for a in agents])
        self.SW = np.stack([a.SW for a in agents])
        self.DEC = np.zeros((n, DECISION_STAGING, D_N))
        self.DEC_n = np.zeros(n, dtype=np.int64)
        self.EV = np.zeros((n, max(a.EV.shape[0] for a in agents), agents[0].EV.shape[1]))
        self.EV_n = np.zeros(n, dtype=np.int64)
        self.ST = np.stack([a.ST for a in agents])
        self.SP = np.stack([a.SP for a in agents])
        self.CS = _pad([a.CS for a in agents])
        self.CP = _pad([a.CP for a in agents])
        self.REF = np.stack([a.REF for a in agents])
        self.UC = _pad([a.U for a in agents])
        self.ACT = np.stack([a.ACT for a in agents])
        self.SAT = np.zeros(n, dtype=np.bool_)
        self.ctl = np.zeros(n, dtype=np.bool_)
        for b, a in enumerate(agents):
            a.est.X, a.est.P = self.AX[b : b + 1], self.AP[b : b + 1]
            a.est.counts, a.est.book = self.AC[b : b + 1], self.AB[b : b + 1]
            a.est._prm = self.PRMS[b]
            a.h_ok, a.h_d2, a.h_meta = self.Hok[b], self.Hd2[b], self.Hmeta[b]
            a.f_body, a.w_body, a.plane = self.Fb[b], self.Wb[b], self.plane[b]
            a.TGT, a.G, a.GP, a.SW = self.TGT[b], self.G[b], self.GP[b], self.SW[b]
            a.ST, a.SP, a.REF, a.ACT = self.ST[b], self.SP[b], self.REF[b], self.ACT[b]
            a.CS = a.controller.cs = self.CS[b, : len(a.CS)]
            a.CP = a.controller.cp = self.CP[b, : len(a.CP)]
            a.U = self.UC[b, : len(a.U)]
            a.DEC, a.DEC_n = self.DEC[b], self.DEC_n[b : b + 1]
            a.EV, a.EV_n = self.EV[b], self.EV_n[b : b + 1]
            if a.role_code == ROLE_CHASER:
                a.guidance.G, a.guidance.GP, a.guidance.REF = a.G, a.GP, a.REF
                a.guidance.EV, a.guidance.EV_n = a.EV, a.EV_n
                a.switcher.SW, a.switcher.staged, a.switcher.staged_n = a.SW, a.DEC, a.DEC_n
            else:
                a.guidance.ST, a.guidance.SP, a.guidance.REF = a.ST, a.SP, a.REF
        self.t_agent = np.zeros(n)
        self.last_vision = np.zeros(n)
        # the camera mounts the filters use (a compiled camera model's frame is fused in the compiled loop)
        self.MP = np.stack([a.est._cam_pos for a in agents])
        self.MR = np.ascontiguousarray(np.stack([a.est._R_bc for a in agents]))
        self.MQ = np.stack([a.est._q_bc for a in agents])
        n_pairs = len(self.referee.chasers)
        self._compiled_cams = self.world.compiled_cameras
        self._V = (
            np.array([self._compiled_cams]),
            np.zeros((n_pairs, self.world.frame_width)),
            np.zeros(n_pairs, dtype=np.bool_),
        )
        sc, first = self.sc, agents[0]
        self._vision_every = sc.every(sc.camera.rate_hz)
        self._series_every = sc.sim.series_every if self.record_series else 0
        self._cfg = (
            sc.dt_s, self.network.every, self.world.ahrs_every, sc.ahrs.enabled, first._ahrs_cov,
            first._gate_1d, first._gate_3d, first._sigma_range, sc.agent.vision_recent_s,
            sc.agent.uwb_with_vision, sc.agent.latch_target_with_vision, float(sc.guidance.dock_speed_m_s),
            self._series_every, self._vision_every, sc.agent.vision_target_cov, first._gate_6d,
            np.array([a._gate_features for a in agents]), np.array([a._sigma_feature for a in agents]),
        )  # fmt: skip
        # camera_possible: the target within the camera's range plus a body's diagonal and 5 cm, within
        # its field-of-view cone plus 5 deg (margins for the motion within a control period)
        cam = sc.camera
        axes = [sc.kind(c).mounts.camera_axis_body for c in self.referee.chasers]
        self._cam = (
            np.ones(1, dtype=np.bool_), np.array(axes, dtype=float).reshape(-1, 3),
            float(cam.max_range_m + 4.0 * sc.guidance.half_size_m + 0.05),
            float(np.cos(np.radians(min(cam.fov_half_angle_deg + 5.0, 180.0)))),
        )  # fmt: skip
        max_k = round(sc.sim.max_duration_s / sc.dt_s)
        rows = max_k // self._series_every + 2 if self._series_every else 0
        self.SER = np.zeros((len(self.referee.chasers), rows, SERIES_N))
        self.SER_n = np.zeros(len(self.referee.chasers), dtype=np.int64)

    @property
    def _camera(self) -> bool:
        return bool(self._cam[0][0])

    def _update_camera(self) -> None:
        self._cam[0][0] = camera_possible(self.world.X, self.referee.pairs, *self._cam[1:])

    # ---- the run -----------------------------------------------------------------------------------
    def run(self) -> dict:
        sc = self.sc
        dt = sc.dt_s
        max_k = round(sc.sim.max_duration_s / dt)
        watched = {sc.vehicles[c].target for c in sc.chasers}
        frames = None  # tick k's sensor frames; NO_VISION: they are in the world's arrays, no camera frame
        tap = self.tap
        if tap is not None:
            tap.start(self)
        wall0 = time.perf_counter()
        k = 0
        while k <= max_k:
            t = k * dt
            if self.fast and frames is not None and (frames is NO_VISION or not _has_vision(frames)):
                k_end = min(k + SEGMENT_TICKS, max_k + 1)
                if (
                    self._camera and not self._compiled_cams
                ):  # no further than the next camera tick (it stops there)
                    k_end = min(k_end, (k // self._vision_every + 1) * self._vision_every)
                k, frames = self._fast(k, k_end)
                if frames is None:  # the run is over
                    break
                continue
            # one tick in Python: tick 0, a camera frame that sees the target, or the per-tick path
            snap = {vid: self.agents[vid].estimate() for vid in watched}  # estimates of tick k - 1
            targets = {cid: snap[sc.vehicles[cid].target] for cid in sc.chasers}
            commands = {}
            if frames is not None:
                if tap is not None:
                    tap.world(self, k, frames)
                ranges = self.network.step(k, t, self.world.X, *self.world.radio_env(t))
                if tap is not None:
                    tap.uwb(self, k)
                for vid, agent in self.agents.items():
                    fr = frames[vid]
                    r = ranges.get(vid)
                    tdoa = isinstance(r, TdoaSample)
                    inp = AgentInputs(
                        k, t, dt, fr.gyro_body, fr.q_ahrs_nav_body,
                        None if r is None or tdoa else (r.anchor_id, r.range_m),
                        None if fr.vision is None else (fr.vision_kind, fr.vision), targets.get(vid),
                        control=vid not in self.done,  # a docked chaser's filter runs on; it commands nothing
                        tdoa=r.rows if tdoa else None,
                    )  # fmt: skip
                    cmd = agent.tick(inp)
                    if cmd is not None:
                        commands[vid] = cmd
            else:  # tick 0: no sample yet
                for cid, est in targets.items():
                    self.agents[cid].set_target_estimate(est)
                for vid, agent in self.agents.items():
                    if agent.is_control_tick(0):  # a vehicle whose control_phase is later idles until then
                        commands[vid] = agent.control(t, agent.control_dt)
            if tap is not None:
                for vid in self.agents:
                    tap.agent(self, vid, k, commands.get(vid))
            if self._finish_tick(k, commands, series=True):
                break
            self._update_camera()
            build = not self.fast or ((k + 1) % self._vision_every == 0 and self._camera)
            frames = self.world.step(build_frames=build)
            if frames is None:
                frames = NO_VISION
            k += 1
        wall = time.perf_counter() - wall0
        if tap is not None:
            reason = "all_contact" if len(self.done) == len(self.outcomes) else "max_duration"
            tap.end(self, min(k, max_k), reason, wall)
        return self._summary(min(k, max_k) * dt, wall)

    def _finish_tick(self, k: int, commands: dict, series: bool) -> bool:
        """The rest of tick ``k`` after the agents' steps: the chasers' mode switches logged, the commands
        held (and the modes handed to the fault schedule), the series sample (``series``) and the referee.
        Returns True when every chaser is done."""
        for vid, cmd in commands.items():
            if vid in self.outcomes:
                self._log_events(vid, cmd.events)
        self.world.take_commands(k, {v: (c.u, self.agents[v].mode.value) for v, c in commands.items()})
        if series:
            self._record_series(k)
        self._judge(k, k * self.sc.dt_s)
        return len(self.done) == len(self.outcomes)

    def _fast(self, k0: int, k1: int):
        """Ticks from ``k0`` compiled (:func:`swarm.step.tick.run_ticks`) until ``k1`` or until one needs
        Python; finishes a tick the loop left half done. Returns the next tick and its frames (NO_VISION:
        none built; None: the run is over)."""
        w, net, ref = self.world, self.network, self.referee
        w.reserve_noise(k1 - k0)
        net.reserve_noise((k1 - k0) // net.every + 1)
        agents = list(self.agents.values())
        for b, a in enumerate(agents):
            self.last_vision[b] = a._last_vision_s
            self.t_agent[b] = a.t_s
        ref.set_modes({c: self.agents[c].mode for c in ref.chasers})
        ko_before = ref.ko_flag.copy()
        k, code = run_ticks(
            k0, k1, self._cfg, world_arrays(w), radio_arrays(net), agent_arrays(self), referee_arrays(ref),
            self._cam, self._V, w.cam_arrays, self.SER, self.SER_n,
        )  # fmt: skip
        for b, a in enumerate(agents):
            a.t_s = float(self.t_agent[b])
            a._last_vision_s = float(self.last_vision[b])
        for c, cid in enumerate(ref.chasers):
            if ref.ko_flag[c] and not ko_before[c]:
                self._keepout(cid, float(ref.ko_t[c]), float(ref.ko_r[c]))
        dt = self.sc.dt_s
        if code == STAGING_FULL:
            w.k = k
            for a in agents:
                if a.switcher is not None:
                    a.switcher.drain()
            return k, NO_VISION
        if code == EVENT:  # tick k's agents are done; the commands, the series and the referee are not
            w.k = k
            commands = {
                vid: a.command_of(k * dt, bool(self.SAT[b]))
                for b, (vid, a) in enumerate(self.agents.items())
                if self.ctl[b]
            }
            if self._finish_tick(k, commands, series=True):
                return k, None
        elif code == CONTACT:  # only the referee's verdict and the world step are left
            w.k = k
            self._judge(k, k * dt)
            if len(self.done) == len(self.outcomes):
                return k, None
        else:  # REACHED_END, CAMERA: the world's state is that of tick k
            w.k = k
            if k % self._vision_every == 0 and self._camera and not self._compiled_cams:
                return k, w.frames()
            return k, NO_VISION  # (compiled cameras: the loop built tick k's frames)
        build = (k + 1) % self._vision_every == 0 and self._camera
        frames = w.step(build_frames=build)
        return k + 1, (NO_VISION if frames is None else frames)

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

    def _record_series(self, k: int) -> None:
        """The time-series sample of tick ``k`` of every chaser not done (compiled
        :func:`swarm.step.tick.record_series`, as the compiled loop records it)."""
        if not (self._series_every and k % self._series_every == 0):
            return
        t = k * self.sc.dt_s
        for c, cid in enumerate(self.referee.chasers):
            if cid in self.done:
                continue
            agent = self.agents[cid]
            mode = float(MODES.index(agent.mode))
            i = int(self.referee.pairs[c, 0])
            row = self.SER[c, self.SER_n[c]]
            record_series(
                row,
                t,
                self.world.X[i],
                agent.est.X[0],
                agent.est.P[0],
                agent.TGT,
                mode,
                bool(agent.relative_nav),
            )
            self.SER_n[c] += 1

    def _judge(self, k: int, t: float) -> None:
        keepouts, contacts = self.referee.judge(
            self.world.X, t, {c: self.agents[c].mode for c in self.referee.chasers}
        )
        for cid, range_m in keepouts:
            if self.tap is not None:
                self.tap.keepout(cid, t, self.agents[cid].mode.value, range_m)
            self._keepout(cid, t, range_m)
        for cid, ct in contacts:
            if self.tap is not None:
                self.tap.contact(cid, t, self.agents[cid].mode.value, ct)
            out = self.outcomes[cid]
            out.docked, out.collided = ct.docked, not ct.docked
            out.contact = ct.contact
            out.docking_time_s = t
            out.position_error_m = ct.position_error_m
            out.attitude_error_rad = ct.attitude_error_rad
            self.world.attach(cid, self.sc.vehicles[cid].target)
            self.done.add(cid)
            self.vdone[list(self.agents).index(cid)] = True
            self._log_events(cid, [ct.event(self.agents[cid].mode.value)])

    def series(self, chaser: str, keys: tuple[str, ...] | None = None) -> dict[str, list]:
        """The chaser's time series (:data:`SERIES_KEYS`, or only ``keys``), one sample every
        ``sim.series_every`` ticks."""
        c = self.referee.chasers.index(chaser)
        rows = self.SER[c, : self.SER_n[c]]
        columns = {
            "t_s": lambda: rows[:, S_T].tolist(),
            "p_true_nav": lambda: rows[:, S_PTRUE : S_PTRUE + 3].tolist(),
            "p_est_nav": lambda: rows[:, S_PEST : S_PEST + 3].tolist(),
            "q_true_nav_body": lambda: rows[:, S_QTRUE : S_QTRUE + 4].tolist(),
            "q_est_nav_body": lambda: rows[:, S_QEST : S_QEST + 4].tolist(),
            "cov_pos": lambda: rows[:, S_COV : S_COV + 9].reshape(-1, 3, 3).tolist(),
            "mode": lambda: [MODES[int(m)].value for m in rows[:, S_MODE]],
            "relative_nav": lambda: [bool(r) for r in rows[:, S_REL]],
        }
        unknown = set(keys or ()) - set(columns)
        if unknown:
            raise ValueError(f"series keys: unknown {sorted(unknown)}, known {list(columns)}")
        return {k: make() for k, make in columns.items() if keys is None or k in keys}

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
                d["series"] = self.series(cid, self.series_keys)
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


def run_docking(
    scenario, policy: str | None = None, seed: int = 0, record_series: bool = True, tap=None
) -> dict:
    """Run one docking in-process and return its summary (swarm/step/outcome.py fields per chaser); ``tap``:
    :class:`DockingSim`'s (``swarm sim --mcap``)."""
    return DockingSim(scenario, policy, seed, record_series, tap=tap).run()
