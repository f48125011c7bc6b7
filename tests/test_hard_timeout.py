"""The suite's last resort against a hang (``tests/hard_timeout.py``): a test stuck where pytest-timeout's
SIGALRM never reaches it ends the whole run with every thread's stack, instead of holding CI until its own
limit. A real pytest run in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from tests.transport.procs import REPO

STUCK_S = 60.0  # the stuck test's own sleep: the run must end long before it


def test_a_test_stuck_where_no_signal_reaches_it_ends_the_run_with_every_stack(tmp_path):
    """SIGALRM blocked in the main thread (as in a call that never returns to Python): pytest-timeout's
    signal (timeout 1 s) cannot fail the test; at twice that plus the margin (1 s) the watchdog writes the
    stacks, the stuck test's frame among them, and the run exits 1."""
    test = tmp_path / "test_stuck.py"
    test.write_text(
        "import signal\nimport time\n\n\ndef test_stuck_here():\n"
        "    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGALRM})\n"
        f"    time.sleep({STUCK_S})\n"
    )
    args = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-c", os.devnull,
            "--rootdir", str(tmp_path), "-p", "tests.hard_timeout", "-o", "timeout=1",
            "-o", "hard_timeout_margin=1", str(test)]  # fmt: skip
    t0 = time.monotonic()
    r = subprocess.run(args, cwd=REPO, capture_output=True, text=True, timeout=STUCK_S - 10)
    took = time.monotonic() - t0
    assert r.returncode == 1, r.stdout + r.stderr
    assert took < STUCK_S / 2, took  # 3 s of limit plus pytest's start
    assert "Timeout (0:00:03)!" in r.stderr, r.stderr
    assert 'test_stuck.py", line 7 in test_stuck_here' in r.stderr, r.stderr
