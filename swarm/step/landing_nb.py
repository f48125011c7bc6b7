"""The landing tick compiled (:mod:`swarm.step.landing`; docs/architecture.md, "The landing tick").

The three steps of a landing tick over explicit arrays: :func:`world_sample` (step 1: the truth and the
sensors of tick ``k``), :func:`agent_fuse` and :func:`agent_decide` (step 2: the filter, then the guidance
and the controller) and :func:`world_hold` (step 3). The per-tick objects
(:class:`~swarm.step.landing.LandingWorld`, :class:`~swarm.step.landing.LandingAgent`), which the landing
world and agent processes call one tick at a time, call these kernels; :func:`run_landing_ticks` calls the
same kernels in the same order for one UAV from tick to tick in compiled code, so an in-process landing is
bit for bit the per-tick one (a test checks it), as :func:`swarm.step.tick.run_ticks` is for docking.

Random draws: a UAV's sensors read standard normal draws in order from a buffer ``Z`` filled from the UAV's
generator (:class:`~swarm.step.landing.NoiseStream`); ``rng.normal(0, s, n)`` is ``s`` times the next ``n``
standard normals of the same generator, so the draws are those of the generator, whatever the buffer's
size. A tick takes at most :func:`draws_per_tick` of them; the caller refills ``Z`` before a tick that could
run out.

Layouts (indices into float64 arrays; a flag as 0.0/1.0, an absent time as NaN):

* ``WP`` (:data:`WP_N`,) the scenario's world parameters, ``WC`` (:data:`WC_N`,) one UAV's (its sensor
  biases, its pad, the anchors' reach), ``WSC`` (:data:`WSC_N`,) its world state besides the truth.
* ``INP`` (:data:`INP_N`,) one tick's samples (:class:`~swarm.step.landing.LandingInputs`); the camera's
  markers (board indices) in ``CIDX`` and their corners in ``CPX``.
* ``AC`` (:data:`AC_N`,) an agent's constants, ``AF`` (:data:`AF_N`,) its state besides the filter's
  ``X``, ``P`` and the guidance's and controller's arrays.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarm.core import _imu_nb as inb
from swarm.core import _landing_nb as lnb
from swarm.core import platform_path as pp
from swarm.core import range_errors as rerr
from swarm.core._pad_nb import corner_frame_nb, pack_frame_nb
from swarm.core._pnp_nb import solve_pose_nb
from swarm.core._rot_nb import qmat, qmat9, qrotate
from swarm.kinds.quadrotor import control as qc
from swarm.kinds.quadrotor import dynamics as qd

# ---- world parameters WP ----------------------------------------------------------------------------------
(WP_DT, WP_G, WP_ACC_NOISE, WP_GYRO_NOISE, WP_UWB_SIGMA, WP_RATE_CAM, WP_RATE_UWB, WP_RATE_GNSS, WP_UWB_ON,
 WP_GNSS_ON, WP_HIDDEN_ALWAYS, WP_HIDDEN_FROM, WP_HIDDEN_FOR, WP_CORNERS, WP_END_AFTER, WP_ABORT_H,
 WP_ABORT_TOL, WP_ABORT_V) = range(18)  # fmt: skip
WP_GNSS_SIGMA = 18  # 18:21
WP_CAM_POS = 21  # 21:24 the camera, body frame [m]
WP_LEVER = 24  # 24:27 the UWB tag, body frame [m]
WP_RF_ON, WP_RF_RATE, WP_RF_SIGMA, WP_RF_MIN, WP_RF_MAX, WP_RF_COS_TILT, WP_GROUND_Z = range(27, 34)
# a moving pad (swarm.landing_scenario.LandingPlatform): on, the robot shares its estimate, every how many
# ticks, its position's and velocity's sigmas, the board's heading on the deck [rad]
WP_PLATFORM, WP_SHARE_ON, WP_SHARE_RATE, WP_SHARE_SIGMA_P, WP_SHARE_SIGMA_V, WP_PAD_YAW = range(34, 40)
WP_N = 40

# ---- one UAV's world constants WC -------------------------------------------------------------------------
WC_BA = 0  # 0:3 accelerometer bias
WC_BG = 3  # 3:6 gyro bias
WC_PAD = 6  # 6:9 its pad (nav)
WC_UWB_RANGE = 9  # the anchors' reach [m]
WC_R_NAV_PAD = 10  # 10:19 the pad's attitude, row-major
WC_CAM_OFF = 19  # 19:21 a run-time camera loss: the pad hidden in [from, until) [s] (NaN: none)
WC_UWB_OFF = 21  # 21:23 a run-time UWB dropout: every reply lost in [from, until) [s] (NaN: none)
WC_ARC0 = 23  # a moving pad: where on its path the robot starts [m]; WC_PAD, WC_R_NAV_PAD follow it
WC_PAD_V = 24  # 24:27 a moving pad's velocity (nav) [m/s]
WC_N = 27

# ---- one UAV's world state WSC ----------------------------------------------------------------------------
WSC_NEXT_ANCHOR, WSC_ENERGY, WSC_FRAMES, WSC_LANDED_T, WSC_DONE, WSC_END_K = range(6)
# a moving pad: the touchdown (the first tick on the ground: time, horizontal distance to the pad's centre,
# horizontal speed relative to the pad, vertical speed) and the UAV's velocity before the tick
WSC_TD_T, WSC_TD_ERR, WSC_TD_REL_V, WSC_TD_VZ = range(6, 10)
WSC_PREV_V = 10  # 10:13
WSC_N = 13

# ---- one tick's samples INP -------------------------------------------------------------------------------
INP_K, INP_T = 0, 1
INP_GYRO = 2  # 2:5
INP_ACC = 5  # 5:8
INP_HAS_UWB, INP_ANCHOR, INP_RANGE, INP_HAS_GNSS = 8, 9, 10, 11
INP_GNSS = 12  # 12:15
INP_CAM = 15  # CAM_NONE, CAM_MARKERS (CIDX, CPX), CAM_RENDER (the caller renders the pose below)
INP_N_MARKERS = 16
INP_T_CAM = 17  # 17:20 the pad in the camera (CAM_RENDER)
INP_R_CAM_PAD = 20  # 20:29 row-major (CAM_RENDER)
INP_HAS_RF = 29  # a rangefinder tick
INP_RF = 30  # its distance [m] (NaN: no reading, out of reach or too tilted)
INP_HAS_PAD = 31  # a moving pad's robot shares its estimate this tick
INP_PAD_P = 32  # 32:35 the shared position of the pad (nav) [m]
INP_PAD_V = 35  # 35:38 its velocity (nav) [m/s]
INP_N = 38
CAM_NONE, CAM_MARKERS, CAM_RENDER, CAM_POSE = 0.0, 1.0, 2.0, 3.0
"""CAM_POSE (agent side): the pad's pose is already solved (``POSE``), by OpenCV on a rendered image."""

# ---- an agent's constants AC ------------------------------------------------------------------------------
AC_DT, AC_GATE3 = 0, 1
AC_PAD = 2  # 2:5
AC_CAM_POS = 5  # 5:8
AC_R_BC = 8  # 8:17 camera to body, row-major
AC_GNSS_COV = 17  # 17:26 row-major
AC_RF_SIGMA, AC_GROUND_Z, AC_GATE1, AC_RF_COS_TILT = 26, 27, 28, 29
AC_PLATFORM = 30  # a moving pad: the pad is the robot's shared estimate (AF_PAD_EST), not AC_PAD
AC_SHARE_VAR = 31  # the shared position's variance [m^2], added to the camera's
AC_N = 32

# ---- an agent's state AF ----------------------------------------------------------------------------------
(AF_T, AF_HELD, AF_DROPPED, AF_IMU_REFUSED, AF_PAD_SEEN, AF_DETECTIONS, AF_LANDED_T, AF_NIS_N, AF_NIS_HEAD,
 AF_SIGMA_H, AF_LAST_D2, AF_LAST_PAD_D2) = range(12)  # fmt: skip
AF_P_EST = 12  # 12:15 the estimate the last decision used
AF_SHARE_T = 15  # a moving pad: the time of the last shared estimate [s]
AF_SHARE_P = 16  # 16:19 its position (nav) [m]
AF_SHARE_V = 19  # 19:22 its velocity (nav) [m/s]
AF_PAD_EST = 22  # 22:25 the pad now: the shared position extrapolated with the shared velocity
AF_N = 25

# ---- a series sample, a row of SER (in process only) ------------------------------------------------------
SER_T, SER_PTRUE, SER_PEST, SER_SIGMA, SER_MODE, SER_SEEN = 0, 1, 4, 7, 8, 9
SER_N = 10

SERIES_EVERY = 10
"""An in-process run samples its series every this many ticks (:func:`series_sample`)."""

SEEN_RECENT_S = 0.2
"""A series sample marks the pad seen when its last measurement is at most this old [s]."""

POSE_N = 12
"""``POSE``: the pad's position in the camera (3) and its covariance (9, row-major)."""

# run_landing_ticks' answers
RUN_DONE = 0
"""The UAV's run is over at tick ``k`` (``WSC_DONE``), or tick ``k = k1 - 1`` is done."""
RUN_NOISE = 1
"""Tick ``k`` may run out of noise draws: refill ``Z`` and call again from ``k``."""
RUN_DRAIN = 2
"""A record buffer (mode switches, passes, series) may overflow at tick ``k``: drain and call again."""


ERR_DRAWS_PER_TICK = 6 + rerr.ERR_DRAWS
"""The most draws a tick takes from a UAV's ``uwb_errors`` stream: the IMU's vibration (6) and one range's
errors (:data:`swarm.core.range_errors.ERR_DRAWS`)."""

VIB_ACC, VIB_GYRO = 0, 1
VIB_N = 2
"""``VIB``: the IMU's vibration in flight, accelerometer [m/s^2] and gyro [rad/s] standard deviations."""


def draws_per_tick(n_markers: int, share: bool = False) -> int:
    """The most standard normals one tick takes: IMU (6), range (1), fix (3), rangefinder (1), each marker's
    corners (8), and a moving pad's shared estimate (6) when the robot shares it."""
    return 11 + 8 * n_markers + (6 if share else 0)


@njit(cache=True)
def _camera_pose(x, WP, WC, t_cam, R_cam_pad):
    """The pad's pose in the downward camera from the truth ``x``: ``X_cam = R_cam_nav (X_nav - p_cam)``.
    The camera's optical axis is body -z (``R_BODY_CAM``, a half turn about body x)."""
    R_nb = qmat(x[6:10])
    p_cam = x[0:3] + R_nb @ WP[WP_CAM_POS : WP_CAM_POS + 3]
    # R_cam_nav = (R_nav_body R_body_cam)^T with R_body_cam = diag(1, -1, -1)
    R_cn = np.empty((3, 3))
    for j in range(3):
        R_cn[0, j] = R_nb[j, 0]
        R_cn[1, j] = -R_nb[j, 1]
        R_cn[2, j] = -R_nb[j, 2]
    d = WC[WC_PAD : WC_PAD + 3] - p_cam
    t_cam[:] = R_cn @ d
    R_cam_pad[:] = R_cn @ WC[WC_R_NAV_PAD : WC_R_NAV_PAD + 9].reshape(3, 3)


@njit(cache=True)
def world_sample(k, x, s, held, kp, WSC, WC, WP, anchors, corners, CAM, Z, zpos, INP, CIDX, CPX):
    """Step 1 of tick ``k`` for one UAV (:meth:`swarm.step.landing.LandingWorld.step`): the truth advances
    by ``dt`` under the held command, then the IMU, the range, the fix and the camera sample, drawing from
    ``Z`` at ``zpos[0]``."""
    dt = WP[WP_DT]
    t = k * dt
    vb0, vb1, vb2 = x[3], x[4], x[5]
    wb0, wb1, wb2 = x[10], x[11], x[12]
    WSC[WSC_ENERGY] += qd.quadrotor_truth_step(x, s, held, kp, dt)
    # what an ideal accelerometer integrates over the tick: the mean non-gravitational acceleration
    # (v(t) - v(t - dt)) / dt + g e_z (so the touchdown's stop too), body frame
    f_nav = np.empty(3)
    f_nav[0] = (x[3] - vb0) / dt
    f_nav[1] = (x[4] - vb1) / dt
    f_nav[2] = (x[5] - vb2) / dt + WP[WP_G]
    q_bn = np.empty(4)
    q_bn[0], q_bn[1], q_bn[2], q_bn[3] = -x[6], -x[7], -x[8], x[9]
    f = qrotate(q_bn, f_nav)
    i = zpos[0]
    sa = WP[WP_ACC_NOISE] / math.sqrt(dt)
    sg = WP[WP_GYRO_NOISE] / math.sqrt(dt)
    INP[INP_K], INP[INP_T] = k, t
    for j in range(3):
        INP[INP_ACC + j] = f[j] + WC[WC_BA + j] + sa * Z[i + j]
    wb = (wb0, wb1, wb2)
    for j in range(3):
        INP[INP_GYRO + j] = 0.5 * (wb[j] + x[10 + j]) + WC[WC_BG + j] + sg * Z[i + 3 + j]
    i += 6
    INP[INP_HAS_UWB] = 0.0
    INP[INP_HAS_GNSS] = 0.0
    INP[INP_CAM] = CAM_NONE
    INP[INP_N_MARKERS] = 0.0
    n_a = anchors.shape[0]
    if WP[WP_UWB_ON] != 0.0 and n_a > 0 and k % int(WP[WP_RATE_UWB]) == 0:
        a = int(WSC[WSC_NEXT_ANCHOR])
        WSC[WSC_NEXT_ANCHOR] = (a + 1) % n_a
        dropout = WC[WC_UWB_OFF] <= t < WC[WC_UWB_OFF + 1]  # False with NaN
        tag = x[0:3] + qrotate(x[6:10], WP[WP_LEVER : WP_LEVER + 3])
        e0, e1, e2 = tag[0] - anchors[a, 0], tag[1] - anchors[a, 1], tag[2] - anchors[a, 2]
        true_r = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if true_r <= WC[WC_UWB_RANGE] and not dropout:
            INP[INP_HAS_UWB], INP[INP_ANCHOR] = 1.0, a
            INP[INP_RANGE] = true_r + WP[WP_UWB_SIGMA] * Z[i]
            i += 1
    if WP[WP_GNSS_ON] != 0.0 and k % int(WP[WP_RATE_GNSS]) == 0:
        INP[INP_HAS_GNSS] = 1.0
        for j in range(3):
            INP[INP_GNSS + j] = x[j] + Z[i + j] * WP[WP_GNSS_SIGMA + j]
        i += 3
    INP[INP_HAS_RF] = 0.0
    INP[INP_RF] = np.nan
    if WP[WP_RF_ON] != 0.0 and k % int(WP[WP_RF_RATE]) == 0:
        # the beam along body -z meets the ground at (z - ground_z) / cos(tilt), cos(tilt) = R_22
        INP[INP_HAS_RF] = 1.0
        cos_tilt = qmat9(x[6], x[7], x[8], x[9])[8]
        if cos_tilt >= WP[WP_RF_COS_TILT]:
            r = (x[2] - WP[WP_GROUND_Z]) / cos_tilt
            if WP[WP_RF_MIN] <= r <= WP[WP_RF_MAX]:
                INP[INP_RF] = r + WP[WP_RF_SIGMA] * Z[i]
                i += 1
    if k % int(WP[WP_RATE_CAM]) == 0:
        hf = WP[WP_HIDDEN_FROM]
        hidden = WP[WP_HIDDEN_ALWAYS] != 0.0 or (not math.isnan(hf) and hf <= t < hf + WP[WP_HIDDEN_FOR])
        hidden = hidden or WC[WC_CAM_OFF] <= t < WC[WC_CAM_OFF + 1]
        t_cam = INP[INP_T_CAM : INP_T_CAM + 3]
        R_cp = np.empty((3, 3))
        _camera_pose(x, WP, WC, t_cam, R_cp)
        WSC[WSC_FRAMES] += 1.0
        INP[INP_CAM] = CAM_MARKERS
        if not (hidden or t_cam[2] <= 0.05):
            if WP[WP_CORNERS] != 0.0:
                n, i = corner_frame_nb(corners, R_cp, t_cam, CAM, Z, i, CIDX, CPX)
                INP[INP_N_MARKERS] = n
            else:
                INP[INP_CAM] = CAM_RENDER
                for r in range(3):
                    for c in range(3):
                        INP[INP_R_CAM_PAD + 3 * r + c] = R_cp[r, c]
    zpos[0] = i


@njit(cache=True)
def world_platform(k, x, WSC, WC, WP, PATH, Z, zpos, INP):
    """Before :func:`world_sample` of tick ``k``, a moving pad (nothing otherwise, ``WP_PLATFORM`` 0): the
    UAV's velocity before the tick is kept (the touchdown's, :func:`world_hold`), the pad moves to the
    robot's pose at ``t = k dt`` on its path (:func:`swarm.core.platform_path.path_pose_nb`: ``WC_PAD``,
    ``WC_PAD_V``, ``WC_R_NAV_PAD`` a turn about nav z by the robot's heading plus the board's), and on a
    share tick the robot's estimate of it goes into ``INP``: the true position and velocity plus white
    noise of the stated sigmas, 6 draws from ``Z`` at ``zpos[0]``."""
    INP[INP_HAS_PAD] = 0.0
    if WP[WP_PLATFORM] == 0.0:
        return
    t = k * WP[WP_DT]
    WSC[WSC_PREV_V : WSC_PREV_V + 3] = x[3:6]
    pose = np.empty(pp.POSE_N)
    pp.path_pose_nb(PATH, WC[WC_ARC0], t, pose)
    WC[WC_PAD], WC[WC_PAD + 1] = pose[pp.POSE_X], pose[pp.POSE_Y]
    WC[WC_PAD_V], WC[WC_PAD_V + 1], WC[WC_PAD_V + 2] = pose[pp.POSE_VX], pose[pp.POSE_VY], 0.0
    heading = pose[pp.POSE_YAW] + WP[WP_PAD_YAW]
    c, sn = math.cos(heading), math.sin(heading)
    R = WC[WC_R_NAV_PAD : WC_R_NAV_PAD + 9]
    R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8] = c, -sn, 0.0, sn, c, 0.0, 0.0, 0.0, 1.0
    if WP[WP_SHARE_ON] != 0.0 and k % int(WP[WP_SHARE_RATE]) == 0:
        i = zpos[0]
        INP[INP_HAS_PAD] = 1.0
        for j in range(3):
            INP[INP_PAD_P + j] = WC[WC_PAD + j] + WP[WP_SHARE_SIGMA_P] * Z[i + j]
            INP[INP_PAD_V + j] = WC[WC_PAD_V + j] + WP[WP_SHARE_SIGMA_V] * Z[i + 3 + j]
        zpos[0] = i + 6


@njit(cache=True)
def world_errors(s, REP, VIB, RS, OFF, STEP, Z2, zpos2, INP):
    """After :func:`world_sample`, what real flights add to its samples (:mod:`swarm.core.range_errors`),
    from the UAV's own draws ``Z2`` at ``zpos2[0]`` (nothing drawn when off): in flight (``s``: the
    quadrotor off the ground), the IMU's vibration ``VIB`` (6 draws a tick whenever it is on, added in
    flight), and each range's errors (``REP``, the link states ``RS`` (anchors, RS_N), the anchors' offsets
    ``OFF`` and the UAV's take-off steps ``STEP``)."""
    i = zpos2[0]
    airborne = s[qd.S_GROUND] == 0.0
    if VIB[VIB_ACC] > 0.0 or VIB[VIB_GYRO] > 0.0:
        if airborne:
            for j in range(3):
                INP[INP_ACC + j] += VIB[VIB_ACC] * Z2[i + j]
                INP[INP_GYRO + j] += VIB[VIB_GYRO] * Z2[i + 3 + j]
        i += 6
    if REP[rerr.RE_ON] != 0.0 and INP[INP_HAS_UWB] != 0.0:
        a = int(INP[INP_ANCHOR])
        extra, _ = rerr.range_error_step(INP[INP_T], airborne, RS[a], Z2[i : i + rerr.ERR_DRAWS], REP, OFF[a],
                                         STEP[a])  # fmt: skip
        INP[INP_RANGE] += extra
        i += rerr.ERR_DRAWS
    zpos2[0] = i


@njit(cache=True)
def world_hold(u, mode, k, x, s, held, kp, WSC, WC, WP):
    """Step 3 for one UAV (:meth:`swarm.step.landing.LandingWorld.hold`): the rotors take the command ``u``
    of guidance mode ``mode``; the run ends (``WSC_DONE``) ``end_after_landed_s`` after the touchdown, or
    hovering (within ``abort_hold_tolerance_m``, under ``abort_hold_speed_m_s``) at the abort height after an
    abort."""
    qd.quadrotor_hold(u, s, held, kp)
    t = k * WP[WP_DT]
    if WP[WP_PLATFORM] != 0.0 and s[qd.S_GROUND] != 0.0 and math.isnan(WSC[WSC_TD_T]):
        # a moving pad's touchdown: where, and how fast relative to the deck, the skids met it
        ex, ey = x[0] - WC[WC_PAD], x[1] - WC[WC_PAD + 1]
        rx, ry = WSC[WSC_PREV_V] - WC[WC_PAD_V], WSC[WSC_PREV_V + 1] - WC[WC_PAD_V + 1]
        WSC[WSC_TD_T], WSC[WSC_TD_ERR] = t, math.sqrt(ex * ex + ey * ey)
        WSC[WSC_TD_REL_V], WSC[WSC_TD_VZ] = math.sqrt(rx * rx + ry * ry), -WSC[WSC_PREV_V + 2]
    if mode == lnb.L_LANDED and math.isnan(WSC[WSC_LANDED_T]):
        WSC[WSC_LANDED_T] = t
    done = not math.isnan(WSC[WSC_LANDED_T]) and t - WSC[WSC_LANDED_T] >= WP[WP_END_AFTER]
    if not done and mode == lnb.L_ABORT:
        climb_to = WC[WC_PAD + 2] + WP[WP_ABORT_H]
        speed = math.sqrt(x[3] * x[3] + x[4] * x[4] + x[5] * x[5])
        done = abs(x[2] - climb_to) < WP[WP_ABORT_TOL] and speed < WP[WP_ABORT_V]
    if done:
        WSC[WSC_DONE], WSC[WSC_END_K] = 1.0, k
    return done


@njit(cache=True)
def _predict_to(X, P, AF, HELD, t, prm):
    """The filter's clock to ``t``: predict with the held IMU sample (``ImuFilter._predict_to``)."""
    if AF[AF_HELD] != 0.0 and t > AF[AF_T]:
        if not inb.predict_one(X, P, HELD[0], HELD[1], t - AF[AF_T], prm):
            AF[AF_IMU_REFUSED] += 1.0
    AF[AF_T] = max(AF[AF_T], t)


@njit(cache=True)
def _nis_push(AF, NIS, x):
    """The last ``len(NIS)`` normalised innovations, a ring."""
    w = NIS.shape[0]
    NIS[int(AF[AF_NIS_HEAD])] = x
    AF[AF_NIS_HEAD] = (AF[AF_NIS_HEAD] + 1.0) % w
    AF[AF_NIS_N] = min(AF[AF_NIS_N] + 1.0, w)


@njit(cache=True)
def agent_fuse(INP, CIDX, CPX, POSE, X, P, AF, HELD, NIS, counts, anchors, ridx, sigma, prm, work, res,
               AC, corners, CAM, OBJ, IMG, VAR, T_OUT, R_OUT, COV_OUT):  # fmt: skip
    """The filter's half of step 2 (:meth:`swarm.step.landing.LandingAgent.fuse`): the IMU sample (stamped
    ``t - dt``), the range, the fix, the rangefinder's distance and the pad's position in the camera, solved
    from the markers' corners (:func:`swarm.core._pnp_nb.solve_pose_nb`) or given in ``POSE`` (``CAM_POSE``).
    A sample older than the filter's time is dropped and counted, as :class:`swarm.core.imu_filter.ImuFilter`
    does."""
    t = INP[INP_T]
    if AC[AC_PLATFORM] != 0.0:  # a moving pad: the robot's latest shared estimate, extrapolated to t
        if INP[INP_HAS_PAD] != 0.0:
            AF[AF_SHARE_T] = t
            AF[AF_SHARE_P : AF_SHARE_P + 3] = INP[INP_PAD_P : INP_PAD_P + 3]
            AF[AF_SHARE_V : AF_SHARE_V + 3] = INP[INP_PAD_V : INP_PAD_V + 3]
        for j in range(3):
            AF[AF_PAD_EST + j] = AF[AF_SHARE_P + j] + AF[AF_SHARE_V + j] * (t - AF[AF_SHARE_T])
    # the IMU sample's stamp, (k - 1) dt: the same product as the previous tick's t = k dt, so a measurement
    # fused at that t never makes the filter drop this sample (k dt - dt can round below (k - 1) dt)
    ts = (INP[INP_K] - 1.0) * AC[AC_DT]
    if ts >= AF[AF_T]:
        _predict_to(X, P, AF, HELD, ts, prm)
        AF[AF_HELD] = 1.0
        HELD[0, :] = INP[INP_GYRO : INP_GYRO + 3]
        HELD[1, :] = INP[INP_ACC : INP_ACC + 3]
    else:
        AF[AF_DROPPED] += 1.0
    if INP[INP_HAS_UWB] != 0.0:
        if t >= AF[AF_T]:
            _predict_to(X, P, AF, HELD, t, prm)
            a = int(INP[INP_ANCHOR])
            i0, i1, i2 = ridx[a, 0], ridx[a, 1], ridx[a, 2]  # the range-error model's terms (-1: off)
            out = inb.update_range3(X, P, anchors[a], i0, i1, i2, INP[INP_RANGE], sigma[a], prm, work, res)
            counts[a, out] += 1
            AF[AF_LAST_D2] = res[1]
            if out != inb.REFUSED:
                _nis_push(AF, NIS, res[1])
        else:
            AF[AF_DROPPED] += 1.0
    if INP[INP_HAS_GNSS] != 0.0:
        if t >= AF[AF_T]:
            _predict_to(X, P, AF, HELD, t, prm)
            R = AC[AC_GNSS_COV : AC_GNSS_COV + 9].reshape(3, 3)
            inb.update_position_one(X, P, INP[INP_GNSS : INP_GNSS + 3], R, AC[AC_GATE3], res)
        else:
            AF[AF_DROPPED] += 1.0
    if INP[INP_HAS_RF] != 0.0 and not math.isnan(INP[INP_RF]):
        if t >= AF[AF_T]:
            _predict_to(X, P, AF, HELD, t, prm)
            ground, sigma_rf, cos_tilt = AC[AC_GROUND_Z], AC[AC_RF_SIGMA], AC[AC_RF_COS_TILT]
            out = inb.update_height_one(X, P, ground, INP[INP_RF], sigma_rf, cos_tilt, AC[AC_GATE1], res)
            if out != inb.REFUSED:
                _nis_push(AF, NIS, res[1])
        else:
            AF[AF_DROPPED] += 1.0
    cam = INP[INP_CAM]
    have = False
    if cam == CAM_MARKERS and INP[INP_N_MARKERS] > 0:
        n = pack_frame_nb(corners, CIDX, CPX, int(INP[INP_N_MARKERS]), CAM, OBJ, IMG, VAR)
        have = solve_pose_nb(OBJ, IMG, VAR, n, CAM, T_OUT, R_OUT, COV_OUT)
    elif cam == CAM_POSE:
        have = True
        T_OUT[:] = POSE[0:3]
        COV_OUT[0:3, 0:3] = POSE[3:12].reshape(3, 3)
    if have:
        if t >= AF[AF_T]:
            _predict_to(X, P, AF, HELD, t, prm)
            R_bc = AC[AC_R_BC : AC_R_BC + 9].reshape(3, 3)
            cov = np.ascontiguousarray(COV_OUT[0:3, 0:3])
            pad, cam_pos = AC[AC_PAD : AC_PAD + 3], AC[AC_CAM_POS : AC_CAM_POS + 3]
            if AC[AC_PLATFORM] != 0.0:  # relative to the moving pad, known as well as the robot says
                pad = AF[AF_PAD_EST : AF_PAD_EST + 3]
                for j in range(3):
                    cov[j, j] += AC[AC_SHARE_VAR]
            out = inb.update_pad_one(X, P, pad, cam_pos, R_bc, T_OUT, cov, AC[AC_GATE3], res)
            AF[AF_LAST_PAD_D2] = res[1]
            if out == inb.ACCEPTED:
                AF[AF_PAD_SEEN] = t
                AF[AF_DETECTIONS] += 1.0
                _nis_push(AF, NIS, res[1] / 3.0)
        else:
            AF[AF_DROPPED] += 1.0


@njit(cache=True)
def agent_tdoa(INP, rows, X, P, AF, HELD, NIS, prm, RP, anchors, ridx, TV, RS, TC, TD2, SKIP, work, res):
    """A TDoA radio's differences of tick ``k`` (``uwb.mode`` tdoa2/tdoa3; after :func:`agent_fuse`, at the
    same ``t``): ``rows`` (K, 3) anchor ``A``, anchor ``B``, ``d_B - d_A`` [m], each fused in the order heard
    as log replay fuses ``tdoa.csv`` (:func:`swarm.core._imu_nb.fuse_tdoa`: the measurement model and
    Jacobian of Ledergerber, Hamer & D'Andrea 2015 as :func:`swarm.core._imu_nb.tdoa_row` has it, per-anchor
    offsets entering as differences, the NLOS CUSUM per anchor, the gate, Huber, the pair's noise
    ``TV``). Its outcome is counted per pair in ``TC`` (M, M, 3), an accepted one's squared Mahalanobis
    distance (NIS) summed per pair in ``TD2`` (M, M), and its squared distance goes to the consistency ring
    and ``AF_LAST_D2`` as a range's does. A row naming an anchor the scenario does not
    have (or the same anchor twice, or a difference that is not finite) is skipped and counted in
    ``SKIP[0]``, never fused. Rows older than the filter's time are dropped (``AF_DROPPED``, once)."""
    if rows.shape[0] == 0:
        return
    t = INP[INP_T]
    if t < AF[AF_T]:
        AF[AF_DROPPED] += 1.0
        return
    _predict_to(X, P, AF, HELD, t, prm)
    m = anchors.shape[0]
    for k in range(rows.shape[0]):
        fa, fb, z = rows[k, 0], rows[k, 1], rows[k, 2]
        if not (0.0 <= fa < m and 0.0 <= fb < m and fa == math.floor(fa) and fb == math.floor(fb)
                and fa != fb and np.isfinite(z)):  # fmt: skip
            SKIP[0] += 1
            continue
        a, b = int(fa), int(fb)
        out = inb.fuse_tdoa(X, P, prm, RP, anchors, ridx, a, b, z, t, TV, RS, work, res)
        TC[a, b, out] += 1
        if out == inb.ACCEPTED:
            TD2[a, b] += res[1]
        AF[AF_LAST_D2] = res[1]
        if out != inb.REFUSED:
            _nis_push(AF, NIS, res[1])


@njit(cache=True)
def agent_decide(INP, X, P, AF, NIS, G, GP, REF, EV, EV_n, DEC, DEC_n, cs, cp, u, act):
    """The guidance and control half of step 2 (:meth:`swarm.step.landing.LandingAgent.decide`), on the
    filter's estimate: the horizontal sigma (the larger eigenvalue of the 2 x 2 position block), the
    consistency ``d`` (RMS of the recent normalised innovations), the guidance
    (:func:`swarm.core._landing_nb.landing_step`) and the controller, or the idle rotors once landed.
    Returns the guidance mode."""
    t = INP[INP_T]
    p = X[inb.XP : inb.XP + 3].copy()
    v = X[inb.XV : inb.XV + 3].copy()
    a, b, c = P[0, 0], P[0, 1], P[1, 1]
    h = 0.5 * (a - c)
    sigma_h = math.sqrt(max(0.5 * (a + c) + math.sqrt(h * h + b * b), 0.0))
    n = int(AF[AF_NIS_N])
    d = 0.0
    if n > 0:
        acc = 0.0
        for i in range(n):
            acc += NIS[i]
        d = math.sqrt(acc / n)
    if GP[lnb.GP_MOVING] != 0.0:  # the guidance's pad is the moving pad's estimate (agent_fuse)
        for j in range(3):
            GP[lnb.GP_PAD + j] = AF[AF_PAD_EST + j]
            GP[lnb.GP_GLIDE_END + j] = AF[AF_PAD_EST + j]
            GP[lnb.GP_PAD_V + j] = AF[AF_SHARE_V + j]
        GP[lnb.GP_GLIDE_END + 2] += GP[lnb.GP_GLIDE_H]
    lnb.landing_step(G, GP, t, p, v, sigma_h, d, AF[AF_PAD_SEEN], REF, EV, EV_n, DEC, DEC_n)
    mode = G[lnb.G_MODE]
    if mode == lnb.L_LANDED:
        qc.quadrotor_idle(cp, u, act)
        if math.isnan(AF[AF_LANDED_T]):
            AF[AF_LANDED_T] = t
    else:
        w = INP[INP_GYRO : INP_GYRO + 3] - X[inb.XBG : inb.XBG + 3]
        a_ref = np.zeros(3)
        q_ref = np.array([0.0, 0.0, 0.0, 1.0])
        qc.quadrotor_control(cs, cp, p, v, X[inb.XQ : inb.XQ + 4], w, REF[lnb.R_P : lnb.R_P + 3],
                             REF[lnb.R_V : lnb.R_V + 3], a_ref, q_ref, u, act)  # fmt: skip
    AF[AF_SIGMA_H] = sigma_h
    AF[AF_P_EST : AF_P_EST + 3] = p
    return mode


@njit(cache=True)
def series_sample(SER, SER_n, t, p_true, AF, mode):
    """A row of the series (``SER_*``) at time ``t``: the true position ``p_true[0:3]``, the estimate and
    horizontal sigma of the last decision, its mode, whether the pad was measured within
    :data:`SEEN_RECENT_S`; the compiled loop and :meth:`swarm.step.landing.LandingAgent.decide` both take
    it."""
    i = SER_n[0]
    SER[i, SER_T] = t
    SER[i, SER_PTRUE : SER_PTRUE + 3] = p_true[0:3]
    SER[i, SER_PEST : SER_PEST + 3] = AF[AF_P_EST : AF_P_EST + 3]
    SER[i, SER_SIGMA] = AF[AF_SIGMA_H]
    SER[i, SER_MODE] = mode
    seen = AF[AF_PAD_SEEN]
    SER[i, SER_SEEN] = 1.0 if (not math.isnan(seen) and t - seen <= SEEN_RECENT_S) else 0.0
    SER_n[0] = i + 1


@njit(cache=True)
def run_landing_ticks(k, k1, world, agent, guid, ctl, Z, zpos, need, SER, SER_n, series_every):
    """Ticks ``k .. k1 - 1`` of one UAV (module docstring), each :func:`world_platform`,
    :func:`world_sample` (and :func:`world_errors` when the scenario has them), :func:`agent_fuse`,
    :func:`agent_decide`, :func:`world_hold` and, every ``series_every`` ticks (0: never), a series sample.
    Returns ``(RUN_*, k)``: done (or ``k1`` reached), or the tick at which ``Z`` needs ``need`` more draws or
    a record buffer may overflow (nothing of that tick done)."""
    x, s, held, kp, WSC, WC, WP, anchors, corners, CAM, INP, CIDX, CPX = world[:13]
    REP, VIB, RS, OFF, STEP, Z2, zpos2, PATH = world[13:]
    errors = REP[rerr.RE_ON] != 0.0 or VIB[VIB_ACC] > 0.0 or VIB[VIB_GYRO] > 0.0
    POSE, X, P, AF, HELD, NIS, counts, anchs, ridx, sigma, prm, work, res, AC = agent[:14]
    OBJ, IMG, VAR, T_OUT, R_OUT, COV_OUT = agent[14:]
    G, GP, REF, EV, EV_n, DEC, DEC_n = guid
    cs, cp, u, act = ctl
    while k < k1:
        if Z.shape[0] - zpos[0] < need or (errors and Z2.shape[0] - zpos2[0] < ERR_DRAWS_PER_TICK):
            return RUN_NOISE, k
        if EV_n[0] + 4 > EV.shape[0] or DEC_n[0] + 4 > DEC.shape[0] or SER_n[0] + 1 > SER.shape[0]:
            return RUN_DRAIN, k
        world_platform(k, x, WSC, WC, WP, PATH, Z, zpos, INP)
        world_sample(k, x, s, held, kp, WSC, WC, WP, anchors, corners, CAM, Z, zpos, INP, CIDX, CPX)
        if errors:
            world_errors(s, REP, VIB, RS, OFF, STEP, Z2, zpos2, INP)
        agent_fuse(INP, CIDX, CPX, POSE, X, P, AF, HELD, NIS, counts, anchs, ridx, sigma, prm, work, res,
                   AC, corners, CAM, OBJ, IMG, VAR, T_OUT, R_OUT, COV_OUT)  # fmt: skip
        mode = agent_decide(INP, X, P, AF, NIS, G, GP, REF, EV, EV_n, DEC, DEC_n, cs, cp, u, act)
        if series_every > 0 and k % series_every == 0:
            series_sample(SER, SER_n, INP[INP_T], x, AF, mode)
        if world_hold(u, mode, k, x, s, held, kp, WSC, WC, WP):
            return RUN_DONE, k
        k += 1
    return RUN_DONE, k1 - 1
