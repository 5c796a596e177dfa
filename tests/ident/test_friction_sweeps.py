"""Friction from constant-velocity sweeps (mocapfj.ident.friction) against analytic truth.

The recordings are synthesised directly: a staircase of velocity levels joined by 0.2 s cosine
ramps (where the torque also carries I q'', so a plateau finder that let ramps in would bias the
points), the true friction model + gravity G(q) + seeded Gaussian torque noise. Truths: Oueslati et al. (2012)
Table I (Staubli RX-170B axis 2, asymmetric Stribeck eq. 7) and Bompos et al. (2007), Table II joint 1
(PA-10, eq. 18, both sides).
"""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj.dynamics.friction import AsymmetricStribeck, ExtendedStribeck, Stribeck
from mocapfj.dynamics.hysteresis import Dahl
from mocapfj.errors import InputError
from mocapfj.ident.friction import (FrictionFit, SweepPoints, fit_extended_stribeck, fit_presliding, fit_stribeck,
                                    sweep_points)

# Oueslati et al. (2012), Table I, joint 2 (positive / negative velocity), exponent 2
STAUBLI = AsymmetricStribeck(fc_pos=122.19, fs_pos=148.54, vs_pos=0.009, fv_pos=336.73,
                             fc_neg=87.02, fs_neg=111.38, vs_neg=0.009, fv_neg=294.44)
# Bompos et al. (2007), Table II, joint 1 (positive / negative velocity)
PA10_J1 = ExtendedStribeck(f=(0.4362, 0.6632, 0.4469, 0.0622, 0.5612, 16.9787),
                           f_neg=(0.3952, 0.8550, 0.6203, 0.0583, 0.7244, 19.1778))
RATE_HZ = 500.0
HOLD_S, RAMP_S = 1.0, 0.2


def gravity(q):
    """G(q) of a 6.1 kg m link, N m."""
    return 60.0 * np.sin(q + 0.3)


def staircase(levels):
    """t, q, qd, qdd of velocity plateaus `levels` (rad/s, HOLD_S each) joined by cosine ramps."""
    t, v, acc = [], [], []
    prev, t0 = 0.0, 0.0
    tr, th = np.arange(0, RAMP_S, 1 / RATE_HZ), np.arange(0, HOLD_S, 1 / RATE_HZ)
    s = 0.5 - 0.5 * np.cos(np.pi * tr / RAMP_S)
    for lv in levels:
        t += [t0 + tr, t0 + RAMP_S + th]
        v += [prev + (lv - prev) * s, np.full(th.size, lv)]
        acc += [(lv - prev) * 0.5 * np.pi / RAMP_S * np.sin(np.pi * tr / RAMP_S), np.zeros(th.size)]
        t0 += RAMP_S + HOLD_S
        prev = lv
    t, qd, qdd = np.concatenate(t), np.concatenate(v), np.concatenate(acc)
    q = np.concatenate([[0.0], np.cumsum(0.5 * (qd[1:] + qd[:-1]) / RATE_HZ)])
    return t, q, qd, qdd


def two_sided(n, lo=0.001, hi=1.0):
    m = np.geomspace(lo, hi, n)
    return np.concatenate([m, -m])


def recording(truth, levels, noise_nm, seed, inertia=2.0, v_noise_rel=0.002):
    """(t, q, measured qd, tau) with tau = I q'' + G(q) + F(q') + noise; qd with relative noise."""
    t, q, qd, qdd = staircase(levels)
    rng = np.random.default_rng(seed)
    tau = inertia * qdd + gravity(q) + truth.torque(qd) + rng.normal(0.0, noise_nm, t.size)
    return t, q, qd * (1 + rng.normal(0.0, v_noise_rel, t.size)), tau


def monte_carlo(fit, truth, v, se, n, seed):
    """Fit n noisy copies of the true plateau means; (MC-SD / RMS reported std, mean bias / std, names)."""
    clean = truth.torque(v)
    rng = np.random.default_rng(seed)
    fits = [fit(v, clean + rng.normal(0.0, se, v.size)) for _ in range(n)]
    names = list(fits[0].params)
    est = np.array([[f.params[k] for k in names] for f in fits])
    std = np.sqrt(np.mean([[f.std[k] ** 2 for k in names] for f in fits], axis=0))
    bias = (est.mean(axis=0) - [truth.params[k] for k in names]) / std
    return est.std(axis=0, ddof=1) / std, bias, names


def rel_err(fit: FrictionFit, truth) -> dict:
    return {k: v / truth.params[k] - 1 for k, v in fit.params.items()}


# --------------------------------------------------------------------------- plateaus


def test_sweep_points_finds_the_plateaus_and_subtracts_gravity():
    """32 plateaus (16 per side, 0.001..1 rad/s) found, none inside a ramp; the gravity-free
    friction means scatter around the truth as their standard errors say.

    Measured (seed 1, 2 N m torque noise, 0.2 % velocity noise): all 32 found, 472..495 samples
    each, |v / level - 1| < 2.1e-4, se 0.083..0.096 N m, SD of (tau - F(v)) / se = 0.98,
    max |tau - F(v)| / se = 2.3.
    """
    levels = two_sided(16)
    t, q, qd, tau = recording(STAUBLI, levels, 2.0, seed=1)
    p = sweep_points(t, q, qd, tau, gravity=gravity)
    assert isinstance(p, SweepPoints) and len(p) == 32
    np.testing.assert_allclose(p.v, levels, rtol=5e-4)
    # every averaged sample is inside a hold (ramp k ends at k * 1.2 s + 0.2 s)
    k = np.arange(32)
    assert (p.t_start >= k * (HOLD_S + RAMP_S) + RAMP_S).all()
    assert (p.t_end < (k + 1) * (HOLD_S + RAMP_S)).all()
    assert (p.t_end - p.t_start >= 0.5).all() and (p.n_samples > 400).all()
    z = (p.tau - STAUBLI.torque(p.v)) / p.se
    assert 0.8 < z.std() < 1.25 and np.abs(z).max() < 4
    np.testing.assert_allclose(p.se, 2.0 / np.sqrt(p.n_samples), rtol=0.25)
    # gravity as an array G(q) gives the same points; without it the points are off by G
    p2 = sweep_points(t, q, qd, tau, gravity=gravity(q))
    np.testing.assert_allclose(p2.tau, p.tau)
    p3 = sweep_points(t, q, qd, tau)
    assert np.abs(p3.tau - p.tau).max() > 10


def test_sweep_points_settle_and_min_duration():
    """settle_s cuts the start of each plateau; plateaus shorter than min_duration_s are dropped.

    The steadiness window (min_duration_s / 5) trims about half a window at each end of an
    interior plateau: with min_duration_s 0.9 (window 0.18 s) the two 1 s interior holds keep
    0.89 s and are dropped, the last one (not trimmed at the end of the record) keeps 0.92 s.
    """
    t, q, qd, tau = recording(STAUBLI, [0.05, 0.1, -0.05], 1.0, seed=4)
    p = sweep_points(t, q, qd, tau, gravity=gravity, settle_s=0.3)
    assert len(p) == 3
    assert (p.t_start >= np.array([0.5, 1.7, 2.9]) - 1e-9).all()
    for md, n in ((0.5, 3), (0.8, 3), (0.9, 1)):
        pm = sweep_points(t, q, qd, tau, gravity=gravity, min_duration_s=md)
        assert len(pm) == n and (pm.t_end - pm.t_start >= md - 1 / RATE_HZ).all()
    with pytest.raises(InputError, match="plateaus of at least 1.5 s"):
        sweep_points(t, q, qd, tau, min_duration_s=1.5)


# --------------------------------------------------------------------------- Stribeck


def test_fit_stribeck_recovers_oueslati_table1():
    """Full pipeline on Oueslati et al. (2012), Table I (axis 2), 16 plateaus per side, 2 N m noise.

    Measured (seed 1): fc_pos 122.177 (122.19), fs_pos 148.495 (148.54), vs_pos 0.009033 (0.009),
    fv_pos 336.65 (336.73), fc_neg 87.046 (87.02), fs_neg 111.417 (111.38), vs_neg 0.008970
    (0.009), fv_neg 294.442 (294.44): largest error 0.37 % (vs_pos), all within 0.8 std;
    rms 0.085 N m.
    """
    t, q, qd, tau = recording(STAUBLI, two_sided(16), 2.0, seed=1)
    p = sweep_points(t, q, qd, tau, gravity=gravity)
    fit = fit_stribeck(p)
    assert isinstance(fit.model, AsymmetricStribeck) and fit.model.exponent == 2.0
    err = rel_err(fit, STAUBLI)
    assert set(err) == {f"{n}_{s}" for n in ("fc", "fs", "vs", "fv") for s in ("pos", "neg")}
    assert max(abs(e) for e in err.values()) < 0.01, err
    for k, v in fit.params.items():
        assert abs(v - STAUBLI.params[k]) < 3 * fit.std[k], (k, v, fit.std[k])
    assert fit.rms < 0.15 and fit.r2 > 0.9999 and fit.n_points == 32
    np.testing.assert_allclose(fit.predict(p.v), fit.model.torque(p.v))
    # explicit arrays and weights 1/se^2 give the same coefficients within their std
    fw = fit_stribeck(p.v, p.tau, weights=1 / p.se**2)
    for k in fit.params:
        assert abs(fw.params[k] - fit.params[k]) < fit.std[k]


def test_fit_stribeck_std_matches_monte_carlo():
    """Reported std (sigma^2 (J^T J)^-1) against the scatter of 150 seeded noise realisations of
    the plateau means (se 0.1 N m, 16 plateaus per side, 0.002..0.5 rad/s). The reported std is
    averaged as sqrt(mean(std^2)) (sigma is estimated from 12 dof per side in each fit).

    Measured MC-SD / reported std: fc 1.06, fs 0.94, vs 0.95, fv 1.08 (positive side),
    fc 1.12, fs 0.85, vs 0.91, fv 0.98 (negative side); |mean bias| <= 0.05 std. Seeds 5, 6, 7 give
    ratios 0.83..1.16.
    """
    v = two_sided(16, 0.002, 0.5)
    ratio, bias, names = monte_carlo(fit_stribeck, STAUBLI, v, 0.1, 150, seed=11)
    assert ((ratio > 0.75) & (ratio < 1.25)).all(), dict(zip(names, ratio.round(2)))
    assert (np.abs(bias) < 0.5).all(), dict(zip(names, bias.round(2)))


def test_fit_stribeck_symmetric():
    """asymmetric=False fits one set to both sides and returns a Stribeck; exponent 1 works too.

    Measured (0.05 N m noise, seed 5): fc 122.190, fs 148.511, vs 0.009021 (+0.24 %, 0.6 std), fv 336.91.
    """
    truth = Stribeck(fc=122.19, fs=148.54, vs=0.009, fv=336.73, exponent=1.0)
    v = two_sided(10, 0.001, 0.3)
    tau = truth.torque(v) + np.random.default_rng(5).normal(0.0, 0.05, v.size)
    fit = fit_stribeck(v, tau, asymmetric=False, exponent=1.0)
    assert type(fit.model) is Stribeck and fit.model.exponent == 1.0
    for k in ("fc", "fs", "vs", "fv"):
        assert fit.params[k] == pytest.approx(truth.params[k], rel=0.01)
        assert abs(fit.params[k] - truth.params[k]) < 3 * fit.std[k]


# --------------------------------------------------------------------------- Bompos et al. (2007), eq. (18)


def test_fit_extended_stribeck_recovers_bompos_table2_joint1():
    """Full pipeline on Table II joint 1, 24 plateaus per side from 0.001 to 1 rad/s, 0.01 N m
    torque noise (se about 4.5e-4 N m per plateau).

    Measured (seed 2): f1 0.4385 (0.4362), f2 0.6685 (0.6632), f3 0.4525 (0.4469), f4 0.06236
    (0.0622), f5 0.5685 (0.5612), f6 16.99 (16.98); negative side f1 0.3955 (0.3952), f2 0.8532
    (0.8550), f3 0.6184 (0.6203), f4 0.05811 (0.0583), f5 0.7225 (0.7244), f6 19.22 (19.18):
    largest error 1.3 % (f5), largest 2.0 std (f1); curve within 7e-4 N m over +-1 rad/s.
    """
    t, q, qd, tau = recording(PA10_J1, two_sided(24), 0.01, seed=2, inertia=0.05)
    p = sweep_points(t, q, qd, tau, gravity=gravity)
    assert len(p) == 48
    fit = fit_extended_stribeck(p)
    assert isinstance(fit.model, ExtendedStribeck) and fit.model.f_neg is not None
    err = rel_err(fit, PA10_J1)
    assert len(err) == 12 and max(abs(e) for e in err.values()) < 0.03, err
    for k, v in fit.params.items():
        assert abs(v - PA10_J1.params[k]) < 3 * fit.std[k], (k, v, fit.std[k])
    v = np.linspace(-1, 1, 201)
    assert np.abs(fit.predict(v) - PA10_J1.torque(v)).max() < 0.01


def test_fit_extended_stribeck_std_matches_monte_carlo():
    """Reported std against the scatter of 100 seeded realisations of the plateau means
    (se 1e-3 N m, 20 plateaus per side, 0.001..1 rad/s), std averaged as sqrt(mean(std^2)).

    Measured MC-SD / reported std: f1..f6 1.08 1.07 1.06 1.14 1.08 1.14 (positive
    side), 1.09 1.09 1.10 1.01 1.12 0.96 (negative side); |mean bias| <= 0.13 std. Seeds 5, 6, 7
    give ratios 0.89..1.12.
    """
    ratio, bias, names = monte_carlo(fit_extended_stribeck, PA10_J1, two_sided(20), 1e-3, 100, seed=21)
    assert ((ratio > 0.75) & (ratio < 1.25)).all(), dict(zip(names, ratio.round(2)))
    assert (np.abs(bias) < 0.5).all(), dict(zip(names, bias.round(2)))


# --------------------------------------------------------------------------- pre-sliding


def test_presliding_recovers_fs_and_sigma0():
    """Oueslati et al.'s start-of-motion experiment: 5.931e-5 rad/s for 20 s, torque from the Dahl
    element (Fs 148.54 N m, sigma0 1.5e6 N m/rad, i.e. 1e-4 rad to saturate to 63 %) + 1 N m noise,
    in both directions.

    Dahl.run is checked to be the closed form the fit uses (agreement 1e-12 N m).
    Measured (seed 3): Fs 148.557, sigma0 1.5019e6 (+), Fs 148.559, sigma0 1.4990e6 (-); std
    0.027 N m and 1.65e3 N m/rad; MC-SD / RMS std over 40 realisations: Fs 0.88, sigma0 0.88.
    """
    fs, s0 = 148.54, 1.5e6
    t = np.arange(0.0, 20.0, 0.01)
    x = 5.931e-5 * t
    tau = Dahl(sigma=s0, fc=fs).run(x, t)
    np.testing.assert_allclose(tau, fs * (1 - np.exp(-s0 * x / fs)), atol=1e-9)
    rng = np.random.default_rng(3)
    for d in (1, -1):
        f = fit_presliding(d * x, d * tau + rng.normal(0.0, 1.0, x.size))
        assert f.direction == d
        assert f.fs == pytest.approx(fs, rel=1e-3) and f.sigma0 == pytest.approx(s0, rel=0.01)
        assert abs(f.fs - fs) < 4 * f.std["fs"] and abs(f.sigma0 - s0) < 4 * f.std["sigma0"]
        assert isinstance(f.model, Dahl) and f.model.fc == f.fs and f.model.sigma == f.sigma0
        np.testing.assert_allclose(d * f.model.run(x, t), f.predict(d * x), atol=1e-9)
        assert f.rms == pytest.approx(1.0, rel=0.1) and f.r2 > 0.99
    fits = [fit_presliding(x, tau + rng.normal(0.0, 1.0, x.size)) for _ in range(40)]
    est = np.array([[f.fs, f.sigma0] for f in fits])
    std = np.sqrt(np.mean([[f.std["fs"] ** 2, f.std["sigma0"] ** 2] for f in fits], axis=0))
    ratio = est.std(axis=0, ddof=1) / std
    assert ((ratio > 0.75) & (ratio < 1.25)).all(), ratio


# --------------------------------------------------------------------------- bad input


def _one_sided():
    v = np.geomspace(0.001, 1, 12)
    return v, STAUBLI.torque(v)


@pytest.mark.parametrize("call, message", [
    (lambda: fit_stribeck(two_sided(4), STAUBLI.torque(two_sided(4))),
     r"v: expected more than 4 plateaus with v > 0 and more than 4 with v < 0 .*got 4 positive, 4 negative"),
    (lambda: fit_stribeck(*_one_sided()), r"asymmetric Stribeck fit .*got 12 positive, 0 negative .*asymmetric=False"),
    (lambda: fit_stribeck(np.geomspace(0.01, 1, 4), np.ones(4), asymmetric=False),
     r"v: expected more than 4 plateaus for a Stribeck fit \(4 parameters\), got 4"),
    (lambda: fit_extended_stribeck(two_sided(6), PA10_J1.torque(two_sided(6))),
     r"more than 6 plateaus with v > 0 .*eq\. \(18\) fit .*got 6 positive, 6 negative"),
    (lambda: fit_stribeck(two_sided(8), np.where(np.arange(16) == 3, np.nan, 1.0)),
     r"tau: expected finite samples, got 1 NaN/inf"),
    (lambda: fit_stribeck(two_sided(8), np.ones(15)), r"tau: expected a 1-D array of 16 samples, got shape \(15,\)"),
    (lambda: fit_stribeck(np.r_[0.0, two_sided(8)], np.ones(17)), r"v: expected non-zero plateau velocities"),
    (lambda: fit_stribeck(two_sided(8), np.ones(16), weights=-np.ones(16)), r"weights: expected positive weights"),
    (lambda: sweep_points(np.arange(10.0), np.zeros(10), np.zeros(9), np.zeros(10)),
     r"qd: expected a 1-D array of 10 samples, got shape \(9,\)"),
    (lambda: sweep_points(np.arange(10.0), np.zeros(10), np.r_[np.nan, np.ones(9)], np.zeros(10)),
     r"qd: expected finite samples, got 1 NaN/inf"),
    (lambda: sweep_points(np.arange(10.0), np.zeros(10), np.zeros(10), np.zeros(10)),
     r"qd: expected constant-velocity plateaus .*got none"),
    (lambda: sweep_points(np.r_[0.0, 0.0, np.arange(2.0, 10.0)], np.zeros(10), np.ones(10), np.zeros(10)),
     r"t: expected at least 3 strictly increasing times"),
    (lambda: sweep_points(np.arange(10.0), np.zeros(10), np.ones(10), np.zeros(10), gravity=np.zeros(3)),
     r"gravity: expected a 1-D array of 10 samples"),
    (lambda: fit_presliding(np.zeros(20), np.ones(20)), r"x: expected a displacement away from 0"),
    (lambda: fit_presliding(np.linspace(0, 1e-3, 20), -np.ones(20)), r"tau: expected a friction torque of the sign"),
    (lambda: fit_presliding(np.linspace(0, 1e-3, 20), np.ones(19)), r"tau: expected a 1-D array of 20 samples"),
])
def test_bad_input_raises_input_error(call, message):
    with pytest.raises(InputError, match=message):
        call()


def test_unexcited_stribeck_region_shows_in_the_std():
    """Every plateau far above vs (0.5..1 rad/s, vs 0.009): fs and vs are not separable from the
    data, and the reported std says so.

    Measured: exact data give fs = fc to 1e-11 N m and vs_pos 0.25 +- 0.58, vs_neg 0.35 +- 0.28
    rad/s; with 0.1 N m noise (seed 0) vs_pos 0.52 +- 1.02, vs_neg 1.01 +- 0.29 rad/s.
    """
    v = two_sided(8, 0.5, 1.0)
    for noise in (0.0, 0.1):
        fit = fit_stribeck(v, STAUBLI.torque(v) + np.random.default_rng(0).normal(0.0, noise, v.size))
        for side in ("pos", "neg"):
            vs, sd = fit.params[f"vs_{side}"], fit.std[f"vs_{side}"]
            # vs drifts far from the true 0.009 rad/s (the data cannot place it) and its SD says so
            assert vs > 10 * 0.009 and sd > 0.25 * vs, (side, noise, vs, sd)
    # the well-excited sweep of test_fit_stribeck_std_matches_monte_carlo: vs to 1 %
    v = two_sided(16, 0.002, 0.5)
    fit = fit_stribeck(v, STAUBLI.torque(v) + np.random.default_rng(0).normal(0.0, 0.1, v.size))
    assert fit.std["vs_pos"] < 0.01 * fit.params["vs_pos"]


def test_unexcited_presliding_is_refused():
    """A displacement that never changes cannot separate Fs from sigma0."""
    with pytest.raises(InputError, match=r"x: expected displacements from the start of motion through saturation, "
                                         r"got no independent excitation of \['fs', 'sigma0'\]"):
        fit_presliding(np.full(20, 1e-3), np.full(20, 100.0))
