"""Scene-node updates the docking and the landing scenes share (:class:`dashboard.app.SceneView`,
:class:`dashboard.landing.LandingSceneView`): each pushes to the browser only what changed. A vehicle's nodes
object has ``truth``, ``body``, ``estimate``, ``cov``, ``trail_truth``, ``trail_estimate`` and what was last
pushed: ``truth_msg``, ``color``, ``estimate_msg``, ``cov_key``, ``trail_versions``."""

from __future__ import annotations

import numpy as np

from dashboard import mapping
from dashboard.state import AgentSnap


def set_if_changed(handle: object, attr: str, value: object) -> None:
    """Assign only when the value changed (each assignment is a message to every browser)."""
    if getattr(handle, attr) != value:
        setattr(handle, attr, value)


def update_truth(nodes, a: AgentSnap) -> bool:
    """The true pose's frame; True if the truth changed since the last push."""
    if a.truth is nodes.truth_msg:
        return False
    nodes.truth_msg = a.truth
    if a.truth is not None:
        nodes.truth.position, nodes.truth.wxyz = mapping.pose_wxyz(a.truth.p_nav, a.truth.q_nav_body)
    set_if_changed(nodes.truth, "visible", a.truth is not None)
    return True


def update_color(nodes, a: AgentSnap, role: str | None) -> None:
    """The body in the colour of its guidance mode."""
    color = mapping.mode_color(a.guidance.mode if a.guidance is not None else None, role)
    if color != nodes.color:
        nodes.color = color
        nodes.body.color = color


def update_estimate(nodes, a: AgentSnap, n_sigma: float, shapes_due: bool) -> None:
    """The estimate's frame and its covariance ellipsoid. The covariance changes slowly: the ellipsoid's shape
    (an eigen-decomposition and two messages per vehicle) follows when ``shapes_due`` (the trail rate), and
    at once for a first estimate or a new sigma."""
    est = a.estimate
    if est is not nodes.estimate_msg:
        nodes.estimate_msg = est
        set_if_changed(nodes.estimate, "visible", est is not None)
        set_if_changed(nodes.cov, "visible", est is not None)
        if est is not None:
            nodes.estimate.position, nodes.estimate.wxyz = mapping.pose_wxyz(est.p_nav, est.q_nav_body)
            nodes.cov.position = est.p_nav
        else:
            nodes.cov_key = None
    if est is not None and (shapes_due or nodes.cov_key != n_sigma):
        nodes.cov_key = n_sigma
        radii, wxyz = mapping.covariance_ellipsoid(est.cov[:3, :3], n_sigma)
        nodes.cov.wxyz = wxyz
        nodes.cov.scale = tuple(float(r) for r in radii)


def update_trails(nodes, a: AgentSnap, show: bool) -> None:
    """The true and estimated trails (at the trail rate)."""
    nodes.trail_versions = a.trail_versions
    for handle, pts in ((nodes.trail_truth, a.truth_trail), (nodes.trail_estimate, a.estimate_trail)):
        if pts is None or len(pts) < 2 or not show:
            set_if_changed(handle, "visible", False)
        else:
            handle.points = np.stack([pts[:-1], pts[1:]], axis=1).astype(np.float32)
            set_if_changed(handle, "visible", True)
