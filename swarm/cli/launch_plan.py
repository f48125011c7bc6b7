"""How ``swarm launch`` lays a docking swarm out on this machine when the user does not say: how many
vehicles share an agent process, whether the vehicles' controller clocks are staggered and how a
free-running agent alone in its process wakes (:func:`auto_launch_plan`, a pure function of the vehicle
count and the cores; :func:`resolve_plan` applies it to the launcher's flags, each explicit flag keeping
its part)."""

from __future__ import annotations

import os
from dataclasses import dataclass

from swarm.errors import ConfigError

__all__ = [
    "HOSTS_PER_CORE",
    "HOST_MAX_VEHICLES",
    "PROCESS_EACH_PER_CORE",
    "STAGGER_KEY",
    "WAKE_KEY",
    "LaunchPlan",
    "auto_launch_plan",
    "available_cores",
    "given_keys",
    "resolve_plan",
]

PROCESS_EACH_PER_CORE = 4
"""A process per vehicle while the swarm has at most this many vehicles per core (8 on 2 cores), agent hosts
beyond. Measured free-running on 2 cores shared with other work (``swarm bench swarm --clock realtime
--span 20``, BENCHMARKS.md, "Defaults that hold"): 8 vehicles a process each 0.16 % late ticks, 16 a
process each 4.6 %, 32 a process each 8-14 % (five runs), where 16 in two hosts of 8 were late 0.40 % and
32 in four hosts of 8 0.07-0.17 % (four runs). A process per vehicle costs ~300 us of CPU per vehicle per
tick (its own interpreter, Zenoh session and wake at every gyro sample), a vehicle in a host of 8
~90-110 us, of 64 ~40 us."""

HOSTS_PER_CORE = 2
"""Agent hosts per core, beyond a process per vehicle. 32 vehicles on 2 cores, staggered, runs alternated:
four hosts of 8 late 0.17 / 0.14 / 0.07 / 0.10 %, two of 16 0.61 / 0.46 / 0.71 / 1.30 % (a host steps its
vehicles one after the other on one thread: the smaller its round, the sooner its last command leaves, and
on a shared machine each process gets its share of the cores), one of 32 0.75 %. Four hosts with the world
and the mothership are six processes: still a mesh (``swarm.cli.children.MESH_MAX_PEERS``)."""

HOST_MAX_VEHICLES = 64
"""The most vehicles one agent host takes (``--vehicles-per-process``' bound): a host steps its vehicles on
one thread, 128 vehicles in hosts of 64 cost ~40 us per vehicle per tick, 2.6 ms of a 10 ms tick each."""

STAGGER_KEY = "swarm.stagger_control"
"""The scenario key of the staggered controller clocks (``--set swarm.stagger_control=...`` overrides the
plan's choice)."""

WAKE_KEY = "agent.wake_at_control"
"""The scenario key of the control-rate wake (``--set agent.wake_at_control=...`` overrides the plan's
choice)."""


@dataclass(frozen=True)
class LaunchPlan:
    """A docking swarm's layout on a machine: what :func:`auto_launch_plan` chose, or the user's flags."""

    vehicles_per_process: int
    """Vehicles per agent process (``--vehicles-per-process``): 1 is a process per vehicle."""
    stagger_control: bool
    """The vehicles' control steps spread over the control period (``swarm.stagger_control``)."""
    wake_at_control: bool
    """A free-running agent alone in its process wakes twice per control period, not at every gyro sample
    (``agent.wake_at_control``; agent hosts of several and lockstep ignore it)."""
    n_vehicles: int
    """The vehicles the plan is for."""
    n_cores: int
    """The cores the plan is for (:func:`available_cores`)."""
    chosen: tuple[str, ...] = ()
    """The parts the plan chose itself (``"hosts"``, ``"stagger"``, ``"wake"``); the others the user gave."""

    @property
    def agent_processes(self) -> int:
        """The agent processes the swarm runs (the last one hosting the rest)."""
        return -(-self.n_vehicles // self.vehicles_per_process)

    def describe(self) -> str:
        """One line for the launcher's log."""
        if self.vehicles_per_process == 1:
            hosts = f"a process per vehicle ({self.n_vehicles})"
        else:
            hosts = f"{self.agent_processes} agent hosts of up to {self.vehicles_per_process} vehicles"
        stagger = "controller clocks staggered" if self.stagger_control else "controller clocks in phase"
        if self.vehicles_per_process > 1:
            wake = "each host wakes as its messages come"
        else:
            wake = "agents wake per control period" if self.wake_at_control else "agents wake per gyro sample"
        auto = ", ".join(self.chosen) if self.chosen else "none"
        return (f"{self.n_vehicles} vehicles on {self.n_cores} cores: {hosts}, {stagger}, {wake} "
                f"(chosen automatically: {auto}; --vehicles-per-process, --set {STAGGER_KEY}=..., "
                f"--set {WAKE_KEY}=... override)")  # fmt: skip

    def as_dict(self) -> dict:
        """The plan in the launch summary (``launch_plan``)."""
        return {
            "vehicles_per_process": self.vehicles_per_process,
            "agent_processes": self.agent_processes,
            "stagger_control": self.stagger_control,
            "wake_at_control": self.wake_at_control,
            "n_vehicles": self.n_vehicles,
            "n_cores": self.n_cores,
            "chosen": list(self.chosen),
        }


def available_cores() -> int:
    """The cores this process may run on (``os.sched_getaffinity``: a ``taskset`` or a container's CPU set
    counts), else ``os.cpu_count()``, at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not on Linux
        return max(1, os.cpu_count() or 1)


def auto_launch_plan(
    n_vehicles: int,
    n_cores: int,
    *,
    free_running: bool = True,
    secure: bool = False,
    vehicles_per_process: int | None = None,
) -> LaunchPlan:
    """The launch layout of ``n_vehicles`` on ``n_cores``, for a free-running clock (``realtime``,
    ``scaled:N``) or lockstep; ``vehicles_per_process`` given (the user's ``--vehicles-per-process``)
    fixes the hosts and the rest follows from it.

    The rule (measured on 2 cores, :data:`PROCESS_EACH_PER_CORE`; BENCHMARKS.md, "Defaults that hold"):

    - **hosts**: a process per vehicle while ``n_vehicles <= PROCESS_EACH_PER_CORE * n_cores`` (and always
      with ``secure``: a host would need every hosted vehicle's identity); beyond, :data:`HOSTS_PER_CORE`
      agent hosts per core (more when a host would take over :data:`HOST_MAX_VEHICLES`), the vehicles
      shared evenly: 32 vehicles on 2 cores are four hosts of 8, 128 four of 32. A process per vehicle
      wakes every one of them at every gyro sample; on two cores 32 such processes were late 8-14 % of
      their ticks, four hosts of 8 0.00-0.99 % (nine runs, six of them beside other jobs). 128 vehicles
      in four hosts of 32 need 0.78 of the two cores: 0.00-0.22 % late on an otherwise idle machine,
      0.4-17 % beside other jobs. Lockstep takes the same hosts (its run is the same, in fewer processes:
      faster);
    - **stagger**: free-running, whenever the swarm is beyond a process per vehicle on each core's share
      (hosts, or many processes of one): an agent host steps its vehicles on one thread, and 16 vehicles
      controlling on one tick need that tick's CPU 16 times over (``swarm.stagger_control``). Never in
      lockstep, whose run must equal ``swarm sim`` of the same scenario (staggering moves the vehicles'
      control ticks), nor for a small swarm of a process each, which holds real time without it;
    - **wake**: at each gyro sample, except for free-running processes of one vehicle beyond the
      hosts' threshold (the user asked for a process each, or ``secure``): then twice per control period
      (``agent.wake_at_control``), ~5 times fewer wakes (32 vehicles a process each, staggered: 0.14-1.52 %
      late with it in six runs, 1.0-2.7 % without in three; the issue saw 4.7 and 79 % with it): the best
      a process each does here, not reliably under 1 %.
    """
    if isinstance(n_vehicles, bool) or not isinstance(n_vehicles, int) or n_vehicles < 1:
        raise ConfigError(f"a launch plan needs a vehicle count >= 1, got {n_vehicles!r}")
    if isinstance(n_cores, bool) or not isinstance(n_cores, int) or n_cores < 1:
        raise ConfigError(f"a launch plan needs a core count >= 1, got {n_cores!r}")
    if vehicles_per_process is not None and not 1 <= vehicles_per_process <= HOST_MAX_VEHICLES:
        raise ConfigError(f"--vehicles-per-process must be an integer in 1..{HOST_MAX_VEHICLES}, "
                          f"got {vehicles_per_process}")  # fmt: skip
    crowded = n_vehicles > PROCESS_EACH_PER_CORE * n_cores
    chosen = []
    if vehicles_per_process is None:
        chosen.append("hosts")
        if secure or not crowded:
            vehicles_per_process = 1
        else:
            hosts = min(n_vehicles, max(HOSTS_PER_CORE * n_cores, -(-n_vehicles // HOST_MAX_VEHICLES)))
            vehicles_per_process = -(-n_vehicles // hosts)
    stagger = free_running and (vehicles_per_process > 1 or crowded)
    wake = free_running and vehicles_per_process == 1 and crowded
    return LaunchPlan(vehicles_per_process, stagger, wake, n_vehicles, n_cores,
                      (*chosen, "stagger", "wake"))  # fmt: skip


def given_keys(overrides: list[str] | tuple[str, ...]) -> set[str]:
    """The dotted scenario keys that ``--set`` overrides name, a table's keys included
    (``--set swarm.stagger_control=true`` and ``--set 'swarm={stagger_control=true}'`` both name
    ``swarm.stagger_control``)."""
    from swarm.config import parse_override

    keys: set[str] = set()

    def walk(prefix: str, value: object) -> None:
        keys.add(prefix)
        if isinstance(value, dict):
            for k, v in value.items():
                walk(f"{prefix}.{k}", v)

    for text in overrides:
        walk(*parse_override(text))
    return keys


def resolve_plan(
    n_vehicles: int,
    clock_lockstep: bool,
    vehicles_per_process: int | None,
    overrides: list[str] | tuple[str, ...],
    *,
    secure: bool = False,
    n_cores: int | None = None,
) -> tuple[LaunchPlan, list[str]]:
    """The plan of a launch (:func:`auto_launch_plan` on :func:`available_cores`) with the user's explicit
    choices kept: ``--vehicles-per-process`` (``vehicles_per_process`` not None) and a ``--set`` of
    :data:`STAGGER_KEY` or :data:`WAKE_KEY` in ``overrides`` (its value, whatever the plan would say). Returns
    the plan as the launch will run it and the ``--set`` overrides to add for the parts the plan chose
    (none where the plan's choice is the scenario's default, ``false``, so a small swarm's children get the
    flags they got before). A scenario file's own ``true`` stays; a file's explicit ``false`` is not told
    from the default and the plan may turn the part on."""
    from dataclasses import replace

    from swarm.config import parse_override

    cores = available_cores() if n_cores is None else n_cores
    plan = auto_launch_plan(n_vehicles, cores, free_running=not clock_lockstep, secure=secure,
                            vehicles_per_process=vehicles_per_process)  # fmt: skip
    given = given_keys(overrides)
    values = dict(parse_override(o) for o in overrides)
    chosen, extra = list(plan.chosen), []
    for key, part, field in ((STAGGER_KEY, "stagger", "stagger_control"),
                             (WAKE_KEY, "wake", "wake_at_control")):  # fmt: skip
        if key in given:
            chosen.remove(part)
            table, _, name = key.partition(".")
            value = values.get(key, values.get(table, {}).get(name) if isinstance(values.get(table), dict)
                               else None)  # fmt: skip
            plan = replace(plan, **{field: bool(value)})
        elif getattr(plan, field):
            extra.append(f"{key}=true")
    return replace(plan, chosen=tuple(chosen)), extra
