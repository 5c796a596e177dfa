"""The parameters' SDs under coloured noise (:func:`mocapfj.discover.tournament.score_covariance`):
the covariance of A' e for the prediction's changes A and noise e whose residual is observed, against
the exact value a'Σa of an AR(1) noise's autocovariance Σ."""

import numpy as np
from scipy.signal import fftconvolve, lfilter

from mocapfj.discover.tournament import score_covariance

FS = 1000.0


def _changes(n: int) -> np.ndarray:
    t = np.arange(n) / FS
    return np.column_stack([np.sin(2 * np.pi * 0.2 * t) + 0.2 * np.sin(2 * np.pi * 0.6 * t),
                            np.cos(2 * np.pi * 0.5 * t) + 0.3 * np.sin(2 * np.pi * 1.1 * t)])


def _ar1(rng, n: int, tau_s: float) -> np.ndarray:
    a = np.exp(-1.0 / (FS * tau_s))
    return lfilter([np.sqrt(1 - a * a)], [1, -a], rng.normal(size=n + 2000))[2000:]   # unit variance


def _exact(A: np.ndarray, tau_s: float) -> np.ndarray:
    """a_i' Σ a_j with Σ_st = a^|s-t| (unit-variance AR(1))."""
    n = A.shape[0]
    a = np.exp(-1.0 / (FS * tau_s))
    acf = a ** np.abs(np.arange(-n + 1, n))
    return np.array([[A[:, i] @ fftconvolve(A[:, j], acf, mode="full")[n - 1: 2 * n - 1]
                      for j in range(2)] for i in range(2)])


def test_coloured_noise_covariance_matches_the_exact_one():
    """AR(1) torque noise of 10 and 40 ms: white-noise covariance (A'A) is 20-80 times short at the
    excitation's frequencies; the residual's spectrum gets the diagonal within 35 %, on average
    over seeds within 10 %."""
    n = 40000
    A = _changes(n)
    rng = np.random.default_rng(7)
    for tau in (0.01, 0.04):
        exact = np.diag(_exact(A, tau))
        assert np.all(exact / np.diag(A.T @ A) > 15)
        est = np.array([np.diag(score_covariance(A, _ar1(rng, n, tau), FS, 0.0)) for _ in range(12)])
        ratio = est / exact
        assert np.all(np.abs(ratio - 1) < 0.35), ratio
        assert np.all(np.abs(ratio.mean(axis=0) - 1) < 0.1), ratio.mean(axis=0)


def test_white_noise_keeps_its_floor():
    """White noise: the covariance is the white one, A'A sigma^2, at least and within 30 % above
    (the spectrum's own scatter above the floor)."""
    n = 40000
    A = _changes(n)
    rng = np.random.default_rng(8)
    for _ in range(6):
        e = 0.5 * rng.normal(size=n)
        c = np.diag(score_covariance(A, e, FS, 0.25))
        white = 0.25 * np.diag(A.T @ A)
        assert np.all(c >= white * (1 - 1e-9)) and np.all(c < 1.3 * white), c / white


def test_short_or_broken_residual_falls_back_to_white():
    A = _changes(10)
    assert np.allclose(score_covariance(A, np.ones(10), FS, 2.0), 2.0 * (A.T @ A))
    A = _changes(2000)
    r = np.zeros(2000)
    r[5] = np.nan
    assert np.allclose(score_covariance(A, r, FS, 2.0), 2.0 * (A.T @ A))
