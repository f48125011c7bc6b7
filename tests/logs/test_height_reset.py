"""The range finder's gate lock-out and its recovery (:func:`swarm.core._imu_nb.fuse_aux`, ``[height]
reset_after``): a 2 cm sensor that keeps disagreeing re-opens the height; an isolated spike does not."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from swarm.core import _imu_nb as nb
from swarm.errors import ConfigError
from swarm.logs.reader import HeightLog


def _state(z_m: float = 0.05, sigma_z_m: float = 0.01):
    """A level filter at height ``z_m`` whose height is known to ``sigma_z_m`` (a pinned pad)."""
    X = np.zeros(16)
    X[nb.XP + 2], X[nb.XQ + 3] = z_m, 1.0
    P = np.diag(np.full(nb.N_CORE, 1e-4))
    P[nb.EP + 2, nb.EP + 2] = sigma_z_m**2
    return X, P


def _aux(reset_after: int) -> np.ndarray:
    AX = np.zeros(nb.N_AX)
    AX[nb.AX_H_ON], AX[nb.AX_H_SIGMA], AX[nb.AX_H_MAX], AX[nb.AX_H_COS] = 1.0, 0.02, 4.0, 0.866
    AX[nb.AX_H_GATE] = chi2.ppf(0.9995, 1)
    AX[nb.AX_H_RESET_N] = reset_after
    return AX


def _feed(X, P, AX, readings):
    res = np.empty(4)
    return [int(nb.fuse_aux(X, P, AX, nb.AUX_HEIGHT, float(z), res)) for z in readings]


def test_five_readings_in_a_row_rejected_reopen_the_height():
    # the vehicle rose to 0.5 m while the estimate stayed at 0.05 m (0.45 m: 20 sigmas of the reading)
    X, P = _state()
    out = _feed(X, P, _aux(5), [0.5] * 6)
    assert out == [nb.REJECTED] * 4 + [nb.ACCEPTED] * 2
    assert X[nb.XP + 2] == pytest.approx(0.5, abs=0.01)  # the 2 cm reading wins over the re-opened height
    X, P = _state()
    assert _feed(X, P, _aux(0), [0.5] * 10) == [nb.REJECTED] * 10  # 0: the gate alone, locked out
    assert X[nb.XP + 2] == 0.05


def test_a_reading_accepted_between_spikes_restarts_the_count():
    X, P = _state()
    spikes = [0.5] * 4 + [0.05] + [0.5] * 4
    out = _feed(X, P, _aux(5), spikes)
    assert out == [nb.REJECTED] * 4 + [nb.ACCEPTED] + [nb.REJECTED] * 4
    assert X[nb.XP + 2] == pytest.approx(0.05, abs=0.01)


def test_reset_after_is_a_count():
    assert HeightLog().reset_after == 5
    for bad in (-1, 2.5, True):
        with pytest.raises(ConfigError, match=r"height\.reset_after"):
            HeightLog(reset_after=bad)
