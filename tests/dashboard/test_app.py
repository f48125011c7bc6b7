"""The dashboard's app in this process (dashboard.app.DashboardApp, its Viser server on a free port, its
render thread) against a fake swarm in another process over loopback Zenoh: what the GUI panels and scene
nodes show when agents are lost, the swarm stops and starts again, garbage arrives on every key, the MDP
moves the switch radii, and a run-control button is pressed. The browser tests do the same through a
real page; here the GUI's content is read from its handles."""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Iterator

import pytest
import zenoh

from dashboard.app import DashboardApp
from dashboard.mapping import FOV_COLORS
from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.messages import DropCounter, Event, Fault, encode
from swarm.transport.session import ZenohArgs, open_session, subscribe_decoded
from tests.dashboard.conftest import ClockWatch, new_namespace, start_fake_swarm
from tests.transport.procs import Proc, Procs, free_port, loopback, wait_until

TIMEOUT_S = 20.0  # the render thread updates panels at 5 Hz; process starts take ~1-2 s on a loaded machine


class Harness:
    """A fake swarm listening on a loopback port, and a DashboardApp connected to it."""

    def __init__(self, procs: Procs) -> None:
        self.procs = procs
        self.endpoint = loopback(free_port())
        self.namespace = new_namespace("app")
        self.app: DashboardApp | None = None
        self._session = None

    def swarm(self, *args: str) -> Proc:
        return start_fake_swarm(self.procs, self.endpoint, self.namespace, *args)

    def token(self, role_id: str) -> Proc:
        proc = self.procs.start(
            [sys.executable, "-m", "tests.dashboard.fake_swarm",
             "--listen", loopback(free_port()), "--connect", self.endpoint, "--namespace", self.namespace,
             "--token-only", role_id]
        )  # fmt: skip
        proc.wait_for_line(r"^token ", TIMEOUT_S)
        return proc

    def start_app(self) -> DashboardApp:
        self._session = open_session(ZenohArgs(connect=(self.endpoint,)))
        self.app = DashboardApp(load_scenario("docking"), self._session, Keys(self.namespace), "127.0.0.1", 0)
        self.app.start()
        return self.app

    def table_row(self, agent_id: str) -> str:
        assert self.app is not None
        for line in self.app.gui.table.content.splitlines():
            if line.startswith(f"| {agent_id} |"):
                return line
        return ""

    def wait_for(self, predicate, what: str) -> None:
        wait_until(predicate, TIMEOUT_S, what, poll_s=0.05)

    def close(self) -> None:
        if self.app is not None:
            self.app.close()
        if self._session is not None:
            self._session.close()


@pytest.fixture
def harness() -> Iterator[Harness]:
    with Procs() as procs:
        h = Harness(procs)
        try:
            yield h
        finally:
            h.close()


def test_table_names_the_agents_with_their_modes(harness: Harness) -> None:
    harness.swarm()
    app = harness.start_app()
    harness.wait_for(lambda: "| APPROACH |" in harness.table_row("chaser"), "the chaser's mode in the table")
    harness.wait_for(lambda: "| STATION |" in harness.table_row("target"), "the target's mode in the table")
    # the status line is redrawn at a lower rate than the table: wait for it rather than race it
    harness.wait_for(lambda: "running" in app.gui.status.content, "the clock state in the status line")
    assert app.drops.total == 0


def test_anchors_of_a_swarm_started_before_the_dashboard_come_from_the_queryable(harness: Harness) -> None:
    harness.swarm()  # it publishes its anchors once at start, before the dashboard exists
    app = harness.start_app()
    harness.wait_for(lambda: app.state.snapshot().anchors_version > 0, "the anchors from a get")
    ids, positions = app.state.snapshot().anchors
    assert ids == (0, 1, 2, 3) and positions.shape == (4, 3)


def test_frames_to_the_browser_never_exceed_the_maximum_rate(harness: Harness) -> None:
    harness.swarm("--rate-hz", "400")  # samples arrive much faster than frames may go
    app = harness.start_app()
    harness.wait_for(lambda: app.frames > 0, "a first frame")
    f0, t0 = app.frames, time.monotonic()
    time.sleep(2.0)
    rate = (app.frames - f0) / (time.monotonic() - t0)
    assert rate <= 1.1 * app.params.max_hz, f"{rate:.1f} frames/s"  # an upper bound: load only lowers it


def test_an_agent_whose_process_dies_is_shown_lost_then_alive_again(harness: Harness) -> None:
    harness.swarm("--skip-token", "chaser")
    token = harness.token("agent/chaser")
    harness.start_app()
    harness.wait_for(lambda: harness.table_row("chaser").endswith("| alive |"), "the chaser alive")
    token.kill_group()  # the agent process is killed: its liveliness token goes within milliseconds
    harness.wait_for(lambda: harness.table_row("chaser").endswith("| lost |"), "the chaser lost")
    assert harness.table_row("target").endswith("| alive |")
    harness.token("agent/chaser")  # restarted
    harness.wait_for(lambda: harness.table_row("chaser").endswith("| alive |"), "the chaser alive again")


def test_dashboard_survives_the_swarm_stopping_and_starting_again(harness: Harness) -> None:
    first = harness.swarm("--seed", "3")
    app = harness.start_app()
    harness.wait_for(lambda: "seed 3" in app.gui.status.content, "the first run")
    first.kill_group()
    harness.wait_for(lambda: "world lost" in app.gui.status.content, "the world seen lost")
    harness.wait_for(lambda: harness.table_row("chaser").endswith("| lost |"), "the chaser lost")
    frames = app.frames
    harness.swarm("--seed", "7")
    harness.wait_for(lambda: "seed 7" in app.gui.status.content, "the second run")
    harness.wait_for(lambda: "world alive" in app.gui.status.content, "the world alive again")
    harness.wait_for(lambda: harness.table_row("chaser").endswith("| alive |"), "the chaser alive again")
    assert app.state.run >= 1  # the new seed started a new run: trails and timelines were cleared
    assert app.frames > frames and app._thread.is_alive()


def test_garbage_on_every_key_changes_nothing_but_the_drop_counters(harness: Harness) -> None:
    harness.swarm("--garbage")
    app = harness.start_app()
    ns = harness.namespace
    keys = [f"{ns}/agent/chaser/{k}" for k in ("truth", "estimate", "guidance", "event")]
    keys += [f"{ns}/agent/target/truth", f"{ns}/world/clock"]

    def all_counted() -> bool:
        counts = app.drops.counts()
        return all(counts.get(k, 0) > 0 for k in keys)

    harness.wait_for(all_counted, f"drops counted on {keys}")
    harness.wait_for(lambda: "| APPROACH |" in harness.table_row("chaser"), "the table still right")

    def shown() -> int:  # the status line is drawn by the render thread, a frame after the counting
        return int(re.search(r"dropped messages (\d+)", app.gui.status.content).group(1))

    harness.wait_for(lambda: shown() > 0, "the drops shown in the status line")
    assert app._frame_errors == 0 and app._thread.is_alive()


def test_switch_spheres_follow_the_mdp_and_the_cone_turns_green_with_vision(harness: Harness) -> None:
    # The scripted MDP starts with r2 = 0.3 m and r1 = 0.1 m, sets r2 to the range when it drops below 0.7 m
    # (REORIENT, ~3.4 s of swarm time at 0.3 m/s: 1.7 s here) and r1 below 0.45 m (ALIGN); vision frames
    # come in REORIENT, ALIGN and DOCK (~2 s here).
    harness.swarm("--speed", "0.3")
    app = harness.start_app()
    harness.wait_for(lambda: "chaser" in app.scene.nodes, "the chaser's nodes")
    nodes = app.scene.nodes["chaser"]
    harness.wait_for(lambda: nodes.radii["r2"].visible and nodes.radii["r2"].scale == 0.3, "r2 at 0.3 m")
    harness.wait_for(lambda: nodes.fov_state == "seen", "markers seen")
    assert tuple(nodes.fov.color) == FOV_COLORS["seen"]
    harness.wait_for(lambda: 0.65 < nodes.radii["r2"].scale <= 0.7, "r2 moved out to ~0.7 m")
    harness.wait_for(lambda: 0.4 < nodes.radii["r1"].scale <= 0.45, "r1 moved out to ~0.45 m")
    assert nodes.radii["r_t"].scale == 1.0
    assert tuple(nodes.radii["r1"].position) == (1.0, 2.0, 1.0)  # around the target (the fake's, at rest)


def test_pause_and_resume_buttons_reach_the_world(harness: Harness) -> None:
    harness.swarm()
    app = harness.start_app()
    watch = ClockWatch(harness.endpoint, harness.namespace)
    try:
        watch.wait_for(lambda c: c.state == "running", TIMEOUT_S, "a running clock")
        app.gui.press("pause")  # what a click on Pause runs
        paused = watch.wait_for(lambda c: c.state == "paused", TIMEOUT_S, "the world paused")
        harness.wait_for(lambda: "**paused**" in app.gui.status.content, "the dashboard showing paused")
        app.gui.press("resume")
        running = lambda c: c.state == "running" and c.tick > paused.tick  # noqa: E731
        watch.wait_for(running, TIMEOUT_S, "the world running")
    finally:
        watch.close()


def test_new_seed_button_starts_a_new_run(harness: Harness) -> None:
    harness.swarm("--seed", "4")
    app = harness.start_app()
    harness.wait_for(lambda: "seed 4" in app.gui.status.content, "the first run")
    app.gui.press("new_seed")
    harness.wait_for(lambda: "seed 5" in app.gui.status.content, "the new seed")
    harness.wait_for(lambda: app.state.run >= 1, "a new run")


def test_hiding_trails_keeps_their_history(harness: Harness) -> None:
    harness.swarm("--speed", "0.3")
    app = harness.start_app()
    harness.wait_for(lambda: "chaser" in app.scene.nodes, "the chaser's nodes")
    nodes = app.scene.nodes["chaser"]
    harness.wait_for(lambda: nodes.trail_truth.visible and len(nodes.trail_truth.points) > 5, "a trail")
    app.scene.set_show_trails(False)
    harness.wait_for(lambda: not nodes.trail_truth.visible, "the trail hidden")
    app.scene.set_show_trails(True)
    harness.wait_for(lambda: nodes.trail_truth.visible, "the trail shown again")
    assert len(app.state.agents["chaser"].truth_trail) > 5


def test_fault_panel_publishes_nothing_for_a_bad_value_and_the_fault_for_a_good_one(harness: Harness) -> None:
    """Inject with a negative duration: the panel names the input, the field and the value, and nothing
    is published; then a valid camera loss is. The dashboard has one publisher on control/fault and Zenoh
    keeps one publisher's order, so the first Fault the test receives being the valid one shows that the
    refused one never left."""
    harness.swarm()
    app = harness.start_app()
    received: list[Fault] = []
    with open_session(ZenohArgs(connect=(harness.endpoint,))) as session:
        drops = DropCounter()
        subscribe_decoded(
            session, Keys(harness.namespace).fault(), Fault, lambda _k, m: received.append(m), drops
        )
        panel = app.gui.faults
        harness.wait_for(panel.listening, "the dashboard hearing of the test's subscriber")
        panel.kind.value = "camera_loss"
        panel.inputs["vehicle"].value = "chaser"
        panel.inputs["duration"].value = -1.0
        assert panel.inject() is None
        assert "**not sent**" in panel.sent.content
        assert "duration [s] (duration_s): must be > 0, got -1.0" in panel.sent.content
        panel.inputs["duration"].value = 3.0
        sent = panel.inject()
        assert sent is not None and "sent **camera_loss** on chaser for 3 s" in panel.sent.content
        harness.wait_for(lambda: len(received) >= 1, "the fault on control/fault")
    assert received[0] == sent and (received[0].kind, received[0].vehicle) == ("camera_loss", "chaser")
    assert drops.total == 0


def test_faults_announced_by_the_world_are_listed(harness: Harness) -> None:
    harness.swarm()
    app = harness.start_app()
    keys = Keys(harness.namespace)
    applied = Event(7.0, "fault", {"kind": "uwb_dropout", "start_s": 7.01, "duration_s": 5.0, "vehicles": []})
    refused = Event(8.0, "fault_refused", {"kind": "sensor_delay", "vehicle": None, "reason": "lockstep run"})
    start = Event(0.0, "run_start", {"seed": 1, "clock": "lockstep", "vehicles": ["chaser", "target"]})
    with open_session(ZenohArgs(connect=(harness.endpoint,))) as session:
        for key, msg in ((keys.world_event(), start), (keys.world_event(), applied),
                         (keys.world_event(), refused)):  # fmt: skip
            pub = session.declare_publisher(key, reliability=zenoh.Reliability.RELIABLE)
            wait_until(lambda pub=pub: pub.matching_status.matching, TIMEOUT_S, f"the dashboard on {key}")
            pub.put(encode(msg))
        panel = app.gui.faults
        harness.wait_for(lambda: "sensor_delay refused" in panel.log.content, "the refusal listed")
    assert "**uwb_dropout** applied by the world on the UWB network" in panel.log.content
    assert "by the world: lockstep run" in app.gui.events.content  # the event log has it too
    panel.kind.value = "sensor_delay"
    harness.wait_for(lambda: "This run is lockstep" in panel.hint.content, "the hint naming the clock")
    assert panel.inputs["vehicle"].visible and panel.inputs["delay"].visible
    assert not panel.inputs["probability"].visible
