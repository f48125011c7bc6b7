"""``swarm launch --topology``: how the launched world, mothership and agents open their Zenoh sessions
(``swarm.cli.children``). The launched mesh itself, its direct links and its run equal to ``swarm sim``, is
checked in ``tests/transport/test_launch.py``."""

from __future__ import annotations

import pytest

from swarm.cli.children import MESH_LISTEN, child_args, topology
from swarm.cli.main import build_parser
from swarm.errors import ConfigError
from swarm.transport.session import ZenohArgs, make_config

ENDPOINT = "tcp/127.0.0.1:7447"


def _args(*flags: str):
    return build_parser().parse_args(["launch", "docking", *flags])


def _session_flags(args) -> list[str]:
    """The Zenoh session flags :func:`child_args` gives every child (from ``--mode`` on)."""
    common = child_args(args, ENDPOINT, 0)
    return common[common.index("--mode") :][: 6 if "--listen" in common else 4]


def test_a_plain_swarm_is_a_mesh_of_peers_that_dial_the_router_and_listen_on_loopback():
    args = _args()
    assert topology(args) == "mesh"
    assert _session_flags(args) == ["--mode", "peer", "--connect", ENDPOINT, "--listen", MESH_LISTEN]
    # and Zenoh takes those flags as such a session (port 0: the system picks a free one)
    config = make_config(ZenohArgs(mode="peer", connect=(ENDPOINT,), listen=(MESH_LISTEN,)))
    assert '"peer"' in config.get_json("mode") and "127.0.0.1:0" in config.get_json("listen/endpoints")


def test_a_star_is_clients_of_the_router_and_listens_on_nothing():
    args = _args("--topology", "star")
    assert topology(args) == "star"
    assert _session_flags(args) == ["--mode", "client", "--connect", ENDPOINT]
    assert "--listen" not in child_args(args, ENDPOINT, 0)


def test_a_secure_swarm_is_a_star_unless_told_otherwise_and_refuses_a_mesh():
    # the router enforces the ACL and the mutual TLS: a direct link between two peers would pass by it
    assert topology(_args("--secure")) == "star"
    assert topology(_args("--secure", "--topology", "star")) == "star"
    with pytest.raises(ConfigError, match="--topology mesh and --secure"):
        topology(_args("--secure", "--topology", "mesh"))
    with pytest.raises(ConfigError, match="--topology mesh and --secure"):
        child_args(_args("--secure", "--topology", "mesh"), ENDPOINT, 0)


def test_an_unknown_topology_is_refused_naming_the_flag_and_the_value(capsys):
    with pytest.raises(SystemExit) as exc:
        _args("--topology", "ring")
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--topology" in err and "'ring'" in err
    args = _args()
    args.topology = "ring"  # (a namespace built by hand, not by the parser)
    with pytest.raises(ConfigError, match="--topology must be one of mesh, star, got 'ring'"):
        topology(args)
