"""Pure text and plot data of the dashboard's GUI panels that every mission shares, from a
:class:`~dashboard.state.Snapshot`: the run status line, the mode timeline, the event log and the list of
run-time faults applied or refused (a mission's agents table and selected-vehicle panel are its drawer's:
:mod:`dashboard.docking`, :mod:`dashboard.landing`). Markdown strings and numpy arrays in,
no Viser: tested without a server.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

import numpy as np

from dashboard.mapping import mode_level
from dashboard.state import AgentSnap, Snapshot
from swarm.transport.messages import Event

__all__ = [
    "DASH",
    "cell",
    "events_markdown",
    "fault_text",
    "faults_markdown",
    "fmt",
    "mode_steps",
    "modes_markdown",
    "natural_key",
    "rejected_text",
    "status_markdown",
]

DASH = "–"


def natural_key(text: str) -> tuple:
    """Sort key that orders ``chaser2`` before ``chaser10``."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text))


def fmt(value: float | None, digits: int = 3, scale: float = 1.0, unit: str = "") -> str:
    """``value * scale`` with ``digits`` decimals and ``unit``; a dash for ``None`` or a non-finite value."""
    if value is None or not math.isfinite(value):
        return DASH
    return f"{value * scale:.{digits}f}{unit}"


def cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def rejected_text(agent: AgentSnap) -> str:
    """Measurements the agent's gate rejected: the sum of its ``*_rejected`` counters and the rejected
    fraction over its health window, e.g. ``12 (3 %)``."""
    est = agent.estimate
    if est is None:
        return DASH
    total = sum(n for name, n in est.counts.items() if name.endswith("_rejected"))
    return f"{total} ({100.0 * est.rejection_fraction:.0f} %)"


def status_markdown(snap: Snapshot, dropped: int, roles: Sequence[str] = ("world", "mothership")) -> str:
    """One line about the run: clock state, tick, time, seed, the processes of ``roles`` (the world and the
    mothership; a landing swarm has no mothership), and the number of invalid messages the dashboard
    dropped."""
    c = snap.clock
    if c is None:
        run = "**no clock yet**"
    else:
        run = f"**{c.state}** · tick {c.tick} · t = {c.t_s:.2f} s · seed {c.seed}"
    procs = []
    for role in roles:
        states = [s for (r, _), s in snap.processes.items() if r == role]
        procs.append(f"{role} {'alive' if 'alive' in states else (states[0] if states else 'unseen')}")
    return f"{run}  \n{' · '.join(procs)} · dropped messages {dropped}"


def modes_markdown(modes: Sequence[tuple[float, str, float | None, str]], last: int = 8) -> str:
    """The latest ``last`` mode changes of one chaser, newest first: time, mode, range."""
    if not modes:
        return "no mode yet"
    lines = [f"- t = {t:.2f} s · **{mode}** · r = {fmt(r)} m" for t, mode, r, _ in list(modes)[-last:]]
    return "\n".join(reversed(lines))


def mode_steps(
    modes: Sequence[tuple[float, str, float | None, str]], t_end_s: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """Step curve of a mode timeline for the plot: ``(t (2N,), level (2N,))``, each mode held until the next
    change (and the last until ``t_end_s``); levels from :func:`~dashboard.mapping.mode_level`."""
    if not modes:
        return np.zeros(1), np.full(1, np.nan)
    t, y = [], []
    for i, (t0, mode, _, _) in enumerate(modes):
        t1 = modes[i + 1][0] if i + 1 < len(modes) else max(t0, t_end_s if t_end_s is not None else t0)
        t += [t0, t1]
        y += [mode_level(mode)] * 2
    return np.array(t, dtype=np.float64), np.array(y, dtype=np.float64)


def _text(value: object) -> str:
    if isinstance(value, list | tuple):
        return ", ".join(str(v) for v in value)
    return str(value)


def fault_text(source: str, ev: Event, uwb_network: bool = True) -> str:
    """One line for a ``fault`` (applied) or ``fault_refused`` event of the world, from its free-form data
    (``kind``, ``start_s``, ``duration_s``, ``vehicles``; ``vehicle``, ``reason``). ``uwb_network``: a UWB
    fault acts on the whole radio network (a docking swarm's), not on the vehicles it names (a landing
    swarm's)."""
    d = ev.data
    kind = _text(d.get("kind", "?"))
    if ev.kind == "fault_refused":
        reason = _text(d.get("reason", "?"))
        return cell(f"t = {ev.t_s:.2f} s · **{kind} refused** by the {source}: {reason}")
    start, dur = d.get("start_s"), d.get("duration_s")
    when = f" from t = {start:.2f} s" if isinstance(start, int | float) else ""
    when += f" for {dur:g} s" if isinstance(dur, int | float) else " (lasts)"
    network = uwb_network and kind in ("uwb_dropout", "nlos_burst")
    who = "the UWB network" if network else _text(d.get("vehicles", "?"))
    return cell(f"t = {ev.t_s:.2f} s · **{kind}** applied by the {source} on {who}{when}")


def faults_markdown(faults: Sequence[tuple[str, Event]], last: int = 8, uwb_network: bool = True) -> str:
    """The latest ``last`` faults applied or refused (``(source, event)``), newest first."""
    if not faults:
        return "no fault applied yet"
    return "\n".join(f"- {fault_text(s, e, uwb_network)}" for s, e in reversed(list(faults)[-last:]))


def _event_text(agent_id: str, ev: Event, uwb_network: bool = True) -> str:
    d = ev.data
    if ev.kind in ("fault", "fault_refused"):
        return fault_text(agent_id, ev, uwb_network).replace("**", "")
    if ev.kind == "mode":
        detail = f"{d.get('from', '?')} → {d.get('to', '?')}"
        if isinstance(d.get("range_m"), int | float):
            detail += f" at r = {fmt(d['range_m'])} m"
    else:
        detail = ", ".join(f"{k}={v}" for k, v in list(d.items())[:4])
    return cell(f"t = {ev.t_s:.2f} s · {agent_id} · {ev.kind} {detail}".strip())


def events_markdown(events: Sequence[tuple[str, Event]], last: int = 10, uwb_network: bool = True) -> str:
    """The latest ``last`` events of the swarm, newest first (``uwb_network``: :func:`fault_text`)."""
    if not events:
        return "no events yet"
    return "\n".join(f"- {_event_text(a, e, uwb_network)}" for a, e in reversed(list(events)[-last:]))
