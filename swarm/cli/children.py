"""What every launcher shares (``swarm launch`` of a docking or a landing scenario): the children's common
flags and their topology, the client endpoint of the launcher's router, and the ``--record`` recorder on the
router's session."""

from __future__ import annotations

import argparse
import logging
import os
import threading
import time
from pathlib import Path

from swarm.errors import ConfigError

_LOG = logging.getLogger("swarm.launch")


def launch_listen(args: argparse.Namespace) -> list[str]:
    """The launcher router's listen endpoints: ``--listen``, else a free loopback port; in a ``--secure``
    swarm the TLS ones (:func:`swarm.transport.security.secure_listen`)."""
    from swarm.transport.session import free_loopback_endpoint

    if getattr(args, "secure", False):
        from swarm.transport.security import secure_listen

        free_port = int(free_loopback_endpoint().rpartition(":")[2])
        return secure_listen(args.listen, args.zenoh_config, free_port)
    return list(args.listen) if args.listen else [free_loopback_endpoint()]


def secure_router(args: argparse.Namespace, keys, vehicle_ids, listen: list[str], zargs, mission: str,
                  platforms=()):  # fmt: skip
    """``--secure``: the swarm's certificates and Zenoh configurations (``args.secure_material``, whose
    ``close`` the launcher owes), and the router's session arguments with the launcher's configuration (the
    access control list of ``mission``; ``platforms``: a landing swarm's moving pads' robots,
    :func:`swarm.transport.security.rights`). Without ``--secure``: ``zargs`` as they are."""
    if not getattr(args, "secure", False):
        return zargs
    from dataclasses import replace

    from swarm.transport.security import SecureMaterial

    args.secure_material = SecureMaterial(keys, vehicle_ids, listen, mission=mission, platforms=platforms)
    print(f"swarm secure: certificates and Zenoh configs in {args.secure_material.directory} "
          "(removed at exit)", flush=True)  # fmt: skip
    return replace(zargs, config_file=str(args.secure_material.config_file("launcher")))


def router_args(args: argparse.Namespace, listen: list[str]):
    """The launcher's own Zenoh session: a router on ``listen`` with the launch flags' connect, config,
    scouting and lease."""
    from swarm.transport.session import ZenohArgs

    return ZenohArgs(
        mode="router", connect=tuple(args.connect or ()), listen=tuple(listen), config_file=args.zenoh_config,
        multicast_scouting=args.multicast_scouting, lease_ms=args.lease_ms,
    )  # fmt: skip


def config_args(args: argparse.Namespace, identity: str) -> list[str]:
    """``--zenoh-config`` of one child: its own file in a ``--secure`` swarm, else the launcher's flag."""
    material = getattr(args, "secure_material", None)
    if material is not None:
        return ["--zenoh-config", str(material.config_file(identity))]
    return ["--zenoh-config", args.zenoh_config] if args.zenoh_config else []


TOPOLOGIES = ("auto", "mesh", "star")
"""``swarm launch --topology``: how the children link (:func:`topology`)."""

MESH_LISTEN = "tcp/127.0.0.1:0"
"""Where a child of a ``mesh`` listens for its siblings' links: loopback, a port of the system's choosing
(the siblings learn it from the router's gossip)."""

MESH_MAX_PEERS = 6
"""``--topology auto`` makes a mesh of at most this many processes (the world, the mothership, the agent
processes), a star of more. Measured alternately (BENCHMARKS.md, "A mesh of peers"): in lockstep one pair
(4 processes) runs 18 % faster as a mesh and two pairs (6) 13 % faster, with lower latencies, where four
pairs (10) run no faster and the world pays more CPU; 128 vehicles in hosts of 64 (4) run alike either
way; from 16 vehicles a process each (18) a mesh costs 12 % more CPU per agent and 40 % more in the world
(each process writes every message to its own link, where a star's client writes them all to one) and is
late more often."""

TOPOLOGY_TEXT = {
    "mesh": "Zenoh peers linked directly to one another, the router their rendezvous (--topology mesh)",
    "star": "Zenoh clients of the router, every message through it (--topology star)",
}
"""What the launcher logs of each topology."""


def topology(args: argparse.Namespace, processes: int) -> str:
    """How the swarm's ``processes`` (the world, the mothership, the agent processes) link,
    ``--topology``:

    - ``star``: each a Zenoh client of the launcher's router, so every message crosses the router (two
      TCP hops, and the router's CPU for each);
    - ``mesh``: each a Zenoh peer that connects to the router and listens on :data:`MESH_LISTEN`; the
      router's gossip tells each the others' endpoints and they link directly, so a message between two
      of them takes one hop and costs the router nothing. The router stays their rendezvous, the
      gateway of every client (the dashboard, the recorder, a probe, a process on another machine) and
      brokers between two peers until their own link is up;
    - ``auto`` (the default): a mesh of at most :data:`MESH_MAX_PEERS` processes, else a star.

    A ``--secure`` swarm is a star: the router enforces its access control and mutual TLS, which a direct
    link between two peers would pass by, so ``--topology mesh --secure`` is refused."""
    chosen, secure = getattr(args, "topology", None) or "auto", bool(getattr(args, "secure", False))
    if chosen not in TOPOLOGIES:
        raise ConfigError(f"--topology must be one of {', '.join(TOPOLOGIES)}, got {chosen!r}")
    if chosen == "mesh" and secure:
        raise ConfigError("--topology mesh and --secure: the router enforces the access control and the "
                          "mutual TLS, and a direct link between two peers would pass by it; a secure "
                          "swarm is a star (leave --topology out, or give --topology star)")  # fmt: skip
    if chosen == "auto":
        return "star" if secure or processes > MESH_MAX_PEERS else "mesh"
    return chosen


def swarm_processes(vehicles: int, per_process: int = 1, *, mothership: bool = True) -> int:
    """The processes a launch of ``vehicles`` starts, the dashboard aside: the world, the mothership (a
    docking swarm's; a landing has none) and one agent process per ``per_process`` vehicles, the last one
    hosting the rest (``swarm launch --vehicles-per-process``). The count :func:`topology`'s ``auto``
    decides by, for the launchers and for the benches' probes alike."""
    return 1 + int(mothership) + -(-vehicles // per_process)


def resolved(chosen: str, processes: int) -> str:
    """The topology a launch of ``processes`` (the world, the mothership, the agent processes) with
    ``--topology chosen`` and no ``--secure`` runs in (:func:`topology`): what a bench's probe must join."""
    return topology(argparse.Namespace(topology=chosen, secure=False), processes)


def member_args(endpoint: str, links: str):
    """The Zenoh session of a process that joins a launched swarm of topology ``links`` (``mesh`` or
    ``star``) as its children do (:func:`child_args`): a client of the router at ``endpoint`` (``star``),
    or a peer that connects to it and listens for its siblings' links (``mesh``). A bench's probe joins
    so, to hear each message on the path the swarm's own processes hear it on."""
    from swarm.transport.session import ZenohArgs

    if links == "mesh":
        return ZenohArgs(mode="peer", connect=(endpoint,), listen=(MESH_LISTEN,))
    if links != "star":
        raise ValueError(f"a launched swarm is a mesh or a star, got {links!r}")
    return ZenohArgs(mode="client", connect=(endpoint,))


def client_endpoint(listen: str) -> str:
    """The endpoint a local child connects to for a listen endpoint (``0.0.0.0``/``[::]`` -> loopback)."""
    proto, _, addr = listen.partition("/")
    host, _, port = addr.split("?")[0].split("#")[0].rpartition(":")
    if host in ("0.0.0.0", "[::]", "::"):
        host = "127.0.0.1"
    return f"{proto}/{host}:{port}"


def child_args(args: argparse.Namespace, endpoint: str, seed: int) -> list[str]:
    common = [str(args.scenario)]
    for o in args.overrides:
        common += ["--set", o]
    common += ["--agents", str(args.agents), "--seed", str(seed), "--namespace", args.namespace]
    if args.policy:
        common += ["--policy", args.policy]
    session = member_args(endpoint, args.links)  # (the launcher's topology(), resolved once)
    common += ["--mode", session.mode, "--connect", endpoint]
    for listen in session.listen:
        common += ["--listen", listen]
    if args.lease_ms:
        common += ["--lease-ms", str(args.lease_ms)]
    return common


def check_record(args: argparse.Namespace) -> None:
    from swarm.transport.recording import check_mcap_path

    if getattr(args, "record", None) is not None:
        check_mcap_path(args.record, "--record")


class LauncherRecorder:
    """``--record FILE.mcap``: the launcher's own router session records the swarm (a
    :class:`~swarm.transport.recording.Recorder` on a thread of the launcher), as rosbag2's recorder runs as
    a component inside a ROS 2 container: every sample that the router forwards reaches it inside the
    process, where a ``swarm record`` child costs one more hop over TCP per sample (the router's sending,
    the child's Zenoh receiving) and a Python interpreter of its own (``BENCHMARKS.md``, "Recording"). In a
    ``--secure`` swarm it needs no identity of its own: it is the router, and it records what the router's
    access control let in.
    Kept across runs (``--repeat``); :meth:`close` finishes the file (its summary and indexes) once the
    samples still in flight are in, before the session closes. Its channel holds
    :data:`~swarm.transport.recording.FIFO_DEPTH` samples (~19 s of a 4-pair swarm): a recorder that far
    behind makes the router wait rather than lose a sample."""

    def __init__(self, args: argparse.Namespace, session, keys) -> None:
        from swarm.transport.recording import Recorder

        self.path = args.record
        self.stop = threading.Event()
        self.recorder = Recorder(session, keys, self.path)
        self.error: BaseException | None = None
        ready = threading.Event()

        def run() -> None:
            try:
                self.recorder.run(self.stop, ready.set)
            except BaseException as e:  # reported by close(); the launcher goes on
                self.error = e
                ready.set()

        self.thread = threading.Thread(target=run, name="recorder", daemon=True)
        self.thread.start()
        if not ready.wait(60.0) or self.error is not None:
            raise ConfigError(f"--record: could not start recording to {self.path}: {self.error}")
        print(f"recording to {self.path}", flush=True)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(30.0)
        if self.error is not None:
            _LOG.error("--record: the recording of %s failed: %s", self.path, self.error)
        else:
            n = sum(self.recorder.counts.values())
            print(f"recorded {n} messages on {len(self.recorder.counts)} keys to {self.path}", flush=True)


def start_recorder(args: argparse.Namespace, session, keys) -> LauncherRecorder | None:
    """The launcher's recorder (``--record``), or None."""
    return None if args.record is None else LauncherRecorder(args, session, keys)


def stop_swarm(sup, session, keys, why: str, t_s: float = 0.0, keep: tuple[str, ...] = ()) -> None:
    """Stop the swarm's processes (but those named in ``keep``) in the order of
    :mod:`swarm.transport.stopping`: those still starting at once (they are not in the swarm yet:
    :meth:`~swarm.cli.supervisor.Supervisor.kill_starting`), the ``stopping`` event on ``world/event``
    (``{"why": why}``, at swarm time ``t_s``), :data:`~swarm.transport.stopping.ANNOUNCE_S` for it to be
    heard, then the world, then the rest (:meth:`~swarm.cli.supervisor.Supervisor.stop_all`). ``session``
    None (closed): no announcement."""
    import zenoh

    from swarm.transport.messages import Event, encode
    from swarm.transport.stopping import ANNOUNCE_S, STOPPING

    sup.kill_starting(keep)  # (not up yet: no token, nothing to lose; it would hear no announcement)
    live = [c for c in sup.children.values() if c.running and c.name not in keep]
    if live and session is not None:
        try:
            payload = encode(Event(max(0.0, t_s), STOPPING, {"why": why}))
            session.put(keys.world_event(), payload, congestion_control=zenoh.CongestionControl.BLOCK,
                        express=True)  # fmt: skip
            time.sleep(ANNOUNCE_S)
        except zenoh.ZError as exc:  # the launcher's session closing under it: stop them unannounced
            _LOG.debug("stop not announced: %s", exc)
    sup.stop_all(keep=keep, first=("world",))


def checkpoint_root() -> Path:
    """A private directory (mode 0700: the checkpoints are pickles) for the world's checkpoints (and the
    landing agents'), outside the source tree, removed at exit. In memory (``/dev/shm``) where there is one:
    a checkpoint must survive a killed process, not a machine crash, and a write to tmpfs costs ~20 us per
    tick where one to an ext4 disk cost 1-3 ms here (``BENCHMARKS.md``). One a SIGKILLed launcher left is
    removed by the next (:func:`swarm.private_dirs.private_dir`)."""
    from swarm.private_dirs import private_dir

    shm = Path("/dev/shm")
    base = str(shm) if shm.is_dir() and os.access(shm, os.W_OK | os.X_OK) else None
    return private_dir("swarm-world-", base)
