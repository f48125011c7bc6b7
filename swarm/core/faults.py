"""Fault injection (issue 7): UWB NLOS outlier bursts and dropouts, camera loss and a gyro bias step, each
in a time window fixed in the scenario or opened when a chaser enters a guidance mode.

Every fault is a *window* ``[start, end)`` in simulated time [s] (start inclusive, end exclusive) on one
of the sensor models the world already has, so a fault changes what a sensor returns and nothing else:

* ``nlos_burst``: inside the window an exchange is an NLOS outlier with probability
  ``nlos_burst_probability`` (at least ``uwb.nlos_probability``), the same long-path outlier model
  (:func:`swarm.core.sensors.uwb_exchange`); network-wide (every radio);
* ``uwb_dropout``: every reply inside the window is lost (no range); network-wide: the mothership's
  radio network, not one tag, goes quiet;
* ``camera_loss``: the chaser's camera returns nothing (a frame is drawn and dropped, so the camera's
  noise stream stays aligned with the fault-free run); per chaser;
* ``gyro_bias_step``: from ``t_s`` on, a constant ``deg_s`` (body frame) adds to the gyro of the listed
  vehicles (every chaser when none is listed), on top of the Gauss-Markov bias the filter models.

**Mode triggers.** A :class:`FaultWindows` with ``on_mode`` set opens a window when a chaser enters that
guidance mode. The mode changes only at a control tick ``k`` (:meth:`swarm.core.agent.VehicleAgent.
control`); the runner then calls :meth:`FaultSchedule.on_mode`, and the window opens ``delay_s`` after
the *next* tick: ``start = t_k + dt + delay_s``, ``end = start + duration_s``; with ``while_in_mode`` it
also closes at ``t_j + dt`` when the chaser leaves the mode at control tick ``j``. Sensor samples of a
tick are those the world returns for that tick (the UWB exchange at ``t``, the gyro averaged over
``[t - dt, t]``, the camera frame at ``t``), so the first faulty samples are those of tick ``k + 1``, never
a sample the agent has already used. The windows are plain numbers checked by the compiled kernels
themselves (:func:`swarm.core.sensors.uwb_exchange`, :func:`swarm.core.world.world_tick`) or by the
Python camera path, so a compiled stretch of ticks cannot run past a fault: a window opened at a control
tick lies in the future of every tick already run. Fixed windows (``windows_s``) need no runner at all:
the world and the mothership's radio network read them from the scenario, in either runner.

All faults are off by default (no window, no step), and then every kernel does exactly the arithmetic it
did before, so fault-free results are unchanged bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from swarm.errors import ConfigError

__all__ = ["MODES", "FaultParams", "FaultSchedule", "FaultWindows"]

MODES = ("HOLD", "APPROACH", "REORIENT", "ALIGN", "DOCK", "ABORT")
"""Guidance modes a window may be triggered by (:class:`swarm.core.guidance.Mode` values)."""


def _windows(section: str, value) -> tuple[tuple[float, float], ...]:
    out = tuple(tuple(w) for w in value)
    for w in out:
        if not (
            len(w) == 2
            and all(isinstance(x, int | float) and math.isfinite(x) for x in w)
            and 0 <= w[0] < w[1]
        ):
            raise ConfigError(
                f"{section} must be (start, end) pairs with 0 <= start < end [s], got {value!r}"
            )
    return tuple((float(a), float(b)) for a, b in out)


@dataclass(frozen=True)
class FaultWindows:
    """When one kind of fault is active: fixed windows, and/or windows opened by a guidance mode."""

    windows_s: tuple[tuple[float, float], ...] = ()
    """Fixed windows ``(start, end)`` of simulated time [s], start inclusive, end exclusive."""
    on_mode: str = ""
    """A window opens when a chaser enters this guidance mode (one of HOLD, APPROACH, REORIENT, ALIGN, DOCK,
    ABORT); ``""``: no mode trigger. It opens at the tick after the control tick of the mode change."""
    delay_s: float = 0.0
    """Delay from that tick to the start of the window [s]."""
    duration_s: float = 5.0
    """Length of a mode-triggered window [s]."""
    while_in_mode: bool = False
    """Also close the window when the chaser leaves ``on_mode`` (at the tick after that control tick)."""
    first_entry_only: bool = True
    """Trigger on the first entry into ``on_mode`` only; ``False``: every entry opens a new window."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "windows_s", _windows("faults.*.windows_s", self.windows_s))
        if self.on_mode not in ("", *MODES):
            raise ConfigError(f"faults.*.on_mode must be '' or one of {MODES}, got {self.on_mode!r}")
        for name in ("delay_s", "duration_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"faults.*.{name} must be a non-negative finite number, got {v!r}")
        if self.on_mode and not self.duration_s > 0:
            raise ConfigError(
                f"faults.*.duration_s must be positive with on_mode set, got {self.duration_s!r}"
            )
        for name in ("while_in_mode", "first_entry_only"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"faults.*.{name} must be a bool, got {getattr(self, name)!r}")

    @property
    def enabled(self) -> bool:
        return bool(self.windows_s) or bool(self.on_mode)


@dataclass(frozen=True)
class FaultParams:
    """The faults of a run (module docstring); all off by default."""

    nlos_burst: FaultWindows = field(default_factory=FaultWindows)
    """When NLOS outlier bursts happen (every radio of the network)."""
    nlos_burst_probability: float = 0.0
    """Outlier probability of an exchange inside a burst window (``uwb.nlos_probability`` outside, and
    inside when it is larger); the outlier size is ``uwb.nlos_min_m`` .. ``uwb.nlos_max_m``."""
    uwb_dropout: FaultWindows = field(default_factory=FaultWindows)
    """When every UWB reply is lost (every radio; ``uwb.dropout_windows_s`` adds fixed windows too)."""
    camera_loss: FaultWindows = field(default_factory=FaultWindows)
    """When the chaser's camera sees nothing (fixed windows: every chaser; mode-triggered: that chaser)."""
    gyro_bias_step_t_s: float | None = None
    """Time of a gyro bias step [s]; left out (None): no step."""
    gyro_bias_step_deg_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The step, added to the gyro output from ``gyro_bias_step_t_s`` on, body frame [deg/s]."""
    gyro_bias_step_vehicles: tuple[str, ...] = ()
    """Vehicles whose gyro steps; empty: every chaser."""

    def __post_init__(self) -> None:
        p = self.nlos_burst_probability
        if not (isinstance(p, int | float) and 0.0 <= p <= 1.0):
            raise ConfigError(f"faults.nlos_burst_probability must be a probability in [0, 1], got {p!r}")
        t = self.gyro_bias_step_t_s
        if t is not None and not (isinstance(t, int | float) and math.isfinite(t) and t >= 0):
            raise ConfigError(f"faults.gyro_bias_step_t_s must be a non-negative finite time, got {t!r}")
        s = tuple(self.gyro_bias_step_deg_s)
        if len(s) != 3 or not all(isinstance(x, int | float) and math.isfinite(x) for x in s):
            raise ConfigError(f"faults.gyro_bias_step_deg_s must be three finite numbers, got {s!r}")
        object.__setattr__(self, "gyro_bias_step_deg_s", tuple(float(x) for x in s))
        object.__setattr__(self, "gyro_bias_step_vehicles", tuple(self.gyro_bias_step_vehicles))

    @property
    def enabled(self) -> bool:
        """Whether any fault of this table is on."""
        return (
            (self.nlos_burst.enabled and self.nlos_burst_probability > 0)
            or self.uwb_dropout.enabled
            or self.camera_loss.enabled
            or self.gyro_bias_step_t_s is not None
        )

    @property
    def mode_triggered(self) -> bool:
        """Whether a runner must report mode changes (:meth:`FaultSchedule.on_mode`)."""
        return any(w.on_mode for w in (self.nlos_burst, self.uwb_dropout, self.camera_loss))

    def gyro_step_rad_s(self, vehicle_id: str, chasers: list[str]) -> tuple[float, np.ndarray]:
        """``(t_step [s], step (3,) [rad/s])`` of one vehicle's gyro; ``(inf, zeros)`` without a step."""
        listed = self.gyro_bias_step_vehicles or tuple(chasers)
        if self.gyro_bias_step_t_s is None or vehicle_id not in listed:
            return math.inf, np.zeros(3)
        return float(self.gyro_bias_step_t_s), np.radians(np.asarray(self.gyro_bias_step_deg_s))


class FaultSchedule:
    """The fault windows of one run, mode-triggered ones included as they open (module docstring).

    ``dt_s`` is the tick [s]; ``chasers`` the ids of the chasers (camera windows are kept per chaser).
    The runner calls :meth:`on_mode` after every control tick at which a chaser's mode may have changed
    and, when it returns True, hands the new windows to the world (:attr:`camera`) and the radio network
    (:meth:`swarm.core.world.UwbNetwork.set_fault_windows` with :attr:`uwb_dropout`, :attr:`nlos`).
    """

    def __init__(
        self, params: FaultParams, dt_s: float, chasers: list[str], uwb_windows_s: tuple = ()
    ) -> None:
        """``uwb_windows_s``: the radio's own fixed dropout windows (``uwb.dropout_windows_s``), kept with
        the fault windows so that one list says when the network is quiet."""
        self.p = params
        self.dt = float(dt_s)
        self.uwb_dropout: list[list[float]] = [list(w) for w in params.uwb_dropout.windows_s]
        self.uwb_dropout += [list(w) for w in uwb_windows_s]
        prob = params.nlos_burst_probability
        self.nlos: list[list[float]] = [[a, b, prob] for a, b in params.nlos_burst.windows_s] if prob else []
        self.camera: dict[str, list[list[float]]] = {
            c: [list(w) for w in params.camera_loss.windows_s] for c in chasers
        }
        self._mode: dict[str, str] = {}
        self._entered: dict[tuple[str, str], int] = {}
        self._open: list[tuple[str, str, list[float]]] = []  # (chaser, mode, window) closing on mode exit
        self.events: list[dict] = []
        """Windows opened, for the run's record: ``{"t_s", "fault", "chaser", "mode", "window_s"}`` (a
        window closed by leaving its mode shows its final end)."""

    def on_mode(self, t_s: float, chaser: str, mode: str) -> bool:
        """Chaser ``chaser`` is in ``mode`` after the control tick at ``t_s``; returns whether a window
        opened or closed (then the world's and the network's copies need refreshing)."""
        prev = self._mode.get(chaser)
        if prev == mode:
            return False
        self._mode[chaser] = mode
        changed = False
        t_next = t_s + self.dt
        for ch, m, w in list(self._open):  # windows that last while in a mode: close on leaving it
            if ch == chaser and m == prev:
                if w[1] > t_next:
                    w[1] = max(w[0], t_next)
                    changed = True
                self._open.remove((ch, m, w))
        for kind, fw in (("nlos_burst", self.p.nlos_burst), ("uwb_dropout", self.p.uwb_dropout),
                         ("camera_loss", self.p.camera_loss)):  # fmt: skip
            if fw.on_mode != mode or (kind == "nlos_burst" and not self.p.nlos_burst_probability):
                continue
            n = self._entered.get((chaser, kind), 0)
            self._entered[chaser, kind] = n + 1
            if n and fw.first_entry_only:
                continue
            start = t_next + fw.delay_s
            w = [start, start + fw.duration_s]
            if kind == "nlos_burst":
                self.nlos.append([*w, self.p.nlos_burst_probability])
                w = self.nlos[-1]
            elif kind == "uwb_dropout":
                self.uwb_dropout.append(w)
            else:
                self.camera[chaser].append(w)
            if fw.while_in_mode:
                self._open.append((chaser, mode, w))
            self.events.append({"t_s": t_s, "fault": kind, "chaser": chaser, "mode": mode, "window_s": w})
            changed = True
        return changed

    def add(self, kind: str, start_s: float, end_s: float, vehicles=(), probability: float = 0.0) -> None:
        """A window opened at run time (``control/fault``): ``uwb_dropout`` and ``nlos_burst`` (with its
        outlier ``probability``) for the whole radio network, ``camera_loss`` for each of ``vehicles``
        that has a camera. The caller makes sure it opens after every sample already taken."""
        w = [float(start_s), float(end_s)]
        if kind == "uwb_dropout":
            self.uwb_dropout.append(w)
        elif kind == "nlos_burst":
            self.nlos.append([*w, float(probability)])
        elif kind == "camera_loss":
            for v in vehicles:
                if v in self.camera:
                    self.camera[v].append(list(w))
        else:
            raise ValueError(f"not a fault window kind: {kind!r}")

    def state(self) -> dict:
        """Everything that changes as the run goes (plain lists and dicts, picklable): :meth:`restore`
        continues from it."""
        return {
            "uwb_dropout": [list(w) for w in self.uwb_dropout], "nlos": [list(w) for w in self.nlos],
            "camera": {c: [list(w) for w in ws] for c, ws in self.camera.items()},
            "mode": dict(self._mode), "entered": [[*k, n] for k, n in self._entered.items()],
            "open": [[c, m, self._index(w)] for c, m, w in self._open],
            "events": [dict(e) for e in self.events],
        }  # fmt: skip

    def _index(self, w: list[float]) -> list:
        """Where a window that closes on a mode exit lives: ``[list name, (chaser,) index]``."""
        for name, lst in (("uwb_dropout", self.uwb_dropout), ("nlos", self.nlos)):
            for i, x in enumerate(lst):
                if x is w:
                    return [name, i]
        for c, lst in self.camera.items():
            for i, x in enumerate(lst):
                if x is w:
                    return ["camera", c, i]
        raise ValueError("an open window that is in no list")

    def restore(self, st: dict) -> None:
        """Continue from :meth:`state` (of a schedule of the same scenario)."""
        self.uwb_dropout = [list(w) for w in st["uwb_dropout"]]
        self.nlos = [list(w) for w in st["nlos"]]
        self.camera = {c: [list(w) for w in ws] for c, ws in st["camera"].items()}
        self._mode = dict(st["mode"])
        self._entered = {(c, k): int(n) for c, k, n in st["entered"]}
        self._open = []
        for c, m, where in st["open"]:
            w = self.camera[where[1]][where[2]] if where[0] == "camera" else getattr(self, where[0])[where[1]]
            self._open.append((c, m, w))
        self.events = [dict(e) for e in st["events"]]

    def dropout_windows(self) -> list[tuple[float, float]]:
        """Every UWB dropout window so far, ``(start, end)`` [s] (window ends may still shrink)."""
        return [(w[0], w[1]) for w in self.uwb_dropout]

    def camera_lost(self, chaser: str, t_s: float) -> bool:
        return any(a <= t_s < b for a, b in self.camera.get(chaser, ()))


def in_windows(t_s: float, windows) -> bool:
    """Whether ``t_s`` lies in one of ``windows`` (``(start, end, ...)`` rows, start inclusive)."""
    return any(w[0] <= t_s < w[1] for w in windows)
