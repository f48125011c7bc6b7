"""The run's random streams: one ``SeedSequence`` per run, one independent stream per vehicle and sensor.

Every runner asks for its streams here, so a seed means the same noise in the in-process simulation and in
the processes (STYLE.md: "a seed is a trajectory").
"""

from __future__ import annotations

import numpy as np

STREAMS = ("init", "gyro", "ahrs", "camera", "uwb", "uwb_errors", "uwb_anchors", "tdoa")
"""Appended only: a stream's index is part of its key, so a new name changes no existing stream."""


def stream(seed: int, vehicle_index: int, name: str) -> np.random.Generator:
    """The random stream ``name`` (one of :data:`STREAMS`) of vehicle ``vehicle_index`` for root ``seed``:
    independent streams from one ``SeedSequence`` (spawn keys ``(vehicle, sensor)``), the same in every
    process that asks for them."""
    key = (int(vehicle_index), STREAMS.index(name))
    return np.random.default_rng(np.random.SeedSequence(entropy=int(seed), spawn_key=key))


def seed_sequence(seed: int, vehicle_index: int, name: str) -> np.random.SeedSequence:
    """The ``SeedSequence`` behind :func:`stream` (for a model that spawns its own children, as the TDoA
    radio does)."""
    return np.random.SeedSequence(entropy=int(seed), spawn_key=(int(vehicle_index), STREAMS.index(name)))
