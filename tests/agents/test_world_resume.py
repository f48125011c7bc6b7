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
    agent.pub_command = Recorder()
    agent._publish_command(7)
    agent._on_world_event("tpods/world/event", _resumed(7))
    first, again = agent.pub_command.sent
    assert again == first and decode(again, Command).tick == 7
    assert agent.resent == 1


def test_no_command_is_sent_for_a_tick_not_processed_yet_or_on_other_events(agent):
    agent.pub_command = Recorder()
    agent._publish_command(7)
    agent._on_world_event("tpods/world/event", _resumed(8))  # tick 8 goes out once processed
    agent._on_world_event("tpods/world/event", Event(0.07, "run_start", {"tick": 7}))
    assert len(agent.pub_command.sent) == 1
