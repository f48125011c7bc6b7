"""The landing guidance compiled: the modes, references and switching rule of
:class:`swarm.core.landing.LandingGuidance` over explicit arrays (its module docstring says what they do).

These kernels *are* the landing guidance: the Python class holds the arrays and calls :func:`landing_step`,
and the compiled landing loop (:func:`swarm.step.landing_nb.run_landing_ticks`) calls it directly, so one
implementation serves every runner, as :mod:`swarm.core._guidance_nb` does for docking. What compiled code
cannot do, build strings and records, it leaves as numbers: a mode switch is a row of :data:`EV_N` floats
(time, modes, a reason code and the values its text quotes; :func:`swarm.core.landing.reason_text`), a pass
of the switching rule a row of :data:`DEC_N` floats (:class:`swarm.core.landing.LandingDecision`'s fields
in order, None as NaN).

Layouts (indices into float64 arrays; an absent time as NaN):

* ``G`` (:data:`G_N`,) the guidance state; ``GP`` (:data:`GP_N`,) its parameters
  (:func:`swarm.core.landing.guidance_row`).
* A moving pad (``GP_MOVING``): the caller moves ``GP_PAD`` and ``GP_GLIDE_END`` to the pad's estimate
  every tick and sets its velocity ``GP_PAD_V``; the references that chase the pad (the glide, the
  viewpoint above the pad, the descents) add that velocity (a feedforward: a target moving at ``v`` is
  otherwise followed ``v / gain`` behind), and the viewpoint moves with the pad.
* ``REF`` (:data:`REF_N`,) the reference: position and velocity (nav); its acceleration is zero and its
  heading the identity.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarm.core.mdp import a11_kernel, chain_kernel

# ---- modes, in the order of swarm.core.landing.LandingMode ----------------------------------------------
L_CRUISE, L_DEVIATE, L_DESCEND, L_FINAL, L_CLIMB, L_LANDED, L_ABORT = range(7)

# ---- state G ---------------------------------------------------------------------------------------------
G_MODE = 0
G_R1 = 1
G_R2 = 2
G_RETRIES = 3
G_HOLD = 4  # 4:7 where the target was lost (the climb's and the abort's horizontal position)
G_TOUCH = 7  # on the skids since [s] (NaN: not)
G_CLIMB = 8  # the height to climb to [m] (NaN: none)
G_AT_VIEW = 9  # at the viewpoint without the pad since [s] (NaN: not)
G_VIEW = 10  # 10:13 the viewpoint (NaN: none yet)
G_DEV = 13  # 13:16 where the UAV deviated (NaN: not yet)
G_N = 16

# ---- parameters GP (swarm.core.landing.guidance_row) ----------------------------------------------------
(GP_CRUISE_V, GP_GLIDE_H, GP_VIEW_MIN, GP_DESCEND_V, GP_FINAL_H, GP_FINAL_V, GP_ACCEPT, GP_LOST_T,
 GP_MAX_RETRIES, GP_RETRY_CLIMB, GP_ABORT_H, GP_VIEW_MAX, GP_TOUCH_H, GP_TOUCH_V, GP_TOUCH_HOLD, GP_FIXED_D,
 GP_R_T, GP_A11_THR, GP_PI2_THR, GP_SIGMA_REF, GP_MDP, GP_TAN_VIEW, GP_GEAR) = range(23)  # fmt: skip
GP_PAD = 23  # 23:26 the pad (nav)
GP_GLIDE_END = 26  # 26:29 the glide's end, glide_end_height_m above the pad
GP_MOVING = 29  # a moving pad (swarm.landing_scenario.LandingPlatform): GP_PAD follows its estimate
GP_PAD_V = 30  # 30:33 the moving pad's estimated velocity (nav), fed forward (module docstring)
GP_N = 33

# ---- reference REF ---------------------------------------------------------------------------------------
R_P = 0
R_V = 3
REF_N = 6

# ---- a mode switch, a row of EV ----------------------------------------------------------------------------
E_T, E_FROM, E_TO, E_REASON, E_A, E_B, E_C = range(7)
E_P = 7  # 7:10 the estimated position
EV_N = 10

# reasons (swarm.core.landing.reason_text says their words and which of E_A .. E_C they quote)
(RS_DEVIATE, RS_DESCEND, RS_FINAL, RS_CLIMB_NO_VIEW, RS_CLIMB_LOST, RS_ABORT_NO_VIEW, RS_ABORT_LOST,
 RS_CLIMBED, RS_LANDED) = range(9)  # fmt: skip

# ---- a pass of the switching rule, a row of DEC (LandingDecision's fields) -----------------------------
(D_T, D_MODE, D_R, D_D, D_SIGMA, D_RHO, D_A11, D_A22, D_A23, D_A32, D_A33, D_PI1, D_PI2, D_R1, D_R2,
 D_SWITCHED) = range(16)  # fmt: skip
DEC_N = 16


@njit(cache=True)
def _switch(G, t, new, reason, a, b, c, p, EV, EV_n):
    """Record a switch to ``new`` in the next row of ``EV`` (dropped when full: the caller drains it every
    tick) and make it."""
    i = EV_n[0]
    if i < EV.shape[0]:
        EV[i, E_T] = t
        EV[i, E_FROM] = G[G_MODE]
        EV[i, E_TO] = new
        EV[i, E_REASON] = reason
        EV[i, E_A] = a
        EV[i, E_B] = b
        EV[i, E_C] = c
        EV[i, E_P : E_P + 3] = p
        EV_n[0] = i + 1
    G[G_MODE] = new


@njit(cache=True)
def view_height(GP, sigma_h):
    """The viewpoint's height above the pad for a horizontal sigma ``sigma_h`` [m]."""
    h = 3.0 * sigma_h / GP[GP_TAN_VIEW]
    return min(max(h, GP[GP_VIEW_MIN]), GP[GP_VIEW_MAX])


@njit(cache=True)
def _toward(p, gx, gy, gz, speed, gain, REF):
    """A reference that flies from ``p`` straight to the goal at ``speed``, slowing in (``v = gain *
    distance``)."""
    REF[R_P : R_P + 3] = p
    dx, dy, dz = gx - p[0], gy - p[1], gz - p[2]
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    if dist < 1e-9:
        REF[R_V : R_V + 3] = 0.0
        return
    s = min(speed, gain * dist)
    REF[R_V] = dx / dist * s
    REF[R_V + 1] = dy / dist * s
    REF[R_V + 2] = dz / dist * s


@njit(cache=True)
def _follow(GP, REF):
    """A moving pad's velocity added to a pad-relative reference (module docstring; nothing for a pad that
    stands still)."""
    if GP[GP_MOVING] != 0.0:
        REF[R_V] += GP[GP_PAD_V]
        REF[R_V + 1] += GP[GP_PAD_V + 1]


@njit(cache=True)
def _hold_ref(G, REF):
    REF[R_P] = G[G_HOLD]
    REF[R_P + 1] = G[G_HOLD + 1]
    REF[R_P + 2] = G[G_CLIMB]
    REF[R_V : R_V + 3] = 0.0


@njit(cache=True)
def _decide(G, GP, t, p, r, d, sigma_h, DEC, DEC_n):
    """One pass of the switching rule in CRUISE or DEVIATE (:mod:`swarm.core.landing`, "Switching"); True to
    switch to the next mode. A pass is recorded when the fixed policy switches and every time the Markov
    rule runs (within ``r_t``)."""
    mode = G[G_MODE]
    row = np.full(DEC_N, np.nan)
    row[D_T], row[D_MODE], row[D_R], row[D_D], row[D_SIGMA] = t, mode, r, d, sigma_h
    switch = False
    if GP[GP_MDP] == 0.0:
        if mode == L_CRUISE:
            switch = r <= GP[GP_FIXED_D]
        else:
            ex, ey = p[0] - G[G_VIEW], p[1] - G[G_VIEW + 1]
            switch = math.sqrt(ex * ex + ey * ey) <= GP[GP_ACCEPT]
        if not switch:
            return False
    else:
        if r > GP[GP_R_T]:
            return False
        if mode == L_CRUISE:
            footprint = GP[GP_GLIDE_H] * GP[GP_TAN_VIEW]
            rho = footprint / max(3.0 * sigma_h, 1e-9)
            a11 = a11_kernel(r, GP[GP_R_T], d, rho)
            row[D_RHO], row[D_A11] = rho, a11
            if a11 <= GP[GP_A11_THR]:
                G[G_R2] = r
                switch = True
        else:
            # paper Algorithm 1's [REORIENT, ALIGN] chain, the docking's kernel
            a22, a23, a32, a33, pi1, pi2 = chain_kernel(
                r, G[G_R2], d, sigma_h, GP[GP_SIGMA_REF], GP[GP_ACCEPT]
            )
            row[D_A22], row[D_A23], row[D_A32], row[D_A33] = a22, a23, a32, a33
            if not np.isnan(pi2):
                row[D_PI1], row[D_PI2] = pi1, pi2
                if pi2 <= GP[GP_PI2_THR]:
                    G[G_R1] = r
            switch = r <= G[G_R1]
    row[D_R1], row[D_R2], row[D_SWITCHED] = G[G_R1], G[G_R2], 1.0 if switch else 0.0
    i = DEC_n[0]
    if i < DEC.shape[0]:
        DEC[i] = row
        DEC_n[0] = i + 1
    return switch


@njit(cache=True)
def _lost(G, GP, t, p, why_view, EV, EV_n):
    """The target is lost: climb and retry, or abort after ``max_retries``."""
    G[G_RETRIES] += 1.0
    top = GP[GP_PAD + 2] + GP[GP_ABORT_H]
    if G[G_RETRIES] > GP[GP_MAX_RETRIES]:
        G[G_CLIMB] = top
        _switch(G, t, L_ABORT, RS_ABORT_NO_VIEW if why_view else RS_ABORT_LOST, 0.0, 0.0, 0.0, p, EV, EV_n)
    else:
        G[G_CLIMB] = min(p[2] + GP[GP_RETRY_CLIMB], top)
        reason = RS_CLIMB_NO_VIEW if why_view else RS_CLIMB_LOST
        _switch(G, t, L_CLIMB, reason, G[G_RETRIES], 0.0, 0.0, p, EV, EV_n)
    G[G_HOLD : G_HOLD + 3] = p


@njit(cache=True)
def landing_step(G, GP, t, p, v, sigma_h, d, pad_seen_s, REF, EV, EV_n, DEC, DEC_n):
    """The reference at time ``t`` [s] into ``REF`` from the estimate ``p``, ``v`` (nav), its horizontal
    sigma ``sigma_h`` [m], the filter's consistency ``d`` and the time of the last pad measurement
    ``pad_seen_s`` (NaN: never). A switch runs the new mode's step in the same call."""
    px, py = p[0] - GP[GP_PAD], p[1] - GP[GP_PAD + 1]
    r = math.sqrt(px * px + py * py)
    height = p[2] - GP[GP_PAD + 2]
    seen = not math.isnan(pad_seen_s) and t - pad_seen_s <= GP[GP_LOST_T]
    for _ in range(8):  # a switch re-runs the step in the new mode; no chain of switches is longer
        m = G[G_MODE]
        if m == L_CRUISE:
            if _decide(G, GP, t, p, r, d, sigma_h, DEC, DEC_n):
                G[G_DEV : G_DEV + 3] = p
                h = view_height(GP, sigma_h)
                G[G_VIEW] = GP[GP_PAD]
                G[G_VIEW + 1] = GP[GP_PAD + 1]
                G[G_VIEW + 2] = GP[GP_PAD + 2] + h
                _switch(G, t, L_DEVIATE, RS_DEVIATE, r, G[G_VIEW + 2] - GP[GP_PAD + 2], sigma_h, p, EV, EV_n)
                continue
            if r > 0.5:
                g = GP[GP_GLIDE_END : GP_GLIDE_END + 3]
                _toward(p, g[0], g[1], g[2], GP[GP_CRUISE_V], 0.8, REF)
            else:
                pz = GP[GP_PAD + 2] + GP[GP_GEAR]
                _toward(p, GP[GP_PAD], GP[GP_PAD + 1], pz, GP[GP_DESCEND_V], 0.8, REF)
            _follow(GP, REF)
            return
        if m == L_DEVIATE:
            if GP[GP_MOVING] != 0.0:  # the viewpoint stays above the moving pad
                G[G_VIEW] = GP[GP_PAD]
                G[G_VIEW + 1] = GP[GP_PAD + 1]
            if seen and _decide(G, GP, t, p, r, d, sigma_h, DEC, DEC_n):
                _switch(G, t, L_DESCEND, RS_DESCEND, r, 0.0, 0.0, p, EV, EV_n)
                continue
            ex, ey, ez = p[0] - G[G_VIEW], p[1] - G[G_VIEW + 1], p[2] - G[G_VIEW + 2]
            at_view = math.sqrt(ex * ex + ey * ey + ez * ez) <= max(GP[GP_ACCEPT], 0.3)
            if at_view and not seen:
                if math.isnan(G[G_AT_VIEW]):
                    G[G_AT_VIEW] = t
                if t - G[G_AT_VIEW] >= GP[GP_LOST_T]:  # at the viewpoint and still no pad: a lost target
                    G[G_AT_VIEW] = np.nan
                    _lost(G, GP, t, p, True, EV, EV_n)
                    continue
            else:
                G[G_AT_VIEW] = np.nan
            _toward(p, G[G_VIEW], G[G_VIEW + 1], G[G_VIEW + 2], GP[GP_CRUISE_V], 0.8, REF)
            _follow(GP, REF)
            return
        if m == L_DESCEND:
            if height <= GP[GP_FINAL_H]:
                _switch(G, t, L_FINAL, RS_FINAL, 0.0, 0.0, 0.0, p, EV, EV_n)
                continue
            if not seen:
                _lost(G, GP, t, p, False, EV, EV_n)
                continue
            REF[R_P : R_P + 3] = p
            vx, vy = (GP[GP_PAD] - p[0]) * 1.0, (GP[GP_PAD + 1] - p[1]) * 1.0
            n = math.sqrt(vx * vx + vy * vy)
            if n > GP[GP_CRUISE_V]:
                vx *= GP[GP_CRUISE_V] / n
                vy *= GP[GP_CRUISE_V] / n
            REF[R_V], REF[R_V + 1] = vx, vy
            REF[R_V + 2] = -GP[GP_DESCEND_V] if r <= GP[GP_ACCEPT] else 0.0
            _follow(GP, REF)
            return
        if m == L_FINAL:
            if height <= GP[GP_TOUCH_H] and abs(v[2]) <= GP[GP_TOUCH_V]:
                if math.isnan(G[G_TOUCH]):
                    G[G_TOUCH] = t
                if t - G[G_TOUCH] >= GP[GP_TOUCH_HOLD]:
                    _switch(G, t, L_LANDED, RS_LANDED, 0.0, 0.0, 0.0, p, EV, EV_n)
            else:
                G[G_TOUCH] = np.nan
            REF[R_P : R_P + 3] = p
            REF[R_V] = (GP[GP_PAD] - p[0]) * 1.0
            REF[R_V + 1] = (GP[GP_PAD + 1] - p[1]) * 1.0
            REF[R_V + 2] = -GP[GP_FINAL_V]
            _follow(GP, REF)
            return
        if m == L_CLIMB:
            if p[2] >= G[G_CLIMB] - 0.1:
                G[G_VIEW] = GP[GP_PAD]
                G[G_VIEW + 1] = GP[GP_PAD + 1]
                G[G_VIEW + 2] = GP[GP_PAD + 2] + max(view_height(GP, sigma_h), p[2] - GP[GP_PAD + 2])
                _switch(G, t, L_DEVIATE, RS_CLIMBED, 0.0, 0.0, 0.0, p, EV, EV_n)
                continue
            _hold_ref(G, REF)
            return
        if m == L_ABORT:
            _hold_ref(G, REF)
            return
        REF[R_P : R_P + 3] = p  # LANDED
        REF[R_V : R_V + 3] = 0.0
        return
