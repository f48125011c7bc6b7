"""A small MCAP recording for the playback tests, made cheaply and faithfully: the recorder's writer
(:class:`~swarm.transport.recording.McapSink`, what ``swarm record`` and ``swarm launch --record`` write every
sample they hear with) writes the file, fed with the messages the scripted fake swarm
(:mod:`tests.dashboard.fake_swarm`) publishes tick by tick, plus the world's ``run_start`` / ``run_end``
events, its clock and the anchors. A launched lockstep run with ``--record`` would take a minute here; this
takes ~2 s.

The run: one chaser/target pair, the chaser flying a straight line from (0, 1, 0) m onto its target at
(1, 2, 1) m at ``speed_m_s`` (docked at ~16 s with the defaults), through APPROACH, REORIENT, ALIGN, DOCK
and DOCKED, one tick every ``dt_s`` of swarm time. Its radio is TDoA (``tdoa=True``, as ``uwb.mode =
"tdoa3"`` publishes it): every second tick (a UWB slot) each vehicle's tag publishes a ``Tdoa`` on
``agent/<id>/tdoa`` with :data:`TDOA_ROWS` rows, whose senders go round the four anchors; at ``dt_s =
0.01`` s each anchor is heard :data:`ANCHOR_HZ` times a second and each tag forms :data:`TAG_HZ` differences
a second (the estimates' counters, :mod:`tests.dashboard.fake_swarm`, accept 50 a second and reject 1).
The differences' values are not drawn (0 m).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from swarm.transport.keys import Keys
from swarm.transport.messages import Anchors, Clock, Event, Tdoa, encode
from swarm.transport.recording import McapSink
from tests.dashboard.fake_swarm import ANCHORS_M, Pair, tick_messages, vehicle_ids

NAMESPACE = "rec-test"
TDOA_ROWS = 2
"""Rows of each scripted ``Tdoa`` (one per UWB slot: every second tick)."""
TAG_HZ = 100.0
"""A tag's differences a second at ``dt_s = 0.01`` s: 2 rows every 0.02 s."""
ANCHOR_HZ = TAG_HZ / len(ANCHORS_M)
"""Each anchor's packets a second as a tag hears them: the senders go round the four anchors."""


def _tdoa(k: int, t: float) -> bytes:
    """The ``Tdoa`` of UWB slot tick ``k``: rows whose senders (``anchor_b``) go round the anchors, each
    row's ``anchor_a`` the sender before it."""
    n = len(ANCHORS_M)
    first = (k // 2) * TDOA_ROWS
    b = tuple((first + i) % n for i in range(TDOA_ROWS))
    a = tuple((j - 1) % n for j in b)
    return encode(Tdoa(tick=k, t_s=t, anchor_a=a, anchor_b=b, ddist_m=np.zeros(TDOA_ROWS)))


def scripted_messages(
    keys: Keys,
    duration_s: float = 20.0,
    dt_s: float = 0.01,
    speed_m_s: float = 0.1,
    seed: int = 7,
    tdoa: bool = True,
) -> list[tuple[str, bytes]]:
    """The messages of the scripted run in the order a recorder would see them (module docstring)."""
    pairs = [Pair(i, c, t, speed_m_s) for i, (c, t) in enumerate(vehicle_ids(1))]
    ids = [v for p in pairs for v in (p.chaser, p.target)]
    start = {"seed": seed, "vehicles": ids, "clock": "lockstep", "scenario": "docking"}
    out = [
        (keys.anchors(), encode(Anchors(anchor_ids=(0, 1, 2, 3), positions_nav=np.array(ANCHORS_M)))),
        (keys.world_event(), encode(Event(t_s=0.0, kind="run_start", data=start))),
    ]
    n = round(duration_s / dt_s)
    for k in range(n + 1):
        t = k * dt_s
        out += tick_messages(keys, pairs, k, t)
        if tdoa and k > 0 and k % 2 == 0:
            out += [(keys.tdoa(vid), _tdoa(k, t)) for vid in ids]
        out.append((keys.world_clock(), encode(Clock(tick=k, t_s=t, state="running", seed=seed))))
    end = {"reason": "all_contact", "tick": n, "t_s": n * dt_s, "seed": seed}
    out.append((keys.world_event(), encode(Event(t_s=n * dt_s, kind="run_end", data=end))))
    return out


def write_recording(path: Path, **script) -> list[tuple[str, bytes]]:
    """Record the scripted run (``script``: :func:`scripted_messages`'s arguments) to ``path`` with the
    recorder's writer (:class:`~swarm.transport.recording.McapSink`, what ``swarm record`` writes each
    sample it hears with); returns the messages recorded, in order."""
    keys = Keys(NAMESPACE)
    messages = scripted_messages(keys, **script)
    sink = McapSink(path, keys)
    for key, payload in messages:
        sink.write(key, payload)
    sink.close()
    return messages
