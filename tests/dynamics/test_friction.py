"""Friction models: special cases reduce to each other, odd symmetry, dissipation (F q' >= 0)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocapfj.dynamics import (AsymmetricCoulombViscous, AsymmetricStribeck, CoulombViscous, ExtendedStribeck,
                              PositionDependent, Stribeck)
from mocapfj.errors import InputError

QD = np.concatenate([-np.logspace(-4, 1, 200), [0.0], np.logspace(-4, 1, 200)])  # rad/s
pos = st.floats(0.0, 100.0)
vel = st.floats(-10.0, 10.0)


def test_coulomb_viscous_values():
    f = CoulombViscous(c=9.28, v=18.38)  # Lightcap and Banks (2007), Table I, joint 2
    assert f.torque(0.5) == pytest.approx(9.28 + 18.38 * 0.5, abs=1e-12)
    assert f.torque(-0.5) == pytest.approx(-9.28 - 18.38 * 0.5, abs=1e-12)
    assert f.torque(0.0) == 0.0
    assert f.params == {"c": 9.28, "v": 18.38}


def test_smoothing_is_tanh_and_converges():
    f = CoulombViscous(c=2.0, v=0.0, smoothing=0.01)
    assert f.torque(0.01) == pytest.approx(2.0 * np.tanh(1.0), rel=1e-12)
    exact = CoulombViscous(2.0, 0.0).torque(QD)
    far = np.abs(QD) > 0.1  # 10 eps: tanh within 2e-8 of sign
    np.testing.assert_allclose(f.torque(QD)[far], exact[far], atol=2 * 2 * np.exp(-20))
    assert f.with_smoothing(0.0).torque(1e-9) == 2.0


def test_stribeck_without_stribeck_term_is_coulomb_viscous():
    cv = CoulombViscous(c=122.19, v=336.73)
    for exponent in (1.0, 2.0):
        s = Stribeck(fc=122.19, fs=122.19, vs=0.009, fv=336.73, exponent=exponent)
        np.testing.assert_array_equal(s.torque(QD), cv.torque(QD))


def test_stribeck_peak_and_plateau():
    # Oueslati et al. (2012), Table I, positive side: at q' -> 0+ the torque is fs, far above vs it is fc + fv q'
    s = Stribeck(fc=122.19, fs=148.54, vs=0.009, fv=336.73)
    assert s.torque(1e-9) == pytest.approx(148.54 + 336.73e-9, rel=1e-12)
    assert s.torque(0.2) == pytest.approx(122.19 + 336.73 * 0.2, rel=1e-12)  # exp(-(0.2/0.009)^2) ~ 1e-214
    assert s.torque(0.009) == pytest.approx(122.19 + 26.35 * np.exp(-1) + 336.73 * 0.009, rel=1e-12)


def test_asymmetric_with_equal_sides_is_symmetric():
    a = AsymmetricCoulombViscous(c_pos=3.0, v_pos=0.5, c_neg=3.0, v_neg=0.5, smoothing=0.02)
    np.testing.assert_array_equal(a.torque(QD), CoulombViscous(3.0, 0.5, smoothing=0.02).torque(QD))
    b = AsymmetricStribeck(1.0, 1.5, 0.01, 0.3, 1.0, 1.5, 0.01, 0.3)
    np.testing.assert_array_equal(b.torque(QD), Stribeck(1.0, 1.5, 0.01, 0.3).torque(QD))


def test_asymmetric_stribeck_oueslati_table():
    f = AsymmetricStribeck(fc_pos=122.19, fs_pos=148.54, vs_pos=0.009, fv_pos=336.73,
                           fc_neg=87.02, fs_neg=111.38, vs_neg=0.009, fv_neg=294.44)
    assert f.torque(0.1) == pytest.approx(122.19 + 33.673, rel=1e-9)
    assert f.torque(-0.1) == pytest.approx(-87.02 - 29.444, rel=1e-9)
    assert f.torque(-1e-9) == pytest.approx(-111.38, rel=1e-6)


def test_extended_stribeck_reductions_and_table():
    # f3 = f5 = 0: Coulomb + viscous (f2, f1)
    e = ExtendedStribeck(f=(0.4362, 0.6632, 0.0, 0.0622, 0.0, 16.9787))
    np.testing.assert_allclose(e.torque(QD), CoulombViscous(0.6632, 0.4362).torque(QD), rtol=0, atol=1e-15)
    # f5 = 0 (Bompos et al. (2007), Table II joint 6, f6 = 0): a Stribeck curve with exponent 1
    j6 = ExtendedStribeck(f=(0.0551, 0.0829, 0.0373, 0.0220, 0.0, 0.0))
    s = Stribeck(fc=0.0829, fs=0.0829 - 0.0373, vs=0.0220, fv=0.0551, exponent=1.0)
    np.testing.assert_allclose(j6.torque(QD), s.torque(QD), rtol=0, atol=1e-15)
    # joint 1 positive side at 0.1 rad/s, by hand
    j1 = ExtendedStribeck(f=(0.4362, 0.6632, 0.4469, 0.0622, 0.5612, 16.9787),
                          f_neg=(0.3952, 0.8550, 0.6203, 0.0583, 0.7244, 19.1778))
    want = 0.04362 + 0.6632 - 0.4469 * np.exp(-0.1 / 0.0622) - 0.5612 * np.exp(-1 / 1.69787)
    assert j1.torque(0.1) == pytest.approx(want, rel=1e-12)
    want_neg = -0.03952 - 0.8550 + 0.6203 * np.exp(-0.1 / 0.0583) + 0.7244 * np.exp(-1 / 1.91778)
    assert j1.torque(-0.1) == pytest.approx(want_neg, rel=1e-12)
    assert j1.torque(0.0) == 0.0 and np.isfinite(j1.torque(QD)).all()


def test_extended_stribeck_rejects_negative_f6():
    with pytest.raises(InputError, match="f6"):
        ExtendedStribeck(f=(0.069, 0.1122, -0.0626, 0.4307, -0.0919, -101.92))  # Table II joint 4, neg


def test_position_dependent_ripple():
    base = CoulombViscous(c=2.0, v=0.1)
    f = PositionDependent(base, orders=(1.0, 2.0), amplitudes=(0.3, 0.1), phases=(0.0, np.pi / 2))
    q = np.linspace(-3, 3, 7)
    want = base.torque(0.5) + 0.3 * np.cos(q) + 0.1 * np.cos(2 * q + np.pi / 2)
    np.testing.assert_allclose(f.torque(0.5, q), want, rtol=1e-14)
    np.testing.assert_allclose(f.torque(-0.5, q), -want, rtol=1e-14)
    # periodic in the joint angle with period 2 pi
    np.testing.assert_allclose(f.torque(0.3, q + 2 * np.pi), f.torque(0.3, q), atol=1e-13)
    assert f.params["amplitude2"] == 0.1 and f.params["base.c"] == 2.0
    assert f.with_smoothing(0.01).smoothing == 0.01
    with pytest.raises(InputError, match="q"):
        f.torque(0.5)


def test_bad_parameters_are_rejected():
    with pytest.raises(InputError):
        Stribeck(fc=1.0, fs=1.2, vs=0.0, fv=0.1)
    with pytest.raises(InputError):
        CoulombViscous(c=1.0, v=float("nan"))
    with pytest.raises(InputError):
        CoulombViscous(c=1.0, v=1.0, smoothing=-1.0)


SYMMETRIC = st.one_of(
    st.builds(CoulombViscous, pos, pos, smoothing=st.sampled_from([0.0, 0.01])),
    st.builds(lambda fc, extra, vs, fv, e: Stribeck(fc, fc + extra, vs, fv, e),
              pos, pos, st.floats(1e-4, 1.0), pos, st.sampled_from([1.0, 2.0])),
    st.builds(lambda f1, f3, f4, f5, f6, extra: ExtendedStribeck(f=(f1, f3 + f5 + extra, f3, f4, f5, f6)),
              pos, pos, st.floats(1e-3, 1.0), pos, st.floats(0.0, 100.0), pos),
)
ASYMMETRIC = st.one_of(
    st.builds(AsymmetricCoulombViscous, pos, pos, pos, pos),
    st.builds(lambda a, b, c, d, e, f: AsymmetricStribeck(a, a + b, 0.01, c, d, d + e, 0.02, f),
              pos, pos, pos, pos, pos, pos),
    st.builds(lambda c, a, ph: PositionDependent(CoulombViscous(c + a, 0.2), (1.0,), (a,), (ph,)),
              pos, pos, st.floats(-np.pi, np.pi)),
)


@settings(max_examples=150, deadline=None)
@given(model=st.one_of(SYMMETRIC, ASYMMETRIC), qd=vel, q=st.floats(-6.3, 6.3))
def test_friction_opposes_motion(model, qd, q):
    # F enters I q'' + ... + F = tau_s on the left: dissipative means F q' >= 0
    assert model.torque(qd, q) * qd >= 0.0


@settings(max_examples=150, deadline=None)
@given(model=SYMMETRIC, qd=vel)
def test_symmetric_models_are_odd(model, qd):
    assert model.torque(-qd) == pytest.approx(-model.torque(qd), rel=1e-12, abs=1e-12)
