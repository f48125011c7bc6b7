"""Pure text and plot data of the dashboard's GUI panels, from a :class:`~dashboard.state.Snapshot`: the
agents table, the run status line, the decision panel (Algorithm 1's latest pass), the mode timeline,
the event log and the list of run-time faults applied or refused. Markdown strings and numpy arrays in,
no Viser: tested without a server.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence

import numpy as np

from dashboard.mapping import mode_level
from dashboard.state import AgentSnap, Snapshot
from swarm.transport.messages import Event, Guidance

__all__ = [
    "agents_table",
    "decision_markdown",
    "events_markdown",
    "fault_text",
    "faults_markdown",
    "fmt",
    "landing_table",
    "landing_uav_markdown",
    "mode_steps",
    "modes_markdown",
    "natural_key",
    "rejected_text",
    "status_markdown",
]

_DASH = "–"


def natural_key(text: str) -> tuple:
    """Sort key that orders ``chaser2`` before ``chaser10``."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text))


def fmt(value: float | None, digits: int = 3, scale: float = 1.0, unit: str = "") -> str:
    """``value * scale`` with ``digits`` decimals and ``unit``; a dash for ``None`` or a non-finite value."""
    if value is None or not math.isfinite(value):
        return _DASH
    return f"{value * scale:.{digits}f}{unit}"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def rejected_text(agent: AgentSnap) -> str:
    """Measurements the agent's gate rejected: the sum of its ``*_rejected`` counters and the rejected
    fraction over its health window, e.g. ``12 (3 %)``."""
    est = agent.estimate
    if est is None:
        return _DASH
    total = sum(n for name, n in est.counts.items() if name.endswith("_rejected"))
    return f"{total} ({100.0 * est.rejection_fraction:.0f} %)"


def agents_table(snap: Snapshot) -> str:
    """Markdown table, one row per vehicle: role, mode, estimated range to its target [m], largest position
    sigma [cm], rejected measurements, and whether its agent process is alive (``alive``, ``lost``, or
    ``unseen`` before its liveliness token ever appeared)."""
    lines = [
        "| agent | role | mode | range [m] | σ [cm] | rejected | agent process |",
        "|---|---|---|---|---|---|---|",
    ]
    for agent_id in sorted(snap.agents, key=natural_key):
        a = snap.agents[agent_id]
        g = a.guidance
        role = a.role
        mode = g.mode if g is not None else _DASH
        rng = fmt(g.range_m if g is not None else None, 3)
        sigma = fmt(a.estimate.sigma_pos_max_m if a.estimate is not None else None, 2, 100.0)
        cells = (agent_id, role, mode, rng, sigma, rejected_text(a), a.alive)
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(lines)


def _pad_markers(a: AgentSnap) -> str:
    """Pad markers in the UAV's latest camera frame (its rows are marker corners, four a marker)."""
    return _DASH if a.vision_rows is None else str(a.vision_rows // 4)


def _altitude(a: AgentSnap, pads: Mapping[str, Sequence[float]]) -> float | None:
    pad = pads.get(a.agent_id)
    return None if a.truth is None or pad is None else float(a.truth.p_nav[2]) - float(pad[2])


def landing_table(snap: Snapshot, pads: Mapping[str, Sequence[float]]) -> str:
    """Markdown table of a landing swarm, one row per UAV: mode, estimated horizontal distance to its pad
    [m] (the guidance's ``range_m``), true altitude above its pad [m] (``pads``: each UAV's pad position),
    largest position sigma [cm], pad markers detected in its latest camera frame, rotor energy so far [kJ]
    (``Truth.effort`` of a quadrotor, J), and whether its agent process is alive."""
    lines = [
        "| UAV | mode | to pad [m] | altitude [m] | σ [cm] | pad markers | energy [kJ] | agent process |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for agent_id in sorted(snap.agents, key=natural_key):
        if agent_id not in pads:  # (a moving pad's robot shares its estimate: not a UAV)
            continue
        a = snap.agents[agent_id]
        g = a.guidance
        cells = (
            agent_id,
            g.mode if g is not None else _DASH,
            fmt(g.range_m if g is not None else None, 2),
            fmt(_altitude(a, pads), 2),
            fmt(a.estimate.sigma_pos_max_m if a.estimate is not None else None, 1, 100.0),
            _pad_markers(a),
            fmt(a.truth.effort if a.truth is not None else None, 2, 1e-3),
            a.alive,
        )
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(lines)


def landing_uav_markdown(
    agent_id: str | None, a: AgentSnap | None, pads: Mapping[str, Sequence[float]]
) -> str:
    """The selected UAV of a landing: mode, distance to its pad, altitude, speed, energy, the pad markers of
    its latest camera frame and the reason of its latest mode switch."""
    if agent_id is None or a is None:
        return "no UAV"
    g = a.guidance
    if g is None and a.truth is None:
        return f"**{agent_id}**: nothing heard yet"
    speed = float(np.linalg.norm(a.truth.v_nav)) if a.truth is not None else None
    energy = fmt(a.truth.effort if a.truth is not None else None, 2, 1e-3)
    text = (
        f"**{agent_id}** · {g.mode if g is not None else _DASH} · {fmt(g.range_m if g else None, 2)} m to "
        f"its pad  \naltitude {fmt(_altitude(a, pads), 2)} m · speed {fmt(speed, 2)} m/s · energy {energy} "
        f"kJ · pad markers in the latest frame {_pad_markers(a)}"
    )
    return text + (f"  \n_{_cell(g.reason)}_" if g is not None and g.reason else "")


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


_MATRIX_KEYS = (("A11", None, None), (None, "A22", "A23"), (None, "A32", "A33"))


def decision_markdown(agent_id: str | None, guidance: Guidance | None) -> str:
    """The latest pass of Algorithm 1 of chaser ``agent_id``: the transition probabilities ``A_ij`` between
    APPROACH (1), REORIENT (2) and ALIGN (3), the steady state ``pi`` of the REORIENT/ALIGN chain, and the
    inputs (``r``, ``d``, ``||q_e||``, ``sigma``) and radii after the pass (paper section V, Algorithm 1)."""
    if agent_id is None:
        return "no chaser"
    if guidance is None:
        return f"**{agent_id}**: no guidance yet"
    head = (
        f"**{agent_id}** · {guidance.mode} · r = {fmt(guidance.range_m)} m · "
        f"r2 = {fmt(guidance.r2_m)} m · r1 = {fmt(guidance.r1_m)} m"
    )
    d = guidance.decision
    if d is None:
        return f"{head}  \nno Algorithm 1 pass yet (outside r_t, or the fixed policy)"
    rows = ["| A | 1 | 2 | 3 |", "|---|---|---|---|"]
    for i, keys in enumerate(_MATRIX_KEYS, start=1):
        rows.append(f"| {i} | " + " | ".join(_DASH if k is None else fmt(d.get(k)) for k in keys) + " |")
    inputs = (
        f"pass at t = {fmt(d.get('t_s'), 2)} s, r = {fmt(d.get('r_m'))} m  \n"
        f"π1 = {fmt(d.get('pi1'))} · π2 = {fmt(d.get('pi2'))}  \n"
        f"d = {fmt(d.get('d'), 2)} · ‖q_e‖ = {fmt(d.get('qe_vec_norm'), 3)} · "
        f"σ_pos = {fmt(d.get('sigma_pos_max_m'), 2, 100.0)} cm · "
        f"σ_uwb = {fmt(d.get('sigma_uwb_m'), 2, 100.0)} cm  \n"
        f"r_t = {fmt(d.get('r_t_m'))} m · r_d = {fmt(d.get('r_d_m'))} m → "
        f"r2 = {fmt(d.get('r2_m'))} m, r1 = {fmt(d.get('r1_m'))} m"
    )
    reason = f"  \n_{_cell(guidance.reason)}_" if guidance.reason else ""
    return f"{head}\n\n" + "\n".join(rows) + f"\n\n{inputs}{reason}"


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
        return _cell(f"t = {ev.t_s:.2f} s · **{kind} refused** by the {source}: {reason}")
    start, dur = d.get("start_s"), d.get("duration_s")
    when = f" from t = {start:.2f} s" if isinstance(start, int | float) else ""
    when += f" for {dur:g} s" if isinstance(dur, int | float) else " (lasts)"
    network = uwb_network and kind in ("uwb_dropout", "nlos_burst")
    who = "the UWB network" if network else _text(d.get("vehicles", "?"))
    return _cell(f"t = {ev.t_s:.2f} s · **{kind}** applied by the {source} on {who}{when}")


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
    return _cell(f"t = {ev.t_s:.2f} s · {agent_id} · {ev.kind} {detail}".strip())


def events_markdown(events: Sequence[tuple[str, Event]], last: int = 10, uwb_network: bool = True) -> str:
    """The latest ``last`` events of the swarm, newest first (``uwb_network``: :func:`fault_text`)."""
    if not events:
        return "no events yet"
    return "\n".join(f"- {_event_text(a, e, uwb_network)}" for a, e in reversed(list(events)[-last:]))
