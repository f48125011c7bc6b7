"""``python -m dashboard`` as a process, without a browser: its ready line, serving the page, a clean exit on
SIGINT/SIGTERM, garbage on every key logged and counted but never fatal, bad input, a busy port, and the
``swarm dashboard`` sub-command."""

from __future__ import annotations

import signal
import sys
import time
import urllib.request

from swarm.cli.main import build_parser
from tests.dashboard.conftest import START_TIMEOUT_S, new_namespace, start_dashboard, start_fake_swarm
from tests.transport.procs import Procs, free_port, loopback, wait_until


def _get(url: str) -> tuple[int, str]:
    with urllib.request.urlopen(url, timeout=10.0) as response:
        return response.status, response.read().decode("utf-8", "replace")


def test_ready_lines_pages_a_busy_port_replaced_and_a_clean_exit_0_on_sigterm_and_on_sigint() -> None:
    """One fake swarm and two dashboards (a Python start with viser is this file's cost: one start serves
    the claims of three former tests). The first prints its ready line on stdout (Viser's banner goes to
    stderr), serves the page and sees the chaser's token; the second asks for the first's port, which is
    busy: it takes the next free one and says so, and serves its page. SIGTERM to the first and SIGINT to
    the second: each exits 0, without a traceback, its process group gone."""
    endpoint, namespace = loopback(free_port()), new_namespace("srv")
    with Procs() as procs:
        start_fake_swarm(procs, endpoint, namespace)
        first, url = start_dashboard(procs, endpoint, namespace, "docking")
        assert url.startswith("http://localhost:")
        status, body = _get(url)
        assert status == 200 and "<html" in body.lower()
        port = url.rsplit(":", 1)[1]
        flags = ["--port", port, "--connect", endpoint, "--namespace", namespace, "--id", "dashboard2"]
        second = procs.start([sys.executable, "-m", "dashboard", *flags])
        url2 = second.wait_for_line(r"^dashboard listening on (http://\S+)$", START_TIMEOUT_S).group(1)
        assert url2 != url and _get(url2)[0] == 200
        assert f"port {port} is busy" in second.output()
        for dash, sig in ((first, signal.SIGTERM), (second, signal.SIGINT)):
            seen = lambda d=dash: "agent chaser alive" in d.output()  # noqa: E731
            wait_until(seen, START_TIMEOUT_S, "the chaser's token seen")
            dash.signal(sig)
            assert dash.wait(START_TIMEOUT_S) == 0, dash.output()
            assert "Traceback" not in dash.output()
            assert not dash.group_alive()
            stdout = "\n".join(dash.stdout)
            assert stdout.startswith("dashboard listening on http://localhost:"), stdout


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


def test_a_bad_scenario_or_endpoint_exits_2_naming_it(capsys) -> None:
    # in this process (dashboard.cli.main, what `python -m dashboard` runs): both are refused before
    # anything is served, and a started Python with viser costs ~2 s of CPU
    from dashboard.cli import main

    assert main(["no-such-scenario.toml", "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "dashboard: error:" in err and "no-such-scenario" in err, err
    assert main(["--port", "0", "--connect", "localhost:7447"]) == 2
    err = capsys.readouterr().err
    assert "dashboard: error:" in err and "--connect endpoint" in err, err


def test_swarm_dashboard_is_a_subcommand_with_the_dashboard_flags() -> None:
    argv = ["dashboard", "docking", "--port", "9000", "--connect", "tcp/127.0.0.1:7447"]
    args = build_parser().parse_args(argv)
    assert (args.command, args.port, args.host, args.namespace) == ("dashboard", 9000, "localhost", "tpods")
    assert args.connect == ["tcp/127.0.0.1:7447"] and callable(args.func)
