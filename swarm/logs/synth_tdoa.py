"""The synthetic flight's ``tdoa.csv`` (``swarm synth-log --tdoa tdoa2|tdoa3``): the same flight heard by a
passive tag on the Loco Positioning TDoA radio of :mod:`swarm.core.tdoa_radio` instead of two-way ranging.

The channel and the tag draw from their own child stream of the log's seed (:data:`STREAM_TDOA`), so the
IMU, the truth, the camera and the main stream's draws are those of the same log without TDoA. Per packet
the tag's distance to the sender is the truth's (the tag ``p + R(q) l`` at that packet's time) plus the
range-error model of that anchor, which enters each difference as ``e_B - e_A``:

* without a sensor profile: the synthetic model's per-anchor biases (``range_bias_m``, the same draws as
  ``uwb.csv``'s) and their step once airborne (``range_bias_step_m``); the slow walk of the airborne
  biases is left out;
* with a profile (:class:`swarm.sensors.profile.UwbProfile`): its offsets and take-off step (again the
  same draws), its Gauss-Markov multipath, NLOS episodes and isolated outliers
  (:func:`swarm.core.range_errors.range_error_step` per packet), from the take-off (``t >= static_s``) on;
* ``spec.tdoa_nlos_anchor``: that anchor's packets in flight long by an exponential excess of mean
  ``spec.nlos_excess_m`` with probability ``spec.nlos_probability`` (so all its pairs are long as ``B``
  and short as ``A``);
* white noise ``spec.tdoa_sigma_m`` a difference (None: sqrt(2) times the ranges' white sigma, the
  difference of two such errors); packets a tag misses with probability ``spec.range_loss``;
* a row longer than its two anchors' baseline is not written (the firmware's ``outlierFilterTdoa.c``
  drops it, and the reader refuses it), counted in the returned ``beyond_baseline``.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from swarm.core import rotations as rot
from swarm.core import tdoa_radio as tr

STREAM_TDOA = 7
"""Spawn key of the TDoA channel's and tag's stream (:func:`swarm.logs.phenomena.child` uses 1-6)."""


def tdoa_sigma(spec, profile) -> float:
    """The white noise of one difference [m] (module docstring)."""
    if spec.tdoa_sigma_m is not None:
        return float(spec.tdoa_sigma_m)
    return math.sqrt(2.0) * (spec.range_sigma_m if profile is None else profile.uwb.sigma_m)


def link_errors(spec, profile, offsets: np.ndarray, steps: np.ndarray) -> tr.LinkErrors:
    """The range-error model of the tag's links: the given per-anchor offsets and steps (the log's draws)
    and, with a profile, its multipath, NLOS episodes and outliers."""
    u = None if profile is None else profile.uwb
    p = SimpleNamespace(
        offset_m=1.0,  # switches the model on; the offsets themselves are given
        offset_spread_m=0.0,
        takeoff_bias_step_m=0.0,
        takeoff_bias_step_spread_m=0.0,
        multipath_sigma_m=0.0 if u is None else u.gm_sigma_m,
        multipath_tau_s=1.0 if u is None else u.gm_tau_s,
        nlos_episode_rate_hz=0.0 if u is None else u.nlos_rate_hz,
        nlos_episode_s=4.0 if u is None else u.nlos_duration_s,
        nlos_episode_excess_m=0.3 if u is None else u.nlos_excess_m,
    )
    out_p, out_x = (0.0, 1.0) if u is None else (u.outlier_share, u.outlier_excess_m)
    prm = tr.re_.range_error_vector(p, out_p, out_x)
    return tr.LinkErrors(prm, np.asarray(offsets, dtype=float), np.asarray(steps, dtype=float)[None, :])


def write_tdoa(d: Path, seed: int, spec, profile, anchors: np.ndarray, offsets, steps, truth_at) -> dict:
    """``tdoa.csv`` of the flight ``truth_at(spec, t)`` (:func:`swarm.logs.synthetic.truth_at`) heard by one
    tag on ``spec.tdoa``'s radio (module docstring); returns what the tests check: the radio's counters,
    the white sigma, the rows' range-error and clock parts."""
    params = tr.TdoaParams(mode=spec.tdoa, tag_loss=spec.range_loss, sigma_m=tdoa_sigma(spec, profile))
    m = len(anchors)
    nlos = -1 if spec.tdoa_nlos_anchor is None else int(spec.tdoa_nlos_anchor)
    if not -1 <= nlos < m:
        from swarm.errors import ConfigError

        raise ConfigError(
            f"tdoa_nlos_anchor must be an anchor index in 0..{m - 1}, got {spec.tdoa_nlos_anchor!r}"
        )
    radio = tr.TdoaRadio(
        params,
        anchors,
        1,
        spec.duration_s,
        np.random.SeedSequence(int(seed), spawn_key=(STREAM_TDOA,)),
        link_errors(spec, profile, offsets, steps),
        nlos_anchor=nlos,
        nlos_probability=spec.nlos_probability,
        nlos_excess_m=spec.nlos_excess_m,
    )
    t = radio.channel.t_s
    p, _, q, _, _ = truth_at(spec, np.maximum(t, 0.0))
    tag = p + rot.quat_rotate(q, np.broadcast_to(np.asarray(spec.lever_arm_m, dtype=float), p.shape))
    # the take-off: with a profile the rotors spin up at static_s (its step and flight errors start there);
    # the synthetic model's biases step once airborne, as uwb.csv's
    t_air = spec.static_s if profile is not None else spec.static_s + spec.takeoff_s
    rows = radio.step_packets(0, tag, t >= t_air)
    # no position has a difference longer than the two anchors' baseline: the firmware's outlier filter
    # drops such rows (outlierFilterTdoa.c) and the reader refuses them (docs/logs.md)
    a, b = rows[:, tr.ROW_A].astype(int), rows[:, tr.ROW_B].astype(int)
    beyond = np.abs(rows[:, tr.ROW_DDIST]) > np.linalg.norm(anchors[a] - anchors[b], axis=1)
    rows = rows[~beyond]
    np.savetxt(
        d / "tdoa.csv",
        rows[:, [tr.ROW_T, tr.ROW_A, tr.ROW_B, tr.ROW_DDIST]],
        delimiter=",",
        header="t_s,anchor_a,anchor_b,ddist_m",
        comments="",
        fmt=["%.6f", "%d", "%d", "%.6f"],
    )
    return {
        "mode": spec.tdoa,
        "counts": {k: int(v[0]) for k, v in radio.counts.items()},
        "beyond_baseline": int(beyond.sum()),
        "sigma_m": params.sigma_m,
        "rows": rows,
        "nlos_anchor": None if nlos < 0 else nlos,
    }
