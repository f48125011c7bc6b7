"""The Faults panel's pure part (dashboard.faults): panel inputs -> the Fault message, validated by the
message itself, errors naming the panel input, the wire field and the value. No server."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dashboard import panels
from dashboard.docking import DockingDrawer
from dashboard.faults import EVERY_CHASER, FAULT_INPUTS, FaultForm, fault_of, kind_hint, sent_text
from dashboard.landing import EVERY_UAV, LandingDrawer
from swarm.errors import ConfigError, MessageError
from swarm.missions import MISSIONS
from swarm.step.landing import LandingWorld
from swarm.transport.messages import FAULT_KINDS, Event, Fault, decode, encode

DOCKING = DockingDrawer.fault_menu(MISSIONS["docking"].fault_menu)
LANDING = LandingDrawer.fault_menu(MISSIONS["landing"].fault_menu)
"""The menus the dashboard offers: each mission's kinds in its drawer's words."""


def test_every_fault_kind_has_its_inputs() -> None:
    assert set(FAULT_INPUTS) == set(FAULT_KINDS)


def test_a_camera_loss_on_one_chaser_sends_only_its_fields() -> None:
    form = FaultForm("camera_loss", vehicle="chaser", duration_s=3.0, probability=7.0, delay_s=-1.0)
    msg = fault_of(form, DOCKING)
    assert (msg.kind, msg.vehicle, msg.duration_s, msg.start_s) == ("camera_loss", "chaser", 3.0, None)
    # the other kinds' inputs are not sent (a bad value there cannot refuse a camera loss)
    assert msg.probability is None and msg.delay_s is None and msg.rate_rad_s is None
    assert decode(encode(msg), Fault).vehicle == "chaser"


def test_uwb_faults_have_no_vehicle_and_every_chaser_means_none() -> None:
    assert fault_of(FaultForm("uwb_dropout", vehicle="chaser", duration_s=5.0), DOCKING).vehicle is None
    assert fault_of(FaultForm("camera_loss", vehicle=EVERY_CHASER), DOCKING).vehicle is None


def test_start_zero_means_at_once_and_a_later_start_is_kept() -> None:
    assert fault_of(FaultForm("uwb_dropout", start_s=0.0), DOCKING).start_s is None
    assert fault_of(FaultForm("uwb_dropout", start_s=12.5), DOCKING).start_s == 12.5


def test_the_gyro_step_is_converted_from_deg_s_to_rad_s() -> None:
    msg = fault_of(
        FaultForm("gyro_bias_step", vehicle="target", rate_deg_s=(1.0, 0.0, -2.0), duration_s=-1), DOCKING
    )
    assert msg.duration_s is None  # a gyro step lasts: its duration input is not sent
    np.testing.assert_allclose(msg.rate_rad_s, [math.pi / 180.0, 0.0, -math.pi / 90.0])


@pytest.mark.parametrize(
    ("form", "expected"),
    [
        (FaultForm("camera_loss", duration_s=-1.0), "duration [s] (duration_s): must be > 0, got -1.0"),
        (FaultForm("uwb_dropout", duration_s=0), "duration [s] (duration_s): must be > 0, got 0"),
        (FaultForm("uwb_dropout", start_s=-2.0), "start at t [s] (start_s): must be >= 0, got -2.0"),
        (
            FaultForm("nlos_burst", probability=1.5),
            "NLOS probability (probability): an nlos_burst needs one in (0, 1], got 1.5",
        ),
        (FaultForm("sensor_delay", delay_s=0.0), "max delay [s] (delay_s): must be > 0, got 0.0"),
        (FaultForm("camera_loss", duration_s=None), "duration [s] (duration_s): required for a camera_loss"),
        (FaultForm("gyro_bias_step", rate_deg_s=("a", 0, 0)), "gyro step [deg/s] (rate_rad_s): expected"),
        (FaultForm("camera_loss", vehicle="a b"), "vehicle (vehicle): must match"),
    ],
)
def test_a_bad_input_is_refused_naming_the_input_the_field_and_the_value(form, expected) -> None:
    with pytest.raises(ConfigError) as info:
        fault_of(form, DOCKING)
    assert str(info.value).startswith(expected), str(info.value)


def test_the_panel_refuses_exactly_what_the_message_refuses() -> None:
    """No second validator: for each bad value, the message built directly raises too, with the same
    reason after the field name."""
    for kind, field, value in (("camera_loss", "duration_s", -1.0), ("nlos_burst", "probability", 0.0)):
        kwargs = {"duration_s": 1.0, "probability": 0.5, field: value}
        with pytest.raises(MessageError) as direct:
            Fault(kind, **kwargs)
        form = FaultForm(kind, **kwargs)
        with pytest.raises(ConfigError) as panel:
            fault_of(form, DOCKING)
        direct_field, _, reason = str(direct.value).partition(": ")
        assert direct_field == field and str(panel.value).endswith(f"({field}): {reason}")


def test_the_sensor_delay_hint_says_a_lockstep_run_refuses_it() -> None:
    assert "Free-running clocks only" in kind_hint("sensor_delay", None, DOCKING)
    assert "This run is lockstep: the world will refuse it" in kind_hint("sensor_delay", "lockstep", DOCKING)
    assert "This run's clock: scaled:4" in kind_hint("sensor_delay", "scaled:4", DOCKING)
    assert "lockstep" not in kind_hint("camera_loss", "lockstep", DOCKING)


def test_the_sent_line_names_the_fault_and_warns_when_nobody_listens() -> None:
    msg = fault_of(FaultForm("camera_loss", vehicle="chaser", duration_s=3.0), DOCKING)
    assert sent_text(msg, True, "12:00:00", DOCKING).startswith(
        "sent **camera_loss** on chaser for 3 s at 12:00:00"
    )
    assert "nobody listens on control/fault" in sent_text(msg, False, "12:00:00", DOCKING)
    assert " on " not in sent_text(fault_of(FaultForm("uwb_dropout"), DOCKING), True, "12:00:00", DOCKING)


def test_the_landing_menu_offers_what_the_landing_world_models_each_on_one_uav_or_every_uav() -> None:
    assert tuple(LANDING.inputs) == LandingWorld.FAULTS and tuple(DOCKING.inputs) == FAULT_KINDS
    for kind in LandingWorld.FAULTS:
        one = fault_of(FaultForm(kind, vehicle="uav2", duration_s=2.0, probability=9.0), LANDING)
        # a landing UWB dropout is the named UAV's (docking's is the whole network's: no vehicle)
        assert (one.kind, one.vehicle, one.duration_s, one.probability) == (kind, "uav2", 2.0, None)
        assert fault_of(FaultForm(kind, vehicle=EVERY_UAV, duration_s=2.0), LANDING).vehicle is None
        assert LANDING.hints[kind] in kind_hint(kind, "lockstep", LANDING)
    assert (
        fault_of(FaultForm("uwb_dropout", vehicle="uav2", duration_s=2.0), DOCKING).vehicle is None
    )  # docking's


def test_a_kind_the_world_does_not_take_is_refused_naming_what_it_takes() -> None:
    with pytest.raises(
        ConfigError, match=r"kind: this world takes camera_loss, uwb_dropout, got 'nlos_burst'"
    ):
        fault_of(FaultForm("nlos_burst", duration_s=1.0, probability=0.5), LANDING)
    with pytest.raises(ConfigError, match="got 'meteor'"):
        fault_of(FaultForm("meteor"), DOCKING)


def test_a_landing_uwb_dropout_is_worded_as_the_uavs_it_names_not_the_network() -> None:
    msg = fault_of(FaultForm("uwb_dropout", vehicle="uav3", duration_s=1.5), LANDING)
    assert sent_text(msg, True, "12:00:00", LANDING).startswith("sent **uwb_dropout** on uav3 for 1.5 s")
    assert sent_text(msg, True, "12:00:00", LANDING).endswith("the world lists it below once applied")
    every = fault_of(FaultForm("camera_loss", vehicle=EVERY_UAV, duration_s=1.0), LANDING)
    assert " on every UAV for 1 s" in sent_text(every, True, "12:00:00", LANDING)
    applied = Event(1.0, "fault", {"kind": "uwb_dropout", "start_s": 1.0, "duration_s": 1.5,
                                   "vehicles": ["uav3"]})  # fmt: skip
    listed = panels.faults_markdown([("world", applied)], uwb_network=False)
    assert "uwb_dropout** applied by the world on uav3 from t = 1.00 s for 1.5 s" in listed
    assert "on the UWB network" in panels.faults_markdown([("world", applied)])  # docking's wording
    assert "applied by the world on uav3" in panels.events_markdown([("world", applied)], uwb_network=False)
