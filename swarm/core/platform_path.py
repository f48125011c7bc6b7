"""The moving landing platform's path: a ground robot that carries the pad drives a polyline of waypoints at a
constant speed (the moving-platform landing, ``swarm/scenarios/landing-moving.toml``).

A kinematic path follower, not the ``ground`` kind's dynamics: the robot's pose is a closed-form function of
time, so the tests have an exact oracle and the robot's speed is exactly the scenario's ``speed_m_s``. (The
ground kind's unicycle and its controller would need their own state, command and tick in the landing world;
what the UAV's landing depends on is the pad's motion, which the path gives.)

With waypoints ``w_0 .. w_{n-1}`` (nav x, y [m]), segment ``i`` from ``w_i`` to ``w_{i+1}`` (a closed path
adds ``w_{n-1} -> w_0``), cumulative lengths ``c_0 = 0, c_{i+1} = c_i + |w_{i+1} - w_i|`` and total length
``L = c_n``, the robot at time ``t`` [s] is at arc length ``s = s0 + v t`` (``s mod L`` on a closed path;
clamped to ``[0, L]`` on an open one: the robot stops at its last waypoint)::

    p(t) = w_i + (s - c_i) / (c_{i+1} - c_i) (w_{i+1} - w_i),        c_i <= s < c_{i+1}
    v(t) = v (w_{i+1} - w_i) / |w_{i+1} - w_i|                       (0 once an open path's end is reached)
    yaw(t) = atan2(w_{i+1,y} - w_{i,y}, w_{i+1,x} - w_{i,x})         (the heading of the segment)

``PATH`` (flat float64, :func:`path_row`): ``[n_segments, closed, speed_m_s, total_m, x_0, y_0, ..., x_n,
y_n, c_0, ..., c_n]`` (the segments' end points in order, the closing point repeated on a closed path).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

PATH_NSEG, PATH_CLOSED, PATH_SPEED, PATH_TOTAL = 0, 1, 2, 3
PATH_HEAD = 4

POSE_X, POSE_Y, POSE_VX, POSE_VY, POSE_YAW = range(5)
POSE_N = 5


def path_row(waypoints_m, closed: bool, speed_m_s: float) -> np.ndarray:
    """The compiled path ``PATH`` (module docstring) of ``waypoints_m`` ((n, 2) [m], nav x, y; n >= 2)."""
    w = np.asarray(waypoints_m, dtype=float).reshape(-1, 2)
    if closed:
        w = np.vstack([w, w[:1]])
    seg = np.hypot(np.diff(w[:, 0]), np.diff(w[:, 1]))
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    n = len(seg)
    head = [float(n), 1.0 if closed else 0.0, float(speed_m_s), float(cum[-1])]
    return np.concatenate([head, w.ravel(), cum])


def path_length_m(PATH: np.ndarray) -> float:
    """The path's total length ``L`` [m]."""
    return float(PATH[PATH_TOTAL])


@njit(cache=True)
def path_pose_nb(PATH, s0, t, out):
    """The robot's pose at time ``t`` [s], starting at arc length ``s0`` [m] (module docstring), into ``out``
    (``POSE_N``): position x, y [m], velocity x, y [m/s] (nav) and heading [rad]."""
    n = int(PATH[PATH_NSEG])
    total = PATH[PATH_TOTAL]
    speed = PATH[PATH_SPEED]
    W = PATH[PATH_HEAD : PATH_HEAD + 2 * (n + 1)]
    C = PATH[PATH_HEAD + 2 * (n + 1) : PATH_HEAD + 3 * (n + 1)]
    s = s0 + speed * t
    moving = True
    if PATH[PATH_CLOSED] != 0.0:
        s = s % total
    elif s >= total:
        s, moving = total, False
    elif s < 0.0:
        s = 0.0
    i = 0
    while i < n - 1 and s >= C[i + 1]:
        i += 1
    while i > 0 and C[i + 1] - C[i] <= 0.0:  # (a zero-length segment has no heading: the one before's)
        i -= 1
    dx, dy = W[2 * i + 2] - W[2 * i], W[2 * i + 3] - W[2 * i + 1]
    ln = C[i + 1] - C[i]
    f = (s - C[i]) / ln if ln > 0.0 else 0.0
    out[POSE_X] = W[2 * i] + f * dx
    out[POSE_Y] = W[2 * i + 1] + f * dy
    if moving and ln > 0.0:
        out[POSE_VX] = speed * dx / ln
        out[POSE_VY] = speed * dy / ln
    else:
        out[POSE_VX] = 0.0
        out[POSE_VY] = 0.0
    out[POSE_YAW] = math.atan2(dy, dx)


def path_pose(PATH: np.ndarray, s0_m: float, t_s: float) -> np.ndarray:
    """:func:`path_pose_nb` in Python: ``(x, y, vx, vy, yaw)``."""
    out = np.zeros(POSE_N)
    path_pose_nb(PATH, float(s0_m), float(t_s), out)
    return out
