"""``swarm launch``'s automatic layout (``swarm.cli.launch_plan``): the rule of
:func:`~swarm.cli.launch_plan.auto_launch_plan` and how the launcher's explicit flags keep their parts."""

from __future__ import annotations

import logging

import pytest

from swarm.cli.launch_plan import (
    HOST_MAX_VEHICLES,
    PROCESS_EACH_PER_CORE,
    auto_launch_plan,
    available_cores,
    given_keys,
    resolve_plan,
)
from swarm.errors import ConfigError


@pytest.mark.parametrize(
    ("vehicles", "cores", "per_process", "hosts"),
    [
        (2, 2, 1, 2),  # a pair: a process each, as before the plan
        (8, 2, 1, 8),  # PROCESS_EACH_PER_CORE vehicles per core: still a process each
        (10, 2, 3, 4),  # one more pair: two hosts per core, the last the rest (3 + 3 + 3 + 1)
        (32, 2, 8, 4),  # the swarm: four hosts of 8
        (128, 2, 32, 4),
        (128, 1, 64, 2),  # one core: two hosts of HOST_MAX_VEHICLES (not 64 + 64 over two cores' 4)
        (200, 1, 50, 4),  # two hosts would take 100 each, over HOST_MAX_VEHICLES: four
        (34, 4, 5, 7),  # 8 hosts of ceil(34 / 8) = 5 vehicles are 7 processes (5 x 6 + 4)
        (32, 8, 1, 32),  # 4 vehicles per core on 8 cores: a process each
        (40, 8, 3, 14),  # 16 hosts of ceil(40 / 16) = 3 vehicles are 14 processes
    ],
)  # fmt: skip
def test_a_process_each_up_to_four_vehicles_per_core_then_two_hosts_per_core(vehicles, cores, per_process,
                                                                             hosts):  # fmt: skip
    plan = auto_launch_plan(vehicles, cores)
    assert (plan.vehicles_per_process, plan.agent_processes) == (per_process, hosts)
    assert plan.vehicles_per_process <= HOST_MAX_VEHICLES
    assert plan.chosen == ("hosts", "stagger", "wake")


def test_free_running_hosts_stagger_and_a_small_swarm_of_processes_keeps_its_phases_and_imu_wake():
    small = auto_launch_plan(PROCESS_EACH_PER_CORE * 2, 2)
    assert not small.stagger_control and not small.wake_at_control  # today's children, unchanged
    big = auto_launch_plan(32, 2)
    assert big.stagger_control and not big.wake_at_control  # a host ignores the wake policy: left off


def test_lockstep_takes_the_hosts_but_never_staggers_so_it_still_equals_swarm_sim():
    plan = auto_launch_plan(32, 2, free_running=False)
    assert plan.vehicles_per_process == 8
    assert not plan.stagger_control and not plan.wake_at_control


def test_a_crowded_swarm_of_processes_of_one_staggers_and_wakes_at_its_control_rate():
    # --secure (a host would need every hosted vehicle's identity) or the user's --vehicles-per-process 1
    for plan in (auto_launch_plan(32, 2, secure=True), auto_launch_plan(32, 2, vehicles_per_process=1)):
        assert plan.vehicles_per_process == 1
        assert plan.stagger_control and plan.wake_at_control
    assert auto_launch_plan(32, 2, vehicles_per_process=1).chosen == ("stagger", "wake")
    assert auto_launch_plan(32, 2, secure=True).chosen == ("hosts", "stagger", "wake")
    # ... and not in lockstep, nor for a small one
    assert not auto_launch_plan(32, 2, secure=True, free_running=False).wake_at_control
    assert not auto_launch_plan(8, 2, vehicles_per_process=1).wake_at_control


def test_the_users_hosts_are_kept_and_a_host_of_several_staggers():
    plan = auto_launch_plan(4, 2, vehicles_per_process=2)
    assert (plan.vehicles_per_process, plan.agent_processes) == (2, 2)
    assert plan.stagger_control and not plan.wake_at_control


@pytest.mark.parametrize(("vehicles", "cores"), [(0, 2), (2, 0), (True, 2), (2.0, 2), (2, None)])
def test_a_plan_for_no_vehicles_or_no_cores_is_refused_naming_the_value(vehicles, cores):
    with pytest.raises(ConfigError, match=rf"got {vehicles!r}|got {cores!r}"):
        auto_launch_plan(vehicles, cores)


@pytest.mark.parametrize("per_process", [0, HOST_MAX_VEHICLES + 1])
def test_the_users_hosts_out_of_bounds_are_refused_as_the_flag(per_process):
    with pytest.raises(
        ConfigError, match=rf"--vehicles-per-process must be an integer in 1\.\.64, got {per_process}"
    ):
        auto_launch_plan(8, 2, vehicles_per_process=per_process)


def test_the_cores_are_those_this_process_may_run_on(monkeypatch):
    import os

    monkeypatch.setattr(os, "sched_getaffinity", lambda _pid: {0, 3, 5}, raising=False)
    assert available_cores() == 3  # a taskset, not the machine's 8
    monkeypatch.delattr(os, "sched_getaffinity", raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: None)
    assert available_cores() == 1


def test_set_keys_are_named_dotted_or_in_a_table():
    assert given_keys(["swarm.stagger_control=false", "uwb.sigma_m=0.1"]) >= {"swarm.stagger_control",
                                                                             "uwb.sigma_m"}  # fmt: skip
    assert "agent.wake_at_control" in given_keys(["agent={wake_at_control=true, late_fusion_s=0.02}"])
    assert "agent.wake_at_control" not in given_keys(["agent.late_fusion_s=0.02"])


def test_each_explicit_flag_keeps_its_part_and_the_plan_fills_the_rest():
    # nothing given: the plan's hosts, and its stagger as an override for the children
    plan, extra = resolve_plan(32, False, None, [], n_cores=2)
    assert (plan.vehicles_per_process, extra) == (8, ["swarm.stagger_control=true"])
    # --set swarm.stagger_control=false: kept, nothing added; the hosts still the plan's
    plan, extra = resolve_plan(32, False, None, ["swarm.stagger_control=false"], n_cores=2)
    assert (plan.vehicles_per_process, plan.stagger_control, extra) == (8, False, [])
    assert plan.chosen == ("hosts", "wake")
    # --vehicles-per-process 1 and a wake given in a table: the stagger alone is the plan's
    plan, extra = resolve_plan(32, False, 1, ["agent={wake_at_control=false}"], n_cores=2)
    assert (plan.vehicles_per_process, plan.wake_at_control) == (1, False)
    assert extra == ["swarm.stagger_control=true"]
    assert plan.chosen == ("stagger",)
    # a small swarm, or lockstep: no override at all (the children's flags as before the plan)
    assert resolve_plan(4, False, None, [], n_cores=2)[1] == []
    assert resolve_plan(32, True, None, [], n_cores=2)[1] == []


def test_the_launcher_logs_its_plan_and_runs_the_children_it_says(caplog, tmp_path):
    """``swarm launch`` resolves the plan before any child starts: the agent processes it will start
    (``_hosts``) are the plan's, the world and mothership send batches to its hosts, and the plan's line
    is logged."""
    from swarm.cli.launch import _hosts
    from swarm.cli.launch_missions import plan as _plan
    from swarm.cli.launch_missions import world_args
    from swarm.cli.main import build_parser
    from swarm.transport.process import scenario_from

    args = build_parser().parse_args(["launch", "docking", "--agents", "16", "--clock", "realtime"])
    args.checkpoint_dir = tmp_path
    sc = scenario_from(args)
    with caplog.at_level(logging.INFO, logger="swarm.launch"):
        plan = _plan(args, sc)
    cores = available_cores()
    want = auto_launch_plan(32, cores)
    assert args.vehicles_per_process == want.vehicles_per_process
    assert len(_hosts(args, scenario_from(args).vehicles)) == want.agent_processes
    assert ("--batch" in world_args(args)) == (want.vehicles_per_process > 1)
    assert ("swarm.stagger_control=true" in args.overrides) == want.stagger_control == (plan is not None)
    assert args.launch_plan["agent_processes"] == want.agent_processes
    assert f"launch plan: 32 vehicles on {cores} cores" in caplog.text
    # the staggered phases reach the launcher's own scenario too (vehicle m controls on tick m % 10)
    if want.stagger_control:
        phases = [v.control_phase for v in scenario_from(args).vehicles.values()]
        assert phases[:12] == [m % 10 for m in range(12)]
