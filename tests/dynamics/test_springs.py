"""Stateless springs: values, continuity and slopes of the piecewise spring, backlash, protocol."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocapfj.dynamics import Backlash, CubicSpring, LinearSpring, PiecewiseSpring, SpringElement
from mocapfj.errors import InputError

# A catalogue-like harmonic drive (CSF-25 class): K1 < K2 < K3, T1 < T2
HD = PiecewiseSpring(k1=3.1e4, k2=5.0e4, k3=5.7e4, tau1=14.0, tau2=48.0)


def test_linear_with_offset():
    s = LinearSpring(k=1.19e4, offset=2e-4)  # Lightcap and Banks (2007), Table I, joint 2
    assert s.torque(1.2e-3) == pytest.approx(1.19e4 * 1e-3, rel=1e-12)
    assert s.torque(2e-4) == 0.0
    assert s.params == {"k": 1.19e4, "offset": 2e-4}


def test_cubic():
    s = CubicSpring(k1=1e4, k3=2e9)
    d = np.array([-0.01, 0.0, 0.005])
    np.testing.assert_allclose(s.torque(d), 1e4 * d + 2e9 * d**3, rtol=1e-14)


def test_piecewise_breakpoints_continuity_and_slopes():
    th1, th2 = HD.breakpoints
    assert th1 == pytest.approx(14.0 / 3.1e4, rel=1e-14)
    assert th2 == pytest.approx(th1 + 34.0 / 5.0e4, rel=1e-14)
    # torque at the breakpoints equals tau1, tau2; continuous from both sides
    assert HD.torque(th1) == pytest.approx(14.0, rel=1e-14)
    assert HD.torque(th2) == pytest.approx(48.0, rel=1e-14)
    eps = 1e-12
    for th in (th1, th2):
        assert abs(HD.torque(th + eps) - HD.torque(th - eps)) < 1e-6
    # slopes of each piece by finite differences
    h = 1e-7
    for mid, k in ((0.5 * th1, 3.1e4), (0.5 * (th1 + th2), 5.0e4), (2 * th2, 5.7e4)):
        for sgn in (1, -1):
            slope = (HD.torque(sgn * mid + h) - HD.torque(sgn * mid - h)) / (2 * h)
            assert slope == pytest.approx(k, rel=1e-6)
    # odd
    d = np.linspace(-3 * th2, 3 * th2, 101)
    np.testing.assert_allclose(HD.torque(-d), -HD.torque(d), rtol=0, atol=1e-12)


def test_piecewise_rejects_bad_limits():
    with pytest.raises(InputError, match="tau2"):
        PiecewiseSpring(1e4, 2e4, 3e4, tau1=10.0, tau2=5.0)
    with pytest.raises(InputError):
        PiecewiseSpring(-1e4, 2e4, 3e4, tau1=1.0, tau2=5.0)


def test_backlash_zero_inside_gap_and_shifted_outside():
    gap = 2e-3
    b = Backlash(gap=gap, spring=LinearSpring(k=1e4))
    inside = np.linspace(-gap / 2, gap / 2, 51)
    np.testing.assert_array_equal(b.torque(inside), np.zeros_like(inside))
    assert b.torque(gap / 2 + 1e-3) == pytest.approx(10.0, rel=1e-9)
    assert b.torque(-gap / 2 - 1e-3) == pytest.approx(-10.0, rel=1e-9)
    # continuous at the gap edge
    assert abs(b.torque(gap / 2 + 1e-12)) < 1e-7
    # wraps any element, e.g. the piecewise spring
    bp = Backlash(gap=gap, spring=HD)
    assert bp.torque(gap / 2 + HD.breakpoints[0]) == pytest.approx(14.0, rel=1e-12)
    assert bp.params["gap"] == gap and bp.params["spring.k1"] == 3.1e4


def test_stateless_protocol():
    t = np.linspace(0.0, 1.0, 11)
    d = 1e-3 * np.sin(2 * np.pi * t)
    for s in (LinearSpring(1e4), CubicSpring(1e4, 1e8), HD, Backlash(1e-4, LinearSpring(1e4))):
        assert isinstance(s, SpringElement)
        assert s.n_states == 0 and s.initial_state().shape == (0,)
        assert s.state_derivative(np.zeros(0), 0.1, 0.2).shape == (0,)
        np.testing.assert_array_equal(s.run(d, t), s.torque(d))
    with pytest.raises(InputError):
        LinearSpring(1e4).run(d, t[::-1])


@settings(max_examples=200, deadline=None)
@given(k1=st.floats(1e2, 1e5), r2=st.floats(1.0, 3.0), r3=st.floats(1.0, 3.0),
       tau1=st.floats(0.1, 100.0), r_tau=st.floats(1.01, 10.0),
       a=st.floats(-0.05, 0.05), b=st.floats(-0.05, 0.05))
def test_piecewise_monotone(k1, r2, r3, tau1, r_tau, a, b):
    s = PiecewiseSpring(k1, k1 * r2, k1 * r2 * r3, tau1, tau1 * r_tau)
    lo, hi = min(a, b), max(a, b)
    assert s.torque(hi) >= s.torque(lo)
    # and never softer than k1 nor stiffer than k3 between two points
    if hi > lo:
        slope = (s.torque(hi) - s.torque(lo)) / (hi - lo)
        assert k1 * (1 - 1e-9) <= slope <= k1 * r2 * r3 * (1 + 1e-9)


@settings(max_examples=100, deadline=None)
@given(gap=st.floats(0.0, 0.01), d=st.floats(-0.05, 0.05))
def test_backlash_dead_zone_property(gap, d):
    b = Backlash(gap, LinearSpring(1e3))
    tau = b.torque(d)
    if abs(d) <= gap / 2:
        assert tau == 0.0
    else:
        assert tau == pytest.approx(1e3 * (d - np.sign(d) * gap / 2), rel=1e-9, abs=1e-12)
