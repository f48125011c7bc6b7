"""``--cpu-latency``: the PM QoS CPU latency request a launch holds (``swarm/cpu_latency.py``).

A file stands in for ``/dev/cpu_dma_latency`` where the test is about what is written and when it is
withdrawn; the kernel's own file is used where the machine lets the test write it (root), to show that the
request takes effect and goes with the block."""

from __future__ import annotations

import argparse
import logging
import os
import struct
import subprocess
from pathlib import Path

import pytest

from swarm.cpu_latency import DEVICE, MAX_US, hold, parse


def _open_fds_to(path: Path) -> int:
    """How many of this process's descriptors are open on ``path``."""
    n = 0
    for fd in Path("/proc/self/fd").iterdir():
        try:
            n += os.readlink(fd) == str(path)
        except OSError:  # the listing's own descriptor, closed meanwhile
            pass
    return n


def test_the_flag_takes_off_or_microseconds_and_names_itself_and_the_value_when_refused():
    assert parse("off") is None
    assert parse("0") == 0 and parse("50") == 50 and parse(str(MAX_US)) == MAX_US
    for bad in ("-1", str(MAX_US + 1), "1.5", "", "none", "0x10"):
        with pytest.raises(argparse.ArgumentTypeError, match=rf"--cpu-latency must be .* got {bad!r}"):
            parse(bad)


def test_the_request_is_written_as_a_signed_32_bit_value_and_withdrawn_when_the_block_ends(tmp_path):
    fake = tmp_path / "cpu_dma_latency"
    fake.write_bytes(b"")
    with hold(7, device=fake) as held:
        assert struct.unpack("=i", fake.read_bytes()) == (7,)
        assert held.held and held.effective_us == 7 and held.error is None
        assert _open_fds_to(fake) == 1  # the kernel holds a request while its file is open
        want = {"cpu_latency_us": 7, "cpu_latency_held": True, "cpu_latency_effective_us": 7}
        assert held.as_dict() == want
    assert _open_fds_to(fake) == 0
    with pytest.raises(RuntimeError, match="boom"), hold(0, device=fake):
        raise RuntimeError("boom")
    assert _open_fds_to(fake) == 0  # withdrawn when the block raises too


def test_off_touches_nothing(tmp_path):
    fake = tmp_path / "cpu_dma_latency"
    with hold(None, device=fake) as held:
        assert not held.held and held.error is None
    assert not fake.exists()


def test_a_request_the_machine_refuses_is_a_warning_naming_the_file_and_the_reason(tmp_path, caplog):
    missing = tmp_path / "no" / "cpu_dma_latency"
    with caplog.at_level(logging.WARNING, logger="swarm.cpu_latency"), hold(0, device=missing) as held:
        ran = True
    assert ran and not held.held and held.effective_us is None
    assert held.error == f"{missing}: No such file or directory"
    assert f"--cpu-latency 0: no CPU latency request held ({held.error})" in caplog.text
    if os.geteuid() != 0:  # root may write a read-only file
        ro = tmp_path / "ro"
        ro.write_bytes(b"")
        ro.chmod(0o444)
        with hold(0, device=ro) as held:
            assert not held.held and "Permission denied" in held.error


def _machine_bound() -> int:
    """The kernel's current CPU latency bound, read as any process may (opening the file adds a request
    of the default, which lowers nothing)."""
    fd = os.open(DEVICE, os.O_RDONLY)
    try:
        return struct.unpack("=i", os.read(fd, 4))[0]
    finally:
        os.close(fd)


@pytest.mark.skipif(not os.access(DEVICE, os.R_OK | os.W_OK), reason=f"{DEVICE} is not writable here")
def test_the_kernel_takes_the_request_for_the_block_alone():
    before = _machine_bound()
    with hold(0) as held:
        assert held.held and held.effective_us == 0 and _machine_bound() == 0
    assert _machine_bound() == before


@pytest.mark.parametrize("what", ["mothership", "router", "replay"])
def test_a_process_started_by_hand_holds_its_own_request_until_it_stops(what, tmp_path):
    """``python -m mothership --cpu-latency 0`` (a process on another machine, started without the launcher;
    every swarm process takes the flag), a router on a machine of its own, a log published as sensor
    drivers would (``swarm replay DIR --zenoh``): the request from its start to its end; a bad value is
    exit 2."""
    import signal
    import sys

    from tests.transport.procs import Procs, free_port, loopback

    ep = loopback(free_port())
    if what == "mothership":
        base = [sys.executable, "-m", "mothership", "docking", "--namespace", f"cpulat{os.getpid()}",
                "--mode", "peer", "--listen", ep]  # fmt: skip
        ready = r"^mothership mothership ready"
    elif what == "router":
        base, ready = [sys.executable, "-m", "swarm.cli.router", "--listen", ep], r"^router listening on "
    else:
        log = tmp_path / "log"
        synth = [sys.executable, "-m", "swarm.cli.main", "synth-log", str(log), "--duration", "20"]
        made = subprocess.run(synth, capture_output=True, text=True, timeout=120)
        assert made.returncode == 0, made.stderr
        base = [sys.executable, "-m", "swarm.cli.main", "replay", str(log), "--zenoh", "--wait", "0.1",
                "--mode", "peer", "--listen", ep]  # fmt: skip
        ready = r"^publishing "
    writable = os.access(DEVICE, os.R_OK | os.W_OK)
    before = _machine_bound() if writable else None
    with Procs() as procs:
        bad = procs.start([*base, "--cpu-latency", "-5"])
        assert bad.wait(60.0) == 2 and "--cpu-latency must be off or microseconds" in bad.output()
        proc = procs.start([*base, "--cpu-latency", "0"])
        proc.wait_for_line(ready, 60.0)
        if writable:
            assert _machine_bound() == 0
        else:
            assert "no CPU latency request held" in proc.output()
        proc.signal(signal.SIGINT if what == "replay" else signal.SIGTERM)
        assert proc.wait(30.0) in ((0, 130) if what == "replay" else (0,)), proc.output()
    if writable:
        assert _machine_bound() == before
