"""Compiled kernels of the Loco Positioning TDoA radio (:mod:`swarm.core.tdoa_radio`): the anchors'
receptions of each other (their remote lists) and one tag's engine, as the Crazyflie firmware's
``tdoaEngine.c`` / ``tdoaStorage.c`` / ``clockCorrectionEngine.c`` process a packet (read, not copied:
bitcraze/crazyflie-firmware ``src/utils/src/tdoa/``, ``src/utils/src/clockCorrectionEngine.c``).

A tag's state is a set of arrays over the anchors (``TS_*`` columns of ``ts`` (M, TS_N)) and per tag
scalars (``tc`` (TC_N,)); the kernel advances them packet by packet, so one run may be cut into chunks (a
runner's ticks) and give the same rows.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarm.core import range_errors as re_

C_M_S = 299792458.0
"""Speed of light [m/s] (the firmware's ``SPEED_OF_LIGHT``)."""

# one tag's per-anchor state (ts (M, TS_N))
TS_CTX, TS_UPD_T, TS_PKT, TS_T, TS_CC, TS_EPS_HAT, TS_EPS, TS_GEO, TS_EXTRA = range(9)
TS_N = 9
"""Per anchor: in the context storage (0/1), its last update time [s] (eviction picks the oldest), the
packet index of the tag's last reception (-1: none), its time [s], the clock-correction state (0: none,
1: a reference, 2: reliable), the estimated and the true clock-rate offset at the last reception, and
that reception's true distance and range error [m] (its pseudo-range is their sum)."""

# one tag's scalars and counters (tc (TC_N,))
(TC_NCTX, TC_OFFSET, TC_RX, TC_GOOD, TC_MATCHED, TC_WRAPPED, TC_ROWS, TC_EVICT, TC_MAXCTX, TC_LOST,
 TC_COUNTING) = range(11)  # fmt: skip
TC_N = 11
"""Occupied context slots, the random matching's offset, then counters over the counted span: packets
received, with a reliable clock correction, with a matching other anchor, matches dropped because the
32-bit timestamps wrapped, rows emitted, context evictions, the most context slots used, packets lost
(not collided, missed by this tag); last, whether the packet in hand is in the counted span."""

# the tag's parameter vector (prm)
P_LOSS, P_WRAP, P_CTX, P_MATCH, P_FROM, P_TO, P_SIGMA, P_CC_FILTER, P_NLOS_P, P_NLOS_X = range(10)
P_N = 10
"""Loss probability of a packet not collided, the timestamp wrap [s], context slots, matching (0 random,
1 youngest), the counted span ``[from, to)`` [s], the white noise of a difference [m], the clock-correction
low-pass factor, and the one-anchor NLOS probability and mean excess [m] (:func:`tag_run`)."""

Z_N = re_.ERR_DRAWS + 4
"""Standard normals one packet takes from the tag's stream: the range-error model's, the white noise of a
row it ends, the loss uniform, the NLOS uniform and size."""

_INV_SQRT2 = 1.0 / math.sqrt(2.0)


@njit(cache=True)
def _u(z):
    """A standard normal as a uniform in (0, 1) (its CDF)."""
    return 0.5 * math.erfc(-z * _INV_SQRT2)


@njit(cache=True)
def anchor_lists(t, anchor, ok, n_anchors, loss_u, anchor_loss, period_s, phase_s, pick_u, n_remote,
                 remote_id, remote_pkt):  # fmt: skip
    """The remote data of every packet (``lps-node-firmware`` ``uwb_tdoa_anchor3.c``): each anchor keeps
    the index of the last packet it received from every other anchor (a packet not collided, ``ok``, is
    received unless its uniform ``loss_u[k, j]`` is below ``anchor_loss``), and every ``period_s`` (from
    its phase ``phase_s[i]``; the first draw at its first packet, as if the system had been running)
    draws the anchors it names: at most ``n_remote`` of those it heard in the
    last period, in a random order (``pick_u`` (K, M) uniforms). Writes ``remote_id`` / ``remote_pkt``
    (K, n_remote): the named anchor and the last packet of it the sender had received (-1: none)."""
    m = n_anchors
    last = np.full((m, m), -1, dtype=np.int64)
    heard = np.ones((m, m), dtype=np.bool_)  # a running system: every anchor heard the others before
    names = np.full((m, n_remote), -1, dtype=np.int64)
    next_t = phase_s.copy()
    K = t.shape[0]
    for k in range(K):
        i = anchor[k]
        if t[k] >= next_t[i]:  # updateAnchorLists: a random subset of the anchors heard since the last one
            next_t[i] += period_s * (1.0 + math.floor((t[k] - next_t[i]) / period_s))
            cand = np.empty(m, dtype=np.int64)
            keys = np.empty(m)
            c = 0
            for j in range(m):
                if heard[i, j] and j != i:
                    cand[c] = j
                    keys[c] = pick_u[k, j]
                    c += 1
                heard[i, j] = False
            order = np.argsort(keys[:c])
            for r in range(n_remote):
                names[i, r] = cand[order[r]] if r < c else -1
        for r in range(n_remote):
            j = names[i, r]
            remote_id[k, r] = j
            remote_pkt[k, r] = last[i, j] if j >= 0 else -1
        if ok[k]:
            for j in range(m):
                if j != i and loss_u[k, j] >= anchor_loss:
                    last[j, i] = k
                    heard[j, i] = True


@njit(cache=True)
def _evict_or_open(ts, tc, a, limit):
    """``tdoaStorageGetCreateAnchorCtx``: give anchor ``a`` a context slot, the first free one or the least
    recently updated one's (whose anchor forgets everything). Returns whether it was there already."""
    if ts[a, TS_CTX] > 0.0:
        return True
    if tc[TC_NCTX] >= limit:
        old, old_t = -1, np.inf
        for j in range(ts.shape[0]):
            if ts[j, TS_CTX] > 0.0 and ts[j, TS_UPD_T] < old_t:
                old, old_t = j, ts[j, TS_UPD_T]
        ts[old, TS_CTX] = 0.0
        ts[old, TS_PKT] = -1.0
        ts[old, TS_CC] = 0.0
        tc[TC_NCTX] -= 1
        if tc[TC_COUNTING] > 0.0:
            tc[TC_EVICT] += 1
    ts[a, TS_CTX] = 1.0
    ts[a, TS_UPD_T] = -np.inf  # a new slot's last update is "never" (the firmware's 0)
    ts[a, TS_PKT] = -1.0
    ts[a, TS_CC] = 0.0
    tc[TC_NCTX] += 1
    if tc[TC_NCTX] > tc[TC_MAXCTX]:
        tc[TC_MAXCTX] = tc[TC_NCTX]
    return False


@njit(cache=True)
def tag_run(k0, k1, t, anchor, ok, remote_id, remote_pkt, eps, pos, anchors_nav, airborne, Z, prm, ts, tc,
            link, err_prm, offset, step, nlos_anchor, out, n_out):  # fmt: skip
    """One tag through packets ``[k0, k1)`` of the channel (``t`` (K,) times [s], ``anchor`` (K,) senders,
    ``ok`` (K,) not collided, ``remote_*`` (K, R) from :func:`anchor_lists`, ``eps`` (K,) the sender's
    clock-rate offset); ``pos`` (k1 - k0, 3) the tag in nav at each of these packets, ``airborne``
    (k1 - k0,) whether it flies, ``Z`` (k1 - k0, :data:`Z_N`) its standard normals. Per received packet
    (``tdoaEngineProcessPacket``):

    1. the sender ``B`` gets a context slot (at most ``prm[P_CTX]``, the least recently updated evicted);
    2. its clock correction (``clockCorrectionEngine.c``) is reliable when the tag's previous reception of
       ``B`` is less than the 32-bit timestamp wrap ago and a reference exists; the first such pair only
       sets the reference. The estimate is the rate over the last interval, low-passed (``P_CC_FILTER``);
    3. a partner ``A`` among the anchors ``B`` names, whose last packet ``B`` received is the tag's last of
       ``A`` (both heard the same one): the first from a rotating offset (random matching, TDoA3's tag) or
       the most recently updated (youngest, TDoA2's); a candidate without a context slot gets one and fails;
    4. a row ``(t, A, B, d_B - d_A)``, each ``d`` the pseudo-range of its packet (the true distance from
       the tag's position at that reception plus the range-error model of the tag-anchor link, and the
       NLOS excess of ``nlos_anchor``), plus white noise ``P_SIGMA`` and the clock residual
       ``c (t_B - t_A) (eps_hat_B - eps_B)``; dropped (counted) when ``A``'s reception is a wrap old.

    ``out`` (rows, 7): t, A, B, ddist, the geometric ddist (positions at the two receptions), the clock
    residual, the range-error part; ``n_out`` (1,) rows so far. ``link`` (M, RS_N), ``offset`` (M,),
    ``step`` (M,), ``err_prm`` the range-error model (:mod:`swarm.core.range_errors`)."""
    loss, wrap, limit = prm[P_LOSS], prm[P_WRAP], prm[P_CTX]
    youngest = prm[P_MATCH] > 0.0
    for k in range(k0, k1):
        if not ok[k]:
            continue
        counted = prm[P_FROM] <= t[k] < prm[P_TO]
        tc[TC_COUNTING] = 1.0 if counted else 0.0
        z = Z[k - k0]
        if _u(z[re_.ERR_DRAWS + 1]) < loss:
            if counted:
                tc[TC_LOST] += 1
            continue
        if counted:
            tc[TC_RX] += 1
        b = anchor[k]
        _evict_or_open(ts, tc, b, limit)
        # this packet's pseudo-range: the range-error model of the link, evaluated at each reception
        geo_b = math.sqrt(np.sum((pos[k - k0] - anchors_nav[b]) ** 2))
        flying = airborne[k - k0]
        extra = 0.0
        if err_prm[re_.RE_ON] != 0.0:
            extra, _ = re_.range_error_step(t[k], flying, link[b], z, err_prm, offset[b], step[b])
        if b == nlos_anchor and flying and _u(z[re_.ERR_DRAWS + 2]) < prm[P_NLOS_P]:
            extra += -prm[P_NLOS_X] * math.log(max(_u(z[re_.ERR_DRAWS + 3]), 1e-300))
        good = False
        if ts[b, TS_PKT] >= 0.0 and t[k] - ts[b, TS_T] < wrap:
            cand = 0.5 * (ts[b, TS_EPS] + eps[k])  # the mean rate over the interval the tick counts span
            if ts[b, TS_CC] >= 1.0:
                ts[b, TS_EPS_HAT] = prm[P_CC_FILTER] * ts[b, TS_EPS_HAT] + (1.0 - prm[P_CC_FILTER]) * cand
                ts[b, TS_CC] = 2.0
                good = True
            else:
                ts[b, TS_EPS_HAT] = cand
                ts[b, TS_CC] = 1.0
        if good:
            if counted:
                tc[TC_GOOD] += 1
            n_rem = 0
            for r in range(remote_id.shape[1]):
                if remote_id[k, r] >= 0:
                    n_rem += 1
            partner = -1
            if n_rem > 0 and not youngest:
                tc[TC_OFFSET] += 1
                off = int(tc[TC_OFFSET])
                for i in range(off, off + n_rem):
                    r = i % n_rem
                    a = remote_id[k, r]
                    if a == b:
                        continue
                    if (
                        _evict_or_open(ts, tc, a, limit)
                        and remote_pkt[k, r] >= 0
                        and (remote_pkt[k, r] == ts[a, TS_PKT])
                    ):
                        partner = a
                        break
            elif n_rem > 0:
                best_t = -np.inf
                for r in range(n_rem):
                    a = remote_id[k, r]
                    if a == b:
                        continue
                    if (
                        _evict_or_open(ts, tc, a, limit)
                        and remote_pkt[k, r] >= 0
                        and (remote_pkt[k, r] == ts[a, TS_PKT] and ts[a, TS_UPD_T] > best_t)
                    ):
                        partner, best_t = a, ts[a, TS_UPD_T]
            if partner >= 0:
                a = partner
                if counted:
                    tc[TC_MATCHED] += 1
                if t[k] - ts[a, TS_T] >= wrap:
                    if counted:
                        tc[TC_WRAPPED] += 1
                else:
                    ka = int(ts[a, TS_PKT])
                    geo_a = ts[a, TS_GEO]
                    clock = C_M_S * (t[k] - t[ka]) * (ts[b, TS_EPS_HAT] - eps[k])
                    err = extra - ts[a, TS_EXTRA]
                    if counted:
                        j = n_out[0]
                        out[j, 0], out[j, 1], out[j, 2] = t[k], a, b
                        out[j, 3] = geo_b - geo_a + err + clock + prm[P_SIGMA] * z[re_.ERR_DRAWS]
                        out[j, 4], out[j, 5], out[j, 6] = geo_b - geo_a, clock, err
                        n_out[0] = j + 1
                        tc[TC_ROWS] += 1
        ts[b, TS_PKT] = k
        ts[b, TS_T] = t[k]
        ts[b, TS_UPD_T] = t[k]
        ts[b, TS_EPS] = eps[k]
        ts[b, TS_GEO] = geo_b
        ts[b, TS_EXTRA] = extra
