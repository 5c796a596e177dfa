"""FRF from periodic data (Makarov et al. 2012, eq. 23-27) against the exact FRF of the two-inertia
joint, simulated independently (tests/ident/frf_sim.py: state-space steady state, exact noise
integration): open and closed loop, H1 against the harmonic-mean and indirect estimators under
closed-loop process noise, the noise level, nonlinear distortion at the detection lines, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.ident.frf import estimate_frf, transient_count
from mocapfj.ident.multisine import design_multisine, multisine_realisations

from .frf_sim import plant_frf, simulate_multisine

P_J1 = dict(J=0.75, I=1.165, k=1150.0, d=1.0, b=0.8, v=0.3)   # modes at 5.0 and 8.0 Hz (ASSIST-like j1)
FS = 1 / 0.003


def _open_loop(n=1024, periods=6, y_noise=0.0, seed=0):
    ms = design_multisine(FS, n, 0.5, 12.0, rms=5.0, seed=seed)     # torque, N m
    u, y, _ = simulate_multisine(P_J1, [ms], periods, y_noise_sd=y_noise, seed=seed)
    return ms, u, y


@pytest.mark.parametrize("estimator", ["h1", "harmonic"])
def test_open_loop_noise_free_is_exact(estimator):
    ms, u, y = _open_loop()
    F = estimate_frf(u, y, FS, ms.n_samples, estimator=estimator)
    assert np.array_equal(F.lines, ms.lines)
    G0 = plant_frf(F.f_hz, P_J1)
    assert np.abs(F.G / G0 - 1).max() < 1e-9
    assert np.all(F.coherence > 1 - 1e-9)
    assert F.n_periods == 5 and F.n_realisations == 1 and not F.closed_loop


def test_open_loop_noise_level_covers_the_error():
    """The period-to-period noise variance predicts the error: mean |G - G0|^2 / var ~ 1 over the lines
    and seeds (an F(2, 2 (P - 1)) variable: mean (P - 1) / (P - 2) = 7/6 for 8 periods); coherence
    below 1 where the output is weak."""
    z2 = []
    for seed in range(12):
        ms, u, y = _open_loop(periods=9, y_noise=2e-5, seed=seed)
        F = estimate_frf(u, y, FS, ms.n_samples)
        G0 = plant_frf(F.f_hz, P_J1)
        z2.append(np.abs(F.G - G0) ** 2 / F.var)
    z2 = np.concatenate(z2)
    assert 0.8 < z2.mean() < 1.6, z2.mean()
    assert F.coherence.min() < 1 - 1e-6 and int(np.argmin(F.coherence)) == int(np.argmin(np.abs(F.G)))   # weakest output


def test_closed_loop_h1_biased_indirect_not():
    """Process noise (a torque disturbance on the motor) fed back by the PD loop: averaged over four
    seeds, H1's error stays hundreds of its own variances away from the truth (a bias, towards -1/C),
    the indirect and harmonic-mean estimators' within theirs (Makarov et al. 2012, eq. 25; Pintelon
    and Schoukens 2012)."""
    ms = design_multisine(FS, 512, 0.5, 12.0, rms=0.01, detection_group=0, seed=1)
    acc = {"h1": [], "indirect": [], "harmonic": []}
    for seed in range(4):
        u, y, r = simulate_multisine(P_J1, [ms], 33, kp=300.0, kd=30.0, noise_sd=10.0, seed=seed)
        for est in acc:
            F = estimate_frf(u, y, FS, ms.n_samples, r=r, estimator=est)
            acc[est].append((F.G, F.var))
    G0 = plant_frf(F.f_hz, P_J1)
    res = {}
    for est, runs in acc.items():
        G = np.mean([g for g, _ in runs], axis=0)
        var = np.mean([v for _, v in runs], axis=0) / len(runs)
        res[est] = (np.sqrt(np.mean(np.abs(G / G0 - 1) ** 2)), np.mean(np.abs(G - G0) ** 2 / var))
    assert res["h1"][1] > 50, res
    assert 0.3 < res["indirect"][1] < 2.0, res
    assert res["h1"][0] > 1.2 * res["indirect"][0] and res["h1"][0] > 0.25, res
    assert res["harmonic"][0] == pytest.approx(res["indirect"][0], rel=1e-9)   # one realisation: the same


def test_realisations_harmonic_and_indirect_agree_and_total_variance():
    ms = design_multisine(FS, 1024, 0.5, 12.0, rms=0.01, seed=1)
    mss = multisine_realisations(ms, 3, seed=7)
    u, y, r = simulate_multisine(P_J1, mss, 5, kp=300.0, kd=30.0, noise_sd=2.0, seed=2)
    Fi = estimate_frf(u, y, FS, 1024, r=r)
    Fh = estimate_frf(u, y, FS, 1024, r=r, estimator="harmonic")
    assert Fi.estimator == "indirect" and Fi.closed_loop and Fi.n_realisations == 3
    G0 = plant_frf(Fi.f_hz, P_J1)
    for F in (Fi, Fh):
        assert np.median(np.abs(F.G / G0 - 1)) < 0.03
        assert F.var_total is not None and F.var_total.shape == F.var.shape
    d = Fi.to_dict()
    assert len(d["frequencies_hz"]) == len(d["magnitude"]) == len(d["coherence"]) == Fi.lines.size
    with pytest.raises(InputError, match="not excited"):                 # u has noise there, r nothing
        estimate_frf(u, y, FS, 1024, r=r, lines=np.r_[ms.lines, ms.detection_even[:1]])


@pytest.mark.parametrize("power, even, odd", [(0, False, False), (2, True, False), (3, False, True)])
def test_distortion_at_the_detection_lines(power, even, odd):
    """A static output nonlinearity y + c y^p: even powers put energy on the even lines only, odd
    powers on the odd detection lines (Schoukens et al. 2001); a linear system on neither."""
    ms, u, y = _open_loop(periods=5, seed=3)
    assert ms.detection_odd.size and ms.detection_even.size
    scale = np.abs(y).max()
    yn = y + (0.05 * scale * (y / scale) ** power if power else 0.0)
    yn = yn + np.random.default_rng(0).normal(0, 1e-6 * scale, y.shape)
    D = estimate_frf(u, yn, FS, ms.n_samples).distortion
    assert D.even_detected == even and D.odd_detected == odd
    if even:
        assert D.even_db > D.noise_db + 20
    if odd:
        assert D.odd_db > D.noise_db + 20


def test_transient_periods_found():
    """A decaying transient over the first periods: 'auto' drops them (and at least one period)."""
    ms, u, y = _open_loop(n=512, periods=8, y_noise=1e-6, seed=2)
    assert transient_count(u, y, 512) == 1                                # steady: the first period only
    t = np.arange(y.shape[1]) / FS
    yt = y + 0.05 * np.abs(y).max() * np.exp(-t / 1.2) * np.cos(2 * np.pi * 5.0 * t)   # tau 1.2 s, periods of 1.54 s
    k = transient_count(u, yt, 512)
    assert 3 <= k <= 6
    F = estimate_frf(u, yt, FS, 512, transient_periods="auto")
    assert F.n_periods == 8 - k
    assert np.median(np.abs(F.G / plant_frf(F.f_hz, P_J1) - 1)) < 1e-3


def test_bad_input():
    ms, u, y = _open_loop(periods=3)
    with pytest.raises(InputError, match="periods"):
        estimate_frf(u[:, : 2 * ms.n_samples], y[:, : 2 * ms.n_samples], FS, ms.n_samples)
    with pytest.raises(InputError, match="singular|not excited"):
        estimate_frf(u, y, FS, ms.n_samples, lines=np.r_[ms.lines, ms.detection_odd[:1]])
    with pytest.raises(InputError) as e:
        estimate_frf(u, y[:, :-1], FS, ms.n_samples)
    assert e.value.field == "y"
    with pytest.raises(InputError) as e:
        estimate_frf(u, y, FS, ms.n_samples, estimator="h2")
    assert e.value.field == "estimator"
    with pytest.raises(InputError, match="reference"):
        estimate_frf(u, y, FS, ms.n_samples, estimator="indirect")
    noise = np.random.default_rng(1).normal(size=u.shape)
    with pytest.raises(InputError, match="periodic excitation"):
        estimate_frf(noise, y, FS, ms.n_samples)
    bad = u.copy()
    bad[0, 5] = np.nan
    with pytest.raises(InputError, match="finite"):
        estimate_frf(bad, y, FS, ms.n_samples)


def test_a_closed_loop_run_without_its_reference_is_told_from_its_noise():
    """The period-to-period noise of a closed loop's input follows its output's with the ratio
    -1 / C, not G: without the reference that is said (frf_notes), from 5 coherent lines on; an open
    loop whose input carries the noise into the plant has the ratio G, and nothing is said; nor when
    the noise is the sensors' own (it is not fed back, and biases nothing)."""
    from mocapfj.pipeline.frf import frf_notes

    cases = {"closed, fed-back torque noise": (dict(kp=300.0, kd=30.0, noise_sd=1.0), 0.01, True),
             "closed, sensor noise": (dict(kp=300.0, kd=30.0, y_noise_sd=1e-5, u_noise_sd=0.05), 0.01, False),
             "open, torque noise into the plant": (dict(noise_sd=1.0), 1.0, False)}
    for name, (kw, rms, fed_back) in cases.items():
        ms = design_multisine(FS, 1024, 0.5, 12.0, rms=rms, seed=5)
        u, y, r = simulate_multisine(P_J1, [ms], 5, seed=6, **kw)
        F = estimate_frf(u, y, FS, 1024)
        assert F.feedback["suspected"] is fed_back, (name, F.feedback)
        said = any("feedback loop" in n for n in frf_notes(F, None, gravity_fitted=False))
        assert said is fed_back, name
        assert estimate_frf(u, y, FS, 1024, r=r).feedback is None        # with the reference: nothing to tell
