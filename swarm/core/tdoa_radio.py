"""The Loco Positioning TDoA radio (issue 45): anchors transmit, tags only listen, so any number of tags
each get the anchors' full rate. A model every runner can call (:class:`TdoaRadio`), its closed-form rates
(:func:`expected_rates`) and the comparison with two-way ranging over TDMA (:func:`per_tag_rates`).

Sources (read, never copied): Bitcraze ``lps-node-firmware`` ``src/uwb_tdoa_anchor3.c`` (2022+),
``src/uwb_tdoa_anchor2.c``, ``src/uwb.c``, docs ``functional-areas/tdoa2-vs-tdoa3.md``,
``user-guides/tdoa3_long_range.md``, ``protocols/tdoa3_protocol.md``; ``crazyflie-firmware``
``src/utils/src/tdoa/tdoaEngine.c``, ``tdoaStorage.c``, ``src/utils/src/clockCorrectionEngine.c``,
``src/deck/drivers/src/lpsTdoa2Tag.c``, ``lpsTdoa3Tag.c``, ``interface/mac.h``.

**TDoA3** (:func:`simulate_channel`). Each anchor sends at random times: its next packet ``D + U(-w/2, w/2)``
after the last, ``w = 10 ms`` (``DELAY_RANDOM_INTERVAL``; the firmware draws whole milliseconds), ``D = 1 /
f`` with ``f = clamp(R / M, 20, 50) Hz`` for ``M`` anchors in range of each other (``updateAnchorLists``:
``systemTxFreq / (availableCount + 1)``, ``R = 400`` packets/s, 200 in long-range mode). A packet collides,
for every receiver, when another anchor's packet starts less than one airtime ``T`` before or after it (both
are lost: the docs list picking one as a possible outcome; we take the pessimistic one). ``T`` is the DW1000
frame time (:func:`dw1000_frame_s`; Decawave DW1000 User Manual sec. 9.3 / the decadriver's symbol-time
table): preamble 128 symbols + SFD 8 at 1017.63 ns (PRF 64 MHz), the 21-bit PHR at 1025.64 ns, and ``8 L + 48
ceil(8 L / 330)`` data bits (Reed-Solomon) at 128.21 ns (6.8 Mbps; 1025.64 ns at 850 kbps, the long-range
mode, ``uwb.c`` ``MODE_SHORTDATA_MID_ACCURACY``), ``L`` = 21 (MAC header) + 7 + 8 x 8 (remote data) + 14 (LPP
position) + 2 (CRC) = 108 bytes: ``T = 0.289 ms`` (1.19 ms long range). Any other packet lost by a tag with
probability ``tag_loss``, by an anchor with ``anchor_loss``.

**TDoA2**: 8 anchors in slots of ``2^27`` DW1000 ticks (2.10 ms), a frame of 8 slots (16.8 ms) behind
anchor 0 (``uwb_tdoa_anchor2.c``); no collisions; every packet names the 7 others.

**The tag** (:func:`swarm.core._tdoa_nb.tag_run`, ``tdoaEngine.c``): at most 16 anchors in context; a
packet of ``B`` gives a difference when ``B``'s clock correction is reliable (the tag's previous packet of
``B`` less than the 32-bit timestamp wrap, ``2^32`` ticks = 67.2 ms, ago, after a first reference) and an
anchor ``A`` that ``B`` names was last heard in the same packet by ``B`` and by the tag: random matching
(TDoA3's tag) or the youngest (TDoA2's, so mostly the previous slot's anchor). The row is
``ddist = d_B - d_A`` (``distanceDiff``, idB minus idA; ``docs/logs.md``), each ``d`` the distance from the
tag's position at that reception plus the range-error model of that tag-anchor link
(:mod:`swarm.core.range_errors`: offsets, take-off step, Gauss-Markov multipath, NLOS episodes; so offsets
and multipath enter as differences and one anchor's NLOS excess reaches all its pairs), plus white noise.

**Clock drift** (what we model): each anchor's clock runs ``eps`` fast, ``eps`` drawn in +-10 ppm
(``MAX_CLOCK_DEVIATION_SPEC``) and walking ``clock_walk_ppm_rts`` per sqrt(s); the tag's own rate is the
reference. The firmware scales ``B``'s interval ``tx_B - rx_A`` (``A``'s packet at ``B``, ~``t_B - t_A``)
by its clock-correction estimate: the rate over the last interval, low-passed 0.1/0.9. What is left is
``c (t_B - t_A) (eps_hat_B - eps_B)``: millimetres (uncorrected, 10 ppm over 20 ms would be 60 m).

**Closed forms** (:func:`expected_rates`). Intervals of at least ``D - w/2 > 2 T`` put at most one packet
of another anchor in a ``2 T`` window; in the stationary state it is there with probability ``2 T f_j``
(its expected count); anchors are independent, so a packet of ``i`` survives with
``s_i = prod_{j != i} (1 - 2 T f_j)`` (exact for this model); pure ALOHA's ``exp(-2 G)``, ``G = T sum f``
(Abramson 1970; Kleinrock & Tobagi 1975, eq. 1), is its Poisson limit. A tag receives ``sum_i f_i s_i
(1 - tag_loss)`` packets/s, whatever the number of tags (they never transmit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from swarm.core import _tdoa_nb as nb
from swarm.core import range_errors as re_
from swarm.errors import ConfigError

C_M_S = nb.C_M_S
"""Speed of light [m/s]."""
DW_TS_HZ = 499.2e6 * 128
"""The DW1000 timestamp clock [Hz] (``LOCODECK_TS_FREQ``)."""
WRAP_S = 2.0**32 / DW_TS_HZ
"""The span of the 32-bit anchor timestamps the tag differences are truncated to (67.2 ms,
``TDOA_ENGINE_TRUNCATE_TO_ANCHOR_TS_BITMAP``)."""
TDOA2_SLOT_S = 2.0**27 / DW_TS_HZ
"""A TDoA2 slot (``TDMA_SLOT_LEN = 1 << (26 + 1)`` ticks: 2.10 ms)."""
TDOA3_FRAME_BYTES = 21 + 7 + 8 * 8 + 14 + 2
"""A TDoA3 packet with 8 remote anchors and its position (MAC header, header, remote data, LPP, CRC)."""


def dw1000_frame_s(frame_bytes: int, data_rate_bps: float = 6.8e6, preamble_symbols: int = 128) -> float:
    """Air time [s] of a DW1000 frame of ``frame_bytes`` (CRC included) at PRF 64 MHz (module docstring:
    preamble and SFD at 1017.63 ns a symbol, SFD 8 symbols at 850 kbps and 6.8 Mbps and 64 at 110 kbps, the
    21-bit PHR at 1025.64 ns (8205.13 at 110 kbps), data ``8 L + 48 ceil(8 L / 330)`` bits)."""
    rates = {
        6.8e6: (128.21e-9, 1025.64e-9, 8),
        850e3: (1025.64e-9, 1025.64e-9, 8),
        110e3: (8205.13e-9,) * 2 + (64,),
    }
    if data_rate_bps not in rates:
        raise ConfigError(f"data_rate_bps must be one of 6.8e6, 850e3, 110e3, got {data_rate_bps!r}")
    t_bit, t_phr, sfd = rates[data_rate_bps]
    bits = 8 * frame_bytes + 48 * math.ceil(8 * frame_bytes / 330)
    return (preamble_symbols + sfd) * 1017.63e-9 + 21 * t_phr + bits * t_bit


AIRTIME_S = dw1000_frame_s(TDOA3_FRAME_BYTES)
"""A TDoA3 packet's air time at 6.8 Mbps [s] (0.289 ms)."""
AIRTIME_LONG_RANGE_S = dw1000_frame_s(TDOA3_FRAME_BYTES, 850e3)
"""In long-range mode, 850 kbps [s] (1.19 ms)."""


@dataclass(frozen=True)
class TdoaParams:
    """The TDoA radio (module docstring); defaults: the Loco Positioning system's."""

    mode: str = "tdoa3"
    """``"tdoa3"`` (random transmit times) or ``"tdoa2"`` (8 TDMA slots behind a master)."""
    long_range: bool = False
    """TDoA3 long-range mode: 850 kbps, the system's rate 200 packets/s."""
    system_rate_hz: float | None = None
    """The packets per second the anchors share (None: 400, 200 in long-range mode)."""
    anchor_min_rate_hz: float = 20.0
    """An anchor's lowest rate [Hz] (``ANCHOR_MIN_TX_FREQ``)."""
    anchor_max_rate_hz: float = 50.0
    """An anchor's highest rate [Hz] (``ANCHOR_MAX_TX_FREQ``)."""
    jitter_s: float = 0.010
    """Width of the uniform interval around the mean transmit period [s] (``DELAY_RANDOM_INTERVAL``)."""
    airtime_s: float | None = None
    """A packet's air time [s] (None: :data:`AIRTIME_S`, :data:`AIRTIME_LONG_RANGE_S` in long-range mode)."""
    slot_s: float = TDOA2_SLOT_S
    """TDoA2: a slot [s]; a frame is 8 of them."""
    tag_loss: float = 0.0
    """Probability that a tag misses a packet that did not collide (fading, range)."""
    anchor_loss: float = 0.0
    """The same for an anchor hearing another one."""
    context_anchors: int = 16
    """Anchors a tag keeps in context (``ANCHOR_STORAGE_COUNT``)."""
    remote_anchors: int = 8
    """Anchors a TDoA3 packet names (``REMOTE_TX_MAX_COUNT``), re-drawn every ``remote_period_s``."""
    remote_period_s: float = 1.0
    """``ANCHOR_LIST_UPDATE_INTERVAL`` [s]."""
    matching: str | None = None
    """``"random"`` or ``"youngest"`` (None: random for TDoA3, youngest for TDoA2, as the tags' drivers)."""
    wrap_s: float = WRAP_S
    """Timestamps further apart than this wrap: no clock correction, no difference [s]."""
    sigma_m: float = 0.05
    """White noise of each difference [m] (beside the range-error model's terms)."""
    clock_ppm: float = 10.0
    """Anchor clock-rate offsets are drawn uniform in +- this [ppm]."""
    clock_walk_ppm_rts: float = 0.001
    """Their random walk [ppm/sqrt(s)] (an Allan deviation of ~1e-10 at 20 ms, a crystal's; 0.01 gives
    centimetres of clock residual at the longest intervals)."""
    clock_filter: float = 0.1
    """The clock-correction low-pass weight of the old value (``CLOCK_CORRECTION_FILTER``)."""
    warmup_s: float = 1.0
    """Simulated before time 0 and not counted, so that the system is in its steady state at 0 [s]."""

    def __post_init__(self) -> None:
        if self.mode not in ("tdoa2", "tdoa3"):
            raise ConfigError(f"tdoa.mode must be 'tdoa2' or 'tdoa3', got {self.mode!r}")
        if self.matching not in (None, "random", "youngest"):
            raise ConfigError(f"tdoa.matching must be 'random' or 'youngest', got {self.matching!r}")
        for name in ("anchor_min_rate_hz", "anchor_max_rate_hz", "slot_s", "wrap_s", "remote_period_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"tdoa.{name} must be a finite number > 0, got {v!r}")
        for name in ("jitter_s", "sigma_m", "clock_ppm", "clock_walk_ppm_rts", "warmup_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"tdoa.{name} must be a finite number >= 0, got {v!r}")
        for name in ("tag_loss", "anchor_loss", "clock_filter"):
            v = getattr(self, name)
            if not 0.0 <= v < 1.0:
                raise ConfigError(f"tdoa.{name} must be in [0, 1), got {v!r}")
        for name in ("context_anchors", "remote_anchors"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"tdoa.{name} must be an integer >= 1, got {v!r}")
        if self.anchor_max_rate_hz < self.anchor_min_rate_hz:
            raise ConfigError(
                f"tdoa.anchor_max_rate_hz must be >= anchor_min_rate_hz, got {self.anchor_max_rate_hz!r}"
            )
        if self.mode == "tdoa3" and 1.0 / self.anchor_max_rate_hz - self.jitter_s / 2 <= 2 * self.airtime:
            raise ConfigError(
                f"tdoa: the shortest transmit interval must exceed two air times ({2 * self.airtime:g} s), "
                f"got {1.0 / self.anchor_max_rate_hz - self.jitter_s / 2:g}"
            )

    @property
    def system_rate(self) -> float:
        """The system's packet cap [1/s]."""
        if self.system_rate_hz is not None:
            return self.system_rate_hz
        return 200.0 if self.long_range else 400.0

    @property
    def airtime(self) -> float:
        """A packet's air time [s]."""
        if self.airtime_s is not None:
            return self.airtime_s
        return AIRTIME_LONG_RANGE_S if self.long_range else AIRTIME_S

    @property
    def youngest(self) -> bool:
        """Whether the tag matches the youngest partner (else a random one)."""
        return (self.matching or ("youngest" if self.mode == "tdoa2" else "random")) == "youngest"


def anchor_rates_hz(params: TdoaParams, n_anchors: int) -> np.ndarray:
    """Each anchor's packets per second (M,): TDoA3 ``clamp(R / M, f_min, f_max)`` (all anchors in range of
    each other: ``availableCount + 1 = M``); TDoA2 one per frame of 8 slots for the first 8 anchors."""
    if params.mode == "tdoa2":
        f = np.zeros(n_anchors)
        f[: min(n_anchors, 8)] = 1.0 / (8 * params.slot_s)
        return f
    f = min(max(params.system_rate / n_anchors, params.anchor_min_rate_hz), params.anchor_max_rate_hz)
    return np.full(n_anchors, f)


@dataclass(frozen=True)
class TdoaRates:
    """The closed-form rates of :func:`expected_rates`."""

    per_anchor_hz: np.ndarray
    """Packets per second of each anchor (M,)."""
    total_hz: float
    """All anchors' packets per second."""
    offered_load: float
    """``G = T sum f``: packets per air time."""
    survive: np.ndarray
    """Probability that a packet of each anchor does not collide (M,): ``prod_{j != i} (1 - 2 T f_j)``."""
    collision_share: float
    """Share of all packets that collide."""
    aloha_collision: float
    """Pure ALOHA's ``1 - exp(-2 G)``, for comparison."""
    received_per_tag_hz: float
    """Packets per second each tag receives (any number of tags)."""
    measurements_per_tag_hz: float
    """Differences per second each tag forms (an approximation: :func:`expected_rates`)."""
    parts: dict = field(default_factory=dict)
    """The measurement rate's factors (``clock_good``, ``match``, ``fresh``)."""


def expected_rates(params: TdoaParams, n_anchors: int) -> TdoaRates:
    """The closed forms (module docstring) for ``n_anchors`` in range of each other and of every tag.

    The measurement rate multiplies the received rate by three probabilities, each assuming the fates of
    different packets independent (they are not quite: a packet that survives says a little about its
    neighbours): ``clock_good``, the tag's previous reception of the sender is less than a wrap old
    (``sum_k (1 - q)^(k - 1) q P(S_k < W)``, ``q`` a packet's reception probability, ``S_k`` the sum of
    ``k`` transmit intervals); ``match``, at least one of the ``R`` anchors the sender names was last heard
    in the same packet by the sender and the tag (per anchor ``h / (1 - n)``, ``h`` the probability that
    both hear a packet and ``n`` that neither does); ``fresh``, that packet is less than a wrap old (the
    age of the last transmission before a random time, plus intervals for packets both missed).
    Probabilities of sums come from densities on a 50 us grid (error < 0.3 %). Measured against
    :class:`TdoaRadio` (tests): within 1 % in the normal mode; in long-range mode, where the two air times
    a collision needs (2.4 ms) are not small beside the ~4 ms a period shifts two anchors' phases, the
    fates of an anchor's successive packets are correlated and the rate is ~7 % low."""
    f = anchor_rates_hz(params, n_anchors)
    T = params.airtime
    if params.mode == "tdoa2":
        s = np.ones(n_anchors)
    else:
        p_in = 2.0 * T * f
        s = np.array([np.prod(np.delete(1.0 - p_in, i)) for i in range(n_anchors)])
    total = float(f.sum())
    G = T * total
    rx = float(np.sum(f * s) * (1.0 - params.tag_loss))
    act = f > 0
    meas, parts = 0.0, {}
    if act.sum() >= 2:
        fa, sa = float(f[act][0]), float(s[act][0])  # the anchors are alike (one room)
        q = sa * (1.0 - params.tag_loss)
        dt = 5e-5
        n = int(params.wrap_s / dt) + 2
        grid = np.arange(n) * dt
        if params.mode == "tdoa2":
            pdf = np.zeros(n)
            pdf[min(round(1.0 / fa / dt), n - 1)] = 1.0 / dt
        else:
            lo, hi = 1.0 / fa - params.jitter_s / 2, 1.0 / fa + params.jitter_s / 2
            pdf = ((grid >= lo) & (grid < hi)) / max(hi - lo, dt)
        cdf_k, dens = [], pdf.copy()
        for _ in range(int(params.wrap_s * fa) + 2):
            cdf_k.append(min(1.0, float(np.sum(dens[grid < params.wrap_s]) * dt)))
            dens = np.convolve(dens, pdf)[:n] * dt
        good = sum((1 - q) ** k * q * c for k, c in enumerate(cdf_k))
        both = sa * (1 - params.tag_loss) * (1 - params.anchor_loss)
        none = (1 - sa) + sa * params.tag_loss * params.anchor_loss
        per = both / (1.0 - none)
        n_named = min(int(act.sum()) - 1, params.remote_anchors if params.mode == "tdoa3" else 7)
        match = 1.0 - (1.0 - per) ** n_named
        # age of the matched packet: the last transmission before B's (backward recurrence: density
        # (1 - F(x)) / mean), plus k intervals for k packets neither heard, with weights none^k both / ...
        F = np.cumsum(pdf) * dt
        back = np.clip(1.0 - F, 0.0, 1.0) * fa
        if params.youngest:  # the previous slot's anchor, one slot back, when it matches
            back = np.zeros(n)
            back[min(round(params.slot_s / dt), n - 1)] = 1.0 / dt
        fresh, dens = 0.0, back.copy()
        for k in range(len(cdf_k) + 1):
            w = none**k * (1.0 - none)
            fresh += w * min(1.0, float(np.sum(dens[grid < params.wrap_s]) * dt))
            dens = np.convolve(dens, pdf)[:n] * dt
        meas = rx * good * match * fresh
        parts = {"clock_good": good, "match": match, "fresh": fresh}
    return TdoaRates(
        per_anchor_hz=f,
        total_hz=total,
        offered_load=G,
        survive=s,
        collision_share=float(np.sum(f * (1 - s)) / total) if total else 0.0,
        aloha_collision=1.0 - math.exp(-2.0 * G),
        received_per_tag_hz=rx,
        measurements_per_tag_hz=meas,
        parts=parts,
    )


def twr_tdma_rate_hz(
    n_tags: int, slot_s: float = 0.0042, rate_hz: float = 50.0, frame_slots: int = 0
) -> float:
    """A tag's ranges per second with TWR over TDMA (:class:`swarm.core.sensors.UwbParams`, ``uwb.tdma``;
    :func:`swarm.step.radio.tdma_slots`): one exchange per frame of ``frame_slots`` (0: the smallest power
    of two >= ``n_tags``) slots of ``slot_s``, at most ``rate_hz``: ~238/N for N tags (docs/logs.md)."""
    frame = frame_slots or 1 << max(0, (n_tags - 1).bit_length())
    return min(rate_hz, 1.0 / (frame * slot_s))


def per_tag_rates(n_tags_list, params: TdoaParams | None = None, n_anchors: int = 8, **twr) -> list[dict]:
    """Per-tag measurement rates of TWR-TDMA (:func:`twr_tdma_rate_hz`, ``twr`` its keywords) and of the
    TDoA radio (:func:`expected_rates`, the same for any number of tags) for each ``n`` of ``n_tags_list``."""
    tdoa = expected_rates(params or TdoaParams(), n_anchors).measurements_per_tag_hz
    return [{"tags": int(n), "twr_hz": twr_tdma_rate_hz(int(n), **twr), "tdoa_hz": tdoa} for n in n_tags_list]


@dataclass(frozen=True)
class Channel:
    """What the anchors sent (:func:`simulate_channel`), sorted by time; packets before 0 are the warm-up."""

    t_s: np.ndarray
    """Transmit times (K,) [s]."""
    anchor: np.ndarray
    """Senders (K,)."""
    ok: np.ndarray
    """Not collided (K,)."""
    eps: np.ndarray
    """The sender's clock-rate offset at that time (K,) [1]."""
    remote_id: np.ndarray
    """The anchors each packet names (K, R), -1 padded."""
    remote_pkt: np.ndarray
    """The last packet of each the sender had received (K, R), -1: none."""

    def counts(self, t0: float, t1: float, n_anchors: int) -> tuple[np.ndarray, np.ndarray]:
        """Packets sent and collided per anchor in ``[t0, t1)`` ((M,) each)."""
        span = (self.t_s >= t0) & (self.t_s < t1)
        sent = np.bincount(self.anchor[span], minlength=n_anchors)
        lost = np.bincount(self.anchor[span & ~self.ok], minlength=n_anchors)
        return sent, lost


def _first_times(rng: np.random.Generator, lo: float, hi: float, n: int) -> np.ndarray:
    """The first transmission after a random time of ``n`` renewal processes with U(lo, hi) intervals: the
    residual life, density ``(1 - F(x)) / mean`` (Cox 1962, *Renewal Theory*, sec. 5.2), so that the
    process is stationary from the start: uniform on [0, lo) with probability ``lo / mean``, else
    ``hi - (hi - lo) sqrt(u)`` (the falling ramp on [lo, hi))."""
    mean = 0.5 * (lo + hi)
    u, v = rng.random(n), rng.random(n)
    return np.where(u < lo / mean, v * lo, hi - (hi - lo) * np.sqrt(v))


def simulate_channel(
    params: TdoaParams, n_anchors: int, duration_s: float, rng: np.random.Generator
) -> Channel:
    """The anchors' packets over ``[-warmup_s, duration_s)`` (module docstring), their collisions, their
    receptions of each other and the remote data each packet carries. Tags do not enter: they never send."""
    t0 = -params.warmup_s
    f = anchor_rates_hz(params, n_anchors)
    times, who = [], []
    if params.mode == "tdoa2":
        frame = 8 * params.slot_s
        start = t0 + frame * rng.random()
        n_frames = math.ceil((duration_s - start) / frame) + 1
        for i in range(min(n_anchors, 8)):
            times.append(start + (np.arange(n_frames) * 8 + i) * params.slot_s)
            who.append(np.full(n_frames, i))
    else:
        for i in range(n_anchors):
            lo, hi = 1.0 / f[i] - params.jitter_s / 2, 1.0 / f[i] + params.jitter_s / 2
            n = int((duration_s - t0) / lo) + 2
            gaps = rng.uniform(lo, hi, n)
            gaps[0] = _first_times(rng, lo, hi, 1)[0]
            times.append(t0 + np.cumsum(gaps))
            who.append(np.full(n, i))
    t = np.concatenate(times)
    a = np.concatenate(who).astype(np.int64)
    keep = t < duration_s
    order = np.argsort(t[keep], kind="stable")
    t, a = t[keep][order], a[keep][order]
    ok = np.ones(len(t), dtype=np.bool_)
    if params.mode == "tdoa3" and len(t) > 1:
        close = np.diff(t) < params.airtime  # packet k overlaps k + 1
        ok[:-1] &= ~close
        ok[1:] &= ~close
    # clock-rate offsets: a uniform start and a random walk per anchor, sampled at its packets
    eps = np.empty(len(t))
    eps0 = rng.uniform(-params.clock_ppm, params.clock_ppm, n_anchors) * 1e-6
    for i in range(n_anchors):
        rows = np.flatnonzero(a == i)
        steps = rng.standard_normal(len(rows)) * params.clock_walk_ppm_rts * 1e-6
        steps *= np.sqrt(np.diff(t[rows], prepend=t0))
        eps[rows] = eps0[i] + np.cumsum(steps)
    R = params.remote_anchors if params.mode == "tdoa3" else 7
    R = max(1, min(R, n_anchors - 1))
    remote_id = np.full((len(t), R), -1, dtype=np.int64)
    remote_pkt = np.full((len(t), R), -1, dtype=np.int64)
    loss_u = rng.random((len(t), n_anchors))
    period = params.remote_period_s if params.mode == "tdoa3" else math.inf
    phase = t0 - params.remote_period_s * rng.random(n_anchors)  # lists drawn before the run began
    pick = (
        rng.random((len(t), n_anchors))
        if params.mode == "tdoa3"
        else np.tile(np.arange(n_anchors, dtype=float), (len(t), 1))
    )
    nb.anchor_lists(
        t, a, ok, n_anchors, loss_u, params.anchor_loss, period, phase, pick, R, remote_id, remote_pkt
    )
    return Channel(t, a, ok, eps, remote_id, remote_pkt)


@dataclass(frozen=True)
class LinkErrors:
    """The range-error model of every tag-anchor link (:mod:`swarm.core.range_errors`)."""

    prm: np.ndarray
    """The ``RE_*`` parameter vector (:func:`~swarm.core.range_errors.range_error_vector`)."""
    offset_m: np.ndarray
    """Per-anchor offsets (M,) [m]."""
    step_m: np.ndarray
    """Per tag and anchor take-off steps (n, M) [m]."""

    @classmethod
    def none(cls, n_tags: int, n_anchors: int) -> LinkErrors:
        """No range errors (the white noise of a difference stays)."""
        return cls(np.zeros(re_.RE_N), np.zeros(n_anchors), np.zeros((n_tags, n_anchors)))

    @classmethod
    def draw(cls, p, n_tags: int, n_anchors: int, rng: np.random.Generator, outlier_probability: float = 0.0,
             outlier_excess_m: float = 1.0) -> LinkErrors:  # fmt: skip
        """From a radio's ``[uwb]`` params ``p`` (:data:`swarm.core.range_errors.FIELDS`): offsets per anchor,
        steps per link, as the TWR radios draw them."""
        prm = re_.range_error_vector(p, outlier_probability, outlier_excess_m)
        off = re_.draw_offsets(p, rng, n_anchors)
        step = np.array([re_.draw_steps(p, rng, n_anchors) for _ in range(n_tags)]).reshape(n_tags, n_anchors)
        return cls(prm, off, step)


ROW_T, ROW_A, ROW_B, ROW_DDIST, ROW_TRUE, ROW_CLOCK, ROW_ERR = range(7)
"""Columns of the rows :meth:`TdoaRadio.step` returns: time [s], anchor ``A``, anchor ``B``, the measured
``d_B - d_A`` [m], the geometric one (positions at the two receptions), the clock residual and the
range-error model's part [m]."""

COUNTERS = ("received", "clock_good", "matched", "wrapped", "rows", "evictions", "max_context", "lost")
"""The per-tag counters of :attr:`TdoaRadio.counts` (:data:`swarm.core._tdoa_nb.TC_RX` ...)."""
_TC = (nb.TC_RX, nb.TC_GOOD, nb.TC_MATCHED, nb.TC_WRAPPED, nb.TC_ROWS, nb.TC_EVICT, nb.TC_MAXCTX, nb.TC_LOST)


class TdoaRadio:
    """The TDoA radio of a run: one channel (:func:`simulate_channel`) heard by ``n_tags`` tags, advanced
    tick by tick (:meth:`step`) or over packets with their own tag positions (:meth:`step_packets`).

    Randomness: the channel from ``seed``'s ``SeedSequence`` child 0, tag ``i``'s draws (losses, range
    errors, white noise: :data:`swarm.core._tdoa_nb.Z_N` normals a packet) from child ``1 + i``, so the
    channel does not depend on the number of tags and a tag's rows not on the others'."""

    def __init__(self, params: TdoaParams, anchors_nav, n_tags: int, duration_s: float,
                 seed: int | np.random.SeedSequence = 0,
                 errors: LinkErrors | None = None, nlos_anchor: int = -1, nlos_probability: float = 0.0,
                 nlos_excess_m: float = 0.0) -> None:  # fmt: skip
        self.params = params
        self.anchors = np.ascontiguousarray(anchors_nav, dtype=float)
        m = len(self.anchors)
        if m < 2:
            raise ConfigError(f"tdoa: at least 2 anchors are needed, got {m}")
        self.duration_s = float(duration_s)
        ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(int(seed))
        kids = ss.spawn(1 + n_tags)
        self.channel = simulate_channel(params, m, duration_s, np.random.default_rng(kids[0]))
        self.rng = [np.random.default_rng(k) for k in kids[1:]]
        self.errors = errors or LinkErrors.none(n_tags, m)
        self.n_tags = n_tags
        self.prm = np.zeros(nb.P_N)
        self.prm[nb.P_LOSS], self.prm[nb.P_WRAP] = params.tag_loss, params.wrap_s
        self.prm[nb.P_CTX], self.prm[nb.P_MATCH] = params.context_anchors, float(params.youngest)
        self.prm[nb.P_FROM], self.prm[nb.P_TO] = 0.0, duration_s
        self.prm[nb.P_SIGMA], self.prm[nb.P_CC_FILTER] = params.sigma_m, params.clock_filter
        self.prm[nb.P_NLOS_P], self.prm[nb.P_NLOS_X] = nlos_probability, nlos_excess_m
        self.nlos_anchor = int(nlos_anchor)
        self.ts = np.zeros((n_tags, m, nb.TS_N))
        self.ts[:, :, nb.TS_PKT] = -1.0
        self.tc = np.zeros((n_tags, nb.TC_N))
        self.link = np.zeros((n_tags, m, re_.RS_N))
        self.link[:, :, re_.RS_T] = np.nan
        self.k = 0

    @property
    def counts(self) -> dict[str, np.ndarray]:
        """Per-tag counters over ``[0, duration_s)`` (:data:`COUNTERS`), (n,) each."""
        return {name: self.tc[:, c].astype(np.int64) for name, c in zip(COUNTERS, _TC, strict=True)}

    def _run(self, i: int, k0: int, k1: int, pos: np.ndarray, airborne: np.ndarray) -> np.ndarray:
        ch = self.channel
        Z = self.rng[i].standard_normal((k1 - k0, nb.Z_N))
        out = np.empty((k1 - k0, 7))
        n_out = np.zeros(1, dtype=np.int64)
        nb.tag_run(
            k0, k1, ch.t_s, ch.anchor, ch.ok, ch.remote_id, ch.remote_pkt, ch.eps, pos, self.anchors,
            airborne, Z, self.prm, self.ts[i], self.tc[i], self.link[i], self.errors.prm,
            self.errors.offset_m, self.errors.step_m[i], self.nlos_anchor, out, n_out,
        )  # fmt: skip
        return out[: n_out[0]]

    def step(self, t_s: float, tag_pos_nav, airborne=True) -> list[np.ndarray]:
        """The packets sent up to ``t_s`` [s] (those of the warm-up included on the first call), heard by each
        tag at its position ``tag_pos_nav`` (n, 3) and ``airborne`` (n,) or one flag for all: each tag's
        rows (r, 7) (:data:`ROW_T` ...) of this tick, counted over ``[0, duration_s)``."""
        k1 = int(np.searchsorted(self.channel.t_s, t_s, side="right"))
        k0, self.k = self.k, max(self.k, k1)
        P = np.asarray(tag_pos_nav, dtype=float).reshape(self.n_tags, 3)
        air = np.broadcast_to(np.asarray(airborne, dtype=np.bool_), (self.n_tags,))
        rows = []
        for i in range(self.n_tags):
            pos = np.broadcast_to(P[i], (max(k1 - k0, 0), 3))
            rows.append(
                self._run(i, k0, max(k0, k1), np.ascontiguousarray(pos), np.full(max(k1 - k0, 0), air[i]))
            )
        return rows

    def step_packets(self, tag: int, pos_nav, airborne) -> np.ndarray:
        """Tag ``tag`` through every packet of the channel, at its position ``pos_nav`` (K, 3) and
        ``airborne`` (K,) at each packet's time (:attr:`Channel.t_s`): its rows (r, 7). For an offline run
        (a log)."""
        K = len(self.channel.t_s)
        pos = np.ascontiguousarray(np.asarray(pos_nav, dtype=float).reshape(K, 3))
        air = np.ascontiguousarray(np.broadcast_to(np.asarray(airborne, dtype=np.bool_), (K,)))
        return self._run(tag, 0, K, pos, air)
