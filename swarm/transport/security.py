"""Mutual TLS and Zenoh access control for a swarm: who may publish what, enforced by Zenoh itself.

Every process of a secure swarm connects to one Zenoh router over TLS with a certificate of its own,
signed by the swarm's certificate authority (CA). The router (the launcher's session) refuses a link
without such a certificate, and its ``access_control`` section (Zenoh's ACL, eclipse-zenoh 1.10) matches
each link to an identity by the common name (CN) of the certificate it presented
(``subjects[].cert_common_names``), then lets through only the messages that identity may send:

- ``world``: sensors (``agent/*/imu``, ``agent/*/vision``, and ``world/imu``: every vehicle's imu of a tick
  in one message for agent hosts), ``agent/*/truth`` (and ``world/truth``, the mothership's batch),
  ``agent/*/bundle`` and ``world/bundle`` (a lockstep world's ticks in one message), ``world/clock``,
  ``world/event``, and ``agent/*/event`` (contact, collision and keep-out events on the chaser's key);
- ``mothership``: ``agent/*/uwb`` (and ``mothership/uwb``, a slot's ranges in one message for agent hosts;
  ``agent/*/bundle``, a lockstep bundle's ranges), ``agent/*/tdoa`` and ``mothership/tdoa`` (the same for a
  TDoA radio's distance differences) and ``mothership/anchors`` (a publication, a queryable,
  its replies);
- ``agent-<id>``: ``agent/<id>/estimate|guidance|command|event`` only;
- ``dashboard``: the operator's controls only, ``control/run`` (pause, resume, reset, new seed) and
  ``control/fault`` (its Faults panel injects the faults ``swarm fault`` does: an operator's console may
  degrade the sensors on purpose, but it can never fly a vehicle, forge a sensor sample or an event);
- ``launcher``: ``agent/*/event`` (its ``lost`` events), ``control/run`` and ``control/fault`` (an operator's
  ``swarm fault --zenoh-config <dir>/launcher.json5``); the launcher's own session is the router, which
  the ACL does not filter (it also announces a lost world on ``world/event``);

and each may declare the subscribers, queries and liveliness token it needs (:func:`rights` is the whole
table). Everything else is denied (``default_permission: "deny"``): a certificate with an unknown CN
connects but can do nothing; a session without a valid certificate cannot connect at all.

The rules filter what the router *receives* (``flows: ["ingress"]``); what it forwards to a known
identity (``egress``) is allowed within the namespace, since what a process receives is already bounded
by the subscriptions it was allowed to declare. A subscriber declared wider than its allowed key expression
is refused (measured here), so every process subscribes within its keys. The router's own session
(the launcher) is not a remote link: the ACL does not filter it.

:class:`SecureMaterial` makes a throwaway CA and one certificate per identity at run time with the
``openssl`` command (EC P-256, ``subjectAltName`` = the router's addresses, by default ``127.0.0.1`` and
``localhost``: Zenoh's TLS client checks the name it dialled against it), writes them with one Zenoh JSON5
configuration per identity (``<identity>.json5``) into a private temporary directory (mode 0700, outside
the source tree) and removes that directory when closed. Nothing of it is ever committed. In production,
issue the same common names from your own CA and give each process its configuration with
``--zenoh-config`` (docs/usage.md, "Security"); ``python -m swarm.transport.security DIR`` writes a template.
"""

from __future__ import annotations

import argparse
import ipaddress
import json
import os
import secrets
import shutil
import subprocess
from collections.abc import Iterable, Sequence
from pathlib import Path

from swarm.errors import ConfigError, SwarmError
from swarm.private_dirs import private_dir
from swarm.transport.keys import Keys, check_id

__all__ = [
    "ACL_MESSAGES",
    "DEFAULT_HOSTS",
    "SecureMaterial",
    "access_control",
    "agent_name",
    "client_config",
    "identities",
    "issue_certificate",
    "make_ca",
    "rights",
    "router_config",
    "secure_listen",
]

ACL_MESSAGES: tuple[str, ...] = (
    "put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
    "liveliness_token", "declare_liveliness_subscriber", "liveliness_query",
)  # fmt: skip
"""Every message kind a Zenoh 1.10 ACL rule can name (``AclMessage`` in zenoh-config)."""

DEFAULT_HOSTS: tuple[str, ...] = ("127.0.0.1", "localhost")
"""Names every certificate carries in its ``subjectAltName`` (loopback)."""

ROLES: tuple[str, ...] = ("launcher", "world", "mothership", "dashboard")
"""Identities other than the agents; an agent's is :func:`agent_name` ``(id)``."""

_SOURCE_TREE = Path(__file__).resolve().parents[2]  # the repository (or site-packages) holding swarm/
_DAYS = 7  # validity of the throwaway certificates [days]: longer than any run, short if one leaks


def agent_name(agent_id: str) -> str:
    """The identity (certificate common name) of the agent flying vehicle ``agent_id``: ``agent-<id>``."""
    return f"agent-{check_id(agent_id)}"


def identities(vehicle_ids: Iterable[str]) -> tuple[str, ...]:
    """Every identity of a swarm with these vehicles: :data:`ROLES` then one ``agent-<id>`` per vehicle."""
    return (*ROLES, *(agent_name(v) for v in vehicle_ids))


def rights(
    keys: Keys, name: str, mission: str = "docking", platforms: Sequence[str] = ()
) -> dict[str, tuple[str, ...]]:
    """What identity ``name`` may send to the router in a ``mission`` swarm: ACL message kind -> key
    expressions (wildcards included, so a rule on ``<ns>/agent/*/imu`` covers every vehicle). Kinds not
    listed are denied. ConfigError for a name that is not a swarm identity or an unknown mission.
    The world's and each agent's are the mission's (:meth:`swarm.missions.Mission.rights`), the other
    roles' the same in every mission. ``platforms``: a swarm's moving pads' robots (``[platform] id``),
    simulated by the world, which puts each one's shared ``estimate`` that the agents read."""
    from swarm.missions import MISSIONS

    if mission not in MISSIONS:
        raise ConfigError(f"mission must be one of {', '.join(MISSIONS)}, got {mission!r}")
    ns = keys.namespace
    alive = (f"{ns}/alive/**",)
    watch = {"declare_liveliness_subscriber": alive, "liveliness_query": alive}
    vid = None
    if name.startswith("agent-") and len(name) > len("agent-"):
        vid = check_id(name[len("agent-") :], "agent id of identity")
    if name == "world" or vid is not None:
        own = MISSIONS[mission].rights(keys, vid, tuple(platforms))
        if own is None:
            raise ConfigError(f"a {mission} swarm has no {name} process")
        return own | watch
    if name == "mothership":
        return {
            "put": (
                keys.agent_all("uwb"),
                keys.agent_all("tdoa"),
                keys.agent_all("bundle"),
                keys.mothership_uwb(),
                keys.mothership_tdoa(),
                keys.anchors(),
            ),
            "declare_queryable": (keys.anchors(),),
            "reply": (keys.anchors(),),
            # (a vehicle's truth: viewers'; world/event: the launcher's stopping, swarm.transport.stopping)
            "declare_subscriber": (
                keys.world_truth(),
                keys.world_bundle(),
                keys.world_clock(),
                keys.world_event(),
            ),
            "liveliness_token": (f"{ns}/alive/mothership/*",),
            **watch,  # to say when the world is lost
        }
    if name == "dashboard":
        return {
            "put": (keys.run_control(), keys.fault()),
            "declare_subscriber": (keys.everything(),),
            "query": (keys.anchors(),),
            "liveliness_token": (f"{ns}/alive/dashboard/*",),
            **watch,
        }
    if name == "launcher":
        return {
            "put": (keys.agent_all("event"), keys.run_control(), keys.fault()),
            "declare_subscriber": (keys.world_event(), keys.world_clock(), keys.agent_all("event"),
                                   keys.agent_all("guidance")),
            "liveliness_token": (f"{ns}/alive/launcher/*",),
            **watch,
        }  # fmt: skip
    raise ConfigError(f"security identity must be one of {', '.join(ROLES)} or agent-<id>, got {name!r}")


def access_control(
    keys: Keys, names: Sequence[str], mission: str = "docking", platforms: Sequence[str] = ()
) -> dict:
    """Zenoh's ``access_control`` configuration section (for the router) that gives each identity in
    ``names`` exactly its :func:`rights` (in a ``mission`` swarm) on what the router receives, lets the
    router forward anything within the namespace to them, and denies everything else, including every
    message of a certificate whose common name is not in ``names``. ``platforms``: :func:`rights`'."""
    names = tuple(dict.fromkeys(names))
    rules: list[dict] = [{
        "id": "forward", "permission": "allow", "flows": ["egress"], "messages": list(ACL_MESSAGES),
        "key_exprs": [keys.everything()],
    }]  # fmt: skip
    subjects: list[dict] = [{"id": "swarm", "cert_common_names": list(names)}]
    policies: list[dict] = [{"id": "forward", "rules": ["forward"], "subjects": ["swarm"]}]
    for name in names:
        own = []
        for kind, key_exprs in rights(keys, name, mission, platforms).items():
            rule_id = f"{name}:{kind}"
            rules.append({
                "id": rule_id, "permission": "allow", "flows": ["ingress"], "messages": [kind],
                "key_exprs": list(key_exprs),
            })  # fmt: skip
            own.append(rule_id)
        subjects.append({"id": name, "cert_common_names": [name]})
        policies.append({"id": name, "rules": own, "subjects": [name]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


# ------------------------------------------------------------------------------------------ certificates


def _openssl(*args: str, cwd: Path) -> None:
    try:
        done = subprocess.run(["openssl", *args], cwd=cwd, capture_output=True, text=True, timeout=60)
    except FileNotFoundError:
        raise SwarmError("--secure needs the openssl command, which was not found on PATH") from None
    if done.returncode != 0:
        raise SwarmError(f"openssl {args[0]} failed: {done.stderr.strip()}")


def _new_key(directory: Path, name: str) -> Path:
    path = directory / f"{name}.key"
    _openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", path.name,
             cwd=directory)  # fmt: skip
    path.chmod(0o600)
    return path


def _san(hosts: Iterable[str]) -> str:
    entries = []
    for host in dict.fromkeys(hosts):
        try:
            entries.append(f"IP:{ipaddress.ip_address(host.strip('[]'))}")
        except ValueError:
            entries.append(f"DNS:{host}")
    return ",".join(entries)


def make_ca(directory: Path, days: int = _DAYS) -> tuple[Path, Path]:
    """A new self-signed certificate authority in ``directory``: ``(ca.pem, ca.key)``."""
    directory = Path(directory)
    key = _new_key(directory, "ca")
    _openssl("req", "-x509", "-new", "-key", key.name, "-sha256", "-days", str(days),
             "-subj", f"/CN=tpods-swarm-ca-{secrets.token_hex(4)}",
             "-addext", "basicConstraints=critical,CA:TRUE",
             "-addext", "keyUsage=critical,keyCertSign,cRLSign",
             "-out", "ca.pem", cwd=directory)  # fmt: skip
    return directory / "ca.pem", key


def issue_certificate(
    directory: Path, name: str, hosts: Iterable[str] = DEFAULT_HOSTS, days: int = _DAYS
) -> tuple[Path, Path]:
    """A certificate with common name ``name`` and ``subjectAltName`` ``hosts``, signed by the CA in
    ``directory`` (``ca.pem``, ``ca.key``, from :func:`make_ca`): ``(<name>.pem, <name>.key)``. Usable for
    both ends of a TLS link (``extendedKeyUsage`` serverAuth and clientAuth)."""
    directory = Path(directory)
    check_id(name, "certificate common name")
    key = _new_key(directory, name)
    ext = directory / f"{name}.ext"
    ext.write_text(
        "basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n"
        f"extendedKeyUsage=serverAuth,clientAuth\nsubjectAltName={_san(hosts)}\n"
    )
    try:
        _openssl(
            "req", "-new", "-key", key.name, "-subj", f"/CN={name}", "-out", f"{name}.csr", cwd=directory
        )
        _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
                 "-set_serial", str(secrets.randbits(63)), "-days", str(days), "-sha256",
                 "-extfile", ext.name,
                 "-out", f"{name}.pem", cwd=directory)  # fmt: skip
    finally:
        ext.unlink(missing_ok=True)
        (directory / f"{name}.csr").unlink(missing_ok=True)
    return directory / f"{name}.pem", key


# ------------------------------------------------------------------------------------------ configs


def client_config(directory: Path, name: str) -> dict:
    """Zenoh configuration of a client with identity ``name``: TLS only, its certificate and key
    (``<name>.pem``, ``<name>.key``) presented to the router, the router checked against ``ca.pem``.
    The mode and the router's endpoint come from the flags (``--mode client --connect tls/...``)."""
    d = Path(directory).resolve()
    return {
        "mode": "client",
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"protocols": ["tls"], "tls": {
            "root_ca_certificate": str(d / "ca.pem"),
            "enable_mtls": True,
            "connect_certificate": str(d / f"{name}.pem"),
            "connect_private_key": str(d / f"{name}.key"),
            "verify_name_on_connect": True,
        }}},
    }  # fmt: skip


def router_config(directory: Path, name: str, acl: dict) -> dict:
    """Zenoh configuration of the swarm's router with identity ``name``: TLS only, client certificates
    required and checked against ``ca.pem`` (mutual TLS), and the ``access_control`` section ``acl``."""
    config = client_config(directory, name)
    config["mode"] = "router"
    tls = config["transport"]["link"]["tls"]
    tls["listen_certificate"] = tls["connect_certificate"]
    tls["listen_private_key"] = tls["connect_private_key"]
    config["access_control"] = acl
    return config


def secure_listen(listen: Sequence[str] | None, zenoh_config: str | None, free_port: int) -> list[str]:
    """The router's listen endpoints for ``swarm launch --secure``: ``listen`` if given (each must be
    ``tls/...``), else ``tls/127.0.0.1:<free_port>``. ConfigError if ``--zenoh-config`` is also given
    (the secure configuration is generated: give your own per process instead, docs/usage.md "Security")."""
    if zenoh_config:
        raise ConfigError(
            "--secure and --zenoh-config cannot be used together: --secure generates each process's Zenoh "
            f"configuration (got --zenoh-config {zenoh_config!r}); for your own, start the processes yourself"
        )
    if not listen:
        return [f"tls/127.0.0.1:{free_port}"]
    plain = [e for e in listen if not e.startswith("tls/")]
    if plain:
        raise ConfigError(f"--secure needs --listen tls/<host>:<port> endpoints, got {plain[0]!r}")
    return list(listen)


def _listen_hosts(listen: Iterable[str]) -> tuple[str, ...]:
    hosts = []
    for endpoint in listen:
        address = endpoint.partition("/")[2].split("?")[0].split("#")[0]
        host = address.rpartition(":")[0].strip("[]")
        if host and host not in ("0.0.0.0", "::"):  # a wildcard listener is dialled on loopback
            hosts.append(host)
    return tuple(hosts)


class SecureMaterial:
    """A throwaway CA, one certificate per identity and one Zenoh configuration per identity, in a private
    temporary directory that :meth:`close` (or leaving the ``with`` block) removes.

    ``with SecureMaterial(keys, ["chaser", "target"]) as m: m.config_file("world")`` -> the world's
    ``--zenoh-config``; ``m.config_file("launcher")`` is the router's (with the ACL). ``listen`` adds the
    router's listen hosts to every certificate's ``subjectAltName``. SwarmError if ``openssl`` fails;
    ConfigError if the temporary directory would be inside the source tree (``TMPDIR`` pointing there)."""

    def __init__(
        self,
        keys: Keys,
        vehicle_ids: Iterable[str],
        listen: Iterable[str] = (),
        mission: str = "docking",
        platforms: Sequence[str] = (),
    ) -> None:
        self.keys = keys
        self.names = identities(vehicle_ids)
        self.hosts = (*DEFAULT_HOSTS, *_listen_hosts(listen))
        self.directory = private_dir("tpods-secure-").resolve()  # mode 0700; a SIGKILLed owner's: removed
        try:
            if self.directory.is_relative_to(_SOURCE_TREE):
                raise ConfigError(
                    f"--secure: the temporary directory {str(self.directory)!r} is inside the source tree "
                    f"{str(_SOURCE_TREE)!r}: point TMPDIR elsewhere (keys must never land in the repository)"
                )
            os.chmod(self.directory, 0o700)
            make_ca(self.directory)
            acl = access_control(keys, self.names, mission, platforms)
            for name in self.names:
                issue_certificate(self.directory, name, self.hosts)
                config = router_config(self.directory, name, acl) if name == "launcher" else None
                self._write(name, config or client_config(self.directory, name))
        except BaseException:
            self.close()
            raise

    def _write(self, name: str, config: dict) -> None:
        path = self.directory / f"{name}.json5"
        path.write_text(json.dumps(config, indent=1) + "\n")  # JSON is JSON5
        path.chmod(0o600)

    def config_file(self, name: str) -> Path:
        """The Zenoh configuration file of identity ``name`` (``launcher``: the router's)."""
        if name not in self.names:
            raise ConfigError(f"no security identity {name!r} in this swarm (have {', '.join(self.names)})")
        return self.directory / f"{name}.json5"

    def issue(self, name: str) -> tuple[Path, Path]:
        """One more certificate from this swarm's CA (a driver, or a test's intruder); its common name
        has no rights unless it is one of :attr:`names`."""
        return issue_certificate(self.directory, name, self.hosts)

    def close(self) -> None:
        """Remove the directory with every key in it. Idempotent."""
        shutil.rmtree(self.directory, ignore_errors=True)

    def __enter__(self) -> SecureMaterial:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def main(argv: list[str] | None = None) -> int:
    """``python -m swarm.transport.security DIR``: write a CA, certificates and per-process Zenoh
    configurations into ``DIR`` (kept): a template for a swarm whose processes are started by hand."""
    p = argparse.ArgumentParser(prog="python -m swarm.transport.security", description=main.__doc__)
    p.add_argument("directory", type=Path, help="where to write (created, mode 0700; must not exist)")
    p.add_argument("--namespace", default="tpods", help="key namespace of the swarm (default tpods)")
    p.add_argument("--vehicles", nargs="+", default=["chaser", "target"], help="agent ids (chaser target)")
    p.add_argument("--host", action="append", default=[], help="router address for the certificates")
    args = p.parse_args(argv)
    keys = Keys(args.namespace)
    names = identities(args.vehicles)
    d = args.directory
    d.mkdir(mode=0o700, parents=True)
    make_ca(d)
    hosts = (*DEFAULT_HOSTS, *args.host)
    for name in names:
        issue_certificate(d, name, hosts)
        config = router_config(d, name, access_control(keys, names)) if name == "launcher" else None
        (d / f"{name}.json5").write_text(json.dumps(config or client_config(d, name), indent=1) + "\n")
    print(f"wrote a CA, {len(names)} certificates and configs to {d} (launcher.json5 is the router's)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
