"""Vehicle kinds as plug-ins (docs/architecture.md, "Vehicle kinds").

:data:`KINDS` maps a scenario's ``kind = "..."`` to its :class:`~swarm.kinds.base.VehicleKind` class;
:class:`KindsParams` is the scenario's ``[kinds]`` table, one sub-table per registered kind, built from
:data:`KINDS` so that a new kind needs only its entry here (and its branch in :mod:`swarm.kinds._dispatch`,
or a :attr:`~swarm.kinds.base.VehicleKind.docking_missing` that keeps it out of docking scenarios, as the
``quadrotor``'s does: the landing tick flies it).
"""

from __future__ import annotations

from dataclasses import field, make_dataclass

from swarm.errors import ConfigError
from swarm.kinds.base import VehicleKind
from swarm.kinds.cubesat import CubesatKind
from swarm.kinds.ground import GroundKind
from swarm.kinds.quadrotor import QuadrotorKind

KINDS: dict[str, type[VehicleKind]] = {k.name: k for k in (CubesatKind, GroundKind, QuadrotorKind)}
"""Every registered kind by name."""

assert len({k.code for k in KINDS.values()}) == len(KINDS), "kind codes must be distinct"

KindsParams = make_dataclass(
    "KindsParams",
    [(name, kind.Params, field(default_factory=kind.Params)) for name, kind in KINDS.items()],
    frozen=True,
)
KindsParams.__doc__ = "The ``[kinds]`` table: each registered kind's parameter tables (``[kinds.<name>]``)."
KindsParams.__module__ = __name__


def check_docking_kind(vehicle_id: str, name: str) -> None:
    """ConfigError naming ``vehicles.<vehicle_id>.kind`` and its value unless the docking runners fly the
    registered kind ``name`` (:attr:`~swarm.kinds.base.VehicleKind.docking_missing` says what they lack)."""
    missing = KINDS[name].docking_missing
    if missing is not None:
        raise ConfigError(
            f"vehicles.{vehicle_id}.kind = {name!r}: the docking runners cannot fly this kind yet: "
            f"{missing}. "
            'It flies landing scenarios ([mission] name = "landing", swarm/scenarios/landing.toml)'
        )


__all__ = ["KINDS", "KindsParams", "VehicleKind", "check_docking_kind"]
