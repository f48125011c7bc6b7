"""Command line of the dashboard: ``python -m dashboard SCENARIO`` and ``swarm dashboard SCENARIO``; with
``--open FILE.mcap`` the playback of a recording instead of a live swarm (:mod:`dashboard.playback`: no
Zenoh session; the scenario and the namespace are the recording's unless given).

Once serving, it prints one line on stdout (flushed), ``dashboard listening on http://<host>:<port>``, so
that a launcher or a test can wait for it and read the URL (with ``--port 0`` the OS picks the port;
if the requested port is busy, Viser takes the next free one and the line says which). It runs until
SIGINT or SIGTERM, then closes its Zenoh session and the Viser server and exits 0 (started by ``swarm
launch``, it leaves a SIGINT to the launcher, which stops it in the swarm's order:
:mod:`swarm.transport.stopping`); 2 for bad input (a missing, truncated or corrupt recording: one line
naming the file and the byte offset where reading stopped).

``--host`` defaults to ``localhost``: the dashboard can pause and reset the swarm, so it is not offered
to the network unless asked (``--host 0.0.0.0``).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from pathlib import Path

from swarm.errors import SwarmError
from swarm.stacks import enable_stack_dumps

__all__ = ["DEFAULT_PORT", "READY_PREFIX", "add_arguments", "main", "run"]

_LOG = logging.getLogger("dashboard")

READY_PREFIX = "dashboard listening on "
"""Start of the line printed once the dashboard serves; the URL follows."""
DEFAULT_PORT = 8080
DESCRIPTION = (
    "Viser web dashboard of a running swarm: live 3D scene (poses, trails, covariance, camera cones, "
    "switch radii; for a landing scenario the pads, quadrotors and camera frustums), agents table, mode "
    "timeline, Algorithm 1 decisions and run controls. It only "
    "subscribes and sends run controls. Prints 'dashboard listening on <url>' once up. With --open "
    "FILE.mcap it plays a recording (swarm record, swarm launch --record) instead: time slider, "
    "play/pause and speed, no Zenoh."
)


def _agents(text: str) -> int:
    from swarm.args import agents

    return agents(text)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The dashboard's flags: scenario (+ ``--set``), ``--port``, ``--host``, ``--namespace``, ``--id``,
    ``--max-hz`` and the Zenoh session flags."""
    from swarm.transport.session import add_zenoh_arguments

    p.add_argument(
        "scenario",
        nargs="?",
        default=None,
        help="bundled scenario name or TOML file (default docking; with --open, the recording's)",
    )
    p.add_argument(
        "--open",
        dest="recording",
        type=Path,
        default=None,
        metavar="FILE.mcap",
        help="play this recording instead of subscribing to a swarm (no Zenoh session is opened)",
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override one scenario field, as for swarm sim (repeatable)",
    )
    p.add_argument(
        "--agents",
        type=_agents,
        default=None,
        metavar="N",
        help="copies of the pairs, as launched (1; with --open, as recorded)",
    )
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help="HTTP port (default 8080; 0: any port)")
    p.add_argument(
        "--host",
        default="localhost",
        help="address to serve on (default localhost; 0.0.0.0 to let other machines in)",
    )
    p.add_argument(
        "--namespace",
        default="tpods",
        help="Zenoh key namespace of the swarm (default tpods; with --open, the recorder's if it says)",
    )
    p.add_argument("--id", dest="process_id", default="dashboard", help="liveliness id (default dashboard)")
    p.add_argument("--max-hz", type=float, default=30.0, help="most frames per second sent to browsers (30)")
    add_zenoh_arguments(p)


def _url(host: str, port: int) -> str:
    shown = "localhost" if host in ("", "0.0.0.0", "::", "localhost", "127.0.0.1") else host
    if ":" in shown:
        shown = f"[{shown}]"
    return f"http://{shown}:{port}"


def run(args: argparse.Namespace, stop: threading.Event | None = None) -> int:
    """Serve the dashboard of the parsed ``args`` until ``stop`` is set; with ``stop=None`` (the command
    line) until SIGINT or SIGTERM, whose handlers it installs and restores. Returns 0 after a clean close;
    ConfigError / SwarmError for bad input or a session that cannot open."""
    from dashboard.app import DashboardApp, DashboardParams
    from dashboard.drawer import drawer_of
    from swarm.errors import ConfigError
    from swarm.missions import mission_of
    from swarm.transport.keys import Keys, check_id
    from swarm.transport.session import open_session, zenoh_args_from

    if not (0 <= args.port <= 65535):
        raise ConfigError(f"--port must be in 0..65535, got {args.port}")
    check_id(args.process_id, "--id")
    params = DashboardParams(max_hz=args.max_hz)
    if args.recording is not None:
        return _serve(args, stop, lambda: _playback_app(args, params))
    keys = Keys(args.namespace)
    if args.scenario is None:
        args.scenario = "docking"
    sc = mission_of(args.scenario).dashboard_scenario(args)
    drawer_of(sc)  # a mission without a drawer is refused before a session opens
    zargs = zenoh_args_from(args)
    with open_session(zargs) as session:
        make = lambda: DashboardApp(sc, session, keys, args.host, args.port, params, args.process_id)  # noqa: E731
        return _serve(args, stop, make)


def _playback_app(args: argparse.Namespace, params):
    """The DashboardApp of ``--open FILE.mcap``: the recording, its scenario, no Zenoh session."""
    from dashboard.app import DashboardApp
    from dashboard.playback import load_recording, recorded_mission, scenario_of
    from swarm.config import parse_override
    from swarm.errors import ConfigError
    from swarm.transport.keys import Keys

    for flag in ("connect", "listen", "zenoh_config"):
        if getattr(args, flag, None):
            flag_name = "--" + flag.replace("_", "-")
            raise ConfigError(f"{flag_name}: --open plays a recording and opens no Zenoh session")
    recording = load_recording(args.recording, default_namespace=args.namespace)
    overrides = dict(parse_override(text) for text in args.overrides)
    sc = scenario_of(recording, args.scenario, overrides)
    sc = recorded_mission(recording, args.scenario).with_agents(sc, args.agents)
    span_s = recording.end_s - recording.start_s
    _LOG.info(
        "playing %s: %d messages over %.2f s of swarm time, scenario %s, namespace %s",
        recording.path, len(recording.items), span_s, sc.name, recording.namespace,
    )  # fmt: skip
    keys = Keys(recording.namespace)
    return DashboardApp(sc, None, keys, args.host, args.port, params, args.process_id, recording=recording)


def _serve(args: argparse.Namespace, stop: threading.Event | None, make) -> int:
    """Serve the app ``make()`` builds until ``stop`` (or a signal, module docstring)."""
    previous: dict[int, object] = {}
    if stop is None:
        from swarm.transport.stopping import StopFlag, install_stop_signals

        stop = StopFlag()
        previous = install_stop_signals(stop, _LOG)
    try:
        try:
            app = make()
        except OSError as exc:
            raise SwarmError(f"cannot serve on {args.host}:{args.port}: {exc}") from None
        try:
            app.start()
            if args.port not in (0, app.port):
                _LOG.warning("port %d is busy: serving on %d instead", args.port, app.port)
            print(READY_PREFIX + _url(args.host, app.port), flush=True)
            while not stop.wait(0.5):
                pass
        finally:
            app.close()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]
    _LOG.info("dashboard closed")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m dashboard``: the same as ``swarm dashboard``."""
    enable_stack_dumps()  # kill -USR1: every thread's stack on stderr (swarm/stacks.py)
    parser = argparse.ArgumentParser(prog="python -m dashboard", description=DESCRIPTION)
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    add_arguments(parser)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    if not args.verbose:
        logging.getLogger("websockets").setLevel(logging.WARNING)  # one line per browser connection
    try:
        return run(args)
    except SwarmError as exc:
        print(f"dashboard: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
