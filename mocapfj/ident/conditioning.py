"""Signal conditioning for identification (seed 003 §3; Gautier 1997): zero-phase low-pass
filtering, derivatives by central differences, parallel decimation of the observation matrix and
the torque together, resampling onto another clock. Every default is overridable.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from ..errors import InputError

__all__ = ["lowpass", "derivatives", "decimate_parallel", "resample_to", "complementary", "white_noise_sd",
           "noise_gain"]


def _check_rate(fs_hz: float, cutoff_hz: float, what: str) -> None:
    if not (np.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(None, "fs_hz", "a positive sampling rate in Hz", fs_hz)
    if not 0 < cutoff_hz < fs_hz / 2:
        raise InputError(None, what, f"a cut-off between 0 and the Nyquist rate {fs_hz / 2:g} Hz", cutoff_hz)


def lowpass(x: np.ndarray, fs_hz: float, cutoff_hz: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 (forward-backward, so the order doubles).

    x : (T, ...) float, uniformly sampled at fs_hz, without NaN (fill or cut gaps first).
    """
    _check_rate(fs_hz, cutoff_hz, "cutoff_hz")
    x = np.asarray(x, dtype=np.float64)
    if np.isnan(x).any():
        raise InputError(None, "x", "a signal without NaN (fill or cut the gaps before filtering)",
                         f"{int(np.isnan(x).sum())} NaN samples")
    sos = signal.butter(order, cutoff_hz, fs=fs_hz, output="sos")
    padlen = min(3 * (2 * len(sos) + 1), x.shape[0] - 1)
    if x.shape[0] < 3 * (2 * len(sos) + 1) + 1:
        raise InputError(None, "x", f"at least {3 * (2 * len(sos) + 1) + 1} samples for an order-{order} filter",
                         x.shape[0], hint="record longer")
    return signal.sosfiltfilt(sos, x, axis=0, padlen=padlen)


def derivatives(x: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives by central differences (second order inside, one-sided at
    the ends) along axis 0, for a uniformly sampled signal: (x', x'')."""
    if not (np.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(None, "fs_hz", "a positive sampling rate in Hz", fs_hz)
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 0 or x.shape[0] < 3:
        raise InputError(None, "x", "at least 3 samples for a second derivative", x.shape[:1])
    dt = 1.0 / fs_hz
    d1 = np.gradient(x, dt, axis=0)
    return d1, np.gradient(d1, dt, axis=0)


def decimate_parallel(W: np.ndarray, y: np.ndarray, factor: int, fs_hz: float | None = None,
                      cutoff_hz: float | None = None, order: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Parallel decimation (seed 003 §3): the same low-pass on y and on every column of W, then
    one sample in `factor`. The default cut-off is 0.8 x the new Nyquist rate (as
    scipy.signal.decimate's Chebyshev filter); pass fs_hz and cutoff_hz to choose it.
    """
    if int(factor) != factor or factor < 1:
        raise InputError(None, "factor", "a positive whole decimation factor", factor)
    factor = int(factor)
    if np.shape(W)[0] != np.shape(y)[0]:
        raise InputError(None, "W, y", "as many rows in W as samples in y", f"{np.shape(W)}, {np.shape(y)}")
    if factor == 1:
        return np.asarray(W, float), np.asarray(y, float)
    fs = 1.0 if fs_hz is None else fs_hz
    fc = 0.8 * fs / (2 * factor) if cutoff_hz is None else cutoff_hz
    Wf = lowpass(W, fs, fc, order // 2)
    yf = lowpass(y, fs, fc, order // 2)
    return Wf[::factor], yf[::factor]


def resample_to(t_from: np.ndarray, x: np.ndarray, t_to: np.ndarray) -> np.ndarray:
    """Linear interpolation of x (T, ...) sampled at t_from onto t_to; NaN outside its span."""
    x = np.asarray(x, dtype=np.float64)
    flat = x.reshape(x.shape[0], -1)
    out = np.column_stack([np.interp(t_to, t_from, flat[:, k], left=np.nan, right=np.nan) for k in range(flat.shape[1])])
    return out.reshape((len(t_to),) + x.shape[1:])


def complementary(low: np.ndarray, high: np.ndarray, fs_hz: float, split_hz: float) -> np.ndarray:
    """A complementary split: `low` below `split_hz` and `high` above it, L(low) + high - L(high)
    with L the zero-phase low-pass (e.g. a deflection from mocap below and from the spring above)."""
    return lowpass(low, fs_hz, split_hz) + high - lowpass(high, fs_hz, split_hz)


def white_noise_sd(x: np.ndarray, fs_hz: float) -> float:
    """SD of the white measurement noise on x (T,), from the mean periodogram above fs/4 (where
    a joint's motion has no power at mocap rates): E|X_f|^2 / T = sigma^2 for white noise."""
    x = np.asarray(x, dtype=np.float64)
    f = np.fft.rfftfreq(x.size, 1.0 / fs_hz)
    P = np.abs(np.fft.rfft(x - x.mean())) ** 2 / x.size
    band = (f > fs_hz / 4) & (f < 0.98 * fs_hz / 2)
    return float(np.sqrt(P[band].mean())) if band.any() else 0.0


def noise_gain(fs_hz: float, *cutoffs_hz: float) -> float:
    """Variance gain of white noise through zero-phase low-passes in cascade (sum of the squared
    impulse response): the noise variance after them is sigma^2 times this."""
    n = int(40 * fs_hz / min(cutoffs_hz)) | 1
    h = np.zeros(n)
    h[n // 2] = 1.0
    for fc in cutoffs_hz:
        h = lowpass(h, fs_hz, fc)
    return float(h @ h)
