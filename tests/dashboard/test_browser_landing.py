"""The dashboard of a landing swarm in a real browser (issue 15, part 5): ``swarm launch landing-swarm`` with
its dashboard (no ``--headless``) and ``--record``, on the TDoA3 radio (``--set uwb.mode=tdoa3``, issue 45),
the real landing world and four landing agent processes in lockstep over loopback Zenoh. Headless Chromium on
the live page sees the four UAVs, their landing modes and their rotor energy, and while they fly the Radio
panel's rates (every anchor's packets a second, each UAV's differences and accepted ones); its Faults panel
offers the landing world's two kinds and a UWB dropout injected from it is applied by the world and listed;
its Pause and Resume stop and restart the world's clock; and all four LANDED when the run ends; the launcher
then holds until SIGINT, which stops it cleanly. The run's recording played back (``python -m dashboard
--open``) shows the landing from its recorded scenario: at two times of the time slider the screenshots
differ where the recorded UAVs are (their poses projected through the dashboard's initial camera), and the
Radio panel shows each UAV's differences a second as the recording has them.

numba's cache is warmed in this process first (a cold compile in five processes at once outlasts the
world's start timeout on two cores). The run is paced (``--pace scaled:0.5``: lockstep, never ahead of half
the wall clock's rate), so that the page's Pause comes while the UAVs still fly (unpaced the run is over in ~7
s, and the page's clicks take seconds each with software WebGL); it takes ~40 s. Screenshots are kept in
``artifacts/`` (``dashboard-landing-*.png``).
"""

from __future__ import annotations

import re
import signal
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from unittest.mock import MagicMock

import cv2
import msgpack
import numpy as np
import pytest

from dashboard.landing import frame_landing_scene
from swarm.core.landing import LandingMode
from swarm.landing_scenario import load_landing
from swarm.step.landing import LandingWorld
from swarm.transport.recording import read_recording
from tests.dashboard.conftest import ARTIFACTS, START_TIMEOUT_S, choose, fill_number, new_namespace
from tests.dashboard.pinhole import project
from tests.dashboard.test_browser import MIN_SCENE_VARIANCE, SCENE_REGION, UI_TIMEOUT_MS
from tests.dashboard.test_browser_playback import _seek, _steady_screenshot, _table_rows, _window
from tests.dashboard.test_landing import _tdoa_rows_per_s
from tests.transport.procs import Proc, Procs, free_port, loopback

WIDTH, HEIGHT = 1280, 800
UAVS = ("uav1", "uav2", "uav3", "uav4")
LANDING_MODES = {m.value for m in LandingMode}
RUN_TIMEOUT_S = 240.0  # the launched run: ~40 s here with numba's cache warm, far more on a loaded machine
T1_S, T2_S = 2.0, 12.0  # cruising or deviating far from the pads, then descending over them
MIN_MOVED = 8.0  # mean grey-level change in the window of a UAV that moved away or came


@dataclass
class LandingRun:
    launcher: Proc
    url: str
    recording: Path
    namespace: str


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LandingRun]:
    from agents.landing import warm_up

    sc = load_landing("landing-swarm")
    warm_up(sc, 0, 0, sc.policy)
    rec = tmp_path_factory.mktemp("landing") / "run.mcap"
    ns = new_namespace("land")
    with Procs() as procs:
        launcher = procs.start(
            [sys.executable, "-m", "swarm.cli.main", "launch", "landing-swarm", "--seed", "0",
             "--dashboard-port", "0", "--namespace", ns, "--listen", loopback(free_port()),
             "--record", str(rec), "--timeout", "600", "--pace", "scaled:0.5", "--set", "uwb.mode=tdoa3"]
        )  # fmt: skip
        url = launcher.wait_for_line(r"^dashboard on (http://\S+)$", 120.0).group(1)
        yield LandingRun(launcher, url, rec, ns)


@pytest.fixture(scope="module")
def live_page(browser, run: LandingRun) -> Iterator[object]:
    context = browser.new_context(viewport={"width": WIDTH, "height": HEIGHT})
    pg = context.new_page()
    pg.goto(run.url)
    pg.get_by_text("Connected").first.wait_for(timeout=UI_TIMEOUT_MS)
    pg.get_by_text("energy [kJ]").first.wait_for(timeout=UI_TIMEOUT_MS)  # the landing agents table
    yield pg
    context.close()


def _rows(pg) -> dict[str, list[str]]:
    """The agents table's rows by UAV id, as the page shows them (tab-separated cells)."""
    rows = {}
    for line in pg.inner_text("body").splitlines():
        cells = [c.strip() for c in line.split("\t")]
        if cells[0] in UAVS and len(cells) >= 8:
            rows[cells[0]] = cells
    return rows


def _wait_rows(pg, ok, what: str, timeout_s: float) -> dict[str, list[str]]:
    deadline = time.monotonic() + timeout_s
    while True:
        rows = _rows(pg)
        if set(rows) == set(UAVS) and all(ok(r) for r in rows.values()):
            return rows
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} never showed; table rows: {rows}\n{pg.inner_text('body')}")
        time.sleep(0.2)


def test_the_landing_page_injects_the_landing_worlds_faults_and_pauses_and_resumes_its_run(
    live_page, run: LandingRun
):
    """While the UAVs fly (before the test below waits for them to land), Pause first: the landing world stops
    between two ticks and the status line says its clock is paused, so that the clicks below, however slow
    the machine, find the run still on. The Faults panel offers what a landing world models, no more; a bad
    duration is refused on the page; a 1 s UWB dropout of uav2 is sent. Resume: the clock runs again, the
    landing world applies the dropout at its next tick, and the page lists it on uav2 (the docking wording,
    "the UWB network", would be wrong here). One second without ranges is well within what the IMU-driven
    filter rides through: the run still ends with four UAVs landed (the next test)."""
    _wait_rows(live_page, lambda r: r[1] in LANDING_MODES, "four UAVs with a landing mode", 120.0)
    live_page.get_by_role("button", name="Pause", exact=True).click()
    live_page.get_by_text(re.compile(r"paused · tick \d+")).first.wait_for(timeout=UI_TIMEOUT_MS)
    live_page.get_by_label("fault", exact=True).click(timeout=UI_TIMEOUT_MS)
    live_page.get_by_role("option").first.wait_for(timeout=UI_TIMEOUT_MS)  # the list open
    offered = {o.strip() for o in live_page.get_by_role("option").all_inner_texts()}
    assert offered == set(LandingWorld.FAULTS), offered
    live_page.keyboard.press("Escape")  # closed again: a re-render of the panel may have closed it anyway
    choose(live_page, "fault", "uwb_dropout", UI_TIMEOUT_MS)
    choose(live_page, "vehicle", "uav2", UI_TIMEOUT_MS)
    fill_number(live_page, "duration [s]", "-1", UI_TIMEOUT_MS)
    live_page.get_by_role("button", name="Inject").click()
    live_page.get_by_text("duration [s] (duration_s): must be > 0, got -1.0").wait_for(timeout=UI_TIMEOUT_MS)
    fill_number(live_page, "duration [s]", "1", UI_TIMEOUT_MS)
    live_page.get_by_role("button", name="Inject").click()
    live_page.get_by_text("sent uwb_dropout on uav2 for 1 s").first.wait_for(timeout=UI_TIMEOUT_MS)
    assert "no fault applied yet" in live_page.inner_text("body")  # paused: the world steps no tick
    live_page.get_by_role("button", name="Resume", exact=True).click()
    live_page.get_by_text(re.compile(r"running · tick \d+")).first.wait_for(timeout=UI_TIMEOUT_MS)
    live_page.get_by_text("uwb_dropout applied by the world on uav2").first.wait_for(timeout=UI_TIMEOUT_MS)
    ARTIFACTS.mkdir(exist_ok=True)
    live_page.screenshot(path=str(ARTIFACTS / "dashboard-landing-fault.png"))
    assert "the UWB network" not in live_page.inner_text("body")


def _radio(pg) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
    """The Radio panel's anchor rows and UAV rows as the page shows them, by anchor id and UAV id."""
    return _table_rows(pg, "packets/s (best tag)"), _table_rows(pg, "differences/s")


def _flying_radio(pg, timeout_s: float) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
    """The Radio panel once it has a row for every anchor and every UAV, two UAVs or more hear differences
    (a UAV out of every anchor's reach, or landed, hears none) and the best heard anchor more than a third of
    its transmit rate (50 a second: the UAVs far out hear little the first seconds, 6 a second at 2 s)."""
    anchors_ids = {str(j) for j in range(len(load_landing("landing-swarm").uwb.anchors_m))}
    deadline = time.monotonic() + timeout_s
    seen = []
    while True:
        anchors, tags = _radio(pg)
        seen.append((anchors, tags))
        if set(anchors) == anchors_ids and set(tags) == set(UAVS):
            hearing = sum(1 for r in tags.values() if _number(r[1]) and float(r[1]) > 0)
            if hearing >= 2 and max(float(r[1]) for r in anchors.values()) > 50.0 / 3:
                return anchors, tags
        if time.monotonic() > deadline:
            raise AssertionError(f"the Radio panel never showed two UAVs hearing: {seen[-20:]}")
        time.sleep(0.2)


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def test_the_live_page_shows_four_uavs_flying_landing_modes_then_all_landed(live_page, run: LandingRun):
    """... and the Radio panel, read once its rates are measured (:func:`_flying_radio`): the run's radio
    (TDOA3), every anchor's packets a second as the best tag hears them, at most its transmit rate (50 a
    second, [tdoa] rate_hz; measured 10-29 here, an anchor out of most UAVs' reach the lowest); each UAV's
    differences a second, accepted at most as many (to one slot's rows), a rejected share."""
    ARTIFACTS.mkdir(exist_ok=True)
    flying = _wait_rows(live_page, lambda r: r[1] in LANDING_MODES, "four UAVs with a landing mode", 120.0)
    live_page.screenshot(path=str(ARTIFACTS / "dashboard-landing-live.png"))
    assert all(r[7] == "alive" for r in flying.values()), flying  # the agent process column
    anchors, tags = _flying_radio(live_page, 60.0)
    print(f"the live Radio panel: anchors {anchors}, UAVs {tags}")
    assert "TDOA3" in live_page.inner_text("body")
    best = [float(r[1]) for r in anchors.values()]
    assert all(0.0 <= b <= 52.5 for b in best), anchors
    for uid, r in tags.items():  # (accepted and heard are counted at their own instants: one slot apart)
        if _number(r[1]) and float(r[1]) > 0:
            assert float(r[2]) <= float(r[1]) + 1.0 and r[3].endswith("%"), (uid, r)
    landed = _wait_rows(live_page, lambda r: r[1] == "LANDED", "four LANDED UAVs", RUN_TIMEOUT_S)
    live_page.screenshot(path=str(ARTIFACTS / "dashboard-landing-landed.png"))
    energy_kj = {u: float(r[6]) for u, r in landed.items()}
    # a quadrotor of 1.5 kg hovers on ~170 W: every landing of 15-50 s took kilojoules
    assert all(1.0 < e < 30.0 for e in energy_kj.values()), energy_kj
    assert "landing" in live_page.inner_text("body")  # the title says what is drawn
    # the Run folder's four controls, as a docking swarm's (New seed: tests/transport/test_landing_launch.py)
    for name in ("Pause", "Resume", "Reset", "New seed"):
        assert live_page.get_by_role("button", name=name, exact=True).count() == 1, name
    run.launcher.wait_for_line(r"^4 of 4 UAVs landed on their pads", 30.0)
    run.launcher.wait_for_line(r"^run over; the dashboard stays up", 30.0)


def test_after_the_run_sigint_stops_the_launcher_and_its_recording_is_complete(live_page, run: LandingRun):
    run.launcher.wait_for_line(r"^run over; the dashboard stays up", RUN_TIMEOUT_S)
    run.launcher.signal(signal.SIGINT)
    assert run.launcher.wait(60.0) == 0, run.launcher.output()
    messages, metadata = read_recording(run.recording)
    assert metadata["run_start"]["mission"] == "landing" and "run_end" in metadata
    assert {f"{run.namespace}/agent/{u}/truth" for u in UAVS} <= {m.key for m in messages}


def _camera() -> tuple[np.ndarray, np.ndarray]:
    """The dashboard's initial camera (position, look-at) of landing-swarm, from its own code."""
    server = SimpleNamespace(scene=MagicMock(), initial_camera=SimpleNamespace())
    frame_landing_scene(server, load_landing("landing-swarm"))
    return np.array(server.initial_camera.position), np.array(server.initial_camera.look_at)


def _project(p_nav: np.ndarray) -> tuple[int, int]:
    """Pixel (column, row) of ``p_nav`` [m] through the initial camera (tests/dashboard/pinhole.py)."""
    return project(*_camera(), p_nav, WIDTH, HEIGHT)


def _recorded_positions(recording: Path, namespace: str, t_s: float) -> dict[str, np.ndarray]:
    """Each UAV's last recorded true position at ``t_s``, read with plain msgpack."""
    last: dict[str, np.ndarray] = {}
    for m in read_recording(recording)[0]:
        for u in UAVS:
            if m.key == f"{namespace}/agent/{u}/truth" and m.log_time_ns <= round(t_s * 1e9):
                p = msgpack.unpackb(m.payload, raw=False)["p_nav"]
                last[u] = np.frombuffer(p["data"], dtype=p["dtype"]).reshape(p["shape"])
    assert set(last) == set(UAVS)
    return last


def test_the_recording_plays_back_as_a_landing_and_the_uavs_move(browser, run: LandingRun):
    run.launcher.wait_for_line(r"^run over; the dashboard stays up", RUN_TIMEOUT_S)
    assert run.recording.exists()
    with Procs() as procs:
        dash = procs.start([sys.executable, "-m", "dashboard", "--open", str(run.recording), "--port", "0"])
        url = dash.wait_for_line(r"^dashboard listening on (http://\S+)$", START_TIMEOUT_S + 30).group(1)
        context = browser.new_context(viewport={"width": WIDTH, "height": HEIGHT})
        try:
            pg = context.new_page()
            pg.goto(f"{url}?fixedDpr=1")  # one resolution for both shots (test_browser_playback.py)
            pg.get_by_text("Connected").first.wait_for(timeout=UI_TIMEOUT_MS)
            pg.get_by_text("energy [kJ]").first.wait_for(timeout=UI_TIMEOUT_MS)
            shots, modes = {}, {}
            for t in (T1_S, T2_S):
                _seek(pg, t)
                shots[t] = _steady_screenshot(pg, ARTIFACTS / f"dashboard-landing-playback-{t:g}s.png")
                modes[t] = {u: r[1] for u, r in _rows(pg).items()}
            _, radio_tags = _radio(pg)  # at T2_S
        finally:
            context.close()
    # the recorded differences (counted with plain msgpack, tests/dashboard/test_landing.py) at T2_S: the
    # panel's 2 s window starts at a slot, the count at an instant, and the page prints one decimal
    counted = _tdoa_rows_per_s(run.recording, T2_S)
    assert set(radio_tags) == set(UAVS), radio_tags
    for uid, r in radio_tags.items():
        assert float(r[1]) == pytest.approx(counted.get(uid, 0.0), rel=0.03, abs=1.0), (uid, r, counted)
    assert set(modes[T1_S]) == set(UAVS) and set(modes[T1_S].values()) <= {"CRUISE", "DEVIATE"}, modes
    assert set(modes[T2_S].values()) <= LANDING_MODES - {"CRUISE"}, modes
    assert shots[T1_S][SCENE_REGION].var() > MIN_SCENE_VARIANCE
    diff = np.abs(shots[T1_S] - shots[T2_S])
    cv2.imwrite(
        str(ARTIFACTS / "dashboard-landing-playback-diff.png"), np.clip(4 * diff, 0, 255).astype(np.uint8)
    )
    moved = {}
    for t in (T1_S, T2_S):
        for u, p in _recorded_positions(run.recording, run.namespace, t).items():
            px = _project(p)
            if 0 <= px[0] < SCENE_REGION[1].stop and SCENE_REGION[0].start <= px[1] < HEIGHT:  # in the view
                moved[(u, t)] = float(_window(diff, px).mean())
    print(f"change around each UAV at either time: {moved}")
    assert len(moved) >= 4, moved  # most of them are in the view at either time
    assert all(v > MIN_MOVED for v in moved.values()), moved
