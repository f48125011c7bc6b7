"""The one tick, compiled: the ticks between two events that need Python (docs/architecture.md).

A tick is the radio step, every agent's step (the target estimates a chaser takes, the IMU and UWB
samples, and on a vehicle's control ticks guidance, Algorithm 1 and its kind's controller), the world
holding the new commands, the referee and the world step. :func:`run_ticks` runs those ticks by calling
the *same* compiled step functions that the objects call one tick at a time, in the same order, on the
same arrays: :func:`swarm.step.radio.radio_env`, :func:`~swarm.step.radio.uwb_tick` and
:func:`~swarm.step.radio.uwb_errors_tick`,
:func:`swarm.step.agent.agent_imu`, :func:`~swarm.step.agent.agent_uwb` and
:func:`~swarm.step.agent.agent_control`, :func:`swarm.kinds._dispatch.hold_step`,
:func:`swarm.step.referee.referee_tick` and :func:`swarm.step.world.world_tick`. A run is bit for bit
the run of the per-tick path (a test checks it).

It returns to Python only for what compiled code cannot do: a camera frame that may see the target
(projecting markers, PnP), a guidance mode switch (its words, the fault windows it may open), a contact
(its record), a full staging buffer of Algorithm 1 passes.

Each step's arrays travel as one tuple, built by the object that owns them (:func:`world_arrays`,
:func:`radio_arrays`, :func:`agent_arrays`, :func:`referee_arrays`), in the order of the kernels'
arguments.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from swarm.core import _guidance_nb as gnb
from swarm.core._ekf_nb import ST_ACCEPTED
from swarm.core._rot_nb import qrotate
from swarm.kinds._dispatch import hold_step
from swarm.step.agent import (
    ROLE_CHASER,
    TG_COV,
    TG_HAS,
    TG_P,
    TG_Q,
    TG_T,
    absolute_cov_pos,
    agent_control,
    agent_features,
    agent_imu,
    agent_pose,
    agent_uwb,
    relative_nav,
)
from swarm.step.radio import radio_env, uwb_errors_tick, uwb_tick
from swarm.step.referee import NO_CONTACT, referee_tick
from swarm.step.world import CAM_FEATURES, CAM_POSE, camera_frame, world_tick

REACHED_END = 0
"""Ticks ``k0 .. k1 - 1`` are done; the world is at tick ``k1``."""
CONTACT = 1
"""A chaser may touch its target at tick ``k``: everything of tick ``k`` is done but the referee's
verdict and the world step."""
EVENT = 2
"""A guidance mode switch at tick ``k``: its sensors and control are done (the commands are in the
agents' ``U``); holding the commands, the series sample, the referee and the world step are left."""
CAMERA = 3
"""The world is at tick ``k``, a camera tick at which a camera may see its target: the caller builds the
camera frames and runs tick ``k``."""
STAGING_FULL = 4
"""Nothing of tick ``k`` is done: a chaser that controls at tick ``k`` has a full staging buffer of
Algorithm 1 passes (the caller drains it)."""

# one time-series sample of a chaser (DockingSim.series): t, p_true (3), p_est (3), q_true (4), q_est (4),
# cov_pos (9), mode code, relative navigation
S_T, S_PTRUE, S_PEST, S_QTRUE, S_QEST, S_COV, S_MODE, S_REL = 0, 1, 4, 7, 11, 15, 24, 25
SERIES_N = 26


def world_arrays(w) -> tuple:
    """The arrays of :func:`swarm.step.world.world_tick` (without ``do_ahrs`` and ``t_s``), then the radio
    fault windows, of a :class:`swarm.step.world.World`."""
    return (w.X, w.S, w.U, w.KP, w.codes, w.effort, w.attached_arr, w.bias, w.gyro_noise, w.gi, w.ahrs_noise,
            w.ai, w.prm, w.gyro_out, w.ahrs_out, w.gyro_step_t, w.gyro_step, w.drop_w, w.nlos_w)  # fmt: skip


def radio_arrays(net) -> tuple:
    """The arrays of :func:`swarm.step.radio.uwb_tick` (without ``t_s`` and ``X``) of a
    :class:`swarm.step.radio.UwbNetwork`."""
    return (net.lever, net.anchors, net.drift, net.prm, net.next_anchor, net.noise, net.ui, net.env_lost,
            net.env_p, net.lost, net.anchor_id, net.range_m, net.outlier, net.tdma_slot, net.tdma_prm,
            net.idle, net.collided, net.collisions, net.airborne, net.err_state, net.err_offset, net.err_step,
            net.err_noise, net.err_prm)  # fmt: skip


def agent_arrays(a) -> tuple:
    """Every agent's filter, health and control arrays, stacked (n, ...), of the in-process runner ``a``
    (:class:`swarm.sim.docking.DockingSim`)."""
    return (a.AX, a.AP, a.AC, a.AB, a.PRMS, a.Fb, a.Wb, a.mass, a.plane, a.Hok, a.Hd2, a.Hmeta, a.last_vision,
            a.MP, a.t_agent, a.role, a.every, a.phase, a.vdone, a.tidx, a.TGT, a.G, a.GP, a.SW, a.DEC,
            a.DEC_n, a.EV, a.EV_n, a.ST, a.SP, a.CS, a.CP, a.REF, a.UC, a.ACT, a.SAT, a.ctl, a.MR,
            a.MQ)  # fmt: skip


def referee_arrays(r) -> tuple:
    """The arrays of :func:`swarm.step.referee.referee_tick` (without ``X`` and ``t_s``) of a
    :class:`swarm.step.referee.Referee`."""
    g = r.g
    return (r.pairs, r.done, r.docking, g.face_normal_target, r.q_tc, g.half_size_m, g.keepout_radius_m,
            g.corridor_cos, g.contact_distance_m, r.ko_flag, r.ko_t, r.ko_r, r.closest)  # fmt: skip


@njit(cache=True)
def camera_possible(X, pairs, cam_axis_body, reach, cos_fov):
    """Whether any chaser (pair ``(chaser, target)`` of ``pairs``) could see its target before its next
    control tick: a necessary condition on the truth ``X``: the target within ``reach`` [m] (the camera's
    range plus margins for a control period's motion and the bodies' size) and within the cone of
    half-angle ``acos(cos_fov)`` about the camera's axis (``cam_axis_body`` (P, 3), body frame)."""
    for c in range(pairs.shape[0]):
        ic, it = pairs[c, 0], pairs[c, 1]
        d0 = X[it, 0] - X[ic, 0]
        d1 = X[it, 1] - X[ic, 1]
        d2 = X[it, 2] - X[ic, 2]
        dist2 = d0 * d0 + d1 * d1 + d2 * d2
        if dist2 > reach * reach:
            continue
        a = qrotate(X[ic, 6:10], cam_axis_body[c])
        if a[0] * d0 + a[1] * d1 + a[2] * d2 >= cos_fov * np.sqrt(dist2):
            return True
    return False


@njit(cache=True)
def docking_on_vision(mode, last_vision):
    """In the final approach (DOCK, DOCKED) with vision acquired at some point
    (:attr:`swarm.step.agent.VehicleAgent.docking_on_vision`; ``mode`` the code of its guidance mode)."""
    return (mode == gnb.M_DOCK or mode == gnb.M_DOCKED) and last_vision > -np.inf


@njit(cache=True)
def set_target(TGT, X_t, P_t, t, latch, rel_nav):
    """A chaser takes its target's estimate (the target filter's ``X_t``, ``P_t`` as of the previous tick)
    into ``TGT``, unless it holds the one it has while navigating relative to the target (``latch`` and
    ``rel_nav``)."""
    if latch and rel_nav and TGT[TG_HAS] != 0.0:
        return
    TGT[TG_HAS] = 1.0
    TGT[TG_T] = t
    for i in range(3):
        TGT[TG_P + i] = X_t[i]
    for i in range(4):
        TGT[TG_Q + i] = X_t[6 + i]
    for i in range(3):
        for j in range(3):
            TGT[TG_COV + 3 * i + j] = P_t[i, j]


@njit(cache=True)
def record_series(row, t, x, X_est, P_est, TGT, mode, rel):
    """One time-series sample of a chaser (``S_*``): its truth ``x`` and estimate at ``t``, the position
    covariance in nav (:func:`swarm.step.agent.absolute_cov_pos`)."""
    row[S_T] = t
    for i in range(3):
        row[S_PTRUE + i] = x[i]
        row[S_PEST + i] = X_est[i]
    for i in range(4):
        row[S_QTRUE + i] = x[6 + i]
        row[S_QEST + i] = X_est[6 + i]
    cov = np.empty((3, 3))
    absolute_cov_pos(P_est, TGT, rel, cov)
    for i in range(3):
        for j in range(3):
            row[S_COV + 3 * i + j] = cov[i, j]
    row[S_MODE] = mode
    row[S_REL] = 1.0 if rel else 0.0


@njit(cache=True)
def _world(W, do_ahrs, t):
    (X, S, U, KP, codes, effort, attached, bias, gyro_noise, gi, ahrs_noise, ai, wprm, gyro_out, ahrs_out,
     gstep_t, gstep, _drop_w, _nlos_w) = W  # fmt: skip
    world_tick(X, S, U, KP, codes, effort, attached, bias, gyro_noise, gi, ahrs_noise, ai, do_ahrs, wprm,
               gyro_out, ahrs_out, t, gstep_t, gstep)  # fmt: skip


@njit(cache=True)
def run_ticks(k0, k1, cfg, W, R, A, F, C, V, PC, SER, SER_n):
    """Ticks ``k0 .. k1 - 1`` (module docstring). ``cfg`` = ``(dt, uwb_every, ahrs_every, ahrs_enabled,
    ahrs_cov, gate1, gate3, sigma_range, vision_recent_s, uwb_with_vision, latch_target, dock_speed,
    series_every, vision_every, vision_target_cov, gate6, gate_features (n,), sigma_feature (n,))``; ``W``,
    ``R``, ``A``, ``F`` the world's, radio's, agents' and referee's arrays; ``C`` = ``(camera flag (1,),
    each pair's camera axis (P, 3), reach, cos_fov)`` (:func:`camera_possible`); ``V`` = ``(every camera
    model is compiled, frames (P, W), frame present (P,))`` and ``PC`` the world's ``cam_arrays``
    (:func:`swarm.step.world.camera_frame`): with compiled camera models only ("features", "pose"), the
    camera frames are built and fused here, else the loop stops at a camera tick (CAMERA). ``SER`` (P, cap,
    SERIES_N) the chasers' time series, ``SER_n`` (P,) rows used. Returns ``(k, code)``: ``(k1,
    REACHED_END)`` or the tick and reason of an earlier stop (the codes' docstrings say what of tick ``k``
    is done)."""
    (dt, uwb_every, ahrs_every, ahrs_enabled, ahrs_cov, gate1, gate3, sigma_r, recent_s, uwb_with_vision,
     latch, dock_speed, series_every, vision_every, target_cov, gate6, gate_f, sigma_f) = cfg  # fmt: skip
    X, S, U, KP, codes, attached = W[0], W[1], W[2], W[3], W[4], W[6]
    drop_w, nlos_w = W[17], W[18]
    gyro_out, ahrs_out = W[13], W[14]
    (lever, anchors, drift, uprm, next_anchor, unoise, ui, env_lost, env_p, lost, anchor_id, range_m,
     outlier, tdma_slot, tdma_prm, idle, collided, collisions, airborne, err_state, err_offset, err_step,
     err_noise, err_prm) = R  # fmt: skip
    (AX, AP, AC, AB, PRMS, f_body, w_body, mass, plane, Hok, Hd2, Hmeta, last_vision, MP, t_agent,
     role, every, phase, vdone, tidx, TGT, G, GP, SW, DEC, DEC_n, EV, EV_n, ST, SP, CS, CP, REF, UC, ACT, SAT,
     ctl, MR, MQ) = A  # fmt: skip
    (pairs, done, docking, n_target, q_tc, half, keepout_r, corridor_cos, contact_d, ko_flag, ko_t, ko_r,
     closest) = F  # fmt: skip
    cam, cam_axis, reach, cos_fov = C
    compiled_cams, VF, VF_ok = V
    cam_model, markers_t = PC[11], PC[4]
    n = AX.shape[0]
    n_pairs = pairs.shape[0]
    for j in range(k0, k1):
        t = j * dt
        any_ctl = False
        for v in range(n):
            ctl[v] = (j - phase[v]) % every[v] == 0 and not vdone[v]
            any_ctl = any_ctl or ctl[v]
            if ctl[v] and role[v] == ROLE_CHASER and DEC_n[v] >= DEC.shape[1]:
                return j, STAGING_FULL
        # a chaser that controls or sees its target this tick takes its target's estimate of tick j - 1
        for v in range(n):
            if role[v] != ROLE_CHASER:
                continue
            seen = False
            for c in range(n_pairs):
                if pairs[c, 0] == v and VF_ok[c]:
                    seen = True
            if ctl[v] or seen:
                rel = relative_nav(t_agent[v], last_vision[v], recent_s,
                                   docking_on_vision(REF[v, gnb.R_MODE], last_vision[v]))  # fmt: skip
                set_target(TGT[v], AX[tidx[v]], AP[tidx[v]], t_agent[tidx[v]], latch, rel)
        uwb_now = j % uwb_every == 0
        if uwb_now:
            lost_all, p_all = radio_env(t, drop_w, nlos_w)
            env_lost[:] = lost_all
            env_p[:] = p_all
            uwb_tick(t, X, lever, anchors, drift, uprm, next_anchor, unoise, ui, env_lost, env_p, lost,
                     anchor_id, range_m, outlier, tdma_slot, tdma_prm, idle, collided,
                     collisions)  # fmt: skip
            uwb_errors_tick(t, lost, anchor_id, range_m, outlier, airborne, err_state, err_offset, err_step,
                            err_noise, ui, err_prm)  # fmt: skip
        has_ahrs = ahrs_enabled and j % ahrs_every == 0
        for v in range(n):
            agent_imu(AX[v], AP[v], AC[v], AB[v], PRMS[v], gyro_out[v], dt, f_body[v], mass[v], w_body[v],
                      has_ahrs, ahrs_out[v], ahrs_cov, gate3, plane[v])  # fmt: skip
            t_agent[v] = t
            if uwb_now and not lost[v]:
                dock = docking_on_vision(REF[v, gnb.R_MODE], last_vision[v])
                if uwb_with_vision or not relative_nav(t, last_vision[v], recent_s, dock):
                    agent_uwb(AX[v], AP[v], AC[v], AB[v], PRMS[v], anchors[anchor_id[v]], anchor_id[v],
                              range_m[v], sigma_r, gate1, Hok[v], Hd2[v], Hmeta[v])  # fmt: skip
        for c in range(n_pairs):
            if VF_ok[c]:
                VF_ok[c] = False
                v = pairs[c, 0]
                if TGT[v, TG_HAS] != 0.0:
                    if cam_model[c] == CAM_POSE:
                        status = agent_pose(AX[v], AP[v], AC[v], AB[v], PRMS[v], TGT[v], VF[c], target_cov,
                                            MP[v], MR[v], MQ[v], gate6)  # fmt: skip
                    elif cam_model[c] == CAM_FEATURES:
                        status = agent_features(AX[v], AP[v], AC[v], AB[v], PRMS[v], TGT[v], VF[c], markers_t,
                                                target_cov, sigma_f[v], MP[v], MR[v], gate_f[v])  # fmt: skip
                    else:
                        status = -1
                    if status == ST_ACCEPTED:
                        last_vision[v] = t
        if any_ctl:
            switched = False
            for v in range(n):
                if ctl[v]:
                    SAT[v] = agent_control(
                        role[v], codes[v], t, every[v] * dt, AX[v], AP[v], Hok[v], Hd2[v], Hmeta[v],
                        last_vision[v], recent_s, w_body[v], f_body[v], TGT[v], G[v], GP[v], SW[v], DEC[v],
                        DEC_n[v : v + 1], EV[v], EV_n[v : v + 1], ST[v], SP[v], CS[v], CP[v], REF[v], UC[v],
                        ACT[v], dock_speed,
                    )  # fmt: skip
                    switched = switched or EV_n[v] > 0
            cam[0] = camera_possible(X, pairs, cam_axis, reach, cos_fov)
            if switched:
                return j, EVENT
            for v in range(n):
                if ctl[v] and not attached[v]:
                    hold_step(codes[v], UC[v], S[v], U[v], KP[v])
        if series_every > 0 and j % series_every == 0:
            for c in range(n_pairs):
                v = pairs[c, 0]
                if not done[c]:
                    dock = docking_on_vision(REF[v, gnb.R_MODE], last_vision[v])
                    rel = relative_nav(t_agent[v], last_vision[v], recent_s, dock)
                    record_series(SER[c, SER_n[c]], t, X[v], AX[v], AP[v], TGT[v], REF[v, gnb.R_MODE], rel)
                    SER_n[c] += 1
        c = referee_tick(X, pairs, done, docking, n_target, q_tc, half, keepout_r, corridor_cos, contact_d,
                         ko_flag, ko_t, ko_r, closest, t)  # fmt: skip
        if c != NO_CONTACT:
            return j, CONTACT
        _world(W, ahrs_enabled and (j + 1) % ahrs_every == 0, t)
        if cam[0] and (j + 1) % vision_every == 0:
            if not compiled_cams[0]:
                return j + 1, CAMERA
            for c in range(n_pairs):
                VF_ok[c] = camera_frame(c, j + 1, dt, X, *PC, VF[c])
    return k1, REACHED_END
