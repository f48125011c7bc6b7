"""``swarm launch --topology``: how the launched world, mothership and agents open their Zenoh sessions
(``swarm.cli.children``). The launched mesh itself, its direct links and its run equal to ``swarm sim``, is
checked in ``tests/transport/test_launch.py``."""

from __future__ import annotations

import pytest

from swarm.cli.children import (
    MESH_LISTEN,
    MESH_MAX_PEERS,
    child_args,
    member_args,
    resolved,
    swarm_processes,
    topology,
)
from swarm.cli.main import build_parser
from swarm.errors import ConfigError
from swarm.transport.session import make_config

ENDPOINT = "tcp/127.0.0.1:7447"


def _args(*flags: str):
    return build_parser().parse_args(["launch", "docking", *flags])


def _session_flags(args, processes: int) -> list[str]:
    """The Zenoh session flags :func:`child_args` gives every child (from ``--mode`` on), once the launcher
    has resolved the topology for ``processes``."""
    args.links = topology(args, processes)
    common = child_args(args, ENDPOINT, 0)
    return common[common.index("--mode") :][: 6 if "--listen" in common else 4]


def test_a_mesh_is_peers_that_dial_the_router_and_listen_on_loopback():
    args = _args("--topology", "mesh")
    assert _session_flags(args, 40) == ["--mode", "peer", "--connect", ENDPOINT, "--listen", MESH_LISTEN]
    # and Zenoh takes those flags as such a session (port 0: the system picks a free one)
    config = make_config(member_args(ENDPOINT, "mesh"))
    assert '"peer"' in config.get_json("mode") and "127.0.0.1:0" in config.get_json("listen/endpoints")


def test_a_star_is_clients_of_the_router_and_listens_on_nothing():
    args = _args("--topology", "star")
    assert _session_flags(args, 4) == ["--mode", "client", "--connect", ENDPOINT]
    assert "--listen" not in child_args(args, ENDPOINT, 0)


def test_auto_meshes_a_few_processes_and_stars_many():
    # the default: one pair with a process each (4 processes) is a mesh, up to MESH_MAX_PEERS; beyond, the
    # per-link writes of a mesh cost more than the router's hop saves (BENCHMARKS.md, "A mesh of peers")
    assert _args().topology == "auto"
    assert topology(_args(), 4) == "mesh"
    assert topology(_args(), MESH_MAX_PEERS) == "mesh"
    assert topology(_args(), MESH_MAX_PEERS + 1) == "star"
    assert resolved("auto", 4) == "mesh" and resolved("star", 4) == "star" and resolved("mesh", 40) == "mesh"


def test_a_secure_swarm_is_a_star_unless_told_otherwise_and_refuses_a_mesh():
    # the router enforces the ACL and the mutual TLS: a direct link between two peers would pass by it
    assert topology(_args("--secure"), 4) == "star"
    assert topology(_args("--secure", "--topology", "star"), 4) == "star"
    with pytest.raises(ConfigError, match="--topology mesh and --secure"):
        topology(_args("--secure", "--topology", "mesh"), 4)


def test_an_unknown_topology_is_refused_naming_the_flag_and_the_value(capsys):
    with pytest.raises(SystemExit) as exc:
        _args("--topology", "ring")
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--topology" in err and "'ring'" in err
    args = _args()
    args.topology = "ring"  # (a namespace built by hand, not by the parser)
    with pytest.raises(ConfigError, match="--topology must be one of auto, mesh, star, got 'ring'"):
        topology(args, 4)
    with pytest.raises(ValueError, match="a mesh or a star, got 'auto'"):
        member_args(ENDPOINT, "auto")  # (unresolved: the launcher resolves it before any child starts)


@pytest.mark.parametrize(
    ("pairs", "per_process"), [(1, 1), (1, 2), (4, 1), (4, 3), (16, 16), (3, 4), (64, 64)]
)
def test_the_process_count_that_auto_decides_by_is_the_launchers_layout(pairs, per_process):
    # the benches' probes join the topology this count resolves to: it must be the launcher's own layout
    from swarm.cli.launch import _hosts
    from swarm.transport.process import scenario_from

    args = _args("--agents", str(pairs), "--vehicles-per-process", str(per_process))
    ids = scenario_from(args).vehicles
    assert swarm_processes(len(ids), per_process) == 2 + len(_hosts(args, ids))  # world, mothership
    assert swarm_processes(2 * pairs, per_process, mothership=False) == 1 + len(_hosts(args, ids))
