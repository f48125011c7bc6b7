"""The camera's PnP path (pixels from cv2.projectPoints, SQPnP on board) closes the loop too."""

from __future__ import annotations

from swarm.scenario import load_scenario
from swarm.sim.docking import run_docking


def test_docking_with_pnp_vision_docks_without_keepout_violation():
    sc = load_scenario("docking", {"camera.model": "pnp"})
    c = run_docking(sc, "mdp", 1, record_series=False)["chasers"]["chaser"]
    assert c["docked"] and not c["keepout_violated"]
    assert c["estimator"]["accepted_vision"] > 50  # the pose updates came from solvePnP, and were used
    assert c["position_error_m"] < 0.02
