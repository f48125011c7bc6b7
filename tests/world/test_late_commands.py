"""A free-running world counts the vehicle-ticks it steps with an out-of-date command (late ticks,
``run_end``'s ``late_commands``) and the control ticks' commands that were not in by their tick (late
commands, ``late_control_commands``): the two late shares of ``swarm bench swarm``.

Oracle: the rule written out per case. An agent commands on its control ticks (``k % 10 == 0`` in the
docking scenario) and the world holds the command in between. A vehicle counts once its agent has
commanded, until its run is done; its tick ``k`` is late unless the newest command the world holds for it
is of its last control tick ``<= k``; on a control tick, its command is due, and late if not in.
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


def _counts(wp) -> tuple[int, int, int, int]:
    return wp.late_commands, wp.commanded_ticks, wp.late_due_commands, wp.due_commands


def test_late_ticks_and_late_commands_follow_the_control_ticks(tmp_path):
    sc, free = load_scenario("docking"), ClockSpec("realtime")
    assert sc.control_every("chaser") == sc.control_every("target") == 10  # the oracle's control ticks
    wp = WorldProcess(sc, 0, None, Keys("late"), free, threading.Event(), checkpoint_dir=tmp_path)
    wp._count_late(0, {})  # nobody has commanded yet: nothing counted
    assert _counts(wp) == (0, 0, 0, 0)
    wp._count_late(0, {"chaser": _cmd(0)})  # the chaser on time; the target not commanding yet
    assert _counts(wp) == (0, 1, 0, 1)
    for k in range(1, 10):  # ticks between control ticks: the chaser's command(0) holds, none is due
        wp._count_late(k, {})
    assert _counts(wp) == (0, 10, 0, 1)
    wp._count_late(10, {"target": _cmd(10)})  # the chaser's command(10) is not in: late, and due
    assert _counts(wp) == (1, 12, 1, 3)  # the target: on time, due
    wp._count_late(11, {"chaser": _cmd(10)})  # it came one tick late: tick 11 has it
    assert _counts(wp) == (1, 14, 1, 3)
    wp._count_late(12, {"chaser": _cmd(9)})  # an older command than the one held changes nothing
    assert _counts(wp) == (1, 16, 1, 3)
    for k in range(13, 21):  # the target's command(20) never comes: ticks 20.. of the target are late
        wp._count_late(k, {"chaser": _cmd(20)} if k == 20 else {})
    assert _counts(wp) == (2, 32, 2, 5)
    wp.referee.done[list(wp.referee.chasers).index("chaser")] = True  # docked: not stepped on commands
    wp._count_late(21, {})
    assert _counts(wp) == (3, 33, 2, 5)  # the target only


def test_a_free_running_world_takes_the_queued_commands_at_its_tick(tmp_path):
    """Free-running, the commands wait in their queues until the world's tick drains them: a command that
    came is not held before the tick, then the newest of each vehicle is the one applied, an agent host's
    batch as much as a single command."""
    sc = load_scenario("docking")
    wp = WorldProcess(
        sc, 0, None, Keys("q"), ClockSpec("realtime"), threading.Event(), checkpoint_dir=tmp_path
    )
    came: list = []

    class Queue:
        def __init__(self, handler) -> None:
            self.handler = handler

        def drain(self) -> int:
            taken = [c for c in came if c[0] is self]
            for _, key, msg in taken:
                self.handler(key, msg)
            came[:] = [c for c in came if c[0] is not self]
            return len(taken)

    single, batch = Queue(wp._on_command), Queue(wp._on_command_batch)
    wp._queued = [single, batch]
    n = wp.world.command_size("chaser")
    older, newer = (Command(tick=0, t_s=0.0, actuators=np.zeros(n), force_body_n=np.zeros(3),
                            torque_body_nm=np.zeros(3), mode=m) for m in ("HOLD", "APPROACH"))  # fmt: skip
    came += [(single, "q/agent/chaser/command", older), (single, "q/agent/chaser/command", newer)]
    assert wp._latest == {}  # nothing taken before the tick
    assert wp._take_commands(0)
    assert came == [] and wp.modes["chaser"] == "APPROACH"  # the newer of the two
    assert wp.commanded_ticks == 1 and wp.drops.total == 0  # the chaser counted from its first command on
    # an agent host's batch of the next control tick, the same way
    from swarm.transport.messages import CommandBatch, encode

    later = Command(tick=10, t_s=0.1, actuators=np.zeros(n), force_body_n=np.zeros(3),
                    torque_body_nm=np.zeros(3), mode="REORIENT")  # fmt: skip
    came.append((batch, "q/agent/chaser/commands", CommandBatch(ids=("chaser",), commands=(encode(later),))))
    assert wp._latest == {}
    assert wp._take_commands(10)
    assert came == [] and wp.modes["chaser"] == "REORIENT" and wp.drops.total == 0
