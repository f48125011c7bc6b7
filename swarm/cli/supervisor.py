"""Child processes of ``swarm launch``: start, watch, restart with backoff, and stop, leaving nothing behind.

Each child runs ``python -m <module> ...`` in its own session (process group), so a Ctrl-C in the terminal
reaches only the launcher, which then stops the children in order (:mod:`swarm.transport.stopping`: the
world first, then the rest; a child that gets a SIGINT all the same leaves the stop to its launcher, whose
pid it finds in :data:`~swarm.transport.stopping.LAUNCHER_ENV`); on Linux each child also gets
``PR_SET_PDEATHSIG = SIGKILL``, so even a launcher killed with SIGKILL takes its children with it. Stopping
is SIGTERM to the child's group, then SIGKILL to the group after a grace period (a hung child included).
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from swarm.transport.stopping import LAUNCHER_ENV

_LOG = logging.getLogger("swarm.launch")

_PR_SET_PDEATHSIG = 1
STACKS_GAP_S = 0.1
"""Seconds between two children's stack dumps: each writes its dump in well under that (a few hundred
lines), so that they follow each other on the launcher's stderr instead of interleaving."""


def _die_with_parent() -> None:  # runs in the child between fork and exec
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except OSError:
        pass


@dataclass
class Child:
    """One supervised process."""

    name: str
    """``world``, ``mothership``, ``agent/<id>``, ``dashboard``."""
    args: list[str]
    """Arguments after ``python -m``."""
    restartable: bool = False
    rejoin_args: list[str] = field(default_factory=list)
    """Extra arguments of a restart (an agent joins the run in progress: ``--rejoin``)."""
    popen: subprocess.Popen | None = None
    restarts: int = 0
    next_start_s: float | None = None
    """Monotonic time of a pending restart."""
    on_line: Callable[[str], None] | None = None
    """Called with each line the child prints on stdout (on a reader thread)."""
    spoke: bool = False
    """Whether the current process has printed a line on stdout (its ready line): by then it answers
    :data:`~swarm.stacks.STACKS_SIGNAL`, which would have ended it while it was still importing."""

    @property
    def running(self) -> bool:
        return self.popen is not None and self.popen.poll() is None


class Supervisor:
    """Starts children, restarts the restartable ones that die (bounded, with exponential backoff) and
    stops them all."""

    def __init__(self, max_restarts: int = 3, backoff_s: float = 0.5, grace_s: float = 3.0) -> None:
        self.children: dict[str, Child] = {}
        self.max_restarts = max_restarts
        self.backoff_s = backoff_s
        self.grace_s = grace_s
        # one dump at a time (a stall's, a signal's and a hung agent's would interleave); dump_all holds it
        # around dump_children
        self._dumping = threading.RLock()

    def dump_all(self, why: str) -> None:
        """The launcher's own stacks, then every child's (:meth:`dump_children`), on stderr, announced by a
        line that says ``why`` and which process dumps in which order."""
        from swarm.stacks import dump_stacks

        with self._dumping:
            names = [f"{c.name} (pid {c.popen.pid})" for c in self._answering()]
            _LOG.warning("%s: the stacks of the launcher (pid %d), then of %s follow", why, os.getpid(),
                         ", ".join(names) or "no child")  # fmt: skip
            dump_stacks()
            self.dump_children()

    def start(self, child: Child, rejoin: bool = False) -> None:
        args = [sys.executable, "-m", *child.args, *(child.rejoin_args if rejoin else [])]
        child.popen = subprocess.Popen(
            args,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,  # ready lines: copied to the launcher's stderr, and to on_line
            stderr=sys.stderr.fileno(),
            text=True,
            bufsize=1,
            start_new_session=True,
            preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,
            env={**os.environ, "PYTHONUNBUFFERED": "1", LAUNCHER_ENV: str(os.getpid())},
        )
        child.next_start_s = None
        child.spoke = False
        self.children[child.name] = child
        threading.Thread(target=self._pump, args=(child, child.popen), daemon=True).start()
        _LOG.debug("started %s (pid %d): %s", child.name, child.popen.pid, " ".join(args))

    def _pump(self, child: Child, popen: subprocess.Popen) -> None:
        for line in popen.stdout:
            if child.popen is popen:
                child.spoke = True
            try:
                sys.stderr.write(line)
                if child.on_line is not None:
                    child.on_line(line.rstrip("\n"))
            except Exception:  # a closed stderr or a bad callback must not kill the pump
                pass

    def dump_children(self, gap_s: float = STACKS_GAP_S, names: tuple[str, ...] | None = None) -> list[str]:
        """Ask every running child that has spoken (or those of ``names``) for its threads' stacks
        (:mod:`swarm.stacks`), one after the other ``gap_s`` apart so that their dumps do not interleave on
        the launcher's stderr; returns ``"<name> (pid N)"`` of each, in that order."""
        from swarm.stacks import STACKS_SIGNAL

        asked = []
        with self._dumping:
            for c in self._answering(names):
                pid = c.popen.pid
                try:
                    os.kill(pid, STACKS_SIGNAL)
                except (ProcessLookupError, PermissionError):
                    continue
                asked.append(f"{c.name} (pid {pid})")
                time.sleep(gap_s)
        return asked

    def _answering(self, names: tuple[str, ...] | None = None) -> list[Child]:
        """The running children (of ``names``, if given) that have spoken: those that answer the stacks
        signal."""
        return [c for c in list(self.children.values())
                if (names is None or c.name in names) and c.running and c.spoke]  # fmt: skip

    def lost(self, name: str, why: str) -> str:
        """``name`` was seen lost (its liveliness token went, or it exited): kill what is left of it and
        schedule its restart. Returns what the launcher logs."""
        child = self.children.get(name)
        if child is None or child.next_start_s is not None:
            return ""
        self._kill(child)
        if not child.restartable:
            return f"{name} lost ({why}); not restartable"
        if child.restarts >= self.max_restarts:
            return f"{name} lost ({why}); already restarted {child.restarts} times, giving up"
        delay = self.backoff_s * 2**child.restarts
        child.restarts += 1
        child.next_start_s = time.monotonic() + delay
        return f"{name} lost ({why}); restart {child.restarts}/{self.max_restarts} in {delay:.1f} s"

    def due_restarts(self) -> list[Child]:
        """Start every child whose restart is due; returns them."""
        now = time.monotonic()
        due = [c for c in self.children.values() if c.next_start_s is not None and c.next_start_s <= now]
        for c in due:
            self.start(c, rejoin=True)
        return due

    def exited(self) -> list[Child]:
        """Children that exited without the launcher asking (not already handled)."""
        return [c for c in self.children.values() if c.popen is not None and c.popen.poll() is not None
                and c.next_start_s is None]  # fmt: skip

    def _kill(self, child: Child) -> None:
        if child.popen is None:
            return
        try:
            os.killpg(child.popen.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            child.popen.wait(5.0)
        except subprocess.TimeoutExpired:
            _LOG.error("%s (pid %d) survived SIGKILL for 5 s", child.name, child.popen.pid)

    def kill_starting(self, keep: tuple[str, ...] = ()) -> list[str]:
        """SIGKILL every running child (but those named in ``keep``) that has not said it is ready yet (no
        line on stdout: it is importing, or loading or compiling its kernels, and handles no signal until
        that is done): it has no liveliness token and no run state yet, so nobody sees it go and it loses
        nothing. Returns their names (each logged at INFO)."""
        starting = [c for c in self.children.values() if c.running and not c.spoke and c.name not in keep]
        for c in starting:
            c.next_start_s = None
            self._kill(c)
            _LOG.info("%s was still starting: stopped", c.name)
        return [c.name for c in starting]

    def stop_all(self, keep: tuple[str, ...] = (), first: tuple[str, ...] = ()) -> None:
        """Stop every child (but those named in ``keep``): those named in ``first`` before the others
        (the world: :mod:`swarm.transport.stopping`), each batch by SIGTERM to its groups, up to ``grace_s``
        to exit, then SIGKILL to the groups of the rest."""
        live = [c for c in self.children.values() if c.popen is not None and c.name not in keep]
        head = [c for c in live if c.name in first]
        for batch in (head, [c for c in live if c.name not in first]):
            if batch:
                self._stop(batch)

    def _stop(self, live: list[Child]) -> None:
        for c in live:
            c.next_start_s = None
            try:
                os.killpg(c.popen.pid, signal.SIGTERM)
            except (ProcessLookupError, PermissionError):
                pass
        deadline = time.monotonic() + self.grace_s
        for c in live:
            left = max(0.0, deadline - time.monotonic())
            try:
                c.popen.wait(left)
            except subprocess.TimeoutExpired:
                if c.spoke:
                    _LOG.warning("%s did not stop within %.1f s: killing it", c.name, self.grace_s)
                else:  # still starting (its kernels loading or compiling: no signal handled meanwhile)
                    _LOG.info("%s was still starting: stopped", c.name)
            self._kill(c)  # the group too: a grandchild must not outlive it


def forward_stacks_signal(sup: Supervisor) -> Callable[[], None]:
    """In the launcher, :data:`~swarm.stacks.STACKS_SIGNAL` dumps its own stacks and every child's
    (:meth:`Supervisor.dump_all`, on a thread: the children are asked one after the other). Returns the
    function that puts the plain dump back."""
    import faulthandler

    from swarm.stacks import STACKS_SIGNAL, enable_stack_dumps

    faulthandler.unregister(STACKS_SIGNAL)  # the `swarm` command's own dump, which would not forward

    def on_signal(_signum: int, _frame: object) -> None:
        threading.Thread(target=sup.dump_all, args=(STACKS_SIGNAL.name,), daemon=True).start()

    signal.signal(STACKS_SIGNAL, on_signal)

    def restore() -> None:
        signal.signal(STACKS_SIGNAL, signal.SIG_DFL)
        enable_stack_dumps()

    return restore


class StallWatch:
    """The world's clock standing still in a running run: fed each ``world/clock`` message (its tick and
    state), :meth:`check` says once per stall that the tick has not moved for ``stall_s`` seconds while
    the world said it was running. A paused or stopped world, or one not heard from yet, never stalls."""

    def __init__(self, stall_s: float) -> None:
        self.stall_s = stall_s
        self.tick: int | None = None
        self.state: str | None = None
        self.since: float | None = None
        self.fired = False
        self._lock = threading.Lock()

    def on_clock(self, tick: int, state: str, now: float) -> None:
        with self._lock:
            if tick != self.tick or state != self.state:
                self.tick, self.state, self.since, self.fired = tick, state, now, False

    def check(self, now: float) -> tuple[int, float] | None:
        """``(tick, seconds)`` the first time the clock has stood at ``tick`` for ``stall_s`` or more in a
        running run; None otherwise (and again until the clock moves)."""
        with self._lock:
            if self.since is None or self.state != "running" or self.fired or self.tick is None:
                return None
            if now - self.since < self.stall_s:
                return None
            self.fired = True
            return self.tick, now - self.since

    def tell(self, sup: Supervisor, now: float) -> bool:
        """At a stall (:meth:`check`), every process's stacks (:meth:`Supervisor.dump_all`, on a thread: the
        children are asked one after the other while the launcher's loop goes on). Whether it told."""
        stood = self.check(now)
        if stood is None:
            return False
        why = f"the world's clock has stood at tick {stood[0]} for {stood[1]:.1f} s in a running run"
        threading.Thread(target=sup.dump_all, args=(why,), daemon=True).start()
        return True
