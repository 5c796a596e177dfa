"""Signal conditioning (mocapfj.ident.conditioning) against analytic truth.

References: central differences of sin(w t) have the truncation errors of a Taylor expansion
(d1 error ~ (w dt)^2 / 6, the twice-applied gradient ~ (w dt)^2 / 3 relative); a Butterworth
filter has |H(fc)| = 1/sqrt(2) (-3 dB) at its cut-off, so forward-backward filtering gives
|H(fc)|^2 = 1/2 (-6 dB) there with zero phase at every frequency; parallel decimation
(Jubien, Abba and Gautier (2014), §3, Gautier 1997) filters W and y with the same linear filter, so y = W x survives it.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from mocapfj import InputError
from mocapfj.ident.conditioning import decimate_parallel, derivatives, lowpass, resample_to
from mocapfj.ident.ls import ls_fit

FS = 1000.0


def _amp_phase(x: np.ndarray, t: np.ndarray, f: float) -> tuple[float, float]:
    """Amplitude and phase of the f-Hz component of x by LS on [sin, cos]."""
    A = np.column_stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)])
    a, b = np.linalg.lstsq(A, x, rcond=None)[0]
    return float(np.hypot(a, b)), float(np.arctan2(b, a))


def test_derivatives_of_a_sine_match_the_taylor_truncation_error():
    w, dt = 2 * np.pi * 3.0, 1 / FS
    t = np.arange(4000) * dt
    x = np.sin(w * t)
    d1, d2 = derivatives(x, FS)
    inner = slice(2, -2)
    err1 = d1[inner] - w * np.cos(w * t[inner])
    err2 = d2[inner] + w**2 * np.sin(w * t[inner])
    # (x[i+1]-x[i-1])/(2dt) = w cos(w t) sin(w dt)/(w dt): relative error (w dt)^2/6
    np.testing.assert_allclose(np.abs(err1).max() / w, (w * dt) ** 2 / 6, rtol=1e-3)
    # gradient twice = (x[i+2]-2x[i]+x[i-2])/(4 dt^2): relative error sin^2(w dt)/(w dt)^2 - 1 ~ (w dt)^2/3
    np.testing.assert_allclose(np.abs(err2).max() / w**2, 1 - np.sin(w * dt) ** 2 / (w * dt) ** 2, rtol=1e-6)
    # (T, J) input is differentiated column by column along axis 0
    d1c, d2c = derivatives(np.column_stack([x, 2 * x]), FS)
    np.testing.assert_allclose(d1c[:, 1], 2 * d1)
    np.testing.assert_allclose(d2c[:, 0], d2)


@pytest.mark.parametrize("f_hz", [2.0, 20.0, 50.0, 100.0, 200.0])
def test_lowpass_is_zero_phase_with_squared_butterworth_gain(f_hz):
    fc = 50.0
    t = np.arange(20000) / FS
    x = np.sin(2 * np.pi * f_hz * t + 0.3)
    y = lowpass(x, FS, fc, order=4)
    mid = slice(2000, -2000)
    a_in, p_in = _amp_phase(x[mid], t[mid], f_hz)
    a_out, p_out = _amp_phase(y[mid], t[mid], f_hz)
    gain = 1 / (1 + (f_hz / fc) ** 8)  # |H|^2 of the analog 4th-order Butterworth
    _, h = signal.sosfreqz(signal.butter(4, fc, fs=FS, output="sos"), worN=[f_hz], fs=FS)
    np.testing.assert_allclose(a_out / a_in, np.abs(h[0]) ** 2, rtol=1e-6)  # the digital design, exactly
    if f_hz <= fc:  # below the cut-off the bilinear warping is small: the analog prototype, roughly
        assert a_out / a_in == pytest.approx(gain, rel=0.01)
    assert abs(p_out - p_in) < 1e-6                                        # zero phase


def test_lowpass_gain_at_the_cutoff_is_minus_3_db_per_pass():
    fc = 100.0
    t = np.arange(10000) / FS
    x = np.cos(2 * np.pi * fc * t)
    y = lowpass(x, FS, fc)
    a, _ = _amp_phase(y[1000:-1000], t[1000:-1000], fc)
    assert 20 * np.log10(a) / 2 == pytest.approx(20 * np.log10(1 / np.sqrt(2)), abs=1e-3)  # -3.01 dB per pass


def test_parallel_decimation_keeps_the_ls_solution_of_band_limited_data():
    rng = np.random.default_rng(7)
    t = np.arange(30000) / FS
    freqs = rng.uniform(0.2, 5.0, size=(3, 4))
    phases = rng.uniform(0, 2 * np.pi, size=(3, 4))
    W = np.stack([np.sin(2 * np.pi * f[:, None] * t + p[:, None]).sum(0) for f, p in zip(freqs, phases)], axis=1)
    x_true = np.array([1.5, -0.7, 3.0])
    # band-limited error (below 5 Hz) that LS must fit the same way at both rates
    e = 0.2 * np.sin(2 * np.pi * 1.3 * t + 0.4) + 0.1 * np.sin(2 * np.pi * 3.7 * t)
    y = W @ x_true + e
    full = ls_fit(W, y, ["a", "b", "c"])
    Wd, yd = decimate_parallel(W, y, 10, fs_hz=FS, cutoff_hz=40.0)
    assert Wd.shape == (3000, 3) and yd.shape == (3000,)
    dec = ls_fit(Wd, yd, ["a", "b", "c"])
    np.testing.assert_allclose(dec.values, full.values, rtol=0, atol=1e-4)
    # exact linear relation: recovered to round-off whatever the filter does
    Wd0, yd0 = decimate_parallel(W, W @ x_true, 10, fs_hz=FS, cutoff_hz=40.0)
    np.testing.assert_allclose(ls_fit(Wd0, yd0, ["a", "b", "c"]).values, x_true, atol=1e-10)
    # noise above the cut-off is removed: the decimated fit is much closer to the band-limited one
    hf = 0.5 * np.sin(2 * np.pi * 180.0 * t) * np.sign(np.sin(2 * np.pi * 0.9 * t))
    noisy = ls_fit(W, y + hf, ["a", "b", "c"])
    Wn, yn = decimate_parallel(W, y + hf, 10, fs_hz=FS, cutoff_hz=40.0)
    dec_n = ls_fit(Wn, yn, ["a", "b", "c"])
    np.testing.assert_allclose(dec_n.values, full.values, rtol=0, atol=5e-4)  # well inside full.std (6e-4)
    assert dec_n.residual_rms == pytest.approx(full.residual_rms, rel=0.01)
    assert noisy.residual_rms > 2 * full.residual_rms


def test_decimation_default_cutoff_and_identity():
    W = np.ones((100, 2))
    y = np.arange(100.0)
    Wd, yd = decimate_parallel(W, y, 1)
    np.testing.assert_array_equal(yd, y)
    Wd, yd = decimate_parallel(W, y, 5)
    assert Wd.shape == (20, 2) and yd.shape == (20,)
    np.testing.assert_allclose(Wd, 1.0, atol=1e-9)  # a constant passes the low-pass unchanged


def test_resample_to_is_linear_and_nan_outside():
    t = np.linspace(0, 1, 11)
    x = np.column_stack([3 * t + 1, -t])
    out = resample_to(t, x, np.array([-0.1, 0.25, 0.95, 1.2]))
    np.testing.assert_allclose(out[1:3], [[1.75, -0.25], [3.85, -0.95]])
    assert np.isnan(out[[0, 3]]).all()


def test_bad_inputs_raise_input_error():
    x = np.sin(np.arange(200) / 10.0)
    bad = x.copy()
    bad[50] = np.nan
    with pytest.raises(InputError, match="1 NaN samples"):
        lowpass(bad, FS, 100.0)
    with pytest.raises(InputError, match="at least 16 samples"):  # 3 (2 sections x 2 + 1) + 1
        lowpass(x[:15], FS, 100.0)
    assert lowpass(x[:16], FS, 100.0).shape == (16,)
    with pytest.raises(InputError, match="cutoff_hz"):
        lowpass(x, FS, 600.0)
    with pytest.raises(InputError, match="fs_hz"):
        lowpass(x, -1.0, 100.0)
    with pytest.raises(InputError, match="factor"):
        decimate_parallel(np.ones((200, 1)), x, 2.5)
    with pytest.raises(InputError, match="NaN"):
        decimate_parallel(np.ones((200, 1)), bad, 10, fs_hz=FS, cutoff_hz=40.0)
    with pytest.raises(InputError, match="rows in W"):
        decimate_parallel(np.ones((199, 1)), x, 10, fs_hz=FS, cutoff_hz=40.0)
    with pytest.raises(InputError, match="at least 16 samples"):
        decimate_parallel(np.ones((10, 1)), x[:10], 10, fs_hz=FS, cutoff_hz=40.0)
    with pytest.raises(InputError, match="fs_hz"):
        derivatives(x, 0.0)
    with pytest.raises(InputError, match="at least 3 samples"):
        derivatives(x[:2], FS)


@pytest.mark.parametrize("shape, fs, fc", [((15000,), 250.0, 20.0), ((3000, 6), 1000.0, 60.0), ((16,), 100.0, 10.0)])
def test_lowpass_is_scipys_forward_backward_filter_to_the_bit(shape, fs, fc):
    """lowpass runs sosfiltfilt's steps with its initial conditions designed once: the same numbers."""
    x = np.random.default_rng(3).standard_normal(shape)
    sos = signal.butter(4, fc, fs=fs, output="sos")
    ref = signal.sosfiltfilt(sos, x, axis=0, padlen=min(3 * (2 * len(sos) + 1), shape[0] - 1))
    np.testing.assert_array_equal(lowpass(x, fs, fc), ref)
