"""Test helpers for multi-process Zenoh tests: free loopback ports, subprocesses in their own process group
that are always killed (even when a test fails), and waiting for a line of their output with a timeout.

Usage::

    with Procs() as procs:
        router = procs.start([sys.executable, "-m", "swarm.cli.router", "--listen", loopback(free_port())])
        router.wait_for_line(r"^router listening on ", timeout=10.0)
        ...

Each process is started with ``start_new_session=True``: it leads a new process group, so that the
cleanup (SIGKILL to the group) also reaches any child it spawned. Its stdout and stderr are read by
threads into lists of lines, so a chatty process never blocks on a full pipe.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO

REPORT_WAIT_S = 2.0
"""After a failure, how long the processes get to write their stacks (a launcher asks its children one
after the other, 0.1 s apart) before they are killed."""
REPORT_LINES = 400
"""The lines of each process's output printed after a failure (a launcher's stacks and its children's
fit in a few hundred)."""

REPO = Path(__file__).resolve().parents[2]
"""The repository root: the working directory of every started process."""


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (the OS picks it; the socket is closed again)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def loopback(port: int) -> str:
    """The Zenoh endpoint ``tcp/127.0.0.1:<port>``."""
    return f"tcp/127.0.0.1:{port}"


def wait_until(predicate: Callable[[], object], timeout: float, what: str, poll_s: float = 0.002) -> None:
    """Return once ``predicate()`` is true; AssertionError naming ``what`` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(poll_s)


class Proc:
    """One started process: its output lines so far, waiting for a line, signals to its group."""

    def __init__(self, args: Sequence[str], env: dict[str, str] | None = None) -> None:
        self.args = list(args)
        full_env = dict(os.environ)
        full_env["PYTHONUNBUFFERED"] = "1"
        full_env.update(env or {})
        self.popen = subprocess.Popen(
            self.args,
            cwd=REPO,
            env=full_env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            bufsize=1,
            start_new_session=True,
        )
        self.pgid = self.popen.pid  # a session leader's group id is its pid
        self._cond = threading.Condition()
        self.stdout: list[str] = []
        self.stderr: list[str] = []
        self._eof = {"stdout": False, "stderr": False}
        self._readers = [
            threading.Thread(target=self._read, args=(self.popen.stdout, self.stdout, "stdout"), daemon=True),
            threading.Thread(target=self._read, args=(self.popen.stderr, self.stderr, "stderr"), daemon=True),
        ]
        for t in self._readers:
            t.start()

    def _read(self, stream: IO[str], lines: list[str], name: str) -> None:
        for line in stream:
            with self._cond:
                lines.append(line.rstrip("\n"))
                self._cond.notify_all()
        with self._cond:
            self._eof[name] = True
            self._cond.notify_all()

    @property
    def pid(self) -> int:
        return self.popen.pid

    def output(self) -> str:
        """Everything read so far, for assertion messages."""
        with self._cond:
            out, err = "\n".join(self.stdout), "\n".join(self.stderr)
        return f"$ {' '.join(self.args)}\n--- stdout ---\n{out}\n--- stderr ---\n{err}"

    def wait_for_line(self, pattern: str, timeout: float) -> re.Match[str]:
        """The first stdout line matching the regex ``pattern`` (``re.search``), waiting up to ``timeout``
        seconds for it; AssertionError with the output so far if it does not come or stdout closes."""
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout
        seen = 0
        with self._cond:
            while True:
                for line in self.stdout[seen:]:
                    m = rx.search(line)
                    if m is not None:
                        return m
                seen = len(self.stdout)
                if self._eof["stdout"]:
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._cond.wait(left)
        why = "stdout closed" if self._eof["stdout"] else f"timed out after {timeout} s"
        raise AssertionError(f"no line matching {pattern!r} ({why})\n{self.output()}")

    def wait(self, timeout: float) -> int:
        """The exit code, waiting up to ``timeout`` seconds (AssertionError with the output if longer).
        Also waits for the output readers, so :meth:`output` is complete."""
        try:
            rc = self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"still running after {timeout} s\n{self.output()}") from None
        for t in self._readers:
            t.join(timeout=2.0)
        return rc

    def signal(self, sig: int) -> None:
        """Send ``sig`` to the process itself (not its group)."""
        self.popen.send_signal(sig)

    def group_alive(self) -> bool:
        """Whether any process of this process's group still exists (zombies included until reaped)."""
        try:
            os.killpg(self.pgid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # the group id was reused by someone else's process
            return False
        return True

    def kill_group(self) -> None:
        """SIGKILL every process of the group, then reap the leader. Idempotent."""
        try:
            os.killpg(self.pgid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            self.popen.wait(5.0)
        except subprocess.TimeoutExpired:
            pass
        for t in self._readers:  # EOF comes once every holder of the pipes is dead
            t.join(timeout=2.0)
        if not any(t.is_alive() for t in self._readers):
            for stream in (self.popen.stdout, self.popen.stderr):
                if stream is not None:
                    stream.close()


class Procs:
    """A context manager that starts processes and kills every one of their process groups on exit,
    whatever happened in between."""

    def __init__(self) -> None:
        self.procs: list[Proc] = []

    def start(self, args: Sequence[str], env: dict[str, str] | None = None) -> Proc:
        proc = Proc(args, env)
        self.procs.append(proc)
        return proc

    def __enter__(self) -> Procs:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if exc_type is not None:
            self._report()
        for proc in self.procs:
            proc.kill_group()

    def _report(self) -> None:
        """A test failed (or hung: pytest-timeout's exception lands here): each process still running is
        asked for its threads' stacks (swarm/stacks.py; a launcher forwards the request to each child),
        and the end of every process's output is printed, for pytest's report of the failure."""
        from swarm.stacks import STACKS_SIGNAL

        running = [p for p in self.procs if p.popen.poll() is None]
        for proc in running:
            try:
                os.kill(proc.pid, STACKS_SIGNAL)
            except ProcessLookupError:
                pass
        if running:
            time.sleep(REPORT_WAIT_S)
        for proc in self.procs:
            lines = proc.output().splitlines()
            print(f"=== {' '.join(proc.args)[:200]} (pid {proc.pid}, exit {proc.popen.poll()}): last "
                  f"{min(len(lines), REPORT_LINES)} of {len(lines)} lines ===")  # fmt: skip
            print("\n".join(lines[-REPORT_LINES:]))


class Inbox:
    """Messages an independent subscriber received, by kind: ``session.declare_subscriber(key,
    inbox.on(kind, cls))`` decodes each sample as ``cls`` (an invalid one is counted in ``drops`` and kept
    as None) into ``got[kind]``, in arrival order; thread-safe."""

    def __init__(self, *kinds: str) -> None:
        from swarm.transport.messages import DropCounter

        self.got: dict[str, list] = {k: [] for k in kinds}
        self.drops = DropCounter()
        self._lock = threading.Lock()

    def on(self, kind: str, cls):
        from swarm.transport.messages import safe_decode

        def cb(sample) -> None:
            msg = safe_decode(sample.payload, cls, str(sample.key_expr), self.drops)
            with self._lock:
                self.got[kind].append(msg)

        return cb
