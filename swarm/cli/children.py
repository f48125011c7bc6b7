"""What every launcher shares (``swarm launch`` of a docking or a landing scenario): the children's common
flags, the client endpoint of the launcher's router, and the ``--record`` child."""

from __future__ import annotations

import argparse
import threading

from swarm.errors import ConfigError


def router_args(args: argparse.Namespace, listen: list[str]):
    """The launcher's own Zenoh session: a router on ``listen`` with the launch flags' connect, config,
    scouting and lease."""
    from swarm.transport.session import ZenohArgs

    return ZenohArgs(
        mode="router", connect=tuple(args.connect or ()), listen=tuple(listen), config_file=args.zenoh_config,
        multicast_scouting=args.multicast_scouting, lease_ms=args.lease_ms,
    )  # fmt: skip


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
    common += ["--mode", "client", "--connect", endpoint]
    if args.lease_ms:
        common += ["--lease-ms", str(args.lease_ms)]
    return common


def check_record(args: argparse.Namespace) -> None:
    rec = getattr(args, "record", None)
    if rec is None:
        return
    if rec.suffix != ".mcap":
        raise ConfigError(f"--record: the recording's name must end in .mcap, got {str(rec)!r}")
    if not rec.resolve().parent.is_dir():
        raise ConfigError(f"--record: no such directory {str(rec.parent)!r}")
    if getattr(args, "secure", False):
        raise ConfigError(
            "--record and --secure: the recorder would need its own identity and ACL rule; record a secure "
            "swarm with `swarm record` and a certificate of your own"
        )


def start_recorder(args, endpoint, sup, Child) -> None:
    """The recorder child (``--record``), kept across runs; the run starts once it is subscribed."""
    old = sup.children.get("recorder")
    if args.record is None or (old is not None and old.running):
        return
    ready = threading.Event()

    def on_line(line: str) -> None:
        if line.startswith("recording "):
            ready.set()

    rec = ["swarm.cli.main", "record", str(args.record.resolve()), "--namespace", args.namespace,
           "--mode", "client", "--connect", endpoint]  # fmt: skip
    sup.start(Child("recorder", rec, restartable=False, on_line=on_line))
    if not ready.wait(60.0):
        raise ConfigError(f"--record: the recorder did not subscribe within 60 s (writing {args.record})")
    print(f"recording to {args.record}", flush=True)
