"""The in-process runner's compiled inner loop: the ticks between two events that need Python.

Between control ticks, time-series samples and camera frames, a tick is the world's truth step, the
UWB exchanges and every agent's IMU/AHRS/UWB processing, plus the truth checks (keep-out sphere,
contact). :func:`run_ticks` runs those ticks calling the *same* compiled step functions the objects call
one tick at a time (:func:`swarm.core.world.world_tick`, :func:`~swarm.core.world.uwb_tick`,
:func:`swarm.core.agent.agent_imu`, :func:`~swarm.core.agent.agent_uwb`,
:func:`swarm.core.guidance.pair_geometry`), in the same order, on the same arrays, so a run is
bit-for-bit the run the per-tick path gives (a test checks it).
"""

from __future__ import annotations

from numba import njit

from swarm.core.agent import agent_imu, agent_uwb
from swarm.core.guidance import pair_geometry
from swarm.core.world import keepout_from_geometry, uwb_tick, world_tick

REACHED_END = 0
CONTACT = 1
SENSORS_DONE = 2


@njit(cache=True)
def run_ticks(
    k0, k1, dt, uwb_every, ahrs_every, ahrs_enabled,
    X, wrench, thrust_sum, attached, impulse, bias, gyro_noise, gi, ahrs_noise, ai, wprm, gyro_out, ahrs_out,
    gstep_t, gstep, lever, anchors, drift, uprm, next_anchor, unoise, ui, lost, anchor_id, range_m, outlier,
    AX, AP, AC, AB, PRM, f_body, w_body, mass, ahrs_cov, gate1, gate3, sigma_r, Hok, Hd2, Hmeta,
    last_vision, dock_flag, recent_s, uwb_with_vision, t_agent,
    pairs, done, docking, n_target, q_tc, half, keepout_r, corridor_cos, contact_d,
    ko_flag, ko_t, ko_r, closest, sensors_only,
):  # fmt: skip
    """Ticks ``k0 .. k1 - 1`` (module docstring). Returns ``(k, code)``: ``(k1, REACHED_END)``, or
    ``(k, CONTACT)`` when a chaser may touch its target at tick ``k``: tick ``k``'s sensors are processed,
    its truth check and world step are left to the caller. With ``sensors_only`` the last tick stops after
    its sensors: ``(k1 - 1, SENSORS_DONE)`` (the caller runs control, checks and the world step)."""
    for j in range(k0, k1):
        t = j * dt
        uwb_now = j % uwb_every == 0
        if uwb_now:
            uwb_tick(
                t, X, lever, anchors, drift, uprm, next_anchor, unoise, ui, lost, anchor_id, range_m, outlier
            )
        has_ahrs = ahrs_enabled and j % ahrs_every == 0
        for v in range(AX.shape[0]):
            agent_imu(
                AX[v], AP[v], AC[v], AB[v], PRM, gyro_out[v], dt, f_body[v], mass, w_body[v], has_ahrs,
                ahrs_out[v], ahrs_cov, gate3,
            )  # fmt: skip
            t_agent[v] = t
            if uwb_now and not lost[v]:
                relative = t - last_vision[v] <= recent_s or dock_flag[v]
                if uwb_with_vision or not relative:
                    agent_uwb(
                        AX[v], AP[v], AC[v], AB[v], PRM, anchors[anchor_id[v]], range_m[v], sigma_r, gate1,
                        Hok[v], Hd2[v], Hmeta[v],
                    )  # fmt: skip
        if sensors_only and j == k1 - 1:
            return j, SENSORS_DONE
        for c in range(pairs.shape[0]):
            if done[c]:
                continue
            xc = X[pairs[c, 0]]
            xt = X[pairs[c, 1]]
            centre, gap, lateral, _att, _closing, axial = pair_geometry(
                xc[0:3], xc[3:6], xc[6:10], xt[0:3], xt[3:6], xt[6:10], n_target, q_tc, half
            )
            if not docking[c] and centre < closest[c]:
                closest[c] = centre
            if centre > keepout_r + 2.0 * half:
                continue
            if keepout_from_geometry(centre, axial, keepout_r, corridor_cos, docking[c]) and not ko_flag[c]:
                ko_flag[c] = True
                ko_t[c] = t
                ko_r[c] = centre
            touching = -2.0 * half <= gap <= contact_d and lateral <= 2.0 * half
            if touching or centre < 2.0 * half:
                return j, CONTACT
        world_tick(
            X, wrench, thrust_sum, attached, impulse, bias, gyro_noise, gi, ahrs_noise, ai,
            ahrs_enabled and (j + 1) % ahrs_every == 0, wprm, gyro_out, ahrs_out, t, gstep_t, gstep,
        )  # fmt: skip
    return k1, REACHED_END
