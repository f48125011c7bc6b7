"""Playback of an MCAP recording (issue 16, dashboard.playback): the store at time t holds the recorded
poses and mode at t; seeking backward then forward gives the store a straight play gives; the player's clock;
the app draws the recorded pose at the chosen time, commands nothing and opens no Zenoh session; a missing,
truncated or corrupt file exits 2 with one line naming the file (and the byte offset).

The recording is the scripted fake swarm written by the real Recorder (``tests/dashboard/recorded.py``); the
oracle for "the pose at t" is the recorded payload read with plain msgpack, not the project's decoder."""

from __future__ import annotations

import sys
import threading
import urllib.request
from dataclasses import replace
from pathlib import Path

import msgpack
import numpy as np
import pytest

from dashboard import cli
from dashboard.app import DashboardApp
from dashboard.playback import Player, Timeline, load_recording, scenario_of
from dashboard.radio import radio_markdown
from dashboard.state import Snapshot, SwarmState
from swarm.errors import ConfigError, LogError
from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.messages import Event
from swarm.transport.recording import read_recording
from tests.dashboard.conftest import START_TIMEOUT_S
from tests.dashboard.recorded import ANCHOR_HZ, NAMESPACE, TAG_HZ
from tests.transport.procs import Procs, wait_until

VEHICLES = {"chaser": ("chaser", "target"), "target": ("target", None)}


def _make_state() -> SwarmState:
    sc = load_scenario("docking")
    return SwarmState(VEHICLES, np.array(sc.anchors_m, dtype=float))


def _ns(t_s: float) -> int:
    """A time in ns, as the recorder's log time (``t_s`` of 1999 ticks of 0.01 s is 19.990000000000002)."""
    return round(t_s * 1e9)


def _recorded_truths(path: Path, agent_id: str) -> list[tuple[float, np.ndarray]]:
    """``(t_s, p_nav)`` of every recorded truth of ``agent_id``, read with plain msgpack."""
    msgs, _ = read_recording(path)
    out = []
    for m in msgs:
        if m.key == f"{NAMESPACE}/agent/{agent_id}/truth":
            obj = msgpack.unpackb(m.payload, raw=False)
            p = obj["p_nav"]
            out.append((obj["t_s"], np.frombuffer(p["data"], dtype=p["dtype"]).reshape(p["shape"])))
    return out


def _straight(recording, t_s: float) -> SwarmState:
    """The store after every message of log time <= t_s, applied one by one from an empty store."""
    state = _make_state()
    for (kind, agent_id, msg), t_ns in zip(recording.items, recording.times_ns, strict=True):
        if t_ns > _ns(t_s):
            break
        state.on_message(kind, agent_id, msg)
    return state


def _assert_same(a: Snapshot, b: Snapshot) -> None:
    assert a.agents.keys() == b.agents.keys()
    for k, x in a.agents.items():
        y = b.agents[k]
        assert (x.truth, x.estimate, x.guidance) == (y.truth, y.estimate, y.guidance), k
        assert (x.vision_t_s, x.modes, x.trail_versions, x.radii_version) == (
            y.vision_t_s, y.modes, y.trail_versions, y.radii_version,
        ), k  # fmt: skip
        for u, v in ((x.truth_trail, y.truth_trail), (x.estimate_trail, y.estimate_trail)):
            np.testing.assert_array_equal(u, v)
        np.testing.assert_array_equal(x.radii_t, y.radii_t)
        np.testing.assert_array_equal(x.radii_v, y.radii_v)
    assert (a.clock, a.run, a.events, a.faults, a.clock_mode) == (
        b.clock,
        b.run,
        b.events,
        b.faults,
        b.clock_mode,
    )
    assert a.anchors[0] == b.anchors[0] and np.array_equal(a.anchors[1], b.anchors[1])
    assert a.radio == b.radio


def test_a_recording_is_read_with_its_namespace_scenario_and_vehicles(recording: Path) -> None:
    rec = load_recording(recording)
    assert rec.namespace == NAMESPACE and rec.scenario_name == "docking"
    assert rec.vehicle_ids == ("chaser", "target")
    assert (
        list(rec.times_ns) == sorted(rec.times_ns) and rec.start_s == 0.0 and rec.end_s == pytest.approx(20.0)
    )
    kinds = {kind for kind, _, _ in rec.items}
    assert kinds == {
        "truth",
        "estimate",
        "guidance",
        "vision",
        "event",
        "world_event",
        "world_clock",
        "anchors",
        "tdoa",
    }
    assert rec.uwb_mode == "tdoa"  # its distance differences say so; run_start does not name the radio
    sc = scenario_of(rec, None)
    assert sc.name == "docking" and set(sc.vehicles) == {"chaser", "target"}


def test_a_recorded_vision_batch_plays_as_each_vehicles_frame(tmp_path: Path) -> None:
    """A recording of a swarm of agent hosts holds the chasers' frames in world/vision batches: playback
    reads each entry as that vehicle's vision, at the batch's time, as the live dashboard does; an entry that
    does not decode is counted in the recording's drops, and the other frames stay."""
    from swarm.transport.messages import Vision, VisionBatch, encode
    from swarm.transport.recording import McapSink

    keys = Keys(NAMESPACE)
    frame = Vision(10, 0.1, "target", "+x", "features", np.full((6, 3), 0.2), (0, 1, 2, 3, 4, 5))
    path = tmp_path / "hosted.mcap"
    sink = McapSink(path, keys)
    sink.write(
        keys.world_vision(), encode(VisionBatch(10, 0.1, ("chaser", "chaser2"), (encode(frame), b"x")))
    )
    sink.close()
    rec = load_recording(path)
    assert rec.items == (("vision", "chaser", frame),) and rec.times_ns == (100_000_000,) and rec.dropped == 1


def test_a_recorded_tdoa_run_plays_the_radio_panels_rates(recording: Path) -> None:
    """The scripted run's tags hear each anchor ANCHOR_HZ times a second and form TAG_HZ differences; their
    estimates accept 50 a second and reject 1 (tests/dashboard/recorded.py): the store at t, played from the
    recording, says so in the Radio panel's table. Within 2 %: the 2 s window's base slot can sit one 0.02 s
    slot off a float boundary (one slot of the window's 100 shifts an anchor's count by 1 of 50)."""
    rec = load_recording(recording)
    sc = load_scenario("docking")
    state = SwarmState(VEHICLES, np.array(sc.anchors_m, dtype=float), uwb_mode=rec.uwb_mode)
    timeline = Timeline(rec, state, lambda: SwarmState(VEHICLES, state._anchors[1], uwb_mode=rec.uwb_mode))
    timeline.seek(13.5)
    radio = state.snapshot(radio=True).radio
    assert radio.mode == "tdoa" and [a.anchor for a in radio.anchors] == [0, 1, 2, 3]
    for a in radio.anchors:
        assert a.best_hz == pytest.approx(ANCHOR_HZ, rel=0.02) and a.mean_hz == pytest.approx(
            ANCHOR_HZ, rel=0.02
        )
        assert a.tags == 2
    tags = {t.tag: t for t in radio.tags}
    assert set(tags) == {"chaser", "target"}
    for t in tags.values():
        assert t.heard_hz == pytest.approx(TAG_HZ, rel=0.02)
        assert t.accepted_hz == pytest.approx(50.0, rel=0.02)
        assert t.rejected_share == pytest.approx(1.0 / 51.0, rel=0.05)
    text = radio_markdown(radio)
    assert (
        text.startswith("**TDOA**")
        and "| anchor | packets/s (best tag) |" in text
        and "differences/s" in text
    )


def test_recorded_tdoa_in_batches_and_bundles_plays_as_each_vehicles_tdoa(tmp_path: Path) -> None:
    """However the differences travelled (docs/protocol.md: a mothership/tdoa batch for agent hosts, a Tdoa
    entry of a vehicle's lockstep bundle), playback reads each as that vehicle's tdoa at its message's time,
    as the live link does; a bundle's other entries are skipped; an entry that does not decode is counted in
    the recording's drops and the others stay. A run_start naming the radio names the playback's."""
    from swarm.transport.messages import Bundle, Imu, Tdoa, TdoaBatch, encode
    from swarm.transport.recording import McapSink

    keys = Keys(NAMESPACE)

    def tdoa(k: int, t: float, b: int) -> Tdoa:
        return Tdoa(k, t, (0,), (b,), np.array([0.25]))

    imu = Imu(4, 0.04, 0.01, np.zeros(3))
    path = tmp_path / "tdoa.mcap"
    sink = McapSink(path, keys)
    sink.write(
        keys.world_event(), encode(Event(0.0, "run_start", {"scenario": "docking", "uwb_mode": "tdoa2"}))
    )
    batch = TdoaBatch(
        2, 0.02, ("chaser", "target", "chaser2"), (encode(tdoa(2, 0.02, 1)), b"x", encode(tdoa(2, 0.02, 2)))
    )
    sink.write(keys.mothership_tdoa(), encode(batch))
    bundle = Bundle(4, ("Imu", "Tdoa", "Tdoa"), (encode(imu), encode(tdoa(4, 0.04, 3)), b"y"))
    sink.write(keys.bundle("chaser"), encode(bundle))
    sink.close()
    rec = load_recording(path)
    tdoa_items = [(kind, vid, msg) for kind, vid, msg in rec.items if kind == "tdoa"]
    assert tdoa_items == [
        ("tdoa", "chaser", tdoa(2, 0.02, 1)),
        ("tdoa", "chaser2", tdoa(2, 0.02, 2)),
        ("tdoa", "chaser", tdoa(4, 0.04, 3)),
    ]
    assert rec.times_ns[-3:] == (20_000_000, 20_000_000, 40_000_000)
    assert rec.dropped == 2 and rec.uwb_mode == "tdoa2"


def test_the_store_at_t_holds_the_recorded_poses_and_mode_at_t(recording: Path) -> None:
    rec = load_recording(recording)
    state = _make_state()
    timeline = Timeline(rec, state, _make_state)
    truths = _recorded_truths(recording, "chaser")
    for t in (0.0, 3.333, 7.5, 12.0, 19.99, 20.0):
        timeline.seek(t)
        t_want, p_want = [(ts, p) for ts, p in truths if _ns(ts) <= _ns(t)][-1]
        chaser = state.agents["chaser"]
        assert chaser.truth.t_s == t_want
        np.testing.assert_array_equal(chaser.truth.p_nav, p_want)
        assert state.clock.t_s == pytest.approx(t_want)
    timeline.seek(5.0)
    assert state.agents["chaser"].guidance.mode == "APPROACH"  # 1.73 m - 0.1 m/s * 5 s = 1.23 m > 0.7 m
    timeline.seek(19.0)
    assert state.agents["chaser"].guidance.mode == "DOCKED"
    modes = [m for _, m, _, _ in state.agents["chaser"].modes]
    assert modes == ["APPROACH", "REORIENT", "ALIGN", "DOCK", "DOCKED"]


def test_the_scenario_is_the_recorded_one_in_as_many_pairs_unless_one_is_given(recording: Path) -> None:
    rec = load_recording(recording)
    four = "['chaser0', 'target0', 'chaser1', 'target1']"
    pairs = replace(rec, metadata={"run_start": {"scenario": "ground-docking", "vehicles": four}})
    sc = scenario_of(pairs, None)
    assert set(sc.vehicles) == {"chaser0", "target0", "chaser1", "target1"}
    assert sc.vehicles["chaser1"].target == "target1" and sc.kind("chaser0").name == "ground"
    assert scenario_of(pairs, "docking").kind("chaser0").name == "cubesat"  # given: it overrides
    with pytest.raises(ConfigError, match=r"run\.mcap: its scenario 'my-own' cannot be loaded .* --open"):
        scenario_of(replace(rec, metadata={"run_start": {"scenario": "my-own"}}), None)


def test_seeking_backward_then_forward_gives_the_store_of_a_straight_play(recording: Path) -> None:
    rec = load_recording(recording)
    state = _make_state()
    timeline = Timeline(rec, state, _make_state, checkpoint_every=700)  # many checkpoints, between ticks
    assert timeline.checkpoints > 10
    for t in (18.0, 2.5, 11.111, 11.0, 20.0, 0.0, 6.0):
        restored = timeline.seek(t)
        _assert_same(state.snapshot(radio=True), _straight(rec, t).snapshot(radio=True))
        assert isinstance(restored, bool)
    t = 6.0  # then played forward frame by frame at 10x and 30 frames/s
    while t < 9.0:
        t += 10.0 / 30.0
        timeline.seek(t)
    _assert_same(state.snapshot(radio=True), _straight(rec, t).snapshot(radio=True))


def test_a_backward_seek_says_the_store_was_restored(recording: Path) -> None:
    rec = load_recording(recording)
    timeline = Timeline(rec, _make_state(), _make_state, checkpoint_every=700)
    timeline.seek(10.0)
    assert not timeline.seek(10.05)  # a frame forward: applied, nothing restored
    assert timeline.seek(4.0)


class _Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_the_player_plays_at_its_speed_stops_at_the_end_and_plays_again_from_the_start(
    recording: Path,
) -> None:
    rec = load_recording(recording)
    clock = _Clock()
    player = Player(Timeline(rec, _make_state(), _make_state), clock)
    player.seek(2.0)
    player.advance()
    assert player.timeline.t_s == 2.0 and not player.playing
    clock.now += 5.0  # paused: time stands still
    player.advance()
    assert player.timeline.t_s == 2.0
    player.set_speed(2.0)
    player.play()
    clock.now += 1.5
    player.advance()
    assert player.timeline.t_s == pytest.approx(5.0)
    player.seek(1.0)  # a seek while playing: playing goes on from there
    clock.now += 0.5
    player.advance()
    assert player.timeline.t_s == pytest.approx(2.0) and player.playing
    clock.now += 60.0
    player.advance()
    assert player.timeline.t_s == rec.end_s and not player.playing
    player.play()
    player.advance()
    assert player.timeline.t_s == rec.start_s and player.playing


def test_the_app_draws_the_recorded_pose_at_the_chosen_time_and_commands_nothing(recording: Path) -> None:
    rec = load_recording(recording)
    app = DashboardApp(load_scenario("docking"), None, Keys(rec.namespace), "127.0.0.1", 0, recording=rec)
    try:
        truths = _recorded_truths(recording, "chaser")
        for t in (15.0, 4.0):  # forward, then backward (the store restored, the scene drawn again)
            app.player.seek(t)
            app.frame()
            p_want = [p for ts, p in truths if _ns(ts) <= _ns(t)][-1]
            nodes = app.scene.nodes["chaser"]
            np.testing.assert_allclose(nodes.truth.position, p_want)
            np.testing.assert_allclose(
                nodes.trail_truth.points[-1, 1], p_want, atol=1e-6
            )  # the trail ends there
            app.gui.playback.update()  # (the render thread's panel update, at its own rate)
            assert f"t = {t:.2f} s of 20.00 s" in app.gui.playback.time.content
            assert app.gui.playback.slider.value == t
        snap = app.state.snapshot(radio=True)  # a panel frame: the Radio panel and the anchors' labels
        app.gui.update_panels(snap, 0)
        app.scene.update(snap, False)
        assert app.state.radio.mode == "tdoa" and "| 0 | 25.0 | 25.0 | 2 |" in app.gui.radio.content
        assert app.scene._anchor_labels[3].text == "anchor 3 · 25/s"
        assert app.link is None and app.gui.buttons == {}  # no Pause/Resume/Reset/New seed
        assert not app.gui.faults.button.visible and app.gui.faults.inject() is None
        assert "not sent" in app.gui.faults.sent.content
    finally:
        app.close()


def test_playback_opens_no_zenoh_session(recording: Path, monkeypatch, capsys) -> None:
    import zenoh

    import swarm.transport.session

    opened = []

    def refuse(*args, **kwargs):
        opened.append(args)
        raise AssertionError("a Zenoh session was opened")

    monkeypatch.setattr(zenoh, "open", refuse)
    monkeypatch.setattr(swarm.transport.session, "open_session", refuse)
    parser = cli.argparse.ArgumentParser()
    cli.add_arguments(parser)
    args = parser.parse_args(["--open", str(recording), "--port", "0", "--host", "127.0.0.1"])
    stop = threading.Event()
    result: list[object] = []
    thread = threading.Thread(target=lambda: result.append(cli.run(args, stop)), daemon=True)
    thread.start()
    out: list[str] = []
    try:
        wait_until(
            lambda: out.append(capsys.readouterr().out) or cli.READY_PREFIX in "".join(out),
            START_TIMEOUT_S,
            "the ready line",
            poll_s=0.05,
        )
        url = "".join(out).split(cli.READY_PREFIX, 1)[1].split()[0]
        with urllib.request.urlopen(url, timeout=10.0) as response:
            assert response.status == 200
    finally:
        stop.set()
        thread.join(START_TIMEOUT_S)
    assert result == [0] and opened == []


def _bad_files(recording: Path, tmp_path: Path) -> dict[str, tuple[Path, str]]:
    data = recording.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"not an mcap file at all" * 10)
    offset = r"\(reading stopped at byte \d+ of \d+\)"
    return {
        "truncated": (cut, rf"cut\.mcap: not a complete MCAP recording: .* {offset}$"),
        "corrupt": (garbage, rf"garbage\.mcap: not a complete MCAP recording: .* {offset}$"),
        "missing": (tmp_path / "nowhere.mcap", r"nowhere\.mcap: cannot read: No such file or directory$"),
    }


@pytest.mark.parametrize("case", ["truncated", "corrupt", "missing"])
@pytest.mark.parametrize("command", ["dashboard", "swarm"])
def test_a_bad_recording_exits_2_with_one_line_naming_the_file(
    recording, tmp_path, case, command, capsys
) -> None:
    """Both entry points (``python -m dashboard``, ``swarm dashboard``) run in this process
    (``dashboard.cli.main``, ``swarm.cli.main.main``); one case is also started as ``python -m dashboard``
    for the real entry point's exit status and output (a Python start with viser costs ~2 s of CPU: one
    instead of six)."""
    import re

    from swarm.cli.main import main as swarm_main

    path, pattern = _bad_files(recording, tmp_path)[case]
    with pytest.raises(LogError, match=pattern):  # the same message, from the loader
        load_recording(path)
    argv = ["--open", str(path), "--port", "0"]
    rc = cli.main(argv) if command == "dashboard" else swarm_main(["dashboard", *argv])
    out, err = capsys.readouterr()
    assert rc == 2, out + err
    assert cli.READY_PREFIX not in out, out  # no ready line: nothing was served
    errors = [line for line in err.splitlines() if "error" in line]
    assert len(errors) == 1 and errors[0].startswith(f"{command}: error: "), err
    assert re.search(pattern, errors[0]), err
    assert "Traceback" not in err
    if (case, command) != ("truncated", "dashboard"):
        return
    with Procs() as procs:
        proc = procs.start([sys.executable, "-m", "dashboard", *argv])
        assert proc.wait(START_TIMEOUT_S) == 2, proc.output()
    assert proc.stdout == [], proc.output()
    errors = [line for line in proc.stderr if "error" in line]
    assert len(errors) == 1 and errors[0].startswith("dashboard: error: "), proc.output()
    assert re.search(pattern, errors[0]), proc.output()
    assert "Traceback" not in proc.output()
