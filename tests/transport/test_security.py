"""Mutual TLS and Zenoh access control (``swarm.transport.security``, ``swarm launch --secure``).

Oracles: the rights the issue lists (written out below as literal tables, independent of the module's
code), Zenoh's own key-expression inclusion (``zenoh.KeyExpr.includes``) to evaluate the generated rules,
``openssl`` to read the certificates back, real Zenoh sessions through a router opened with the generated
configuration (what a subscriber of another identity receives), Zenoh's ACL log, and the in-process
simulation for the launched run. Every Zenoh test runs on loopback with free ports.
"""

from __future__ import annotations

import json
import os
import re
import signal
import stat
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
import zenoh

from swarm.errors import ConfigError
from swarm.scenario import load_scenario
from swarm.sim.docking import run_docking
from swarm.transport.keys import AGENT_KINDS, Keys
from swarm.transport.messages import Bundle, Clock, Command, DropCounter, Imu, bundle_messages, decode, encode
from swarm.transport.recording import read_recording
from swarm.transport.security import (
    ACL_MESSAGES,
    SecureMaterial,
    client_config,
    issue_certificate,
    make_ca,
    secure_listen,
)
from swarm.transport.security import main as security_main
from tests.transport.procs import REPO, Procs, free_port, wait_until

NS = "sectest"
VEHICLES = ("chaser", "target")
K = Keys(NS)

# What each identity may publish, from issue 7 and docs/protocol.md ("Access control"): (identity, key).
MAY_PUT = {
    "world": {K.imu(v) for v in VEHICLES} | {K.vision(v) for v in VEHICLES} | {K.truth(v) for v in VEHICLES}
    | {K.event(v) for v in VEHICLES} | {K.bundle(v) for v in VEHICLES}
    | {K.world_imu(), K.world_vision(), K.world_truth(), K.world_bundle(), K.world_clock(), K.world_event()},
    "mothership": {K.uwb(v) for v in VEHICLES} | {K.tdoa(v) for v in VEHICLES}
    | {K.bundle(v) for v in VEHICLES} | {K.mothership_uwb(), K.mothership_tdoa(), K.anchors()},
    "agent-chaser": {K.estimate("chaser"), K.guidance("chaser"), K.command("chaser"), K.commands("chaser"),
                     K.event("chaser")},
    "agent-target": {K.estimate("target"), K.guidance("target"), K.command("target"), K.commands("target"),
                     K.event("target")},
    "dashboard": {K.run_control(), K.fault()},  # the operator's console: run controls and faults
    "launcher": {K.event(v) for v in VEHICLES} | {K.run_control(), K.fault()},
}  # fmt: skip
ALL_KEYS = sorted({getattr(K, kind)(v) for kind in AGENT_KINDS for v in VEHICLES}
                  | {K.world_clock(), K.world_event(), K.world_imu(), K.world_vision(), K.world_truth(),
                     K.world_bundle(), K.anchors(), K.mothership_uwb(), K.mothership_tdoa(), K.run_control(),
                     K.fault()})  # fmt: skip


def _may(acl: dict, name: str, message: str, key: str, flow: str = "ingress") -> bool:
    """Whether the generated ``acl`` allows ``message`` on ``key`` from a link whose certificate CN is
    ``name`` (Zenoh's semantics with only allow rules: some rule of a policy whose subject names ``name``
    covers the message, the flow and a key expression that includes ``key``; else the default)."""
    subjects = {s["id"] for s in acl["subjects"] if name in s.get("cert_common_names", [])}
    rules = {r["id"]: r for r in acl["rules"]}
    for policy in acl["policies"]:
        if not subjects & set(policy["subjects"]):
            continue
        for rid in policy["rules"]:
            r = rules[rid]
            if message in r["messages"] and flow in r.get("flows", ["ingress", "egress"]):
                if any(zenoh.KeyExpr(ke).includes(zenoh.KeyExpr(key)) for ke in r["key_exprs"]):
                    assert r["permission"] == "allow"
                    return True
    return acl["default_permission"] == "allow"


# --------------------------------------------------------------------------------------- generated config


@pytest.fixture(scope="module")
def material():
    with SecureMaterial(K, VEHICLES) as m:
        m.issue("intruder")  # signed by the swarm's CA, but a common name without rights
        yield m


@pytest.fixture(scope="module")
def acl(material):
    return json.loads(
        zenoh.Config.from_file(str(material.config_file("launcher"))).get_json("access_control")
    )


def test_every_identity_may_put_exactly_the_keys_the_issue_lists(acl):
    for name, want in MAY_PUT.items():
        got = {key for key in ALL_KEYS if _may(acl, name, "put", key)}
        assert got == want, name


def test_no_identity_may_delete_and_only_the_mothership_answers_queries(acl):
    for name in MAY_PUT:
        assert not any(_may(acl, name, "delete", key) for key in ALL_KEYS), name
        serves = {key for key in ALL_KEYS if _may(acl, name, "declare_queryable", key)}
        replies = {key for key in ALL_KEYS if _may(acl, name, "reply", key)}
        assert serves == replies == ({K.anchors()} if name == "mothership" else set()), name
    askers = {name for name in MAY_PUT if _may(acl, name, "query", K.anchors())}
    assert askers == {"dashboard"}


def test_each_identity_may_subscribe_to_what_its_process_reads_and_agents_never_to_truth(acl):
    want = {
        "world": {K.command(v) for v in VEHICLES} | {K.commands(v) for v in VEHICLES}
        | {K.run_control(), K.fault()},
        # batches, not each vehicle's; world/event: the launcher's stopping
        "mothership": {K.world_truth(), K.world_bundle(), K.world_clock(), K.world_event()},
        "agent-chaser": {K.imu("chaser"), K.uwb("chaser"), K.tdoa("chaser"), K.vision("chaser"),
                         K.bundle("chaser")}
        | {K.world_clock()}
        | {K.estimate(v) for v in VEHICLES}
        | {K.world_imu(), K.world_vision(), K.mothership_uwb(), K.mothership_tdoa(), K.world_event()},
        "dashboard": set(ALL_KEYS),
        "launcher": {K.world_event(), K.world_clock()} | {K.event(v) for v in VEHICLES}
        | {K.guidance(v) for v in VEHICLES},
    }  # fmt: skip
    for name, keys in want.items():
        assert {key for key in ALL_KEYS if _may(acl, name, "declare_subscriber", key)} == keys, name
    # the wildcards the processes declare are allowed as declared (a wider declaration would be refused)
    assert _may(acl, "world", "declare_subscriber", K.agent_all("command"))
    assert not _may(acl, "mothership", "declare_subscriber", K.agent_all("truth"))  # it takes world/truth
    assert not _may(acl, "agent-chaser", "declare_subscriber", K.agent_topics("chaser"))


def test_a_landing_swarms_world_also_sends_ranges_and_fixes_and_its_agents_read_their_own(material):
    """Mission ``landing`` (``swarm launch landing-swarm --secure``): the landing world puts every UAV's
    imu, uwb (or tdoa, on a TDoA radio), gnss, rangefinder, barometer, vision and truth (it is its own
    radio network: there is no mothership) and reads the commands, the faults and the run controls; a
    landing agent reads its own sensors, gnss included, never another UAV's, and puts what a docking agent
    puts; a docking world may put neither ranges nor fixes."""
    from swarm.transport.security import access_control, identities, rights

    acl = access_control(K, identities(VEHICLES), "landing")
    keys = sorted(set(ALL_KEYS) | {K.gnss(v) for v in VEHICLES} | {K.rangefinder(v) for v in VEHICLES}
                  | {K.barometer(v) for v in VEHICLES})  # fmt: skip
    world_puts = {key for key in keys if _may(acl, "world", "put", key)}
    sensors = ("imu", "uwb", "tdoa", "gnss", "rangefinder", "barometer", "vision", "truth")
    assert world_puts == {getattr(K, kind)(v) for kind in sensors for v in VEHICLES} | {
        K.world_clock(),
        K.world_event(),
    }
    assert {key for key in keys if _may(acl, "world", "declare_subscriber", key)} == {
        K.command(v) for v in VEHICLES
    } | {K.fault(), K.run_control()}  # and the run-time faults (swarm fault), pause and resume
    reads = {key for key in keys if _may(acl, "agent-chaser", "declare_subscriber", key)}
    own = (K.imu, K.uwb, K.tdoa, K.gnss, K.rangefinder, K.barometer, K.vision)
    assert reads == {key("chaser") for key in own} | {K.world_event()}
    # what a docking agent puts, but the commands batch (a landing host sends each UAV's on its own key)
    landing_puts = MAY_PUT["agent-chaser"] - {K.commands("chaser")}
    assert {key for key in keys if _may(acl, "agent-chaser", "put", key)} == landing_puts
    docking = access_control(K, identities(VEHICLES))
    assert not any(
        _may(docking, "world", "put", key)
        for v in VEHICLES
        for key in (K.uwb(v), K.gnss(v), K.rangefinder(v), K.barometer(v))
    )
    # a moving pad's robot (swarm/scenarios/landing-moving.toml): the world puts its shared estimate, an
    # agent reads it; neither gains another vehicle's estimate
    moving = access_control(K, identities(VEHICLES), "landing", platforms=("robot",))
    extra = {K.estimate("robot")}
    assert {key for key in [*keys, *extra] if _may(moving, "world", "put", key)} == world_puts | extra
    assert {key for key in [*keys, *extra] if _may(moving, "agent-chaser", "declare_subscriber", key)} == (
        reads | extra
    )
    with pytest.raises(ConfigError, match="mission must be one of docking, landing, got 'orbit'"):
        rights(K, "world", "orbit")


def test_liveliness_tokens_only_under_the_identitys_own_role_and_id(acl):
    def token(role: str, pid: str) -> str:
        return K.alive(role, pid)

    assert _may(acl, "agent-chaser", "liveliness_token", token("agent", "chaser"))
    assert not _may(acl, "agent-chaser", "liveliness_token", token("agent", "target"))
    assert not _may(acl, "agent-chaser", "liveliness_token", token("world", "world"))
    for role in ("world", "mothership", "dashboard", "launcher"):
        assert _may(acl, role, "liveliness_token", token(role, role))
        assert not _may(acl, role, "liveliness_token", token("agent", "chaser")), role
    for name in ("world", "mothership", "agent-chaser", "dashboard", "launcher"):  # they watch liveliness
        assert _may(acl, name, "declare_liveliness_subscriber", K.alive_all()), name
        assert _may(acl, name, "liveliness_query", K.alive_all()), name


def test_an_unknown_common_name_may_do_nothing_and_the_router_forwards_only_within_the_namespace(acl):
    for message in ACL_MESSAGES:
        for flow in ("ingress", "egress"):
            assert not any(_may(acl, "intruder", message, key, flow) for key in ALL_KEYS), (message, flow)
    assert acl["enabled"] is True and acl["default_permission"] == "deny"
    for message in ACL_MESSAGES:
        assert _may(acl, "agent-chaser", message, K.truth("target"), "egress")
        assert not _may(acl, "agent-chaser", message, "other/agent/chaser/imu", "egress")


def test_material_is_private_outside_the_repository_and_removed_on_close():
    with SecureMaterial(K, VEHICLES) as m:
        d = m.directory
        assert not d.is_relative_to(REPO.resolve())
        assert stat.S_IMODE(os.stat(d).st_mode) == 0o700
        keys = sorted(d.glob("*.key"))
        assert [k.stem for k in keys] == sorted(["ca", *m.names])
        assert all(stat.S_IMODE(os.stat(k).st_mode) == 0o600 for k in keys)
    assert not d.exists()


def test_material_refuses_a_temporary_directory_inside_the_source_tree_and_leaves_nothing(monkeypatch):
    import tempfile

    import swarm.transport.security as security

    tmp = Path(tempfile.gettempdir()).resolve()
    before = set(tmp.glob("tpods-secure-*"))
    monkeypatch.setattr(security, "_SOURCE_TREE", tmp)  # as if TMPDIR pointed into the repository
    with pytest.raises(ConfigError, match=r"inside the source tree .*point TMPDIR elsewhere"):
        SecureMaterial(K, VEHICLES)
    assert set(tmp.glob("tpods-secure-*")) == before


def test_certificates_carry_the_identity_as_common_name_and_loopback_as_subject_alt_name(material):
    d = material.directory
    for name in material.names:
        text = subprocess.run(
            ["openssl", "x509", "-in", str(d / f"{name}.pem"), "-noout", "-subject",
             "-ext", "subjectAltName"],
            capture_output=True, text=True, check=True,
        ).stdout  # fmt: skip
        assert re.search(rf"subject=CN ?= ?{re.escape(name)}$", text, re.M), text
        assert "IP Address:127.0.0.1" in text and "DNS:localhost" in text, text
        verify = subprocess.run(["openssl", "verify", "-CAfile", str(d / "ca.pem"), str(d / f"{name}.pem")],
                                capture_output=True, text=True)  # fmt: skip
        assert verify.returncode == 0, verify.stdout + verify.stderr


def test_the_template_writer_makes_configs_zenoh_loads_for_every_identity(tmp_path):
    d = tmp_path / "swarm-pki"
    assert security_main([str(d), "--namespace", NS, "--vehicles", *VEHICLES, "--host", "10.0.0.7"]) == 0
    assert stat.S_IMODE(os.stat(d).st_mode) == 0o700
    for name in ("launcher", "world", "mothership", "dashboard", "agent-chaser", "agent-target"):
        conf = zenoh.Config.from_file(str(d / f"{name}.json5"))
        tls = json.loads(conf.get_json("transport/link/tls"))
        assert Path(tls["connect_certificate"]) == d / f"{name}.pem" and tls["enable_mtls"] is True
    acl = json.loads(zenoh.Config.from_file(str(d / "launcher.json5")).get_json("access_control"))
    assert _may(acl, "agent-chaser", "put", K.command("chaser"))
    assert not _may(acl, "world", "put", K.command("chaser"))
    cert = str(d / "launcher.pem")
    san = subprocess.run(["openssl", "x509", "-in", cert, "-noout", "-ext", "subjectAltName"],
                         capture_output=True, text=True, check=True).stdout  # fmt: skip
    assert "IP Address:10.0.0.7" in san and "IP Address:127.0.0.1" in san


def test_secure_refuses_zenoh_config_and_plain_listen_endpoints():
    with pytest.raises(ConfigError, match=r"--secure and --zenoh-config cannot be used together"):
        secure_listen(None, "mine.json5", 7447)
    with pytest.raises(ConfigError, match=r"--secure needs --listen tls/<host>:<port>.*'tcp/127.0.0.1:7447'"):
        secure_listen(["tcp/127.0.0.1:7447"], None, 7447)
    assert secure_listen(None, None, 7447) == ["tls/127.0.0.1:7447"]
    cmd = [sys.executable, "-m", "swarm.cli.main", "launch", "docking", "--headless", "--secure",
           "--zenoh-config", "mine.json5"]  # fmt: skip
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=60, cwd=REPO)
    assert r.returncode == 2, r.stderr
    assert "--secure and --zenoh-config cannot be used together" in r.stderr
    assert "Traceback" not in r.stderr


# --------------------------------------------------------------------------------------- through a router


def _client(conf: dict | Path, endpoint: str, mode: str = "client") -> zenoh.Config:
    c = (
        zenoh.Config.from_file(str(conf))
        if isinstance(conf, Path)
        else zenoh.Config.from_json5(json.dumps(conf))
    )
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5("connect/endpoints", json.dumps([endpoint]))
    c.insert_json5("scouting/multicast/enabled", "false")
    return c


@pytest.fixture(scope="module")
def router(material):
    """The launcher's router alone: opened with the generated configuration on a free TLS port."""
    endpoint = f"tls/127.0.0.1:{free_port()}"
    conf = zenoh.Config.from_file(str(material.config_file("launcher")))
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    with zenoh.open(conf):
        yield endpoint


def _open_as(material, name: str, endpoint: str) -> zenoh.Session:
    conf = material.config_file(name) if name in material.names else client_config(material.directory, name)
    return zenoh.open(_client(conf, endpoint))


class Inbox:
    """Payloads received by a callback subscriber, thread-safe."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.items: list[tuple[str, bytes]] = []

    def __call__(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.items.append((str(sample.key_expr), sample.payload.to_bytes()))

    def payloads(self) -> set[bytes]:
        with self.lock:
            return {p for _, p in self.items}


def test_through_the_router_each_identity_reaches_subscribers_only_on_its_own_keys(material, router):
    """Every identity (and a CA-signed intruder) puts a tagged payload on every key; a subscriber of
    another session (the dashboard's identity, which may read everything) must get exactly the allowed
    ones. After each identity's puts it puts a fence on a key it may use: the router forwards one link's
    messages in order, so once the fence is in, a denied put that had been let through would be in too.
    The intruder also subscribes to everything and hears nobody (only its own puts, delivered locally)."""
    names = [*MAY_PUT, "intruder"]
    fence_key = {n: sorted(MAY_PUT[n])[0] for n in MAY_PUT}
    inbox, intruder_inbox = Inbox(), Inbox()
    sessions = {n: _open_as(material, n, router) for n in names}
    try:
        with _open_as(material, "dashboard", router) as monitor:
            monitor.declare_subscriber(K.everything(), inbox)
            sessions["intruder"].declare_subscriber(K.everything(), intruder_inbox)
            wait_until(lambda: all(s.info.routers_zid() for s in sessions.values()), 10.0, "every link")
            # a publisher's first puts may precede the router's news of the subscriber: prime each path
            for n, s in sessions.items():
                if n in fence_key:
                    wait_until(lambda s=s, n=n: _primed(s, fence_key[n], inbox), 10.0, f"{n}'s first put")
            for n, s in sessions.items():
                for key in ALL_KEYS:
                    s.put(key, f"{n}|{key}".encode())
                if n in fence_key:
                    s.put(fence_key[n], f"fence|{n}".encode())
            wait_until(lambda: {f"fence|{n}".encode() for n in fence_key} <= inbox.payloads(), 10.0, "fences")
            time.sleep(0.5)  # the intruder has no key to fence with: a bounded wait for its puts
            got = {
                p.decode() for p in inbox.payloads() if b"|" in p and not p.startswith((b"fence", b"prime"))
            }
    finally:
        for s in sessions.values():
            s.close()
    want = {f"{n}|{key}" for n, keys in MAY_PUT.items() for key in keys}
    assert got == want, (sorted(got - want), sorted(want - got))
    assert intruder_inbox.payloads() == {f"intruder|{key}".encode() for key in ALL_KEYS}


def _primed(session: zenoh.Session, key: str, inbox: Inbox) -> bool:
    tag = f"prime|{uuid.uuid4().hex}".encode()
    session.put(key, tag)
    deadline = time.monotonic() + 0.2
    while time.monotonic() < deadline:
        if tag in inbox.payloads():
            return True
        time.sleep(0.005)
    return False


def test_an_agent_subscriber_gets_its_own_sensors_and_never_the_truth_even_on_a_wider_key(material, router):
    own, truth, wide = Inbox(), Inbox(), Inbox()
    with _open_as(material, "agent-chaser", router) as agent, _open_as(material, "world", router) as world:
        agent.declare_subscriber(K.imu("chaser"), own)
        agent.declare_subscriber(K.agent_all("truth"), truth)
        agent.declare_subscriber(K.agent_topics("chaser"), wide)  # wider than any of its rules
        wait_until(lambda: world.info.routers_zid() and agent.info.routers_zid(), 10.0, "links")
        i = 0
        while not own.payloads():  # until the subscription has reached the world's session
            world.put(K.truth("chaser"), f"truth{i}".encode())
            world.put(K.imu("chaser"), f"imu{i}".encode())
            i += 1
            assert i < 1000, "the agent never got its imu"
            time.sleep(0.01)
        world.put(K.truth("chaser"), b"truth-last")
        world.put(K.imu("chaser"), b"imu-last")  # in order after truth-last on the same link
        wait_until(lambda: b"imu-last" in own.payloads(), 10.0, "the last imu")
    assert truth.payloads() == set()
    # the wider subscription itself was refused: it sees only what the session's allowed imu subscription
    # brings in (Zenoh hands a received sample to every matching local subscriber), never the truth
    assert wide.payloads() <= own.payloads() and b"imu-last" in wide.payloads()


def test_only_the_mothership_may_serve_anchors_and_an_agent_may_not_ask(material, router):
    with (
        _open_as(material, "mothership", router) as ms,
        _open_as(material, "world", router) as world,
        _open_as(material, "dashboard", router) as dash,
        _open_as(material, "agent-chaser", router) as agent,
    ):
        ms.declare_queryable(K.anchors(), lambda q: q.reply(K.anchors(), b"from-mothership"))
        world.declare_queryable(K.anchors(), lambda q: q.reply(K.anchors(), b"from-world"))

        def ask(session: zenoh.Session) -> list[bytes]:
            replies = session.get(K.anchors(), target=zenoh.QueryTarget.ALL, timeout=1.0)  # every queryable
            return sorted(r.ok.payload.to_bytes() for r in replies if r.ok is not None)

        wait_until(lambda: ask(dash) == [b"from-mothership"], 10.0, "the mothership's reply only")
        assert ask(agent) == []


def test_a_session_without_the_swarms_certificate_cannot_connect(material, router, tmp_path):
    """Plain TCP, TLS without a client certificate, and a ``world`` certificate from another CA: a client
    session does not open (Zenoh refuses the link). A peer session opens (peers do not need a link to
    start) but never gets one: no router, no data."""
    make_ca(tmp_path)
    forged = issue_certificate(tmp_path, "world")  # the right name, the wrong CA
    port = router.rpartition(":")[2]
    ca = str(material.directory / "ca.pem")
    attempts = {
        "plain tcp": {"connect": f"tcp/127.0.0.1:{port}", "tls": {}},
        "tls without a certificate": {"connect": router, "tls": {"root_ca_certificate": ca}},
        "a certificate of another CA": {"connect": router, "tls": {
            "root_ca_certificate": ca, "enable_mtls": True,
            "connect_certificate": str(forged[0]), "connect_private_key": str(forged[1])}},
    }  # fmt: skip
    for what, a in attempts.items():
        conf = {"transport": {"link": {"tls": a["tls"]}}} if a["tls"] else {}
        with pytest.raises(zenoh.ZError, match="Unable to connect"):
            zenoh.open(_client(conf, a["connect"])).close()
        heard, leaked = Inbox(), Inbox()
        with (
            zenoh.open(_client(conf, a["connect"], mode="peer")) as peer,
            _open_as(material, "world", router) as world,
            _open_as(material, "dashboard", router) as monitor,
        ):
            peer.declare_subscriber(K.imu("chaser"), heard)
            monitor.declare_subscriber(K.command("chaser"), leaked)
            for _ in range(20):
                world.put(K.imu("chaser"), b"x")
                peer.put(K.command("chaser"), b"y")
                time.sleep(0.01)
            assert peer.info.routers_zid() == [] and peer.info.peers_zid() == [], what
        assert heard.payloads() == set() and leaked.payloads() == set(), what


# --------------------------------------------------------------------------------------- Zenoh's own log

_ROUTER = """
import json, sys, threading, zenoh
zenoh.try_init_log_from_env()
conf = zenoh.Config.from_file(sys.argv[1])
conf.insert_json5("listen/endpoints", json.dumps([sys.argv[2]]))
with zenoh.open(conf):
    print("router up", flush=True)
    threading.Event().wait()
"""


def test_zenoh_logs_each_denied_put_with_the_certificates_common_name(material):
    """The router of the generated configuration in a process of its own with Zenoh's ACL log on (trace):
    the dashboard's and the target agent's puts on the chaser's command are logged as denied, the
    chaser's own as allowed."""
    endpoint = f"tls/127.0.0.1:{free_port()}"
    env = {"RUST_LOG": "zenoh::net::routing::interceptor::access_control=trace", "NO_COLOR": "1"}
    with Procs() as procs:
        router = procs.start(
            [sys.executable, "-c", _ROUTER, str(material.config_file("launcher")), endpoint], env
        )
        router.wait_for_line(r"^router up", 30.0)
        got = Inbox()
        with _open_as(material, "world", endpoint) as world:
            world.declare_subscriber(K.agent_all("command"), got)  # so that the publishers do send
            for name in ("dashboard", "agent-target", "agent-chaser"):
                with _open_as(material, name, endpoint) as s:
                    pub = s.declare_publisher(K.command("chaser"))
                    wait_until(lambda pub=pub: pub.matching_status.matching, 10.0, f"{name} sees the world")
                    pub.put(name.encode())
            wait_until(lambda: b"agent-chaser" in got.payloads(), 10.0, "the chaser's own command")
        key = re.escape(K.command("chaser"))
        for name, verdict in (("dashboard", "unauthorized"), ("agent-target", "unauthorized"),
                              ("agent-chaser", "authorized")):  # fmt: skip
            line = rf"CertCommonName\({name}\)\S* is {verdict} to Put \(ingress\) on {key}$"
            router.wait_for_line(line, 10.0)
    assert got.payloads() == {b"agent-chaser"}


# --------------------------------------------------------------------------------------- the launched swarm

SEED = 1
RUN_S = 240.0  # wall-time ceiling of one launched secure docking (measured ~21 s plus ~40 s start here)
HOSTILE_GYRO = (0.7, -0.7, 0.7)  # rad/s: a spin no legitimate sample of this scenario has
HOSTILE_FORCE = (7.0, 7.0, 7.0)  # N: far beyond the chaser's nozzles


def _hostile(pubs: list[tuple[zenoh.Publisher, zenoh.Publisher]], nozzles: int, clock: list[int],
             stop: threading.Event, sent: list[int]) -> None:  # fmt: skip
    """Valid Command and Imu messages for the chaser on the ticks just ahead of the world's clock (so that
    they would arrive before the swarm's own), full thrust and a hostile spin, every 10 ms."""
    while not stop.is_set():
        for tick in range(clock[0], clock[0] + 8):  # the clock is sent every 10 ticks
            cmd = Command(
                tick, 0.01 * tick, np.full(nozzles, 1.0), "DOCK", np.array(HOSTILE_FORCE), np.zeros(3)
            )
            imu = Imu(tick, 0.01 * tick, 0.01, np.array(HOSTILE_GYRO))
            for pub_command, pub_imu in pubs:
                pub_command.put(encode(cmd))
                pub_imu.put(encode(imu))
                sent[0] += 2
        stop.wait(0.01)


def test_secure_launch_docks_as_the_simulation_while_intruders_are_denied_by_zenoh(tmp_path):
    """``--secure --until-docked`` with two intruders publishing valid, hostile chaser commands and gyro
    samples throughout: one with a CA-signed certificate of an unknown name, one with the dashboard's
    (a real identity without those rights). The run equals the in-process simulation bit for bit; a
    subscriber allowed to read those keys gets the swarm's samples and never an intruder's; Zenoh logs
    that the unknown name matches no subject (default deny) and never tells its session of a subscriber;
    sessions without the certificate cannot connect; the certificates are gone after the run."""
    ns = f"sec-{uuid.uuid4().hex[:8]}"
    keys = Keys(ns)
    out = tmp_path / "launch.json"
    sc = load_scenario("docking")
    sim = run_docking(sc, seed=SEED, record_series=False)["chasers"]["chaser"]
    nozzles = sc.kind("chaser").U_N  # hostile but valid: the cube's actuator count
    env = {"RUST_LOG": "zenoh::net::routing::interceptor::access_control=info", "NO_COLOR": "1"}
    seen: dict[str, list] = {"imu": [], "command": []}
    clock = [0]  # the world's latest tick, as the monitor hears it
    lock = threading.Lock()

    def on(kind: str):
        def record(sample: zenoh.Sample) -> None:
            if kind == "bundle":  # a lockstep world's imu come in its bundles (docs/protocol.md, "Bundles")
                got = bundle_messages(
                    decode(sample.payload.to_bytes(), Bundle), kind, DropCounter(), ("Imu",)
                )
                kind_ = "imu"
            else:
                got = [decode(sample.payload.to_bytes(), Imu if kind == "imu" else Command)]
                kind_ = kind
            with lock:
                seen[kind_].extend(got)

        return record

    with Procs() as procs:
        args = [sys.executable, "-m", "swarm.cli.main", "launch", "docking", "--headless", "--secure",
                "--until-docked", "--seed", str(SEED), "--namespace", ns, "--json", str(out),
                "--record", str(tmp_path / "secure.mcap")]  # fmt: skip
        proc = procs.start(args, env=env)
        d = Path(
            proc.wait_for_line(r"^swarm secure: certificates and Zenoh configs in (\S+) ", 60.0).group(1)
        )
        endpoint = proc.wait_for_line(r"^swarm listening on (tls/\S+) ", 60.0).group(1)
        assert not d.is_relative_to(REPO.resolve())
        issue_certificate(d, "intruder")  # the CA is the swarm's: the certificate is valid, the name unknown
        monitor = zenoh.open(_client(d / "dashboard.json5", endpoint))
        intruders = [zenoh.open(_client(client_config(d, "intruder"), endpoint)),
                     zenoh.open(_client(d / "dashboard.json5", endpoint))]  # fmt: skip
        stop, sent, matched = threading.Event(), [0], []
        try:
            monitor.declare_subscriber(keys.imu("chaser"), on("imu"))
            monitor.declare_subscriber(keys.bundle("chaser"), on("bundle"))
            monitor.declare_subscriber(keys.command("chaser"), on("command"))
            monitor.declare_subscriber(
                keys.world_clock(), lambda s: clock.__setitem__(0, decode(s.payload.to_bytes(), Clock).tick)
            )
            assert all(s.info.routers_zid() for s in intruders)  # linked: TLS accepted both
            pubs = [(s.declare_publisher(keys.command("chaser")), s.declare_publisher(keys.imu("chaser")))
                    for s in intruders]  # fmt: skip
            hostile = threading.Thread(target=_hostile, args=(pubs, nozzles, clock, stop, sent), daemon=True)
            hostile.start()
            try:
                proc.wait_for_line(r"^swarm up:", 180.0)
                wait_until(
                    lambda: pubs[1][0].matching_status.matching, 30.0, "the world's command subscriber"
                )
                for conf, where in (({}, endpoint.replace("tls/", "tcp/")), ({"transport": {"link": {"tls": {
                        "root_ca_certificate": str(d / "ca.pem")}}}}, endpoint)):  # fmt: skip
                    with pytest.raises(zenoh.ZError, match="Unable to connect"):
                        zenoh.open(_client(conf, where)).close()
                deadline = time.monotonic() + RUN_S  # a launch that never ends fails here with its output
                while proc.popen.poll() is None and not stop.wait(0.5) and time.monotonic() < deadline:
                    matched.append(pubs[0][0].matching_status.matching or pubs[0][1].matching_status.matching)
                rc = proc.wait(5.0)
            finally:
                stop.set()
                hostile.join(5.0)
            intruder_zid = str(intruders[0].zid())
        finally:
            for s in (*intruders, monitor):
                s.close()
        text = proc.output()
    assert rc == 0, text
    got = json.loads(out.read_text())["chasers"]["chaser"]
    assert got["docked"] and sim["docked"]
    for field in ("docking_time_s", "total_impulse_ns", "position_error_m", "attitude_error_rad", "modes"):
        # (a mismatch shows the launch's log: a tick the world stepped without a command, or a resume, is how
        # a launched run would part from the simulation)
        assert got[field] == sim[field], (field, got[field], sim[field], text[-8000:])
    assert sent[0] > 1000
    with lock:
        imus, cmds = seen["imu"], seen["command"]
    assert len(imus) > 1000 and len(cmds) > 1000  # the monitor does receive these keys ...
    assert not any(tuple(m.gyro_body) == HOSTILE_GYRO for m in imus)  # ... never from an intruder
    assert not any(tuple(m.force_body_n) == HOSTILE_FORCE for m in cmds)
    unmatched = re.findall(
        r"(\w+) did not match any configured ACL subject\. Default permission `Deny`", text
    )
    assert unmatched == [intruder_zid], text[-3000:]  # the unknown name, and nobody else
    assert matched and not any(matched)  # its session never hears of the world's subscriber
    assert "Traceback" not in text
    assert not d.exists()  # the launcher removed its certificates and keys
    # --record in a secure swarm: the recorder is the router's own session; it has what the access control
    # let in (every chaser imu the monitor got, in the same order), never an intruder's message
    msgs, _ = read_recording(tmp_path / "secure.mcap")
    rec_imu = [decode(m.payload, Imu) for m in msgs if m.key == keys.imu("chaser")]
    rec_cmd = [decode(m.payload, Command) for m in msgs if m.key == keys.command("chaser")]
    assert [m.tick for m in rec_imu] == [m.tick for m in imus]
    assert len(rec_cmd) == len(cmds)
    assert not any(tuple(m.gyro_body) == HOSTILE_GYRO for m in rec_imu)
    assert not any(tuple(m.force_body_n) == HOSTILE_FORCE for m in rec_cmd)


def test_a_world_killed_in_a_secure_run_resumes_with_its_identity_and_the_run_equals_the_simulation(
    tmp_path,
):
    """``--secure``: the restarted world gets the same certificate and configuration (the same arguments,
    ``--resume`` added), so the ACL lets it publish the sensors again and the lockstep run is still the
    in-process one; the launcher's log names the loss and the resumption."""
    ns = f"sec-{uuid.uuid4().hex[:8]}"
    out = tmp_path / "launch.json"
    sim = run_docking(load_scenario("docking"), seed=SEED, record_series=False)["chasers"]["chaser"]

    def world() -> list[str]:
        ps = subprocess.run(["ps", "-ww", "-eo", "pid,stat,args"], capture_output=True, text=True).stdout
        mine = [line for line in ps.splitlines() if f"--namespace {ns}" in line and " Z" not in line[:12]]
        return [line.split() for line in mine if "-m swarm.world" in line]

    with Procs() as procs:
        args = [sys.executable, "-m", "swarm.cli.main", "launch", "docking", "--headless", "--secure",
                "--until-docked", "--seed", str(SEED), "--namespace", ns, "--json", str(out)]  # fmt: skip
        proc = procs.start(args)
        proc.wait_for_line(r"^swarm up:", 180.0)
        time.sleep(1.0)  # into the run (a lockstep pair docks ~3.5 s into it here)
        (first,) = world()
        os.kill(int(first[0]), signal.SIGKILL)

        def restarted() -> bool:  # one look at the processes (two could see the old one go in between)
            now = world()
            return len(now) == 1 and now[0][0] != first[0]

        wait_until(restarted, 60.0, "the restarted world")
        (second,) = world()
        rc = proc.wait(RUN_S)
        text = proc.output()
    assert rc == 0, text
    config = first[first.index("--zenoh-config") + 1]
    assert config.endswith("/world.json5") and second[second.index("--zenoh-config") + 1] == config
    assert "--resume" in second and "--resume" not in first
    assert re.search(r"WARNING swarm.launch: world lost \((liveliness token gone|exited with status -9)\); "
                     r"restart 1/", text), text  # fmt: skip
    assert re.search(r"WARNING swarm.launch: world resumed from its checkpoint at tick \d+", text), text
    got = json.loads(out.read_text())
    assert got["restarts"]["world"] == 1
    got = got["chasers"]["chaser"]
    assert got["docked"] and sim["docked"]
    for field in ("docking_time_s", "total_impulse_ns", "position_error_m", "attitude_error_rad", "modes"):
        # (a mismatch shows the launch's log: a tick the world stepped without a command, or a resume, is how
        # a launched run would part from the simulation)
        assert got[field] == sim[field], (field, got[field], sim[field], text[-8000:])
    assert "Traceback" not in text
