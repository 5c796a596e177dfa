"""The logarithmic decrement (Oueslati, Bearee, Gibaru and Moraru 2012, eq. 8) against analytic
damped oscillations and the paper's own numbers; the grid is benchmarks/bench_algebraic.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.ident.decrement import log_decrement, zeta_from_decrement

J2, K2, ZETA2 = 290.39, 1.0794e6, 0.163      # Staubli RX-170B axis 2, their eq. 8
W2 = math.sqrt(K2 / J2)
TS = 0.004


def free_vibration(t, w0=W2, zeta=ZETA2, amp=1.5e-4, phase=0.3, rest=1e-4):
    wd = w0 * math.sqrt(1 - zeta ** 2)
    return rest + amp * np.exp(-zeta * w0 * t) * np.cos(wd * t + phase)


def test_log_decrement_and_the_papers_eq8():
    # their D1 = 99.5544 %, D2 = 35.8370 % one period apart, zeta = 0.1626 = delta / (2 pi)
    delta = math.log(99.5544 / 35.8370)
    assert zeta_from_decrement(delta, exact=False) == pytest.approx(0.1626, abs=1e-4)
    assert zeta_from_decrement(delta) == pytest.approx(0.1605, abs=1e-4)
    assert J2 * 60.968 ** 2 == pytest.approx(K2, rel=1e-4)
    rng = np.random.default_rng(8)
    t = np.arange(0, 0.3, TS)
    z = []
    for _ in range(10):
        e = log_decrement(t, free_vibration(t, phase=rng.uniform(0, 6.3)) + 1e-6 * rng.standard_normal(t.size))
        assert abs(e.omega0 / W2 - 1) < 0.03 and abs(e.zeta / ZETA2 - 1) < 0.06
        z += [(e.omega0 - W2) / e.omega0_std, (e.zeta - ZETA2) / e.zeta_std]
    assert np.sqrt(np.mean(np.square(z))) < 2.0


def test_fine_sampling_and_noise_wiggles():
    """100 samples per period at 1 % noise: wiggles near an extremum are not extrema."""
    h = 1 / (100 * W2 / (2 * math.pi))
    t = np.arange(0, 3 * 2 * math.pi / W2, h)
    rng = np.random.default_rng(4)
    for _ in range(5):
        e = log_decrement(t, free_vibration(t, zeta=0.05, phase=rng.uniform(0, 6.3)) + 1.5e-6 * rng.standard_normal(t.size))
        assert abs(e.omega0 / W2 - 1) < 0.01 and abs(e.zeta / 0.05 - 1) < 0.08


def test_too_short_is_refused():
    t = np.arange(0, 0.05, TS)
    with pytest.raises(InputError, match="extrema"):
        log_decrement(t[:12], 1e-3 * t[:12])
    with pytest.raises(InputError, match="extrema|swings"):
        log_decrement(t, free_vibration(t))
