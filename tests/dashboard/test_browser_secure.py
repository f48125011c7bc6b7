"""The dashboard of a secure swarm in a real browser (issue 7): ``swarm launch docking --secure`` (mutual
TLS, Zenoh's ACL, certificates made by the launcher; lockstep, one pair) with its dashboard, headless
Chromium on the page. The page names both vehicles with a mode, and faults injected from the Faults panel
pass the ACL (the dashboard's identity may publish ``control/fault``) and are applied: a camera loss of the
chaser (the world announces it; its effect cannot be seen here: early in APPROACH the chaser's camera
sees no marker anyway) and a UWB dropout (the mothership announces it, and every exchange of the chaser
inside the window is lost where the exchanges before it had ranges).

What the swarm publishes is recorded by the test's own session, which connects to the secure router with
the dashboard's certificate (:attr:`conftest.LaunchedSwarm.zenoh_config`: an identity that may read
everything of the swarm). Screenshot: ``artifacts/dashboard-secure-faults.png``.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from swarm.transport.messages import MODES, Event
from tests.dashboard.conftest import (
    ARTIFACTS,
    LaunchedSwarm,
    SwarmRecorder,
    choose,
    fill_number,
    launch_swarm,
)
from tests.transport.procs import Procs

UI_TIMEOUT_MS = 40_000  # page load, websocket connect and software-GL rendering on a loaded 2-core machine
EVENT_TIMEOUT_S = 30.0
DURATION_S = 2.0  # of each fault window [s of simulated time]


@pytest.fixture(scope="module")
def swarm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LaunchedSwarm]:
    with Procs() as procs:
        # --timeout: a safety net only; the module ends the swarm when it is done (Procs stops the launcher)
        yield launch_swarm(procs, tmp_path_factory.mktemp("swarm"), pairs=1, secure=True, timeout_s=900)


@pytest.fixture(scope="module")
def page(browser, swarm: LaunchedSwarm) -> Iterator[object]:
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    pg = context.new_page()
    pg.goto(swarm.url)
    pg.get_by_text("Connected").first.wait_for(timeout=UI_TIMEOUT_MS)
    pg.get_by_text("agent process").first.wait_for(timeout=UI_TIMEOUT_MS)  # the agents table header
    yield pg
    context.close()


def test_the_secure_swarm_is_secure_and_the_page_names_both_vehicles_with_a_mode(page, swarm) -> None:
    assert swarm.zenoh_config is not None and swarm.endpoint.startswith("tls/")
    page.wait_for_function(
        "([ids, modes]) => { const rows = document.body.innerText.split('\\n');"
        " return ids.every(a => rows.some(r => r.split('\\t')[0].trim() === a"
        " && modes.some(m => r.split('\\t').includes(m)))); }",
        arg=[list(swarm.agent_ids), list(MODES)],
        timeout=UI_TIMEOUT_MS,
    )


def _window(event: Event) -> tuple[float, float]:
    start = float(event.data["start_s"])
    return start, start + float(event.data["duration_s"])


def test_faults_injected_from_the_page_pass_the_acl_and_happen(page, swarm: LaunchedSwarm) -> None:
    rec = SwarmRecorder(swarm.endpoint, swarm.namespace, ("chaser",), zenoh_config=swarm.zenoh_config)
    try:
        rec.wait_for(lambda c: c.state == "running", EVENT_TIMEOUT_S, "a running clock (routes in place)")
        choose(page, "fault", "camera_loss", UI_TIMEOUT_MS)
        choose(page, "vehicle", "chaser", UI_TIMEOUT_MS)
        fill_number(page, "duration [s]", f"{DURATION_S:g}", UI_TIMEOUT_MS)
        page.get_by_role("button", name="Inject").click()
        camera = rec.wait_event(
            lambda s, e: s == "world" and e.kind == "fault" and e.data.get("kind") == "camera_loss",
            EVENT_TIMEOUT_S,
            "the world applying the camera loss",
        )
        choose(page, "fault", "uwb_dropout", UI_TIMEOUT_MS)
        fill_number(page, "duration [s]", f"{DURATION_S:g}", UI_TIMEOUT_MS)
        page.get_by_role("button", name="Inject").click()
        uwb = rec.wait_event(
            lambda s, e: s == "world" and e.kind == "fault" and e.data.get("kind") == "uwb_dropout",
            EVENT_TIMEOUT_S,
            "the world applying the UWB dropout",
        )
        page.get_by_text("camera_loss applied by the world on chaser").first.wait_for(timeout=UI_TIMEOUT_MS)
        page.get_by_text("uwb_dropout applied by the world").first.wait_for(timeout=UI_TIMEOUT_MS)
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "dashboard-secure-faults.png"))
        # both windows closed: the world's clock is past their ends
        end = max(_window(camera)[1], _window(uwb)[1])
        rec.wait_for(lambda c: c.t_s > end + 0.5, EVENT_TIMEOUT_S, "the clock past both windows")
        faults, ranges = rec.snapshot()
    finally:
        rec.close()
    assert [(f.kind, f.vehicle) for f in faults] == [("camera_loss", "chaser"), ("uwb_dropout", None)]
    assert camera.data["vehicles"] == ["chaser"]
    t0, t1 = _window(uwb)
    inside = [r for t, r in ranges["chaser"] if t0 <= t < t1]
    assert len(inside) >= 10 and all(r is None for r in inside), inside  # every exchange lost
    assert any(r is not None for t, r in ranges["chaser"] if t < t0)  # ... where ranges came before
