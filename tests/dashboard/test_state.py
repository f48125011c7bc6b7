"""The dashboard's store and pacing (dashboard.state): bounded trails and series, rate limiting, frame
pacing, new-run detection, liveliness and the thread-safe SwarmState. No server."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from dashboard.state import (
    FramePacer,
    RateLimiter,
    Series,
    SwarmState,
    Trail,
    is_new_run,
)
from swarm.transport.messages import Clock, Estimate, Event, Guidance, Truth, Vision

VEHICLES = {"chaser": ("chaser", "target"), "target": ("target", None)}
ANCHORS = np.array([[1, -0.2, 0.5], [1, 0.2, -0.5], [-1, 0.2, -0.5], [-1, -0.2, 0.5]])


def _truth(tick: int, p=(0.0, 0.0, 0.0)) -> Truth:
    zero = np.zeros(3)
    return Truth(tick=tick, t_s=0.01 * tick, p_nav=p, v_nav=zero, q_nav_body=[0, 0, 0, 1], w_body=zero)


def _estimate(tick: int, p=(0.0, 0.0, 0.0)) -> Estimate:
    return Estimate(
        tick=tick, t_s=0.01 * tick, p_nav=p, v_nav=np.zeros(3), q_nav_body=[0, 0, 0, 1], cov=np.eye(9) * 1e-4,
        sigma_pos_max_m=0.01, mahalanobis_d=0.5, rejection_fraction=0.0, counts={},
    )  # fmt: skip


def _guidance(tick: int, mode: str, r: float = 0.5) -> Guidance:
    return Guidance(tick=tick, t_s=0.01 * tick, mode=mode, range_m=r, r1_m=0.1, r2_m=0.3, r_t_m=1.0)


def _clock(tick: int, seed: int = 1, state: str = "running") -> Clock:
    return Clock(tick=tick, t_s=0.01 * tick, state=state, seed=seed)


# ------------------------------------------------------------------------------------------ trails


def test_trail_end_follows_the_vehicle_until_a_spacing_away() -> None:
    trail = Trail(cap=10, min_step_m=0.01)
    for x in (0.0, 0.004, 0.008, 0.012, 0.016):
        trail.add([x, 0, 0])
    assert trail.points()[:, 0].tolist() == [0.0, 0.012, 0.016]  # 0.004 and 0.008 were the moving end


def test_a_vehicle_at_rest_does_not_change_its_trail() -> None:
    trail = Trail(cap=10, min_step_m=0.01)
    trail.add([1.0, 2.0, 3.0])
    version = trail.version
    assert not trail.add([1.0, 2.0, 3.0])
    assert trail.version == version


def test_trail_over_an_hour_stays_within_its_cap_and_spans_the_whole_run() -> None:
    cap = 500
    trail = Trail(cap=cap, min_step_m=0.001)
    n = 360_000  # one hour at 100 Hz, moving 1 mm per sample
    x = np.arange(n) * 0.001
    for xi in x:
        trail.add([xi, 0.0, 0.0])
        assert len(trail) <= cap
    pts = trail.points()
    assert pts[-1, 0] == x[-1]  # the newest point is always kept
    assert pts[0, 0] <= 2 * trail.min_step_m  # the start of the run is still drawn
    steps = np.diff(pts[:-1, 0])  # the end point moves with the vehicle: not spaced yet
    assert steps.min() >= trail.min_step_m / 2 - 1e-12  # uniform density after the thinnings


def test_trail_clear_restores_its_spacing_and_bumps_its_version() -> None:
    trail = Trail(cap=4, min_step_m=0.01)
    for i in range(10):
        trail.add([i, 0, 0])
    version = trail.version
    trail.clear()
    assert len(trail) == 0 and trail.min_step_m == 0.01 and trail.version > version


def test_trail_refuses_a_tiny_cap() -> None:
    with pytest.raises(ValueError, match="cap"):
        Trail(cap=2)


def test_series_thins_like_a_trail_and_keeps_the_latest_sample() -> None:
    series = Series(2, cap=50, min_dt_s=0.01)
    for k in range(10_000):
        series.add(0.01 * k, (k, None))
        assert len(series) <= 50
    t, v = series.arrays()
    assert t[-1] == pytest.approx(99.99) and v[-1, 0] == 9999
    assert np.isnan(v[:, 1]).all()  # None is a gap


def test_series_restarts_when_time_goes_back() -> None:
    series = Series(1, cap=10, min_dt_s=0.0)
    series.add(5.0, (1,))
    series.add(6.0, (1,))
    series.add(0.0, (2,))
    t, _ = series.arrays()
    assert t.tolist() == [0.0]


# ------------------------------------------------------------------------------------------ pacing


def test_rate_limiter_allows_one_call_per_period() -> None:
    now = [0.0]
    limiter = RateLimiter(10.0, lambda: now[0])
    assert limiter.due()
    now[0] = 0.05
    assert not limiter.due()
    now[0] = 0.1
    assert limiter.due()


def test_light_frames_are_paced_to_the_maximum_rate() -> None:
    pacer = FramePacer(max_hz=30.0, max_busy=0.5)
    assert pacer.delay(0.003) == pytest.approx(1 / 30 - 0.003)
    assert 1.0 / (0.003 + pacer.delay(0.003)) == pytest.approx(30.0)


def test_heavy_frames_lower_the_rate_to_keep_the_busy_share() -> None:
    pacer = FramePacer(max_hz=30.0, max_busy=0.5)
    frame = 0.04  # 40 ms of work: at most 50 % of a core means a 40 ms rest, 12.5 Hz
    assert frame / (frame + pacer.delay(frame)) == pytest.approx(0.5)


def test_new_run_on_another_seed_or_a_tick_going_back() -> None:
    assert not is_new_run(None, _clock(5))
    assert not is_new_run(_clock(5), _clock(6))
    assert is_new_run(_clock(5), _clock(6, seed=2))
    assert is_new_run(_clock(5), _clock(0))


# ------------------------------------------------------------------------------------------ the store


def test_store_starts_with_the_scenario_vehicles() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    snap = state.snapshot()
    assert set(snap.agents) == {"chaser", "target"}
    assert snap.agents["chaser"].role == "chaser" and snap.agents["chaser"].target == "target"
    assert snap.anchors[0] == (0, 1, 2, 3)
    assert sorted(state.take_new_agents()) == ["chaser", "target"]
    assert state.take_new_agents() == []


def test_a_new_run_clears_what_the_previous_run_drew() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    state.on_clock(_clock(0))
    for k in range(20):
        state.on_truth("chaser", _truth(k, (0.01 * k, 0, 0)))
        state.on_guidance("chaser", _guidance(k, "APPROACH"))
    assert state.on_clock(_clock(0, seed=2))
    snap = state.snapshot()
    chaser = snap.agents["chaser"]
    assert snap.run == 1
    assert chaser.truth is None and chaser.modes == () and len(chaser.truth_trail) == 0


def test_truth_going_back_in_time_restarts_the_trail() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    for k in range(10):
        state.on_truth("chaser", _truth(100 + k, (0.01 * k, 0, 0)))
    state.on_truth("chaser", _truth(0, (5.0, 0, 0)))
    assert state.snapshot().agents["chaser"].truth_trail.tolist() == [[5.0, 0.0, 0.0]]


def test_mode_timeline_takes_each_change_once_from_events_and_guidance() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    state.on_guidance("chaser", _guidance(1, "APPROACH"))
    data = {"from": "APPROACH", "to": "REORIENT", "t_s": 0.02, "range_m": 0.7, "reason": "A11 <= 0.4"}
    state.on_event("chaser", Event(t_s=0.02, kind="mode", data=data))
    state.on_guidance("chaser", _guidance(3, "REORIENT"))
    state.on_guidance("chaser", _guidance(4, "REORIENT"))
    modes = state.snapshot().agents["chaser"].modes
    assert [m[1] for m in modes] == ["APPROACH", "REORIENT"]
    assert modes[1][2] == 0.7 and modes[1][3] == "A11 <= 0.4"


def test_liveliness_goes_alive_then_lost() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    assert state.snapshot().agents["chaser"].alive == "unseen"
    assert state.on_liveliness("agent", "chaser", True) == "alive"
    assert state.on_liveliness("agent", "chaser", True) is None  # no change
    assert state.on_liveliness("agent", "chaser", False) == "lost"
    snap = state.snapshot()
    assert snap.agents["chaser"].alive == "lost" and snap.processes[("agent", "chaser")] == "lost"


def test_a_loss_of_a_never_seen_process_is_ignored() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    assert state.on_liveliness("world", "world", False) is None
    assert state.snapshot().processes == {}


def test_an_agent_outside_the_scenario_appears_with_an_unknown_role() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    state.take_new_agents()
    state.on_liveliness("agent", "stranger", True)
    assert state.take_new_agents() == ["stranger"]
    assert state.snapshot().agents["stranger"].role == "?"


def test_invented_agent_ids_cannot_grow_the_store_without_bound() -> None:
    state = SwarmState(VEHICLES, ANCHORS, max_agents=8)
    for i in range(100):
        state.on_liveliness("agent", f"ghost{i}", True)
    assert len(state.snapshot().agents) == 8


def test_snapshot_copies_a_trail_only_when_it_changed() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    state.on_truth("chaser", _truth(1))
    first = state.snapshot()
    drawn = {k: a.trail_versions for k, a in first.agents.items()}
    assert first.agents["chaser"].truth_trail is not None
    assert state.snapshot(drawn).agents["chaser"].truth_trail is None
    state.on_truth("chaser", _truth(2, (0.1, 0, 0)))
    assert state.snapshot(drawn).agents["chaser"].truth_trail is not None


def test_writers_on_several_threads_and_a_reader_never_see_a_torn_state() -> None:
    state = SwarmState(VEHICLES, ANCHORS, trail_cap=16)
    errors: list[BaseException] = []
    stop = threading.Event()

    def write(agent: str) -> None:
        try:
            for k in range(1000):
                state.on_truth(agent, _truth(k, (0.01 * k, 0, 0)))
                state.on_estimate(agent, _estimate(k, (0.01 * k, 0, 0)))
        except BaseException as exc:
            errors.append(exc)

    def read() -> None:
        try:
            while not stop.is_set():
                for a in state.snapshot().agents.values():
                    if a.truth_trail is not None:
                        assert len(a.truth_trail) <= 16
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=write, args=(a,)) for a in VEHICLES]
    reader = threading.Thread(target=read)
    reader.start()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    stop.set()
    reader.join()
    assert errors == []
    assert state.snapshot().agents["target"].truth.tick == 999


def test_run_events_go_to_the_event_log_faults_also_to_the_fault_log_and_run_start_names_the_clock() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    assert state.snapshot().clock_mode is None
    state.on_run_event("world", Event(t_s=0.0, kind="run_start", data={"seed": 1, "clock": "lockstep"}))
    fault = Event(t_s=2.0, kind="fault", data={"kind": "uwb_dropout", "start_s": 2.01, "duration_s": 5.0})
    state.on_run_event("mothership", fault)
    refused = Event(t_s=3.0, kind="fault_refused", data={"kind": "sensor_delay", "reason": "lockstep"})
    state.on_run_event("world", refused)
    snap = state.snapshot()
    assert snap.clock_mode == "lockstep"
    assert [(s, e.kind) for s, e in snap.events] == [
        ("world", "run_start"),
        ("mothership", "fault"),
        ("world", "fault_refused"),
    ]
    assert snap.faults == (("mothership", fault), ("world", refused)) and snap.faults_version == 2


def test_only_a_camera_frame_with_markers_counts_as_seen() -> None:
    """A camera reports every frame, with zero markers when the target is not seen: the chaser's cone must
    not turn green for those."""
    state = SwarmState(VEHICLES, ANCHORS)
    empty = Vision(tick=5, t_s=0.05, target_id="target", face="+x", kind="features", data=np.zeros((0, 3)),
                   marker_ids=())  # fmt: skip
    state.on_vision("chaser", empty)
    assert state.snapshot().agents["chaser"].vision_t_s is None
    seen = Vision(tick=10, t_s=0.1, target_id="target", face="+x", kind="features", data=np.zeros((1, 3)),
                  marker_ids=(0,))  # fmt: skip
    state.on_vision("chaser", seen)
    state.on_vision("chaser", Vision(11, 0.11, "target", "+x", "features", np.zeros((0, 3)), ()))
    assert state.snapshot().agents["chaser"].vision_t_s == 0.1
