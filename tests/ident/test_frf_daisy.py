"""The single-record FRF and the rational fit on real data: DaISy 96-009, a flexible robot arm
(KU Leuven; DaISy, De Moor et al. 1997): 1024 samples of one
periodic sine sweep, column 1 the reaction torque (input), column 2 the arm's acceleration (output),
frequencies normalised (cycles per sample, no sampling rate given). No published model: the checks
are the coherence, a fit at the noise level (chi2 / dof near 1), every in-band mode found by the
model within one DFT line of the dip or peak of the plain DFT ratio Y / U (the peer), and the same
modes within their SDs when the LPM window and the model order change."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.ident.frf_single import estimate_frf_lpm, estimate_frf_welch, fit_rational

BAND = 0.22           # the input's band ends near 0.2 cycles per sample; the model's poles beyond are not modes


@pytest.fixture(scope="module")
def arm(realdata):
    d = np.loadtxt(realdata / "daisy_robot_arm" / "robot_arm.dat")
    assert d.shape == (1024, 2)
    return d[:, 0], d[:, 1]


def _in_band(fit):
    return [m for m in fit.modes if m.f_hz < BAND]


def test_daisy_arm_frf_coherence_and_modes(arm):
    u, y = arm
    r = estimate_frf_lpm(u, y, 1.0)                      # fs = 1: frequencies in cycles per sample
    f = r.frf
    assert f.f_hz.size == 199 and f.f_hz[0] == pytest.approx(1 / 1024) and 0.215 < f.f_hz[-1] < 0.22
    assert np.median(f.coherence) > 0.93 and np.mean(f.coherence > 0.9) > 0.55   # measured 0.961, 0.61
    welch = estimate_frf_welch(u, y, 1.0, segment=256)   # the ordinary coherence, 7 segments: median 0.959
    assert abs(np.median(welch.coherence) - np.median(f.coherence)) < 0.03
    fit = fit_rational(r, 6, 6)
    assert 0.7 < fit.chi2_red < 1.2                      # measured 0.90; (4, 4) leaves 11.8
    assert fit_rational(r, 4, 4).chi2_red > 5
    with pytest.raises(InputError, match="lower the order or drop the delay"):   # over-parametrised: no SDs
        fit_rational(r, 6, 6, delay=True)
    modes = _in_band(fit)
    assert [m.kind for m in modes] == ["antiresonance", "resonance", "resonance", "antiresonance"]
    U, Y = np.fft.rfft(u), np.fft.rfft(y)
    a = np.abs(Y / np.where(U == 0, 1, U))
    for m in modes:                                      # the DFT ratio's extreme within +-6 lines
        k0 = int(round(m.f_hz * 1024))
        k = np.arange(k0 - 6, k0 + 7)
        k_peer = k[np.argmax(a[k])] if m.kind == "resonance" else k[np.argmin(a[k])]
        assert abs(m.f_hz * 1024 - k_peer) < 1.0, (m, k_peer)
        assert 0 < m.f_hz_std < 3e-3 * m.f_hz and 0 < m.zeta < 0.01 and 0 < m.zeta_std < m.zeta
    f_modes = [m.f_hz for m in modes]
    np.testing.assert_allclose(f_modes, [0.03218, 0.05828, 0.12673, 0.1795], atol=2e-5)   # measured, recorded in docs
    # another LPM window and model order, and the record taken as one steady-state period (Y / U with
    # the LPM's noise; chi2/dof 1.00): the same modes within 2 SDs
    alt = _in_band(fit_rational(estimate_frf_lpm(u, y, 1.0, order=2, half_width=5), 7, 7))
    per = fit_rational(estimate_frf_lpm(u, y, 1.0, periodic=True), 6, 6)
    assert 0.7 < per.chi2_red < 1.3
    for m, m2 in [*zip(modes, alt), *zip(modes, _in_band(per))]:
        assert m.kind == m2.kind
        assert abs(m.f_hz - m2.f_hz) < 2 * np.hypot(m.f_hz_std, m2.f_hz_std)
        assert abs(m.zeta - m2.zeta) < 2 * np.hypot(m.zeta_std, m2.zeta_std)
