"""An agent facing a resumed world (docs/protocol.md, "Restart and loss"): on ``world_resumed`` at tick
``k`` it sends ``command(k)`` again, byte for byte, if that is the last command it sent (the world that
received it is gone), and nothing otherwise (the command goes out as usual once tick ``k`` is processed).

No Zenoh: the agent's publisher is replaced by a recorder; the handler is the one its ``world/event``
subscription calls.
"""

from __future__ import annotations

import threading

import pytest

from agents.process import AgentProcess
from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.messages import Command, Event, decode
from swarm.transport.process import ClockSpec


class Recorder:
    def __init__(self) -> None:
        self.sent: list[bytes] = []

    def put(self, payload: bytes) -> None:
        self.sent.append(bytes(payload))


@pytest.fixture(scope="module")
def agent():
    proc = AgentProcess(load_scenario("docking"), "chaser", 0, "fixed", None, Keys("resume"), ClockSpec(),
                        threading.Event())  # fmt: skip
    return proc


def _resumed(tick: int) -> Event:
    return Event(tick * 0.01, "world_resumed", {"tick": tick, "t_s": tick * 0.01})


def test_the_command_of_the_resumed_tick_is_sent_again_byte_for_byte(agent):
    assert agent.control_every == 10  # the docking scenario's 10 Hz control: ticks 0, 10, 20, ...
    agent.pub_command = Recorder()
    agent._publish_command(20)
    agent._on_world_event("tpods/world/event", _resumed(20))
    first, again = agent.pub_command.sent
    assert again == first and decode(again, Command).tick == 20
    assert agent.resent == 1


def test_no_command_is_sent_for_a_tick_not_processed_yet_or_on_other_events(agent):
    agent.pub_command = Recorder()
    agent._publish_command(10)
    agent._on_world_event("tpods/world/event", _resumed(20))  # tick 20 goes out once processed
    agent._on_world_event("tpods/world/event", _resumed(13))  # not a control tick: command(10) holds
    agent._on_world_event("tpods/world/event", Event(0.1, "run_start", {"tick": 10}))
    assert len(agent.pub_command.sent) == 1


def test_commands_go_out_on_control_ticks_only(agent):
    """The world holds a command until the next control tick (docs/protocol.md, "Rates")."""
    agent.pub_command = Recorder()
    for k in range(31):
        agent._publish_command(k)
    assert [decode(p, Command).tick for p in agent.pub_command.sent] == [0, 10, 20, 30]
