"""Where a point of the scene lands on the page: the browser tests' pinhole model of the dashboard's
camera."""

from __future__ import annotations

import numpy as np

VISER_FOV_DEG = 75.0
"""Viser's default vertical field of view [deg] (its up direction +z)."""


def project(eye, look_at, p_nav, width_px: int, height_px: int) -> tuple[int, int]:
    """Pixel (column, row) of ``p_nav`` [m] through a pinhole at ``eye`` looking at ``look_at``, with
    :data:`VISER_FOV_DEG` over a ``width_px`` x ``height_px`` page."""
    eye, look_at = np.asarray(eye, dtype=float), np.asarray(look_at, dtype=float)
    forward = (look_at - eye) / np.linalg.norm(look_at - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    v = np.asarray(p_nav) - eye
    f_px = (height_px / 2) / np.tan(np.radians(VISER_FOV_DEG) / 2)
    return (
        round(width_px / 2 + f_px * (v @ right) / (v @ forward)),
        round(height_px / 2 - f_px * (v @ up) / (v @ forward)),
    )
