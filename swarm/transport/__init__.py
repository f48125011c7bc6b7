"""Transport: key expressions (:mod:`.keys`) and wire messages with their codec (:mod:`.messages`).

Neither module imports Zenoh: the codec is pure (bytes in, validated messages out), so the in-process
simulation, tests and tools use it without a session. ``docs/protocol.md`` is the protocol reference.
"""

from __future__ import annotations

from swarm.transport.keys import AGENT_KINDS, Keys
from swarm.transport.messages import (
    SCHEMA_VERSION,
    Anchors,
    Clock,
    Command,
    DropCounter,
    Estimate,
    Event,
    Guidance,
    Imu,
    Message,
    RunControl,
    Truth,
    Uwb,
    Vision,
    decode,
    encode,
    safe_decode,
)

__all__ = [
    "AGENT_KINDS",
    "SCHEMA_VERSION",
    "Anchors",
    "Clock",
    "Command",
    "DropCounter",
    "Estimate",
    "Event",
    "Guidance",
    "Imu",
    "Keys",
    "Message",
    "RunControl",
    "Truth",
    "Uwb",
    "Vision",
    "decode",
    "encode",
    "safe_decode",
]
