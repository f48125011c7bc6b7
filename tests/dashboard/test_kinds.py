"""Each vehicle kind is drawn as what it is (dashboard/kinds.py), from its own tables; a kind without a
drawer is a box, so a new kind appears with no dashboard edit."""

from __future__ import annotations

import numpy as np
import pytest

from dashboard import kinds
from swarm.core.thrusters import nozzle_geometry
from swarm.scenario import load_scenario


class RecordingScene:
    """Stands in for ``viser.SceneApi``: records every node added (name, shape, keyword arguments)."""

    def __init__(self) -> None:
        self.nodes: dict[str, tuple[str, dict]] = {}

    def __getattr__(self, method: str):
        if not method.startswith("add_"):
            raise AttributeError(method)

        def add(name: str, *args, **kwargs):
            self.nodes[name] = (method[4:], kwargs)
            return name

        return add


def test_a_cube_is_its_body_and_ten_nozzles_where_the_thrusters_table_puts_them():
    sc = load_scenario("docking")
    scene = RecordingScene()
    body = kinds.draw(scene, "/chaser/truth", sc, "chaser", (1, 2, 3))
    assert body == "/chaser/truth/body" and scene.nodes[body][0] == "box"
    r, _ = nozzle_geometry(sc.kinds.cubesat.thrusters)
    nozzles = sorted(n for n in scene.nodes if "/nozzle" in n)
    assert len(nozzles) == len(r) == 10
    for i, pos in enumerate(r):
        np.testing.assert_allclose(scene.nodes[f"/chaser/truth/nozzle{i}"][1]["position"], pos)


def test_a_ground_module_is_its_body_four_wheels_and_its_uwb_mast():
    sc = load_scenario("ground-docking")
    w = sc.kinds.ground.wheels
    scene = RecordingScene()
    body = kinds.draw(scene, "/chaser/truth", sc, "chaser", (1, 2, 3))
    assert scene.nodes[body] == ("box", {"color": (1, 2, 3), "dimensions": (0.1,) * 3, "opacity": 0.85})
    wheels = [scene.nodes[f"/chaser/truth/wheel{i}"] for i in range(1, 5)]
    assert all(shape == "cylinder" and kw["radius"] == w.radius_m for shape, kw in wheels)
    xs = sorted(kw["position"][0] for _, kw in wheels)
    assert xs == pytest.approx([-w.half_length_m] * 2 + [w.half_length_m] * 2)
    tag = sc.kinds.ground.mounts.tag_lever_arm_body_m
    assert scene.nodes["/chaser/truth/uwb_node"][1]["position"] == tuple(tag)
    assert scene.nodes["/chaser/truth/mast"][0] == "cylinder"


def test_a_kind_without_a_drawer_is_a_box_of_the_guidance_size(monkeypatch):
    sc = load_scenario("ground-docking")
    monkeypatch.delitem(kinds.DRAWERS, "ground")
    scene = RecordingScene()
    body = kinds.draw(scene, "/chaser/truth", sc, "chaser", (9, 9, 9))
    assert list(scene.nodes) == [body] and scene.nodes[body][1]["dimensions"] == (0.1,) * 3
