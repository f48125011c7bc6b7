"""Text and plot data of the dashboard's panels (dashboard.panels), from a store snapshot. No server."""

from __future__ import annotations

import numpy as np

from dashboard import docking, panels
from dashboard.state import SwarmState
from swarm.core.mdp import DECISION_KEYS
from swarm.transport.messages import Clock, Estimate, Event, Guidance

VEHICLES = {"chaser": ("chaser", "target"), "target": ("target", None)}
ANCHORS = np.zeros((4, 3))


def _estimate(counts: dict[str, int], fraction: float = 0.25) -> Estimate:
    return Estimate(
        tick=3, t_s=0.03, p_nav=np.zeros(3), v_nav=np.zeros(3), q_nav_body=[0, 0, 0, 1], cov=np.eye(9) * 1e-4,
        sigma_pos_max_m=0.0123, mahalanobis_d=0.5, rejection_fraction=fraction, counts=counts,
    )  # fmt: skip


def _decision(**values: float | None) -> dict:
    d = dict.fromkeys(DECISION_KEYS, 0.5)
    d.update(A11=None, pi1=None, pi2=None)
    d.update(values)
    return d


def _table_row(table: str, agent: str) -> str:
    return next(line for line in table.splitlines() if line.startswith(f"| {agent} |"))


def test_table_has_a_row_per_agent_with_role_mode_range_sigma_and_process() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    state.on_guidance("chaser", Guidance(tick=3, t_s=0.03, mode="REORIENT", range_m=0.512))
    counts = {"range_accepted": 90, "range_rejected": 7, "features_rejected": 3}
    state.on_estimate("chaser", _estimate(counts))
    state.on_liveliness("agent", "chaser", True)
    state.on_liveliness("agent", "target", True)
    state.on_liveliness("agent", "target", False)
    table = docking.agents_table(state.snapshot())
    assert _table_row(table, "chaser") == "| chaser | chaser | REORIENT | 0.512 | 1.23 | 10 (25 %) | alive |"
    assert _table_row(table, "target") == "| target | target | – | – | – | – | lost |"


def test_status_names_run_state_tick_seed_processes_and_drops() -> None:
    state = SwarmState(VEHICLES, ANCHORS)
    state.on_clock(Clock(tick=1234, t_s=12.34, state="paused", seed=7))
    state.on_liveliness("world", "world", True)
    text = panels.status_markdown(state.snapshot(), dropped=5)
    assert "**paused** · tick 1234 · t = 12.34 s · seed 7" in text
    assert "world alive · mothership unseen · dropped messages 5" in text


def test_decision_panel_shows_the_probabilities_of_the_latest_pass() -> None:
    d = _decision(A22=0.514, A23=0.486, A32=0.417, A33=0.583, pi1=0.462, pi2=0.538, r2_m=0.7, r1_m=0.45)
    g = Guidance(tick=1, t_s=25.65, mode="ALIGN", range_m=0.45, r1_m=0.45, r2_m=0.7, r_t_m=1.0, decision=d)
    text = docking.decision_markdown("chaser", g)
    assert "| 2 | – | 0.514 | 0.486 |" in text
    assert "| 3 | – | 0.417 | 0.583 |" in text
    assert "| 1 | – | – | – |" in text  # A11 was not computed in this branch of Algorithm 1
    assert "π1 = 0.462 · π2 = 0.538" in text
    assert "r2 = 0.700 m, r1 = 0.450 m" in text


def test_decision_panel_without_a_pass_says_so() -> None:
    g = Guidance(tick=1, t_s=1.0, mode="APPROACH", range_m=1.5)
    assert "no Algorithm 1 pass yet" in docking.decision_markdown("chaser", g)
    assert "no guidance yet" in docking.decision_markdown("chaser", None)


def test_mode_steps_hold_each_mode_until_the_next_change() -> None:
    modes = [(0.0, "APPROACH", 1.7, ""), (10.0, "REORIENT", 0.7, ""), (15.0, "ALIGN", 0.45, "")]
    t, level = panels.mode_steps(modes, t_end_s=20.0)
    assert t.tolist() == [0.0, 10.0, 10.0, 15.0, 15.0, 20.0]
    assert level.tolist() == [1, 1, 2, 2, 3, 3]


def test_mode_steps_of_no_modes_is_a_gap() -> None:
    t, level = panels.mode_steps([], None)
    assert len(t) == len(level) == 1 and np.isnan(level[0])


def test_modes_and_events_are_listed_newest_first() -> None:
    modes = [(0.0, "APPROACH", 1.7, ""), (10.0, "REORIENT", 0.7, "")]
    assert panels.modes_markdown(modes).splitlines()[0] == "- t = 10.00 s · **REORIENT** · r = 0.700 m"
    events = [
        ("chaser", Event(t_s=1.0, kind="mode", data={"from": "APPROACH", "to": "REORIENT", "range_m": 0.7})),
        ("chaser", Event(t_s=2.0, kind="contact", data={})),
    ]
    lines = panels.events_markdown(events).splitlines()
    assert lines[0] == "- t = 2.00 s · chaser · contact"
    assert lines[1] == "- t = 1.00 s · chaser · mode APPROACH → REORIENT at r = 0.700 m"


def test_missing_numbers_are_dashes() -> None:
    assert panels.fmt(None) == "–" and panels.fmt(float("nan")) == "–"
    assert panels.fmt(0.01234, 2, 100.0, " cm") == "1.23 cm"


def test_agents_are_listed_in_natural_order() -> None:
    vehicles = {f"chaser{i}": ("chaser", f"target{i}") for i in (10, 2, 1)}
    table = docking.agents_table(SwarmState(vehicles, ANCHORS).snapshot())
    assert [line.split(" | ")[0][2:] for line in table.splitlines()[2:]] == ["chaser1", "chaser2", "chaser10"]


def test_faults_applied_and_refused_are_listed_newest_first_with_who_and_when() -> None:
    applied = Event(
        t_s=3.2,
        kind="fault",
        data={"kind": "camera_loss", "start_s": 3.21, "duration_s": 3.0, "vehicles": ["chaser"]},
    )
    uwb = Event(t_s=4.0, kind="fault", data={"kind": "uwb_dropout", "start_s": 4.01, "duration_s": 5.0})
    gyro = Event(
        t_s=4.5, kind="fault", data={"kind": "gyro_bias_step", "start_s": 4.51, "vehicles": ["target"]}
    )
    refused = Event(
        t_s=5.0,
        kind="fault_refused",
        data={"kind": "sensor_delay", "vehicle": None, "reason": "needs a free-running clock"},
    )
    faults = [("world", applied), ("world", uwb), ("world", gyro), ("world", refused)]
    lines = panels.faults_markdown(faults).splitlines()
    assert lines == [
        "- t = 5.00 s · **sensor_delay refused** by the world: needs a free-running clock",
        "- t = 4.50 s · **gyro_bias_step** applied by the world on target from t = 4.51 s (lasts)",
        "- t = 4.00 s · **uwb_dropout** applied by the world on the UWB network from t = 4.01 s for 5 s",
        "- t = 3.20 s · **camera_loss** applied by the world on chaser from t = 3.21 s for 3 s",
    ]
    assert panels.faults_markdown([]) == "no fault applied yet"
    # the event log says the same, without the emphasis
    assert panels.events_markdown([("world", refused)]) == (
        "- t = 5.00 s · sensor_delay refused by the world: needs a free-running clock"
    )


def test_a_fault_event_with_odd_data_still_gives_a_line() -> None:
    odd = Event(t_s=1.0, kind="fault", data={"kind": 7, "start_s": "soon", "vehicles": "x|y"})
    assert (
        panels.faults_markdown([("world", odd)])
        == "- t = 1.00 s · **7** applied by the world on x\\|y (lasts)"
    )
