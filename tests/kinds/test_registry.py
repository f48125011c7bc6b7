"""The vehicle-kind registry as docs/architecture.md's recipe "Adding a kind" describes it: every entry of
``KINDS`` gives what the recipe lists, the compiled dispatch flies the kinds the docking runners accept,
and the quadrotor, registered, builds the landing stack's arrays exactly as before."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from swarm.kinds import KINDS, KindsParams, check_docking_kind
from swarm.kinds._dispatch import hold_step, truth_step
from swarm.kinds.base import Mounts, VehicleDispersion
from swarm.kinds.quadrotor import QuadrotorKind, QuadrotorParams, control_row, truth_row
from swarm.landing_scenario import LandingScenario
from swarm.scenario import load_scenario


def test_three_kinds_with_distinct_codes_and_one_kinds_table_each():
    assert sorted(KINDS) == ["cubesat", "ground", "quadrotor"]
    assert len({k.code for k in KINDS.values()}) == 3
    assert [f.name for f in dataclasses.fields(KindsParams)] == list(KINDS)


@pytest.mark.parametrize("name", sorted(KINDS))
def test_each_kind_gives_what_the_recipe_lists(name):
    """Step 1 of the recipe: the class attributes, the bound properties and the arrays of the sizes it
    declares (a kind whose ``truth()`` or ``control_row()`` disagreed with its ``KP_N``/``CP_N`` would read
    past its row in the compiled steps)."""
    cls = KINDS[name]
    kind = cls(cls.Params(), load_scenario("docking"))
    assert kind.name == name and isinstance(kind.mounts, Mounts) and kind.mass_kg > 0
    assert kind.control_rate_hz > 0 and kind.control_rate_field.startswith(f"kinds.{name}.")
    assert {"gyro"} <= kind.imu_measures <= {"gyro", "accelerometer"}
    assert kind.effort_key and kind.effort_unit and kind.effort_label and kind.target_effort_key
    truth = kind.truth(VehicleDispersion())
    assert truth.kp.shape == (cls.KP_N,) and truth.s0.shape == (cls.S_N,) and truth.code == cls.code
    assert kind.control_row().shape == (cls.CP_N,)
    q = kind.q_target_chaser_docked("+x")
    assert np.linalg.norm(q) == pytest.approx(1.0)


@pytest.mark.parametrize("name", sorted(KINDS))
def test_a_kind_the_docking_runners_accept_has_its_dispatch_branches(name):
    """Step 3: a kind without ``docking_missing`` is flown by the compiled dispatch: holding a non-zero
    command changes its actuators and a tick under it moves the truth row or spends effort. A kind with
    ``docking_missing`` is refused by the scenario instead (the dispatch's fall-through returns 0)."""
    cls = KINDS[name]
    kind = cls(cls.Params(), load_scenario("docking"))
    tr = kind.truth(VehicleDispersion())
    s, held = tr.s0.copy(), np.zeros(max(cls.U_N, 1))
    x = np.zeros(13)
    x[9] = 1.0
    x0 = x.copy()
    changed = hold_step(cls.code, np.full(cls.U_N, 0.05), s, held, tr.kp)
    effort = truth_step(cls.code, x, s, held, tr.kp, 0.01)
    flown = changed and (effort > 0 or not np.array_equal(x, x0))
    if cls.docking_missing is None:
        assert flown
        check_docking_kind("v", name)
    else:
        assert not flown  # no branch yet: the refusal below is what keeps it out of the docking tick
        with pytest.raises(Exception, match=r"vehicles\.v\.kind = 'quadrotor': the docking runners cannot"):
            check_docking_kind("v", name)


def test_the_registered_quadrotor_builds_the_landing_arrays_of_the_direct_calls():
    """The landing stack takes its truth and controller rows from the registered kind: the same bits as
    the functions it called before."""
    p = QuadrotorParams()
    kind = KINDS["quadrotor"](p, LandingScenario())
    assert np.array_equal(kind.truth(VehicleDispersion()).kp, truth_row(p.airframe))
    assert np.array_equal(kind.control_row(), control_row(p))
    assert LandingScenario().kinds.quadrotor == p


def test_the_quadrotor_mounts_are_where_the_landing_scenario_puts_its_sensors():
    sc = LandingScenario()
    m = KINDS["quadrotor"](sc.kinds.quadrotor, sc).mounts
    assert m.tag_lever_arm_body_m == tuple(sc.uwb.lever_arm_m)
    assert m.camera_pos_body_m == tuple(sc.camera.pos_body_m)
    np.testing.assert_allclose(m.camera_axis_body, [0.0, 0.0, -1.0], atol=1e-15)  # looking down
    assert QuadrotorKind.imu_measures == {"gyro", "accelerometer"}
