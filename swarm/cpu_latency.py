"""A CPU wake-up latency request held while a swarm runs (``swarm launch --cpu-latency US``).

A free-running swarm process sleeps between its messages, and a CPU with nothing to run goes idle. Waking
it costs time: a deep C-state's exit on a laptop, and on a virtual machine the halted vCPU's return through
the hypervisor. Here that is the "wake tax" of BENCHMARKS.md: numpy's sum of 1000 floats takes ~2 us warm
and 37-63 us right after a 10 ms sleep.

Linux's PM QoS interface (the kernel's ``Documentation/power/pm_qos_interface.rst``) lets a process ask
for a bound on that latency. It opens ``/dev/cpu_dma_latency`` and writes a signed 32-bit number of
microseconds. While the file stays open, the cpuidle governor skips every idle state whose exit latency is
longer than the smallest such request. At 0 an idle CPU polls: the same sum then takes ~3 us after a
10 ms sleep. Closing the file (or the process ending) withdraws the request. ``cyclictest --latency`` and
tuned's ``latency-performance`` profile do the same. It is a whole-machine setting: an idle core then draws
power as if busy, so it is off unless asked for.

``swarm launch`` holds it for its whole swarm; a swarm process started by hand (``python -m agents``, the
world, the mothership: :func:`swarm.transport.process.process_main`) holds its own, for a machine that
runs no launcher. Writing the file needs root (or a udev rule that opens it to a group). Without it, or on
a kernel without the file, :func:`hold` logs why and the swarm runs with the kernel's own idle states, as
``cyclictest`` does; the holder's :attr:`CpuLatencyHold.held` says which happened.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

DEVICE = Path("/dev/cpu_dma_latency")
"""The PM QoS CPU latency file."""

MAX_US = 2_000_000_000
"""The kernel's default (no request), ``PM_QOS_CPU_LATENCY_DEFAULT_VALUE``: the largest value a request may
name."""

_S32 = struct.Struct("=i")  # the value the file takes and gives: a native signed 32-bit integer

_LOG = logging.getLogger("swarm.cpu_latency")


def parse(text: str) -> int | None:
    """``--cpu-latency US|off``: microseconds in 0..:data:`MAX_US` (0: idle CPUs poll), or ``off`` (None)."""
    if text == "off":
        return None
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_US:
        raise argparse.ArgumentTypeError(
            f"--cpu-latency must be off or microseconds in 0..{MAX_US}, got {text!r}"
        )
    return value


def add_argument(group) -> None:
    """The ``--cpu-latency`` flag (default ``off``) on an argparse parser or group."""
    group.add_argument(
        "--cpu-latency", type=parse, default=None, metavar="US|off",
        help="hold a PM QoS request that no CPU take longer than US microseconds to wake "
        "(/dev/cpu_dma_latency, as cyclictest --latency does; 0: idle CPUs poll) while this runs: a "
        "process woken every tick then starts on a warm CPU; needs root, else a warning and the kernel's "
        "idle states; an idle core draws power as if busy (default off)",
    )  # fmt: skip


@dataclass
class CpuLatencyHold:
    """What :func:`hold` got."""

    requested_us: int | None
    held: bool = False
    effective_us: int | None = None
    """The machine's bound while held (the smallest request of all processes), read back from the file."""
    error: str | None = None
    """Why nothing is held, when a request was made and it failed."""

    def as_dict(self) -> dict:
        return {
            "cpu_latency_us": self.requested_us,
            "cpu_latency_held": self.held,
            "cpu_latency_effective_us": self.effective_us,
        }


@contextlib.contextmanager
def hold(us: int | None, device: Path = DEVICE) -> Iterator[CpuLatencyHold]:
    """Hold a request of ``us`` microseconds on ``device`` for the ``with`` block (``None``: nothing).

    A failure to open or write the file is logged as a warning naming the file and the reason, and the block
    runs without the request. The request ends when the block does, even when it raises."""
    state = CpuLatencyHold(us)
    if us is None:
        yield state
        return
    fd = None
    try:
        fd = os.open(device, os.O_RDWR | os.O_CLOEXEC)
        os.write(fd, _S32.pack(us))
        raw = os.pread(fd, _S32.size, 0)
        state.effective_us = _S32.unpack(raw)[0] if len(raw) == _S32.size else None
        state.held = True
        _LOG.info(
            "CPU wake-up latency: a request of %d us held on %s while this runs (the machine's bound: %s us)",
            us, device, state.effective_us,
        )  # fmt: skip
    except OSError as exc:
        if fd is not None:
            os.close(fd)
            fd = None
        state.error = f"{device}: {exc.strerror or exc}"
        _LOG.warning(
            "--cpu-latency %d: no CPU latency request held (%s); running with the kernel's idle states "
            "(writing the file needs root)",
            us, state.error,
        )  # fmt: skip
    try:
        yield state
    finally:
        if fd is not None:
            os.close(fd)  # the kernel withdraws the request


SYSFS_CPU = Path("/sys/devices/system/cpu")
"""Where the kernel shows its cpuidle driver, governor and each CPU's idle states."""

HALTPOLL_NS = Path("/sys/module/haltpoll/parameters/guest_halt_poll_ns")
"""A KVM guest's halt polling (the ``haltpoll`` governor): how long an idle vCPU polls before it halts.
The kernel's default is 200000 ns; a boot line may set it (this project's VM: 0, BENCHMARKS.md)."""


_STATE = re.compile(r"state(\d+)")  # an idle state's directory, numbered from 0 (the shallowest)


def _read(path: Path) -> str | None:
    try:
        return path.read_text().strip()
    except (OSError, UnicodeDecodeError):
        return None


def _int(text: str | None) -> int | None:
    try:
        return int(text) if text is not None else None
    except ValueError:
        return None


def idle_config(cpu_root: Path = SYSFS_CPU, haltpoll_ns: Path = HALTPOLL_NS, device: Path = DEVICE) -> dict:
    """The machine's CPU idle configuration, for a benchmark's record: what makes a woken process pay the
    "wake tax" (module docstring). Keys: ``driver`` and ``governor`` (cpuidle), ``states`` (cpu0's, each
    ``{"name", "exit_latency_us", "disabled"}``), ``guest_halt_poll_ns`` (a KVM guest's halt polling) and
    ``pm_qos_bound_us`` (the smallest CPU latency request of all processes, :data:`MAX_US` for none; read
    from :data:`DEVICE`, which needs root). Each is None where this kernel has no such file or it cannot be
    read: the record says what was not known rather than failing the bench."""
    idle = cpu_root / "cpuidle"
    states = []
    numbered = ((d, _STATE.fullmatch(d.name)) for d in (cpu_root / "cpu0" / "cpuidle").glob("state*"))
    for _, d in sorted((int(m[1]), d) for d, m in numbered if m):
        disabled = _int(_read(d / "disable"))
        states.append({
            "name": _read(d / "name"),
            "exit_latency_us": _int(_read(d / "latency")),
            "disabled": None if disabled is None else bool(disabled),
        })  # fmt: skip
    bound = None
    try:
        fd = os.open(device, os.O_RDONLY | os.O_CLOEXEC)
        try:
            raw = os.read(fd, _S32.size)
            bound = _S32.unpack(raw)[0] if len(raw) == _S32.size else None
        finally:
            os.close(fd)
    except OSError:
        pass
    return {
        "driver": _read(idle / "current_driver"),
        "governor": _read(idle / "current_governor") or _read(idle / "current_governor_ro"),
        "states": states or None,
        "guest_halt_poll_ns": _int(_read(haltpoll_ns)),
        "pm_qos_bound_us": bound,
    }


def describe_idle(cfg: dict) -> str:
    """One line of :func:`idle_config` for a bench's report."""
    states = ", ".join(
        f"{s['name']} {s['exit_latency_us']} us" + (" (disabled)" if s["disabled"] else "")
        for s in cfg.get("states") or []
    )  # fmt: skip
    parts = [f"driver {cfg.get('driver') or 'unknown'}", f"states: {states or 'unknown'}"]
    if cfg.get("guest_halt_poll_ns") is not None:
        parts.append(f"guest halt polling {cfg['guest_halt_poll_ns']} ns")
    bound = cfg.get("pm_qos_bound_us")
    parts.append("no PM QoS request" if bound == MAX_US else f"PM QoS bound {bound} us" if bound is not None
                 else "PM QoS bound unknown")  # fmt: skip
    return "CPU idle: " + "; ".join(parts)
