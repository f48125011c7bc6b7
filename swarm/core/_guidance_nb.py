"""The guidance step compiled: the chaser's mode logic and reference (:class:`~swarm.core.guidance.
ChaserGuidance`) and the target's station keeping (:class:`~swarm.core.guidance.StationKeeping`) over
explicit arrays.

These kernels *are* the guidance: the Python classes hold their arrays and call them, and the compiled
closed loop (:func:`swarm.step.tick.run_ticks`) calls them directly, so one implementation serves every
runner (docs/architecture.md, "The one tick"). What they cannot do in compiled code, build strings, they
leave as numbers: a mode switch is a row of :data:`EV_N` floats (time, modes, a reason code and the values
its text quotes), formatted by :func:`swarm.core.guidance.reason_text`; an Algorithm 1 pass is a row of
:data:`swarm.core.mdp.D_N` floats (:func:`swarm.core.mdp.mdp_pass`).

Layouts (indices into float64 arrays; booleans as 0.0/1.0, an absent time as NaN):

* ``G`` (:data:`G_N`,) the chaser's guidance state; ``GP`` (:data:`GP_N`,) its parameters
  (:func:`swarm.core.guidance.guidance_row`); ``SW`` the switcher's (:mod:`swarm.core.mdp`).
* ``ST`` (:data:`ST_N`,) the station keeper's state; ``SP`` (:data:`SP_N`,) its parameters.
* ``REF`` (:data:`REF_N`,) one reference: mode, position, velocity, acceleration, attitude, range and,
  for a station keeper, whether translation and attitude control act.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarm.core._rot_nb import qconj, qexp, qlog, qmul, qnormalize, qrotate
from swarm.core.mdp import D_N, SW_R1, SW_R2, mdp_pass

# ---- modes, in the order of swarm.core.guidance.Mode ------------------------------------------------------
M_HOLD, M_APPROACH, M_REORIENT, M_ALIGN, M_DOCK, M_DOCKED, M_ABORT, M_STATION = range(8)

# ---- chaser guidance state G --------------------------------------------------------------------------
G_MODE = 0
G_RESUME = 1
G_STARTED = 2
G_PREF = 3  # 3:6 the reference position (the carrot) [m]
G_SINCE = 6  # time of the last switch [s]
G_STALL = 7  # stalled since [s], NaN: not stalled
G_RETRIES = 8
G_QMIS = 9  # 9:13 the mission attitude
G_N = 13

# ---- chaser guidance parameters GP (swarm.core.guidance.guidance_row) ------------------------------------
(GP_HALF, GP_ALIGN_D, GP_KO_R, GP_KO_MARGIN, GP_CORR_COS, GP_V_APPROACH, GP_V_ALIGN, GP_V_DOCK, GP_V_ABORT,
 GP_MAX_LEAD, GP_STOP_DECEL, GP_ALIGN_TOL, GP_ALIGN_ATT_TOL, GP_ALIGN_V_TOL, GP_DOCK_OVERSHOOT, GP_CONTACT_D,
 GP_HOLD_SIGMA, GP_RESUME_SIGMA, GP_HOLD_REJ, GP_HOLD_NIS, GP_ABORT_AFTER_HOLD, GP_ABORT_RETREAT,
 GP_RETRY_AFTER, GP_ARC_LOOKAHEAD, GP_MAX_RETRIES, GP_STALL_TIMEOUT,
 GP_DOCK_REQ_VISION) = range(27)  # fmt: skip
GP_NORMAL = 27  # 27:30 the docking face's outward normal, target body frame
GP_QTC = 30  # 30:34 q_target_chaser when docked
GP_N = 34

# ---- reference REF ---------------------------------------------------------------------------------------
R_MODE = 0
R_P = 1
R_V = 4
R_A = 7
R_Q = 10
R_RANGE = 14
R_TRANSLATE = 15
R_ROTATE = 16
REF_N = 17

# ---- one mode switch: a row of EV (EV_MAX, EV_N) ----------------------------------------------------
E_T, E_FROM, E_TO, E_REASON, E_R, E_X = range(6)
EV_N = 6
EV_MAX = 8
"""Switches one evaluation can make at most (HOLD -> resume -> next ... is at most five)."""

# reason codes (their words: swarm.core.guidance.reason_text)
(RS_CONVERGED, RS_HEALTHY, RS_HOLD_LONG, RS_SIGMA, RS_REJECTED, RS_NIS, RS_DOCK_UNHEALTHY, RS_R2,
 RS_SKIP_ALIGN, RS_R1, RS_STALL, RS_AT_ALIGN, RS_NO_VISION, RS_GAP, RS_RETRY) = range(15)  # fmt: skip

# ---- station keeping: state ST, parameters SP --------------------------------------------------------------
ST_TRANSLATE = 0
ST_ROTATE = 1
ST_PREF = 2  # 2:5 the station [m]
ST_QREF = 5  # 5:9 its attitude
ST_N = 9
(SP_DEADBAND, SP_SETTLE, SP_SETTLE_SPEED, SP_DEADBAND_RAD, SP_SETTLE_RAD, SP_CONVERGED,
 SP_SIGNIFICANCE) = range(7)  # fmt: skip
SP_N = 7


@njit(cache=True)
def _norm3(x, y, z):
    return math.sqrt(x * x + y * y + z * z)


@njit(cache=True)
def _switch(G, t, new, r, reason, x, EV, EV_n):
    """Record a switch to ``new`` in the next row of ``EV`` and make it (the mode, its time, no stall)."""
    i = EV_n[0]
    if i < EV.shape[0]:
        EV[i, E_T] = t
        EV[i, E_FROM] = G[G_MODE]
        EV[i, E_TO] = new
        EV[i, E_REASON] = reason
        EV[i, E_R] = r
        EV[i, E_X] = x
        EV_n[0] = i + 1
    G[G_MODE] = new
    G[G_SINCE] = t
    G[G_STALL] = np.nan


@njit(cache=True)
def _carrot(G, GP, p, goal, speed, dt, decel, v_out, a_out):
    """Move the reference ``G[G_PREF]`` toward ``goal`` at ``speed``; wait while it leads the vehicle
    (estimate ``p``) by more than ``max_lead_m``. Writes the reference velocity and acceleration.

    With ``decel > 0`` the reference brakes into the goal: its speed is ``min(speed, sqrt(2 decel d))`` at
    distance ``d`` (``v^2 = 2 a d``), and while that bound is the active one the braking ``-decel`` along
    the path is the feed-forward acceleration."""
    for i in range(3):
        v_out[i] = 0.0
        a_out[i] = 0.0
    dx = goal[0] - G[G_PREF]
    dy = goal[1] - G[G_PREF + 1]
    dz = goal[2] - G[G_PREF + 2]
    dist = _norm3(dx, dy, dz)
    lead = _norm3(G[G_PREF] - p[0], G[G_PREF + 1] - p[1], G[G_PREF + 2] - p[2])
    if dist < 1e-9 or lead > GP[GP_MAX_LEAD]:
        return
    braking = decel > 0.0 and 2.0 * decel * dist < speed * speed
    if braking:
        speed = math.sqrt(2.0 * decel * dist)
    step = min(dist, speed * dt)
    ux, uy, uz = dx / dist, dy / dist, dz / dist
    f = step / dt
    v_out[0], v_out[1], v_out[2] = ux * f, uy * f, uz * f
    for i in range(3):
        G[G_PREF + i] = G[G_PREF + i] + v_out[i] * dt
    if braking and step < dist:
        a_out[0], a_out[1], a_out[2] = -decel * ux, -decel * uy, -decel * uz


@njit(cache=True)
def _arc_goal(G, GP, p_t, n_nav, goal):
    """Next goal on the way to ``goal`` that keeps outside the keep-out sphere: ``goal`` itself when the
    segment from the reference clears the sphere, else a point along the great circle through the
    reference toward the face normal, ``arc_lookahead_rad`` ahead."""
    clear = GP[GP_KO_R] + GP[GP_KO_MARGIN]
    a = np.empty(3)
    seg = np.empty(3)
    for i in range(3):
        a[i] = G[G_PREF + i] - p_t[i]
        seg[i] = (goal[i] - p_t[i]) - a[i]
    ss = max(seg[0] * seg[0] + seg[1] * seg[1] + seg[2] * seg[2], 1e-12)
    s = min(max(-(a[0] * seg[0] + a[1] * seg[1] + a[2] * seg[2]) / ss, 0.0), 1.0)
    if _norm3(a[0] + s * seg[0], a[1] + s * seg[1], a[2] + s * seg[2]) >= clear:
        return goal
    na = _norm3(a[0], a[1], a[2])
    radius = max(na, clear)
    u = a / na
    axis = np.empty(3)
    axis[0] = u[1] * n_nav[2] - u[2] * n_nav[1]
    axis[1] = u[2] * n_nav[0] - u[0] * n_nav[2]
    axis[2] = u[0] * n_nav[1] - u[1] * n_nav[0]
    if _norm3(axis[0], axis[1], axis[2]) < 1e-9:  # exactly opposite the face: any perpendicular axis
        j = 0
        for i in range(1, 3):
            if abs(u[i]) < abs(u[j]):
                j = i
        e = np.zeros(3)
        e[j] = 1.0
        axis[0] = u[1] * e[2] - u[2] * e[1]
        axis[1] = u[2] * e[0] - u[0] * e[2]
        axis[2] = u[0] * e[1] - u[1] * e[0]
    na = _norm3(axis[0], axis[1], axis[2])
    c = min(max(u[0] * n_nav[0] + u[1] * n_nav[1] + u[2] * n_nav[2], -1.0), 1.0)
    ang = min(math.acos(c), GP[GP_ARC_LOOKAHEAD])
    for i in range(3):
        axis[i] = axis[i] / na * ang
    w = qrotate(qexp(axis), u)
    out = np.empty(3)
    for i in range(3):
        out[i] = p_t[i] + radius * w[i]
    return out


@njit(cache=True)
def _port_gap(GP, p, p_t, n_nav):
    """Gap [m] between the ports along the face normal ``n_nav``, for the chaser centre at ``p``."""
    two_h = 2.0 * GP[GP_HALF]
    g = 0.0
    for i in range(3):
        g += ((p[i] - p_t[i]) - two_h * n_nav[i]) * n_nav[i]
    return g


@njit(cache=True)
def chaser_step(G, GP, SW, p, v, q, sigma, d, rej, vision, p_t, q_t, t, dt, REF, EV, EV_n, DEC, DEC_n):
    """One evaluation of the chaser's guidance at time ``t`` [s] for a control period ``dt`` [s]
    (:class:`swarm.core.guidance.ChaserGuidance`, whose docstring and the module's describe the modes):
    estimate ``p``, ``v``, ``q``, its largest position sigma, the health window's Mahalanobis distance
    ``d`` and rejected fraction ``rej``, whether vision is recent, the target's estimated pose ``p_t``,
    ``q_t``. Updates ``G`` and the switcher ``SW``, writes the reference into ``REF``, appends its mode
    switches to ``EV`` (``EV_n[0]`` rows used) and an Algorithm 1 pass to ``DEC`` (``DEC_n[0]``)."""
    n_nav = qrotate(q_t, GP[GP_NORMAL : GP_NORMAL + 3])
    two_h = 2.0 * GP[GP_HALF]
    p_docked = np.empty(3)
    for i in range(3):
        p_docked[i] = p_t[i] + two_h * n_nav[i]
    q_dock = qnormalize(qmul(q_t, GP[GP_QTC : GP_QTC + 4]))
    r = _norm3(p[0] - p_t[0], p[1] - p_t[1], p[2] - p_t[2])
    qe = qmul(qconj(q_dock), q)
    qe_norm = _norm3(qe[0], qe[1], qe[2])
    nis = d * d  # mean NIS of the health window
    unhealthy = sigma > GP[GP_HOLD_SIGMA] or rej > GP[GP_HOLD_REJ] or nis > GP[GP_HOLD_NIS]
    healthy = sigma < GP[GP_RESUME_SIGMA] and rej <= GP[GP_HOLD_REJ] and nis <= GP[GP_HOLD_NIS]
    mode = int(G[G_MODE])

    # --- health supervision (HOLD / ABORT) ---
    if mode == M_HOLD:
        if healthy:
            reason = RS_HEALTHY if G[G_STARTED] != 0.0 else RS_CONVERGED
            G[G_STARTED] = 1.0
            for i in range(3):
                G[G_PREF + i] = p[i]
            _switch(G, t, G[G_RESUME], r, reason, sigma, EV, EV_n)
        elif G[G_STARTED] != 0.0 and t - G[G_SINCE] > GP[GP_ABORT_AFTER_HOLD]:
            _switch(G, t, M_ABORT, r, RS_HOLD_LONG, 0.0, EV, EV_n)
    elif (mode == M_APPROACH or mode == M_REORIENT or mode == M_ALIGN) and unhealthy:
        G[G_RESUME] = mode
        if sigma > GP[GP_HOLD_SIGMA]:
            reason, x = RS_SIGMA, sigma
        elif rej > GP[GP_HOLD_REJ]:
            reason, x = RS_REJECTED, rej
        else:
            reason, x = RS_NIS, nis
        for i in range(3):
            G[G_PREF + i] = p[i]
        _switch(G, t, M_HOLD, r, reason, x, EV, EV_n)
    elif mode == M_DOCK and unhealthy:
        _switch(G, t, M_ABORT, r, RS_DOCK_UNHEALTHY, 0.0, EV, EV_n)

    # --- switching radii (Algorithm 1 or fixed) ---
    mode = int(G[G_MODE])
    if mode == M_APPROACH or mode == M_REORIENT:
        i = DEC_n[0]
        if i < DEC.shape[0]:
            if mdp_pass(SW, t, r, d, qe_norm, sigma, DEC[i]):
                DEC_n[0] = i + 1
        else:  # a full staging buffer (its runner drains it before this happens): the pass is still made
            mdp_pass(SW, t, r, d, qe_norm, sigma, np.empty(D_N))
    r1, r2 = SW[SW_R1], SW[SW_R2]
    rel0, rel1, rel2 = p[0] - p_t[0], p[1] - p_t[1], p[2] - p_t[2]
    rc = _norm3(rel0, rel1, rel2)
    corridor = rc > 0 and rel0 * n_nav[0] + rel1 * n_nav[1] + rel2 * n_nav[2] >= rc * GP[GP_CORR_COS]

    if mode == M_APPROACH and r <= r2:
        _switch(G, t, M_REORIENT, r, RS_R2, r2, EV, EV_n)
    if int(G[G_MODE]) == M_REORIENT:
        if corridor and vision and r <= GP[GP_ALIGN_D] + GP[GP_ALIGN_TOL]:
            _switch(G, t, M_DOCK, r, RS_SKIP_ALIGN, sigma, EV, EV_n)
        elif r <= r1:
            _switch(G, t, M_ALIGN, r, RS_R1, r1, EV, EV_n)
        elif not math.isnan(G[G_STALL]) and t - G[G_STALL] > GP[GP_STALL_TIMEOUT]:
            _switch(G, t, M_ALIGN, r, RS_STALL, r1, EV, EV_n)
    if int(G[G_MODE]) == M_ALIGN:
        p_align = np.empty(3)
        for i in range(3):
            p_align[i] = p_t[i] + GP[GP_ALIGN_D] * n_nav[i]
        att_err = 2.0 * math.asin(min(qe_norm, 1.0))
        if (
            _norm3(p[0] - p_align[0], p[1] - p_align[1], p[2] - p_align[2]) <= GP[GP_ALIGN_TOL]
            and att_err <= GP[GP_ALIGN_ATT_TOL]
            and _norm3(v[0], v[1], v[2]) <= GP[GP_ALIGN_V_TOL]
        ):
            if vision or GP[GP_DOCK_REQ_VISION] == 0.0:
                _switch(G, t, M_DOCK, r, RS_AT_ALIGN, 0.0, EV, EV_n)
            elif math.isnan(G[G_STALL]):
                G[G_STALL] = t  # at the point without vision: wait for it
        if (
            int(G[G_MODE]) == M_ALIGN
            and not math.isnan(G[G_STALL])
            and t - G[G_STALL] > GP[GP_ABORT_AFTER_HOLD]
        ):
            _switch(G, t, M_ABORT, r, RS_NO_VISION, 0.0, EV, EV_n)
    if int(G[G_MODE]) == M_DOCK:
        gap = _port_gap(GP, p, p_t, n_nav)
        if gap <= GP[GP_CONTACT_D]:
            _switch(G, t, M_DOCKED, r, RS_GAP, gap, EV, EV_n)
    if int(G[G_MODE]) == M_ABORT and G[G_RETRIES] < GP[GP_MAX_RETRIES] and healthy:
        ref_r = _norm3(G[G_PREF] - p_t[0], G[G_PREF + 1] - p_t[1], G[G_PREF + 2] - p_t[2])
        retreat = ref_r >= GP[GP_KO_R] + GP[GP_ABORT_RETREAT] - 1e-3
        if retreat and t - G[G_SINCE] > GP[GP_RETRY_AFTER]:
            G[G_RETRIES] += 1.0
            for i in range(3):
                G[G_PREF + i] = p[i]
            _switch(G, t, M_APPROACH, r, RS_RETRY, G[G_RETRIES], EV, EV_n)

    # --- reference for the mode ---
    v_ref = np.zeros(3)
    a_ref = np.zeros(3)
    q_ref = q_dock
    clear = GP[GP_KO_R] + GP[GP_KO_MARGIN]
    mode = int(G[G_MODE])
    goal = np.empty(3)
    if mode == M_APPROACH or mode == M_REORIENT:
        dx, dy, dz = G[G_PREF] - p_t[0], G[G_PREF + 1] - p_t[1], G[G_PREF + 2] - p_t[2]
        nd = max(_norm3(dx, dy, dz), 1e-9)
        goal[0] = p_t[0] + dx / nd * clear
        goal[1] = p_t[1] + dy / nd * clear
        goal[2] = p_t[2] + dz / nd * clear
        _carrot(G, GP, p, goal, GP[GP_V_APPROACH], dt, GP[GP_STOP_DECEL], v_ref, a_ref)
        if mode == M_APPROACH:
            q_ref = G[G_QMIS : G_QMIS + 4].copy()
        if mode == M_REORIENT:
            gd = _norm3(G[G_PREF] - goal[0], G[G_PREF + 1] - goal[1], G[G_PREF + 2] - goal[2])
            if gd < 1e-6 and math.isnan(G[G_STALL]):
                G[G_STALL] = t
    elif mode == M_ALIGN:
        for i in range(3):
            goal[i] = p_t[i] + GP[GP_ALIGN_D] * n_nav[i]
        sub = _arc_goal(G, GP, p_t, n_nav, goal)
        _carrot(G, GP, p, sub, GP[GP_V_ALIGN], dt, 0.0, v_ref, a_ref)
    elif mode == M_DOCK:
        for i in range(3):
            goal[i] = p_docked[i] - GP[GP_DOCK_OVERSHOOT] * n_nav[i]
        _carrot(G, GP, p, goal, GP[GP_V_DOCK], dt, 0.0, v_ref, a_ref)
    elif mode == M_ABORT:
        rr = max(r, 1e-9)
        reach = GP[GP_KO_R] + GP[GP_ABORT_RETREAT]
        for i in range(3):
            goal[i] = p_t[i] + (p[i] - p_t[i]) / rr * reach
        _carrot(G, GP, p, goal, GP[GP_V_ABORT], dt, 0.0, v_ref, a_ref)
        q_ref = q.copy()
    elif mode == M_HOLD and (G[G_STARTED] == 0.0 or int(G[G_RESUME]) == M_APPROACH):
        q_ref = G[G_QMIS : G_QMIS + 4].copy()  # holding before the start or during APPROACH: mission attitude
    elif mode == M_DOCKED:
        for i in range(3):
            G[G_PREF + i] = p[i]
    REF[R_MODE] = mode
    for i in range(3):
        REF[R_P + i] = G[G_PREF + i]
        REF[R_V + i] = v_ref[i]
        REF[R_A + i] = a_ref[i]
    for i in range(4):
        REF[R_Q + i] = q_ref[i]
    REF[R_RANGE] = r
    REF[R_TRANSLATE] = 1.0
    REF[R_ROTATE] = 1.0


@njit(cache=True)
def hold_reference(p, q, REF):
    """The reference of a chaser with nothing to fly to yet (no target estimate): HOLD where it is."""
    REF[R_MODE] = M_HOLD
    for i in range(3):
        REF[R_P + i] = p[i]
        REF[R_V + i] = 0.0
        REF[R_A + i] = 0.0
    for i in range(4):
        REF[R_Q + i] = q[i]
    REF[R_RANGE] = 0.0
    REF[R_TRANSLATE] = 1.0
    REF[R_ROTATE] = 1.0


@njit(cache=True)
def station_step(ST, SP, p, v, q, sigma, REF):
    """One evaluation of the target's station keeping (:class:`swarm.core.guidance.StationKeeping`):
    updates whether translation and attitude control act (``ST``) and writes the reference."""
    r = _norm3(p[0] - ST[ST_PREF], p[1] - ST[ST_PREF + 1], p[2] - ST[ST_PREF + 2])
    e = qlog(qmul(qconj(ST[ST_QREF : ST_QREF + 4]), q))
    att = _norm3(e[0], e[1], e[2])
    if sigma > SP[SP_CONVERGED]:
        ST[ST_TRANSLATE] = 0.0
        ST[ST_ROTATE] = 0.0
    else:
        speed = _norm3(v[0], v[1], v[2])
        if ST[ST_TRANSLATE] != 0.0:
            ST[ST_TRANSLATE] = 0.0 if (r < SP[SP_SETTLE] and speed < SP[SP_SETTLE_SPEED]) else 1.0
        else:
            significant = r > SP[SP_SIGNIFICANCE] * sigma
            ST[ST_TRANSLATE] = 1.0 if (r > SP[SP_DEADBAND] and significant) else 0.0
        if ST[ST_ROTATE] != 0.0:
            ST[ST_ROTATE] = 1.0 if att > SP[SP_SETTLE_RAD] else 0.0
        else:
            ST[ST_ROTATE] = 1.0 if att > SP[SP_DEADBAND_RAD] else 0.0
    REF[R_MODE] = M_STATION
    for i in range(3):
        REF[R_P + i] = ST[ST_PREF + i]
        REF[R_V + i] = 0.0
        REF[R_A + i] = 0.0
    for i in range(4):
        REF[R_Q + i] = ST[ST_QREF + i]
    REF[R_RANGE] = r
    REF[R_TRANSLATE] = ST[ST_TRANSLATE]
    REF[R_ROTATE] = ST[ST_ROTATE]


__all__ = ["D_N"]
