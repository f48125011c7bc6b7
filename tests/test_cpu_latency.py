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

from swarm.cpu_latency import DEVICE, MAX_US, describe_idle, hold, idle_config, parse


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


def _fake_sysfs(root: Path, states: list[tuple[str, str, str]], driver: str | None = "haltpoll") -> Path:
    """A ``/sys/devices/system/cpu`` with cpu0's idle states (name, exit latency, disable) as files."""
    if driver is not None:
        (root / "cpuidle").mkdir(parents=True)
        (root / "cpuidle" / "current_driver").write_text(driver + "\n")
        (root / "cpuidle" / "current_governor_ro").write_text("menu\n")
    for i, (name, latency, disable) in enumerate(states):
        d = root / "cpu0" / "cpuidle" / f"state{i}"
        d.mkdir(parents=True)
        (d / "name").write_text(name + "\n")
        (d / "latency").write_text(latency + "\n")
        (d / "disable").write_text(disable + "\n")
    return root


def test_the_idle_configuration_is_read_state_by_state_in_their_order(tmp_path):
    # twelve states: state10 and state11 must sort after state2 (numerically, not as text)
    states = [("POLL", "0", "0"), ("C1", "2", "0"), ("C2", "80", "1")] + [
        (f"C{i}", str(100 * i), "0") for i in range(3, 12)
    ]
    cpu = _fake_sysfs(tmp_path / "cpu", states)
    (cpu / "cpu0" / "cpuidle" / "state1x").mkdir()  # not a state's directory: left out
    poll = tmp_path / "guest_halt_poll_ns"
    poll.write_text("200000\n")
    device = tmp_path / "cpu_dma_latency"
    device.write_bytes(struct.pack("=i", 25))
    cfg = idle_config(cpu, poll, device)
    assert cfg["driver"] == "haltpoll" and cfg["governor"] == "menu"
    assert [s["name"] for s in cfg["states"]] == [s[0] for s in states]
    assert cfg["states"][2] == {"name": "C2", "exit_latency_us": 80, "disabled": True}
    assert cfg["states"][11]["exit_latency_us"] == 1100 and cfg["states"][11]["disabled"] is False
    assert cfg["guest_halt_poll_ns"] == 200000 and cfg["pm_qos_bound_us"] == 25
    line = describe_idle(cfg)
    assert "C2 80 us (disabled)" in line and "guest halt polling 200000 ns" in line
    assert "PM QoS bound 25 us" in line


def test_an_idle_configuration_the_kernel_does_not_show_is_none_not_an_error(tmp_path):
    cpu = _fake_sysfs(tmp_path / "cpu", [("POLL", "not a number", "")], driver=None)
    cfg = idle_config(cpu, tmp_path / "absent", tmp_path / "absent_device")
    assert cfg == {
        "driver": None,
        "governor": None,
        "states": [{"name": "POLL", "exit_latency_us": None, "disabled": None}],
        "guest_halt_poll_ns": None,
        "pm_qos_bound_us": None,
    }
    assert describe_idle(cfg) == ("CPU idle: driver unknown; states: POLL None us; PM QoS bound unknown")
    assert idle_config(tmp_path / "nothing", tmp_path / "absent", tmp_path / "absent")["states"] is None


@pytest.mark.skipif(not os.access(DEVICE, os.R_OK | os.W_OK), reason=f"{DEVICE} is not writable here")
def test_the_machine_bound_read_with_the_idle_configuration_follows_a_held_request():
    assert idle_config()["pm_qos_bound_us"] == _machine_bound()
    with hold(0):
        assert idle_config()["pm_qos_bound_us"] == 0
        assert "PM QoS bound 0 us" in describe_idle(idle_config())
