"""Every Zenoh key expression of the swarm, built in one place under a configurable namespace.

docs/protocol.md: one namespace per swarm (default ``tpods``) so that two swarms can share a router.
Per-vehicle topics are ``<ns>/agent/<id>/<kind>``; the rest are ``<ns>/world/clock``, ``<ns>/world/imu``,
``<ns>/world/truth``, ``<ns>/world/bundle``, ``<ns>/mothership/uwb``, ``<ns>/mothership/tdoa``,
``<ns>/mothership/anchors``,
``<ns>/control/run``, ``<ns>/control/fault`` and the liveliness tokens ``<ns>/alive/<role>/<id>``.
Agent ids and roles are single key chunks of ``[A-Za-z0-9_-]`` (1 to 64 characters), so that no id can
smuggle a ``/`` or a wildcard into a key. ``docs/protocol.md`` lists every key with its publisher,
subscribers, rate and QoS.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from swarm.errors import ConfigError

__all__ = ["AGENT_KINDS", "ID_PATTERN", "Keys", "check_id"]

ID_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,64}")
"""An agent id, a role or any other single key chunk chosen by a user (``fullmatch``)."""

AGENT_KINDS: tuple[str, ...] = (
    "imu", "uwb", "tdoa", "vision", "gnss", "rangefinder", "barometer", "estimate", "guidance", "command",
    "commands", "truth", "event", "bundle",
)  # fmt: skip
"""The per-vehicle topics ``<ns>/agent/<id>/<kind>``."""

_FORBIDDEN_NS_CHARS = frozenset("*$?#")  # wildcards and characters Zenoh reserves in key expressions

# parse() names for the keys that are not per-vehicle: the name of the Keys method that builds them
_FIXED = {
    ("world", "clock"): "world_clock",
    ("world", "event"): "world_event",
    ("world", "imu"): "world_imu",
    ("world", "vision"): "world_vision",
    ("world", "truth"): "world_truth",
    ("world", "bundle"): "world_bundle",
    ("mothership", "anchors"): "anchors",
    ("mothership", "uwb"): "mothership_uwb",
    ("mothership", "tdoa"): "mothership_tdoa",
    ("control", "run"): "run_control",
    ("control", "fault"): "fault",
}


def check_id(value: object, what: str = "agent id") -> str:
    """``value`` if it is one key chunk of ``[A-Za-z0-9_-]`` (1-64 characters), else ConfigError naming it."""
    if not isinstance(value, str) or not ID_PATTERN.fullmatch(value):
        raise ConfigError(f"{what} must be 1-64 characters of [A-Za-z0-9_-] (one key chunk), got {value!r}")
    return value


@dataclass(frozen=True)
class Keys:
    """Key expressions of one swarm. ``Keys().imu("chaser")`` -> ``"tpods/agent/chaser/imu"``."""

    namespace: str = "tpods"
    """Prefix of every key: one or more ``/``-separated chunks, no wildcard (``*``), no ``$ ? #``, no
    leading/trailing ``/``, no empty chunk. Two swarms on one router differ here."""

    def __post_init__(self) -> None:
        ns = self.namespace
        ok = (
            isinstance(ns, str)
            and ns != ""
            and not (_FORBIDDEN_NS_CHARS & set(ns))
            and all(chunk != "" for chunk in ns.split("/"))
        )
        if not ok:
            raise ConfigError(
                "transport.namespace must be non-empty '/'-separated chunks without '*', '$', '?', '#', "
                f"empty chunks or a leading/trailing '/', got {ns!r}"
            )

    # ---------------------------------------------------------------------------------- per vehicle

    def _agent(self, agent_id: str, kind: str) -> str:
        return f"{self.namespace}/agent/{check_id(agent_id)}/{kind}"

    def imu(self, agent_id: str) -> str:
        """Gyro (+ AHRS) samples of one vehicle: world or IMU driver -> agent."""
        return self._agent(agent_id, "imu")

    def uwb(self, agent_id: str) -> str:
        """UWB ranges of one vehicle's tag: mothership or UWB driver -> agent."""
        return self._agent(agent_id, "uwb")

    def tdoa(self, agent_id: str) -> str:
        """TDoA distance differences heard by one vehicle's tag (``uwb.mode`` tdoa2/tdoa3, a ``Tdoa`` a UWB
        slot): mothership or UWB driver -> agent."""
        return self._agent(agent_id, "tdoa")

    def vision(self, agent_id: str) -> str:
        """Camera observations of the target's markers: world or camera driver -> agent."""
        return self._agent(agent_id, "vision")

    def gnss(self, agent_id: str) -> str:
        """Position fixes of one vehicle's satellite receiver: world or GNSS driver -> agent."""
        return self._agent(agent_id, "gnss")

    def rangefinder(self, agent_id: str) -> str:
        """Distances to the ground of one vehicle's downward rangefinder: world or its driver -> agent."""
        return self._agent(agent_id, "rangefinder")

    def barometer(self, agent_id: str) -> str:
        """Barometric altitudes (any constant offset) of one vehicle's barometer: its driver or a log feed
        -> agent."""
        return self._agent(agent_id, "barometer")

    def estimate(self, agent_id: str) -> str:
        """Pose estimate of one vehicle: agent -> its chasers, dashboard."""
        return self._agent(agent_id, "estimate")

    def guidance(self, agent_id: str) -> str:
        """Guidance mode, switch radii and the last Algorithm 1 decision: agent -> dashboard."""
        return self._agent(agent_id, "guidance")

    def command(self, agent_id: str) -> str:
        """Nozzle thrusts of one control step: agent -> world (or actuator driver)."""
        return self._agent(agent_id, "command")

    def commands(self, agent_id: str) -> str:
        """The commands of one round of an agent host, in one message (``CommandBatch``): the host of
        vehicle ``agent_id`` (its first) -> world."""
        return self._agent(agent_id, "commands")

    def truth(self, agent_id: str) -> str:
        """True state of one vehicle: world -> dashboard, metrics (never an agent)."""
        return self._agent(agent_id, "truth")

    def event(self, agent_id: str) -> str:
        """Mode transitions, docking, aborts, estimator resets of one vehicle."""
        return self._agent(agent_id, "event")

    def bundle(self, agent_id: str) -> str:
        """Several lockstep ticks' samples of one vehicle in one message (``Bundle``): world (its ``imu``
        and ``vision``) and mothership (its ``uwb``) -> agent, viewers."""
        return self._agent(agent_id, "bundle")

    def agent_all(self, kind: str) -> str:
        """Wildcard over every vehicle's ``kind`` topic: ``<ns>/agent/*/<kind>``."""
        if kind not in AGENT_KINDS:
            raise ConfigError(f"agent key kind must be one of {AGENT_KINDS}, got {kind!r}")
        return f"{self.namespace}/agent/*/{kind}"

    def agent_topics(self, agent_id: str) -> str:
        """Wildcard over every topic of one vehicle: ``<ns>/agent/<id>/*``. One subscriber on it delivers
        that vehicle's samples in publication order (separate subscribers run on separate threads)."""
        return f"{self.namespace}/agent/{check_id(agent_id)}/*"

    # ---------------------------------------------------------------------------------- swarm-wide

    def world_clock(self) -> str:
        """Tick, time, run state and seed: world -> everyone."""
        return f"{self.namespace}/world/clock"

    def world_imu(self) -> str:
        """Every vehicle's gyro (+ AHRS) samples of one tick in one message (``ImuBatch``): a simulated world
        serving agent hosts -> agents (each takes its own row)."""
        return f"{self.namespace}/world/imu"

    def world_vision(self) -> str:
        """Every chaser's camera frame of one camera tick in one message (``VisionBatch``): a simulated world
        serving agent hosts -> agents (each decodes its own entry), and viewers."""
        return f"{self.namespace}/world/vision"

    def world_truth(self) -> str:
        """Every vehicle's true state of one tick in one message (``TruthBatch``): a simulated world serving
        agent hosts -> its mothership (never an agent)."""
        return f"{self.namespace}/world/truth"

    def world_bundle(self) -> str:
        """Several lockstep ticks' ``world/truth`` batches in one message (``Bundle``): a lockstep world ->
        its mothership."""
        return f"{self.namespace}/world/bundle"

    def world_event(self) -> str:
        """Run start and end (with each vehicle's total impulse), lockstep timeouts: world -> launcher,
        dashboard."""
        return f"{self.namespace}/world/event"

    def mothership_uwb(self) -> str:
        """Every vehicle's range of one UWB slot in one message (``UwbBatch``): a simulated radio network
        serving agent hosts -> agents (each takes its own entry)."""
        return f"{self.namespace}/mothership/uwb"

    def mothership_tdoa(self) -> str:
        """Every vehicle's distance differences of one UWB slot in one message (``TdoaBatch``): a simulated
        TDoA radio serving agent hosts -> agents (each takes its own entry)."""
        return f"{self.namespace}/mothership/tdoa"

    def anchors(self) -> str:
        """Anchor ids and positions: mothership (publisher and queryable) -> agents, dashboard."""
        return f"{self.namespace}/mothership/anchors"

    def run_control(self) -> str:
        """Pause / resume / reset / new seed: dashboard or launcher -> world."""
        return f"{self.namespace}/control/run"

    def fault(self) -> str:
        """A fault to inject at run time (``swarm fault``): operator -> world (camera, gyro) and
        mothership (UWB)."""
        return f"{self.namespace}/control/fault"

    def alive(self, role: str, process_id: str) -> str:
        """Liveliness token of one process; ``role`` e.g. ``world``, ``mothership``, ``agent``, ``dashboard``,
        ``launcher``."""
        return f"{self.namespace}/alive/{check_id(role, 'role')}/{check_id(process_id, 'process id')}"

    def alive_all(self) -> str:
        """Wildcard over every liveliness token of this swarm."""
        return f"{self.namespace}/alive/**"

    def everything(self) -> str:
        """Wildcard over every key of this swarm (a recorder): ``<ns>/**``."""
        return f"{self.namespace}/**"

    # ---------------------------------------------------------------------------------- inverse

    def _rest(self, key: object) -> list[str] | None:
        text = str(key)
        prefix = self.namespace + "/"
        if not text.startswith(prefix):
            return None
        return text[len(prefix) :].split("/")

    def parse(self, key: object) -> tuple[str, str | None] | None:
        """Inverse of the builders: ``(kind, agent_id)`` for ``<ns>/agent/<id>/<kind>``; ``(name, None)``
        for a swarm-wide key, named by its builder (``world_clock``, ``world_event``, ``world_imu``,
        ``world_vision``, ``world_truth``, ``world_bundle``, ``anchors``, ``mothership_uwb``,
        ``mothership_tdoa``, ``run_control``, ``fault``);
        ``("alive", process_id)`` for a liveliness token (its role: :meth:`parse_alive`). ``None`` for a
        key outside this namespace, a wildcard or anything this protocol does not define. ``key`` may be a
        ``str`` or any object whose ``str()`` is the key (a Zenoh ``KeyExpr``)."""
        rest = self._rest(key)
        if rest is None:
            return None
        if len(rest) == 3 and rest[0] == "agent" and rest[2] in AGENT_KINDS and ID_PATTERN.fullmatch(rest[1]):
            return rest[2], rest[1]
        if len(rest) == 2 and tuple(rest) in _FIXED:
            return _FIXED[(rest[0], rest[1])], None
        parsed = self.parse_alive(key)
        if parsed is not None:
            return "alive", parsed[1]
        return None

    def parse_alive(self, key: object) -> tuple[str, str] | None:
        """``(role, process_id)`` of a liveliness key ``<ns>/alive/<role>/<id>``, else ``None``."""
        rest = self._rest(key)
        if rest is None or len(rest) != 3 or rest[0] != "alive":
            return None
        if not (ID_PATTERN.fullmatch(rest[1]) and ID_PATTERN.fullmatch(rest[2])):
            return None
        return rest[1], rest[2]
