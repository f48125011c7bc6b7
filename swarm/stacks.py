"""Every thread's stack on demand: ``kill -USR1 <pid>`` makes any process of the swarm write the Python stack
of each of its threads to its stderr and go on, the way a JVM answers SIGQUIT.

It is ``faulthandler``'s, written from C: it answers even when a thread holds the GIL for good or the main
thread waits in a call that never returns, where a Python signal handler would never run. Every process
enables it first thing (:func:`swarm.transport.process.process_main`, the ``swarm`` command, the router and
the dashboard). ``swarm launch`` writes its own stacks and forwards the signal to each of its children
(:meth:`swarm.cli.supervisor.Supervisor.dump_children`), and sends it itself when the world's clock stands
still in a running run or ``--timeout`` ends a run that did not end: a hung swarm says where each process
was before it is stopped.
"""

from __future__ import annotations

import faulthandler
import signal
import sys

STACKS_SIGNAL = signal.SIGUSR1
"""The signal that asks a process for its threads' stacks."""


STDERR_FD = 2
"""Where the stacks go: the process's own stderr, by descriptor (``sys.stderr`` may be replaced by an object
with no descriptor, as pytest's capture does when a test calls a command's ``main``)."""


def enable_stack_dumps() -> None:
    """:data:`STACKS_SIGNAL` writes every thread's stack to stderr from now on (the module docstring)."""
    faulthandler.register(STACKS_SIGNAL, file=STDERR_FD, all_threads=True)


def dump_stacks() -> None:
    """Every thread's stack to stderr now (what :data:`STACKS_SIGNAL` does), after what Python has
    buffered for it."""
    sys.stderr.flush()
    faulthandler.dump_traceback(file=STDERR_FD, all_threads=True)
