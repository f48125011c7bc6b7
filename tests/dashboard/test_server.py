"""``python -m dashboard`` as a process, without a browser: its ready line, serving the page, a clean exit on
SIGINT/SIGTERM, garbage on every key logged and counted but never fatal, bad input, a busy port, and the
``swarm dashboard`` sub-command."""

from __future__ import annotations

import signal
import sys
import time
import urllib.request

import pytest

from swarm.cli.main import build_parser
from tests.dashboard.conftest import START_TIMEOUT_S, new_namespace, start_dashboard, start_fake_swarm
from tests.transport.procs import Procs, free_port, loopback, wait_until


def _get(url: str) -> tuple[int, str]:
    with urllib.request.urlopen(url, timeout=10.0) as response:
        return response.status, response.read().decode("utf-8", "replace")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_ready_line_then_serves_the_page_and_exits_0_on_a_signal(sig: signal.Signals) -> None:
    endpoint, namespace = loopback(free_port()), new_namespace("srv")
    with Procs() as procs:
        start_fake_swarm(procs, endpoint, namespace)
        dash, url = start_dashboard(procs, endpoint, namespace, "docking")
        assert url.startswith("http://localhost:")
        status, body = _get(url)
        assert status == 200 and "<html" in body.lower()
        wait_until(lambda: "agent chaser alive" in dash.output(), START_TIMEOUT_S, "the chaser's token seen")
        dash.signal(sig)
        assert dash.wait(START_TIMEOUT_S) == 0, dash.output()
        assert "Traceback" not in dash.output()
        assert not dash.group_alive()
        stdout = "\n".join(dash.stdout)
        assert stdout.startswith("dashboard listening on http://localhost:"), stdout  # Viser's banner: stderr


def test_garbage_on_every_key_is_logged_and_counted_never_fatal() -> None:
    endpoint, namespace = loopback(free_port()), new_namespace("srv")
    with Procs() as procs:
        start_fake_swarm(procs, endpoint, namespace, "--garbage")
        dash, url = start_dashboard(procs, endpoint, namespace, "docking")
        for kind in ("agent/chaser/event", "agent/chaser/truth", "world/clock"):
            line = f"invalid message on {namespace}/{kind} "
            wait_until(lambda line=line: line in dash.output(), START_TIMEOUT_S, f"a drop logged: {line!r}")
        time.sleep(1.0)
        assert dash.popen.poll() is None, dash.output()
        assert _get(url)[0] == 200
        dash.signal(signal.SIGTERM)
        assert dash.wait(START_TIMEOUT_S) == 0, dash.output()
        assert "Traceback" not in dash.output()


def test_a_bad_scenario_exits_2_naming_it() -> None:
    with Procs() as procs:
        dash = procs.start([sys.executable, "-m", "dashboard", "no-such-scenario.toml", "--port", "0"])
        assert dash.wait(START_TIMEOUT_S) == 2
        assert "dashboard: error:" in dash.output() and "no-such-scenario" in dash.output()


def test_a_bad_endpoint_exits_2_naming_it() -> None:
    with Procs() as procs:
        dash = procs.start([sys.executable, "-m", "dashboard", "--port", "0", "--connect", "localhost:7447"])
        assert dash.wait(START_TIMEOUT_S) == 2
        assert "--connect endpoint" in dash.output()


def test_a_busy_port_is_replaced_by_the_next_free_one_and_the_ready_line_says_so() -> None:
    endpoint, namespace = loopback(free_port()), new_namespace("srv")
    with Procs() as procs:
        start_fake_swarm(procs, endpoint, namespace)
        _, first = start_dashboard(procs, endpoint, namespace, "docking")
        port = first.rsplit(":", 1)[1]
        flags = ["--port", port, "--connect", endpoint, "--namespace", namespace, "--id", "dashboard2"]
        second = procs.start([sys.executable, "-m", "dashboard", *flags])
        url = second.wait_for_line(r"^dashboard listening on (http://\S+)$", START_TIMEOUT_S).group(1)
        assert url != first and _get(url)[0] == 200
        assert f"port {port} is busy" in second.output()


def test_swarm_dashboard_is_a_subcommand_with_the_dashboard_flags() -> None:
    argv = ["dashboard", "docking", "--port", "9000", "--connect", "tcp/127.0.0.1:7447"]
    args = build_parser().parse_args(argv)
    assert (args.command, args.port, args.host, args.namespace) == ("dashboard", 9000, "localhost", "tpods")
    assert args.connect == ["tcp/127.0.0.1:7447"] and callable(args.func)
