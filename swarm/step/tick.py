"""The one tick, compiled: the ticks between two events that need Python (docs/architecture.md).

Between control ticks, time-series samples and camera frames, a tick is the radio step, every agent's
sensor step, the referee and the world step. :func:`run_ticks` runs those ticks by calling the *same*
compiled step functions that the objects call one tick at a time, in the same order, on the same arrays:
:func:`swarm.step.radio.radio_env` and :func:`~swarm.step.radio.uwb_tick`,
:func:`swarm.step.agent.agent_imu` and :func:`~swarm.step.agent.agent_uwb` (with
:func:`~swarm.step.agent.relative_nav`), :func:`swarm.step.referee.referee_tick` and
:func:`swarm.step.world.world_tick`. A run is bit for bit the run of the per-tick path (a test checks it).

Each step's arrays travel as one tuple, built by the object that owns them (:func:`world_arrays`,
:func:`radio_arrays`, :func:`agent_arrays`, :func:`referee_arrays`), in the order of the kernels'
arguments.
"""

from __future__ import annotations

from numba import njit

from swarm.step.agent import agent_imu, agent_uwb, relative_nav
from swarm.step.radio import radio_env, uwb_tick
from swarm.step.referee import NO_CONTACT, referee_tick
from swarm.step.world import world_tick

REACHED_END = 0
CONTACT = 1
SENSORS_DONE = 2


def world_arrays(w) -> tuple:
    """The arrays of :func:`swarm.step.world.world_tick` (without ``do_ahrs`` and ``t_s``), then the radio
    fault windows, of a :class:`swarm.step.world.World`."""
    return (w.X, w.S, w.U, w.KP, w.codes, w.effort, w.attached_arr, w.bias, w.gyro_noise, w.gi, w.ahrs_noise,
            w.ai, w.prm, w.gyro_out, w.ahrs_out, w.gyro_step_t, w.gyro_step, w.drop_w, w.nlos_w)  # fmt: skip


def radio_arrays(net) -> tuple:
    """The arrays of :func:`swarm.step.radio.uwb_tick` (without ``t_s`` and ``X``) of a
    :class:`swarm.step.radio.UwbNetwork`."""
    return (net.lever, net.anchors, net.drift, net.prm, net.next_anchor, net.noise, net.ui, net.env_lost,
            net.env_p, net.lost, net.anchor_id, net.range_m, net.outlier)  # fmt: skip


def agent_arrays(a) -> tuple:
    """Every agent's filter and health arrays, stacked (n, ...), of the in-process runner ``a``."""
    return (a.AX, a.AP, a.AC, a.AB, a.PRMS, a.Fb, a.Wb, a.mass, a.plane, a.Hok, a.Hd2, a.Hmeta, a.last_vision,
            a.dock_flag, a.t_agent)  # fmt: skip


def referee_arrays(r) -> tuple:
    """The arrays of :func:`swarm.step.referee.referee_tick` (without ``X`` and ``t_s``) of a
    :class:`swarm.step.referee.Referee`."""
    g = r.g
    return (r.pairs, r.done, r.docking, g.face_normal_target, r.q_tc, g.half_size_m, g.keepout_radius_m,
            g.corridor_cos, g.contact_distance_m, r.ko_flag, r.ko_t, r.ko_r, r.closest)  # fmt: skip


@njit(cache=True)
def _world(W, do_ahrs, t):
    (X, S, U, KP, codes, effort, attached, bias, gyro_noise, gi, ahrs_noise, ai, wprm, gyro_out, ahrs_out,
     gstep_t, gstep, _drop_w, _nlos_w) = W  # fmt: skip
    world_tick(X, S, U, KP, codes, effort, attached, bias, gyro_noise, gi, ahrs_noise, ai, do_ahrs, wprm,
               gyro_out, ahrs_out, t, gstep_t, gstep)  # fmt: skip


@njit(cache=True)
def run_ticks(k0, k1, cfg, W, R, A, F, sensors_only):
    """Ticks ``k0 .. k1 - 1`` (module docstring). ``cfg`` = ``(dt, uwb_every, ahrs_every, ahrs_enabled,
    ahrs_cov, gate1, gate3, sigma_range, vision_recent_s, uwb_with_vision)``; ``W``, ``R``, ``A``, ``F`` the
    world's, radio's, agents' and referee's arrays. Returns ``(k, code)``: ``(k1, REACHED_END)``, or
    ``(k, CONTACT)`` when a chaser may touch its target at tick ``k``: tick ``k``'s sensors are processed,
    its truth check and world step are left to the caller. With ``sensors_only`` the last tick stops after
    its sensors: ``(k1 - 1, SENSORS_DONE)`` (the caller runs control, checks and the world step)."""
    dt, uwb_every, ahrs_every, ahrs_enabled, ahrs_cov, gate1, gate3, sigma_r, recent_s, uwb_with_vision = cfg
    X = W[0]
    drop_w, nlos_w = W[17], W[18]
    (
        lever,
        anchors,
        drift,
        uprm,
        next_anchor,
        unoise,
        ui,
        env_lost,
        env_p,
        lost,
        anchor_id,
        range_m,
        outlier,
    ) = R
    AX, AP, AC, AB, PRMS, f_body, w_body, mass, plane, Hok, Hd2, Hmeta, last_vision, dock_flag, t_agent = A
    (
        pairs,
        done,
        docking,
        n_target,
        q_tc,
        half,
        keepout_r,
        corridor_cos,
        contact_d,
        ko_flag,
        ko_t,
        ko_r,
        closest,
    ) = F
    gyro_out, ahrs_out = W[13], W[14]
    for j in range(k0, k1):
        t = j * dt
        uwb_now = j % uwb_every == 0
        if uwb_now:
            lost_all, p_all = radio_env(t, drop_w, nlos_w)
            env_lost[:] = lost_all
            env_p[:] = p_all
            uwb_tick(t, X, lever, anchors, drift, uprm, next_anchor, unoise, ui, env_lost, env_p, lost,
                     anchor_id, range_m, outlier)  # fmt: skip
        has_ahrs = ahrs_enabled and j % ahrs_every == 0
        for v in range(AX.shape[0]):
            agent_imu(AX[v], AP[v], AC[v], AB[v], PRMS[v], gyro_out[v], dt, f_body[v], mass[v], w_body[v],
                      has_ahrs, ahrs_out[v], ahrs_cov, gate3, plane[v])  # fmt: skip
            t_agent[v] = t
            if uwb_now and not lost[v]:
                if uwb_with_vision or not relative_nav(t, last_vision[v], recent_s, dock_flag[v]):
                    agent_uwb(AX[v], AP[v], AC[v], AB[v], PRMS[v], anchors[anchor_id[v]], range_m[v], sigma_r,
                              gate1, Hok[v], Hd2[v], Hmeta[v])  # fmt: skip
        if sensors_only and j == k1 - 1:
            return j, SENSORS_DONE
        c = referee_tick(X, pairs, done, docking, n_target, q_tc, half, keepout_r, corridor_cos, contact_d,
                         ko_flag, ko_t, ko_r, closest, t)  # fmt: skip
        if c != NO_CONTACT:
            return j, CONTACT
        _world(W, ahrs_enabled and (j + 1) % ahrs_every == 0, t)
    return k1, REACHED_END
