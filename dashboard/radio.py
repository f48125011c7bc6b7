"""The UWB radio's rates as the dashboard measures them on the wire (issue 45, item 5): on a TDoA radio
(``uwb.mode`` tdoa2/tdoa3) each anchor's packets a second and each tag's distance differences a second; on
either radio each tag's measurements the filter accepted a second and the share it rejected. Over a sliding
window of swarm time (the messages' ``t_s``, so a lockstep run faster or slower than the wall clock reads
the radio's true rates). Pure: no Viser, no Zenoh; :class:`~dashboard.state.SwarmState` holds one
:class:`RadioRates` under its lock and the panel draws :func:`radio_markdown`.

What is on the wire, and so what is measured:

- A tag's ``Tdoa`` of a UWB slot holds the differences it formed since its previous slot, one row per
  packet of anchor ``B`` it received and matched (``anchor_b``: the sender). Its differences a second are
  the rows of the window's slots over the time they cover (:class:`SlotWindow`). A packet lost to a
  collision, missed by the tag or left unmatched makes no row, so an anchor's rate as one tag hears it is a
  lower bound of the anchor's transmissions; every tag hears the same packets, so the anchor's rate shown
  is the best tag's (and the mean over tags beside it). The rates are not the configuration's: a
  collision or a dropout shows.
- An agent's ``Estimate.counts`` are its filter's cumulative counters; a distance difference is fused as a
  range is, under ``range_accepted`` / ``range_rejected`` / ``range_refused`` (:func:`swarm.step.agent.
  agent_tdoa`), so the tag's accepted rate and rejected share come from their increase over the window
  (:class:`CounterWindow`); on a TWR radio their sum is the tag's ranges a second (the filter's: ranges
  skipped while the chaser navigates on vision near its target are not counted, as it does not count
  them).

The window (both kinds): the samples from the newest one at or before ``t_n - window_s`` (the base) to the
newest, ``t_n``; a rate is what came after the base over ``t_n - t_0``. A sample earlier than the newest
(a new run) or a counter that went down (a restarted agent) starts the window again; a window whose newest
sample is more than ``window_s`` older than the world's clock is stale (a tag, or the radio, that went
silent: its last rates would read as current) and reads as not measured. A tag's differences a
second are counted over its accepted rate's window (the estimates' ``t_0``, ``t_n``) when the slots kept
reach it, so that the two compare (accepted <= heard); the anchors' over their own.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from swarm.transport.messages import Tdoa

__all__ = [
    "AnchorRate",
    "CounterWindow",
    "RadioRates",
    "RadioSnap",
    "SlotWindow",
    "TagRate",
    "radio_markdown",
]

COUNTERS = ("range_accepted", "range_rejected", "range_refused")
"""The ``Estimate.counts`` entries the tag rates come from (a TDoA difference is counted as a range)."""


def _trim(samples: deque, window_s: float) -> None:
    """Drop the oldest samples while the second oldest is at or before ``t_n - window_s`` (module docstring:
    the base is the newest sample at or before the window's start)."""
    start = samples[-1][0] - window_s
    while len(samples) >= 2 and samples[1][0] <= start:
        samples.popleft()


class SlotWindow:
    """The rows a tag heard in its UWB slots (one ``Tdoa`` each: its ``t_s`` and the senders of its rows,
    ``anchor_b``) over a window of ``window_s`` of swarm time; the slots of the last ``keep_s`` (default
    ``2 window_s``) are kept, at most ``cap``, so that :meth:`rows_in` can count over another window.

    ``rate(j) = (C_n(j) - C_0(j)) / (t_n - t_0)``, ``C_k(j)`` the rows of anchor ``j`` up to slot ``k``
    (cumulative), slot 0 the base: the rows of the slots after it cover exactly ``(t_0, t_n]`` (each slot's
    rows were heard since the previous slot)."""

    def __init__(self, window_s: float, keep_s: float | None = None, cap: int = 8192) -> None:
        self.window_s = float(window_s)
        self.keep_s = max(float(keep_s if keep_s is not None else 2.0 * window_s), self.window_s)
        # (t_s, rows per anchor up to this slot, rows up to this slot); a slot without rows shares the dict
        self._slots: deque[tuple[float, dict[int, int], int]] = deque(maxlen=cap)
        self._cum: dict[int, int] = {}
        self._total = 0

    def clear(self) -> None:
        self._slots.clear()
        self._cum, self._total = {}, 0

    def add(self, t_s: float, senders: Sequence[int]) -> None:
        """One slot at ``t_s`` [s] whose rows had these sender anchors (``Tdoa.anchor_b``)."""
        if self._slots and t_s < self._slots[-1][0]:
            self.clear()
        if len(senders):
            cum = dict(self._cum)
            for j in senders:
                cum[j] = cum.get(j, 0) + 1
            self._cum, self._total = cum, self._total + len(senders)
        self._slots.append((float(t_s), self._cum, self._total))
        _trim(self._slots, self.keep_s)

    def _at_or_before(self, t_s: float) -> tuple[float, dict[int, int], int] | None:
        """The newest slot at or before ``t_s``; None if every slot kept is later."""
        for slot in reversed(self._slots):
            if slot[0] <= t_s:
                return slot
        return None

    def _base(self) -> tuple[float, dict[int, int], int]:
        return self._at_or_before(self._slots[-1][0] - self.window_s) or self._slots[0]

    def newest_s(self) -> float | None:
        """``t_n`` [s], None before a slot."""
        return self._slots[-1][0] if self._slots else None

    def span_s(self) -> float:
        """``t_n - t_0`` [s]: 0 before two slots."""
        return self._slots[-1][0] - self._base()[0] if self._slots else 0.0

    def rates_hz(self) -> dict[int, float] | None:
        """Rows a second per sender anchor (anchors not heard in the window absent); None before two slots
        at different times."""
        if not self._slots:
            return None
        (t0, c0, _), (t1, c1, _) = self._base(), self._slots[-1]
        if t1 <= t0:
            return None
        out = {j: (n - c0.get(j, 0)) / (t1 - t0) for j, n in c1.items()}
        return {j: r for j, r in out.items() if r > 0.0}

    def total_hz(self) -> float | None:
        """All rows a second (the tag's differences a second); None before two slots."""
        rates = self.rates_hz()
        return None if rates is None else sum(rates.values())

    def rows_in(self, t_a: float, t_b: float) -> int | None:
        """The rows of the slots in ``(t_a, t_b]``; None when the slots kept do not reach back to ``t_a``
        or the slot of ``t_b`` has not come yet (a count would miss rows)."""
        if not self._slots or t_b > self._slots[-1][0]:
            return None
        a, b = self._at_or_before(t_a), self._at_or_before(t_b)
        return None if a is None or b is None else b[2] - a[2]


class CounterWindow:
    """Cumulative counters sampled now and then (an agent's ``Estimate.counts``, the newest one each frame)
    over a window of ``window_s`` of swarm time: ``rate_i = (v_n,i - v_0,i) / (t_n - t_0)``. A sample at the
    newest's time replaces it; one earlier, or with a counter lower than the newest's, starts again."""

    def __init__(self, window_s: float, cap: int = 4096) -> None:
        self.window_s = float(window_s)
        self._samples: deque[tuple[float, tuple[int, ...]]] = deque(maxlen=cap)

    def clear(self) -> None:
        self._samples.clear()

    def add(self, t_s: float, values: tuple[int, ...]) -> None:
        s = self._samples
        if s:
            t_last, v_last = s[-1]
            if t_s < t_last or any(v < w for v, w in zip(values, v_last, strict=True)):
                s.clear()
            elif t_s == t_last:
                s.pop()
        s.append((float(t_s), tuple(values)))
        _trim(s, self.window_s)

    def newest_s(self) -> float | None:
        """``t_n`` [s], None before a sample."""
        return self._samples[-1][0] if self._samples else None

    def deltas(self) -> tuple[float, float, tuple[int, ...]] | None:
        """``(t_0, t_n, v_n - v_0)``; None before two samples at different times."""
        s = self._samples
        if len(s) < 2 or s[-1][0] <= s[0][0]:
            return None
        (t0, v0), (t1, v1) = s[0], s[-1]
        return t0, t1, tuple(b - a for a, b in zip(v0, v1, strict=True))


@dataclass(frozen=True)
class AnchorRate:
    """One anchor's packets as the tags heard them (TDoA only)."""

    anchor: int
    best_hz: float
    """Rows a second naming it the sender, the best tag's: a lower bound of its transmissions a second."""
    mean_hz: float
    """The same, the mean over the tags with a window (0 for a tag that did not hear it)."""
    tags: int
    """Tags that heard it in their window."""


@dataclass(frozen=True)
class TagRate:
    """One tag's measurements a second (None: not measured yet)."""

    tag: str
    heard_hz: float | None
    """Distance differences a second on the wire (TDoA); on a TWR radio the filter's ranges a second
    (accepted, rejected and refused)."""
    accepted_hz: float | None
    """Measurements the filter accepted a second."""
    rejected_share: float | None
    """Rejected over accepted plus rejected in the window; None when none was gated."""
    span_s: float | None = None
    """The time the TDoA rows were counted over [s] (``t_n - t_0``: the accepted rate's window when the slots
    kept reach it, else the slots' own)."""


@dataclass(frozen=True)
class RadioSnap:
    """The rates of one frame (:meth:`RadioRates.snapshot`)."""

    mode: str
    """``twr``, ``tdoa2`` or ``tdoa3``."""
    window_s: float
    anchors: tuple[AnchorRate, ...]
    """Every anchor, in id order; empty on a TWR radio, and before a tag's window holds two slots."""
    tags: tuple[TagRate, ...]
    """Every tag seen, in the order first seen."""

    def anchor_hz(self) -> dict[int, float]:
        """``anchor -> best_hz``."""
        return {a.anchor: a.best_hz for a in self.anchors}


class RadioRates:
    """The rates of one swarm (module docstring): :meth:`on_tdoa` for every ``Tdoa`` heard, :meth:`on_counts`
    for each estimate's counters, :meth:`snapshot` for the panel. Not thread-safe (the store's lock)."""

    def __init__(self, mode: str, window_s: float = 2.0, max_tags: int = 256) -> None:
        if not (math.isfinite(window_s) and window_s > 0):
            raise ValueError(f"rate window must be a positive finite number of seconds, got {window_s!r}")
        self.mode = mode
        self.window_s = float(window_s)
        self.max_tags = max_tags
        self._slots: dict[str, SlotWindow] = {}
        self._counts: dict[str, CounterWindow] = {}

    @property
    def tdoa(self) -> bool:
        return self.mode != "twr"

    def _tag(self, table: dict, tag: str, make) -> object | None:
        w = table.get(tag)
        if w is None and len(table) < self.max_tags:
            w = table[tag] = make(self.window_s)
        return w

    def on_tdoa(self, tag: str, msg: Tdoa) -> None:
        w = self._tag(self._slots, tag, SlotWindow)
        if w is not None:
            w.add(msg.t_s, msg.anchor_b)

    def on_counts(self, tag: str, t_s: float, counts: Mapping[str, int]) -> None:
        w = self._tag(self._counts, tag, CounterWindow)
        if w is not None:
            w.add(t_s, tuple(int(counts.get(name, 0)) for name in COUNTERS))

    def clear(self) -> None:
        """A new run: every window starts again."""
        for w in (*self._slots.values(), *self._counts.values()):
            w.clear()

    def snapshot(self, anchor_ids: Iterable[int], now_s: float | None = None) -> RadioSnap:
        """The rates now, for the anchors ``anchor_ids`` (those of the ``Anchors`` message); ``now_s`` the
        world's clock [s], if known (stale windows, module docstring)."""

        def fresh(w: SlotWindow | CounterWindow) -> bool:
            t = w.newest_s()
            return t is not None and (now_s is None or t >= now_s - self.window_s)

        per_tag = {tag: w.rates_hz() if fresh(w) else None for tag, w in self._slots.items()}
        measured = [r for r in per_tag.values() if r is not None]
        anchors = []
        if measured:  # (a TDoA radio: only Tdoa messages fill the slot windows)
            for j in sorted(anchor_ids):
                heard = [r.get(j, 0.0) for r in measured]
                anchors.append(
                    AnchorRate(
                        anchor=j,
                        best_hz=max(heard, default=0.0),
                        mean_hz=sum(heard) / len(heard) if heard else 0.0,
                        tags=sum(1 for h in heard if h > 0.0),
                    )
                )
        tags = []
        for tag in dict.fromkeys([*self._slots, *self._counts]):
            heard_hz = accepted_hz = share = span = None
            rates = per_tag.get(tag)
            if rates is not None:
                heard_hz, span = sum(rates.values()), self._slots[tag].span_s()
            cw = self._counts.get(tag)
            d = cw.deltas() if cw is not None and fresh(cw) else None
            if d is not None:
                t0, t1, (acc, rej, ref) = d
                accepted_hz = acc / (t1 - t0)
                share = rej / (acc + rej) if acc + rej else None
                if not self.tdoa:
                    heard_hz = (acc + rej + ref) / (t1 - t0)
                elif rates is not None:  # heard over the accepted rate's window when the slots reach it
                    rows = self._slots[tag].rows_in(t0, t1)
                    if rows is not None:
                        heard_hz, span = rows / (t1 - t0), t1 - t0
            tags.append(TagRate(tag, heard_hz, accepted_hz, share, span))
        return RadioSnap(self.mode, self.window_s, tuple(anchors), tuple(tags))


_DASH = "–"


def _hz(value: float | None) -> str:
    return _DASH if value is None else f"{value:.1f}"


def radio_markdown(snap: RadioSnap | None, order=None) -> str:
    """The Radio panel: on a TDoA radio a table of the anchors (packets a second heard by the best tag, the
    mean per tag, the tags that heard it) and one of the tags (differences a second, accepted a second,
    rejected share); on a TWR radio the tags' table only, with ranges a second. ``order``: a sort key of
    the tags (the dashboard's natural order)."""
    if snap is None:
        return "no radio rates yet"
    head = f"**{snap.mode.upper()}** · per second of swarm time, over the last {snap.window_s:g} s"
    lines = [head, ""]
    if snap.anchors:
        lines += ["| anchor | packets/s (best tag) | per tag (mean) | tags |", "|---|---|---|---|"]
        lines += [f"| {a.anchor} | {a.best_hz:.1f} | {a.mean_hz:.1f} | {a.tags} |" for a in snap.anchors]
        lines.append("")
    elif snap.mode != "twr":
        lines += ["no distance differences yet", ""]
    heard = "differences/s" if snap.mode != "twr" else "ranges/s"
    lines += [f"| tag | {heard} | accepted/s | rejected |", "|---|---|---|---|"]
    for t in sorted(snap.tags, key=(lambda t: order(t.tag)) if order else (lambda t: t.tag)):
        share = _DASH if t.rejected_share is None else f"{100.0 * t.rejected_share:.0f} %"
        lines.append(f"| {t.tag} | {_hz(t.heard_hz)} | {_hz(t.accepted_hz)} | {share} |")
    if not snap.tags:
        lines.append(f"| {_DASH} | {_DASH} | {_DASH} | {_DASH} |")
    return "\n".join(lines)
