"""The dashboard of the moving-platform landing in a real browser (issue 44, the third mission), without a
launched swarm: ``swarm sim landing-moving --mcap`` writes what the launched processes would publish (the
robot's shared estimate on ``agent/robot/estimate`` included; ``swarm launch landing-moving`` equals it:
tests/transport/test_landing_launch.py), and ``python -m dashboard --open`` plays it back in headless
Chromium. At two times of the time slider the pad is drawn where the robot was: the screenshots differ
around the pad's place at the first time (the pad has left it; the UAV is far from it), and the agents table
has the UAV's row and no row for the robot. Screenshots in ``artifacts/``
(``dashboard-landing-moving-*.png``)."""

from __future__ import annotations

import sys
from types import SimpleNamespace
from unittest.mock import MagicMock

import cv2
import msgpack
import numpy as np

from dashboard.landing import frame_landing_scene
from swarm.landing_scenario import load_landing
from swarm.sim.landing import run_landing_fleet
from swarm.transport.recording import read_recording
from swarm.transport.wire import LandingTap
from tests.dashboard.conftest import ARTIFACTS, START_TIMEOUT_S
from tests.dashboard.pinhole import project
from tests.dashboard.test_browser import MIN_SCENE_VARIANCE, SCENE_REGION, UI_TIMEOUT_MS
from tests.dashboard.test_browser_playback import _seek, _steady_screenshot, _window
from tests.transport.procs import Procs

WIDTH, HEIGHT = 1280, 800
OVERRIDES = {"platform.speed_m_s": 0.6, "max_duration_s": 14.0}  # the pad drives 6 m between the two shots
T1_S, T2_S = 2.0, 12.0
MIN_MOVED = (
    8.0  # mean grey-level change in the window where the pad was (tests/dashboard/test_browser_landing)
)


def _project(sc, p_nav: np.ndarray) -> tuple[int, int]:
    """Pixel (column, row) of ``p_nav`` [m] through the dashboard's initial camera of ``sc`` (its own code;
    tests/dashboard/pinhole.py)."""
    server = SimpleNamespace(scene=MagicMock(), initial_camera=SimpleNamespace())
    frame_landing_scene(server, sc)
    return project(server.initial_camera.position, server.initial_camera.look_at, p_nav, WIDTH, HEIGHT)


def _shared_pad(path, t_s: float) -> np.ndarray:
    """The robot's last shared pad position at ``t_s`` in the recording, read with plain msgpack."""
    last = None
    for m in read_recording(path)[0]:
        if m.key == "tpods/agent/robot/estimate" and m.log_time_ns <= round(t_s * 1e9):
            p = msgpack.unpackb(m.payload, raw=False)["p_nav"]
            last = np.frombuffer(p["data"], dtype=p["dtype"]).reshape(p["shape"])
    assert last is not None
    return last


def _table_rows(body: str) -> list[str]:
    """The first cells of the landing agents table's rows (eight cells: UAV, mode, ... agent process)."""
    rows = [[c.strip() for c in line.split("\t")] for line in body.splitlines()]
    return [r[0] for r in rows if len(r) == 8 and r[0] in ("uav", "robot")]


def test_the_played_back_moving_landing_draws_the_pad_where_the_robot_was(browser, tmp_path):
    sc = load_landing("landing-moving", OVERRIDES)
    rec = tmp_path / "moving.mcap"
    run_landing_fleet(sc, seed=0, record_series=False, tap=LandingTap(rec, 0))
    pads = {t: _shared_pad(rec, t) for t in (T1_S, T2_S)}
    assert np.linalg.norm(pads[T2_S][:2] - pads[T1_S][:2]) > 5.0  # 10 s at 0.6 m/s along the lap
    ARTIFACTS.mkdir(exist_ok=True)
    with Procs() as procs:
        dash = procs.start([sys.executable, "-m", "dashboard", "--open", str(rec), "--port", "0"])
        url = dash.wait_for_line(r"^dashboard listening on (http://\S+)$", START_TIMEOUT_S + 30).group(1)
        context = browser.new_context(viewport={"width": WIDTH, "height": HEIGHT})
        try:
            pg = context.new_page()
            pg.goto(f"{url}?fixedDpr=1")
            pg.get_by_text("Connected").first.wait_for(timeout=UI_TIMEOUT_MS)
            pg.get_by_text("energy [kJ]").first.wait_for(timeout=UI_TIMEOUT_MS)
            shots, rows = {}, {}
            for t in (T1_S, T2_S):
                _seek(pg, t)
                shots[t] = _steady_screenshot(pg, ARTIFACTS / f"dashboard-landing-moving-{t:g}s.png")
                rows[t] = _table_rows(pg.inner_text("body"))
        finally:
            context.close()
    assert rows[T1_S] == ["uav"] and rows[T2_S] == ["uav"], rows  # the robot is no UAV
    assert shots[T1_S][SCENE_REGION].var() > MIN_SCENE_VARIANCE
    diff = np.abs(shots[T1_S] - shots[T2_S])
    cv2.imwrite(
        str(ARTIFACTS / "dashboard-landing-moving-diff.png"), np.clip(4 * diff, 0, 255).astype(np.uint8)
    )
    c, r = _project(sc, np.array([*pads[T1_S][:2], 0.0]))
    assert 0 <= c < SCENE_REGION[1].stop and SCENE_REGION[0].start <= r < HEIGHT, (c, r)  # in the view
    changed = float(_window(diff, (c, r)).mean())
    # a control: around anchor 1 (-13, 8), far from the UAV's path and the pad's, nothing moved
    still = float(_window(diff, _project(sc, np.asarray(sc.uwb.anchors_m[1]))).mean())
    print(f"change where the pad was at {T1_S:g} s: {changed:.1f}; around anchor 1: {still:.1f}")
    assert changed > MIN_MOVED and still < 1.0, (changed, still)
