"""Shared helpers of the dashboard's process tests: starting a swarm and a dashboard as real processes on
loopback Zenoh, watching the world's clock from the test, and a headless Chromium.

:func:`launch_swarm` is the one place that starts "a launched swarm with its dashboard": ``swarm launch
docking --clock lockstep --pace realtime --dashboard-port 0 ...``, the real world, mothership and agent
processes. Other dashboard tests drive the dashboard with :mod:`tests.dashboard.fake_swarm`, a scripted
swarm whose every message a test controls. :func:`recording` is an MCAP recording of that scripted swarm
for the playback tests (:mod:`tests.dashboard.recorded`).
"""

from __future__ import annotations

import shutil
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import zenoh

from swarm.scenario import load_scenario
from swarm.transport.keys import Keys
from swarm.transport.messages import Clock, DropCounter, Event, Fault, Uwb
from swarm.transport.session import ZenohArgs, open_session, subscribe_decoded
from tests.transport.procs import REPO, Proc, Procs, free_port, loopback, wait_until

PACE = "realtime"  # the launched swarm's pace (launch_swarm): lockstep, never ahead of real time
START_TIMEOUT_S = 20.0  # a Python start with numpy, zenoh and viser (~1-2 s here) on a loaded 2-core machine
ARTIFACTS = REPO / "artifacts"
CHROMIUM_FLAGS = [
    # measured here: headless Chromium renders Viser's WebGL scene with software GL (SwiftShader);
    # never --disable-software-rasterizer, which kills WebGL.
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--window-size=1280,800",
    # no network chatter from the browser itself
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def start_fake_swarm(procs: Procs, endpoint: str, namespace: str, *extra: str) -> Proc:
    """The fake swarm listening on ``endpoint``, once it says it runs."""
    module = "tests.dashboard.fake_swarm"
    proc = procs.start([sys.executable, "-m", module, "--listen", endpoint, "--namespace", namespace, *extra])
    proc.wait_for_line(r"^fake swarm running", START_TIMEOUT_S)
    return proc


def start_dashboard(
    procs: Procs, endpoint: str, namespace: str, scenario: str, *extra: str
) -> tuple[Proc, str]:
    """``python -m dashboard`` connected to ``endpoint`` on a free port; ``(process, url)`` once ready."""
    proc = procs.start(
        [sys.executable, "-m", "dashboard", scenario, "--port", "0", "--connect", endpoint,
         "--namespace", namespace, *extra]
    )  # fmt: skip
    url = proc.wait_for_line(r"^dashboard listening on (http://\S+)$", START_TIMEOUT_S).group(1)
    return proc, url


def new_namespace(what: str) -> str:
    """A namespace no other test run uses (tests may share a machine)."""
    return f"test-{what}-{uuid.uuid4().hex[:8]}"


@dataclass
class LaunchedSwarm:
    """A running swarm with its dashboard."""

    url: str
    """The dashboard's URL."""
    endpoint: str
    """A Zenoh endpoint of the swarm that a test's own session connects to."""
    namespace: str
    agent_ids: tuple[str, ...]
    dashboard: Proc
    """The launcher (the dashboard is its child: its log lines are in the launcher's output)."""
    zenoh_config: str | None = None
    """``--secure``: the Zenoh configuration of the dashboard's identity (its certificate), with which a
    test's own session may connect and subscribe to anything of the swarm; else None (plain TCP)."""


def launch_swarm(
    procs: Procs,
    workdir: Path,
    pairs: int = 2,
    secure: bool = False,
    timeout_s: float | None = None,
    scenario: str = "docking",
    sets: tuple[str, ...] = (),
) -> LaunchedSwarm:
    """``swarm launch SCENARIO --agents PAIRS`` (lockstep, paced at real time) with its dashboard on a
    free port (module docstring). The pace leaves the cores to the browser: a lockstep swarm stepping as
    fast as it can takes both, and the page then takes seconds to draw each frame. The chasers approach at
    a tenth of the docking scenario's speed so that the run lasts longer than the browser tests, and the
    run may last 1000 simulated seconds. ``secure``: ``--secure`` (mutual TLS and Zenoh's ACL, certificates
    made by the launcher; its router listens on a free TLS port); ``timeout_s``: the launcher's
    ``--timeout``; ``sets``: more ``--set`` overrides (``uwb.mode=tdoa3``)."""
    namespace = new_namespace("dash")
    listen = [] if secure else ["--listen", loopback(free_port())]
    extra = (["--secure"] if secure else []) + ([] if timeout_s is None else ["--timeout", str(timeout_s)])
    proc = procs.start(
        [sys.executable, "-m", "swarm.cli.main", "launch", scenario, "--agents", str(pairs),
         "--clock", "lockstep", "--pace", PACE, "--dashboard-port", "0", "--namespace", namespace, *listen,
         *extra,
         "--set", "guidance.approach_speed_m_s=0.002", "--set", "sim.max_duration_s=1000",
         *(arg for o in sets for arg in ("--set", o))]
    )  # fmt: skip
    config = None
    if secure:
        certs = proc.wait_for_line(r"^swarm secure: certificates and Zenoh configs in (\S+) ", 60.0).group(1)
        config = str(Path(certs) / "dashboard.json5")
    endpoint = proc.wait_for_line(r"^swarm listening on (\S+) ", 60.0).group(1)
    url = proc.wait_for_line(r"^dashboard on (http://\S+)$", 120.0).group(1)
    proc.wait_for_line(r"^swarm up:", 120.0)
    sc = load_scenario(scenario).with_pairs(pairs)
    return LaunchedSwarm(url, endpoint, namespace, tuple(sc.vehicles), proc, config)


class ClockWatch:
    """The world's clock as a test sees it, over its own Zenoh session (``zenoh_config``: a secure swarm's
    client configuration, :attr:`LaunchedSwarm.zenoh_config`)."""

    def __init__(self, endpoint: str, namespace: str, zenoh_config: str | None = None) -> None:
        self._cond = threading.Condition()
        self.clocks: list[Clock] = []
        self.arrived: list[float] = []  # time.monotonic() at each of clocks' arrivals
        self.drops = DropCounter()
        mode = None if zenoh_config is None else "client"
        self._session = open_session(ZenohArgs(mode=mode, connect=(endpoint,), config_file=zenoh_config))
        self._declare(self._session, Keys(namespace))
        subscribe_decoded(self._session, Keys(namespace).world_clock(), Clock, self._on_clock, self.drops)

    def _declare(self, session: zenoh.Session, keys: Keys) -> None:
        """Subscriptions of a subclass, declared before the clock's (see :class:`SwarmRecorder`)."""

    def _on_clock(self, _key: str, msg: Clock) -> None:
        with self._cond:
            self.clocks.append(msg)
            self.arrived.append(time.monotonic())
            del self.clocks[:-1000], self.arrived[:-1000]
            self._cond.notify_all()

    @property
    def latest(self) -> Clock | None:
        with self._cond:
            return self.clocks[-1] if self.clocks else None

    def wait_for(self, predicate: Callable[[Clock], bool], timeout: float, what: str) -> Clock:
        """The first clock from now on (or the latest) that satisfies ``predicate``."""
        found: list[Clock] = []

        def check() -> bool:
            latest = self.latest
            if latest is not None and predicate(latest):
                found.append(latest)
                return True
            return False

        wait_until(check, timeout, what, poll_s=0.01)
        return found[0]

    def close(self) -> None:
        self._session.close()


class SwarmRecorder(ClockWatch):
    """A :class:`ClockWatch` that also records what the operator's controls cause: every Fault published
    on ``control/fault``, the events of ``world/event`` and ``mothership/event``, and each chaser's UWB
    exchanges (``(t_s, range_m)``, ``None`` for a lost one).

    These subscriptions are declared before the clock's, and a client's declarations reach the router in
    order (docs/protocol.md, "Processes and topology"): once :meth:`wait_for` returns a clock, the router
    routes every one of them to this session, so a fault published after that cannot pass unseen."""

    def __init__(
        self, endpoint: str, namespace: str, chasers: tuple[str, ...], zenoh_config: str | None = None
    ):
        self.faults: list[Fault] = []
        self.events: list[tuple[str, Event]] = []
        self.uwb: dict[str, list[tuple[float, float | None]]] = {c: [] for c in chasers}
        super().__init__(endpoint, namespace, zenoh_config)

    def _declare(self, session: zenoh.Session, keys: Keys) -> None:
        def keep(into: list, item: object) -> None:
            with self._cond:
                into.append(item)
                del into[:-20000]
                self._cond.notify_all()

        subscribe_decoded(session, keys.fault(), Fault, lambda _k, m: keep(self.faults, m), self.drops)
        subscribe_decoded(
            session, keys.world_event(), Event, lambda _k, m: keep(self.events, ("world", m)), self.drops
        )
        for c in self.uwb:
            on_uwb = lambda _k, m, c=c: keep(self.uwb[c], (m.t_s, m.range_m))  # noqa: E731
            subscribe_decoded(session, keys.uwb(c), Uwb, on_uwb, self.drops)

    def wait_event(self, predicate: Callable[[str, Event], bool], timeout: float, what: str) -> Event:
        """The first recorded ``(source, event)`` that satisfies ``predicate``."""
        found: list[Event] = []

        def check() -> bool:
            with self._cond:
                found.extend(e for s, e in self.events if predicate(s, e))
            return bool(found)

        wait_until(check, timeout, what, poll_s=0.05)
        return found[0]

    def snapshot(self) -> tuple[list[Fault], dict[str, list[tuple[float, float | None]]]]:
        """Copies of the faults and the UWB exchanges recorded so far."""
        with self._cond:
            return list(self.faults), {c: list(v) for c, v in self.uwb.items()}


def choose(page, label: str, option: str, timeout_ms: float) -> None:
    """Pick ``option`` in the Viser dropdown labelled ``label`` (a Mantine Select: open it, click the
    option)."""
    page.get_by_label(label, exact=True).click(timeout=timeout_ms)
    page.get_by_role("option", name=option, exact=True).click(timeout=timeout_ms)


def fill_number(page, label: str, text: str, timeout_ms: float) -> None:
    """Type ``text`` into the Viser number input labelled ``label`` and leave it (Tab), as a user does."""
    field = page.get_by_label(label, exact=True)
    field.fill(text, timeout=timeout_ms)
    field.press("Tab")


@pytest.fixture
def clock_watch() -> Iterator[Callable[[str, str], ClockWatch]]:
    watches: list[ClockWatch] = []

    def make(endpoint: str, namespace: str) -> ClockWatch:
        watches.append(ClockWatch(endpoint, namespace))
        return watches[-1]

    yield make
    for w in watches:
        w.close()


@pytest.fixture(scope="session")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An MCAP recording of the scripted docking run (:mod:`tests.dashboard.recorded`), written once."""
    from tests.dashboard.recorded import write_recording

    path = tmp_path_factory.mktemp("recording") / "run.mcap"
    write_recording(path)
    return path


def chromium_path() -> str | None:
    """The system Chromium (Debian's ``chromium``), or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    """A headless Chromium driven by Playwright (no browser download: the system's binary)."""
    path = chromium_path()
    if path is None:
        pytest.skip("chromium not found: `make chromium` (apt-get install chromium) installs it")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright missing: pip install '.[test]'")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=path, headless=True, args=CHROMIUM_FLAGS)
        try:
            yield b
        finally:
            b.close()
