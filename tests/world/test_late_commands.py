"""A free-running world counts the vehicle-ticks it steps without that tick's command (late commands,
``run_end``'s ``late_commands``, the late ticks of ``swarm bench swarm``).

Oracle: the rule written out per case: a vehicle counts once its agent has commanded, until its run is
done; its tick ``k`` is late unless the newest command the world holds for it at that step is ``command(k)``.
"""

from __future__ import annotations

import threading

import numpy as np

from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.messages import Command
from swarm.transport.process import ClockSpec
from swarm.world.process import WorldProcess


def _cmd(k: int) -> Command:
    return Command(tick=k, t_s=0.01 * k, actuators=np.zeros(8), force_body_n=np.zeros(3),
                   torque_body_nm=np.zeros(3), mode="HOLD")  # fmt: skip


def test_late_commands_are_the_vehicle_ticks_stepped_without_their_command(tmp_path):
    sc, free = load_scenario("docking"), ClockSpec("realtime")
    wp = WorldProcess(sc, 0, None, Keys("late"), free, threading.Event(), checkpoint_dir=tmp_path)
    wp._count_late(0, {})  # nobody has commanded yet: nothing counted
    assert (wp.late_commands, wp.commanded_ticks) == (0, 0)
    wp._count_late(1, {"chaser": _cmd(1)})  # the chaser on time; the target not commanding yet
    assert (wp.late_commands, wp.commanded_ticks) == (0, 1)
    wp._count_late(2, {"chaser": _cmd(1), "target": _cmd(2)})  # the chaser's command(2) came too late
    assert (wp.late_commands, wp.commanded_ticks) == (1, 3)
    wp._count_late(3, {"target": _cmd(3)})  # nothing from the chaser: it holds command(1), late
    assert (wp.late_commands, wp.commanded_ticks) == (2, 5)
    wp.referee.done[list(wp.referee.chasers).index("chaser")] = True  # docked: not stepped on commands
    wp._count_late(4, {})
    assert (wp.late_commands, wp.commanded_ticks) == (3, 6)  # the target only
