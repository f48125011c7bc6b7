"""The dashboard of a launched ``ground-docking`` swarm (issue 12) in a real browser: the page names both
wheeled modules with a mode, and its 3D view (the table's anchors, the modules drawn as wheeled bodies,
dashboard/kinds.py) is not blank. The screenshot is kept as ``artifacts/dashboard-ground.png``."""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from tests.dashboard.conftest import ARTIFACTS, LaunchedSwarm, launch_swarm
from tests.dashboard.test_browser import MIN_SCENE_VARIANCE, SCENE_REGION, UI_TIMEOUT_MS, _wait_for_table
from tests.transport.procs import Procs


@pytest.fixture(scope="module")
def swarm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LaunchedSwarm]:
    with Procs() as procs:
        yield launch_swarm(procs, tmp_path_factory.mktemp("swarm"), pairs=1, scenario="ground-docking")


def test_the_ground_swarm_is_shown_with_its_modes_and_scene(browser, swarm: LaunchedSwarm) -> None:
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    try:
        page = context.new_page()
        page.goto(swarm.url)
        page.get_by_text("Connected").first.wait_for(timeout=UI_TIMEOUT_MS)
        text = _wait_for_table(page, swarm.agent_ids)
        assert "chaser" in text and "target" in text
        ARTIFACTS.mkdir(exist_ok=True)
        path = ARTIFACTS / "dashboard-ground.png"
        # software WebGL fades the view in over the first seconds after the page loads (measured: grey-level
        # variance 154, then ~817 from 1.5 s later): look again until the scene is there, for at most 20 s
        variance = 0.0
        for _ in range(10):
            page.wait_for_timeout(2000)
            page.screenshot(path=str(path))
            img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            variance = float(np.var(img[SCENE_REGION]))
            if variance > 4 * MIN_SCENE_VARIANCE:
                break
    finally:
        context.close()
    assert variance > MIN_SCENE_VARIANCE
