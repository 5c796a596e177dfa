"""Hysteresis operators: loop area = dissipated energy, exact runs vs ODE, virgin curves."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj.dynamics import Backlash, BoucWen, Dahl, MaxwellSlip, SpringElement, integrate_states
from mocapfj.errors import InputError

MS = MaxwellSlip(k=(1e4, 2e4, 3e4), f=(20.0, 50.0, 80.0), k0=2e3)
DAHL = Dahl(sigma=2e4, fc=60.0, k0=1e3)
BW = BoucWen(k=1e4, alpha=0.2, beta=150.0, gamma=50.0)


def sine_path(amplitude, freq_hz, cycles, per_cycle):
    t = np.arange(cycles * per_cycle + 1) / (per_cycle * freq_hz)
    return t, amplitude * np.sin(2 * np.pi * freq_hz * t), amplitude * 2 * np.pi * freq_hz * np.cos(2 * np.pi * freq_hz * t)


def last_cycle(per_cycle, *arrays):
    return [a[-per_cycle - 1:] for a in arrays]


def loop_area(tau, delta):
    """Closed integral of tau d delta (trapezoid)."""
    return float(np.sum(0.5 * (tau[1:] + tau[:-1]) * np.diff(delta)))


def trapz(y, t):
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def play_reference(d, r):
    """Play operator, one sample at a time (the textbook definition)."""
    w = np.empty_like(d)
    w[0] = d[0]
    for i in range(1, d.size):
        w[i] = min(max(w[i - 1], d[i] - r), d[i] + r)
    return w


def test_protocol():
    for h in (MS, DAHL, BW):
        assert isinstance(h, SpringElement)
        z0 = h.initial_state()
        assert z0.shape == (h.n_states,)
        assert h.state_derivative(z0, 0.0, 0.1).shape == (h.n_states,)
        assert h.torque(np.zeros(5), np.zeros((5, h.n_states))).shape == (5,)
    assert MS.n_states == 3 and DAHL.n_states == 1 and BW.n_states == 1


def test_maxwell_slip_scan_equals_play_operator():
    rng = np.random.default_rng(1)
    d = np.cumsum(rng.normal(0, 1e-3, 3000))
    t = np.arange(d.size) * 1e-3
    z = MS.run_states(d, t, method="exact")
    for i, (k, r) in enumerate(zip(MS.k, MS.thresholds)):
        np.testing.assert_allclose(z[:, i], k * (d - play_reference(d, r)), rtol=0, atol=1e-9)
    np.testing.assert_allclose(MS.run(d, t), MS.k0 * d + z.sum(1), rtol=1e-14)


def test_maxwell_slip_loop_area_is_slip_work():
    A, per = 0.01, 4000
    t, d, dd = sine_path(A, 1.0, 3, per)
    z = MS.run_states(d, t)
    tau = MS.torque(d, z)
    tc, dc, ddc, tauc, zc = last_cycle(per, t, d, dd, tau, z)
    area = loop_area(tauc, dc)
    # slip work per cycle: element i slides 2 (A - r_i) twice at torque f_i
    slip_work = sum(4 * f * max(A - r, 0.0) for f, r in zip(MS.f, MS.thresholds))
    assert slip_work == pytest.approx(4.4867, abs=1e-4)
    assert area > 0
    assert area == pytest.approx(slip_work, rel=1e-4)
    # power balance: the dissipation rate integrated over the cycle
    assert trapz(MS.dissipation_rate(zc, dc, ddc), tc) == pytest.approx(slip_work, rel=5e-4)


def test_maxwell_slip_virgin_stiffness_and_saturation():
    t = np.linspace(0, 1, 1001)
    d = 1e-3 * t  # below every threshold (2e-3 rad and up)
    np.testing.assert_allclose(MS.run(d, t), (MS.k0 + sum(MS.k)) * d, rtol=1e-12)
    d = 0.05 * t  # far beyond: every element slips
    assert MS.run(d, t)[-1] == pytest.approx(MS.k0 * 0.05 + sum(MS.f), rel=1e-12)


def test_maxwell_slip_ode_matches_exact():
    t, d, _ = sine_path(0.006, 2.0, 2, 1000)
    d = d + 0.002 * np.sin(2 * np.pi * 7.3 * t)
    exact = MS.run(d, t)
    ode = MS.run_states(d, t, method="ode")
    # the ODE blends stick to slip over 0.1 % of each slip level: error ~ 1e-3 f
    np.testing.assert_allclose(MS.torque(d, ode), exact, rtol=0, atol=0.2)


def test_maxwell_slip_stribeck_levels():
    m = MaxwellSlip(k=(1e4,), f=(10.0,), stribeck_ratio=1.5, stribeck_velocity=1e-3, attraction=200.0)
    for v, level in ((1e-5, 10.0 * (1 + 0.5 * np.exp(-1e-4))), (0.1, 10.0)):
        t = np.linspace(0.0, 0.02 / v, 401)  # slide 10 thresholds
        assert m.run(v * t, t)[-1] == pytest.approx(level, rel=1e-4)
    with pytest.raises(InputError, match="exact"):
        m.run_states(np.array([0.0, 1.0]), np.array([0.0, 1.0]), method="exact")


def test_dahl_loop_area_closed_form_and_power_balance():
    A, per = 0.01, 4000
    t, d, dd = sine_path(A, 0.5, 4, per)
    z = DAHL.run_states(d, t)
    tc, dc, ddc, zc = last_cycle(per, t, d, dd, z)
    area = loop_area(DAHL.torque(dc, zc), dc)
    a = DAHL.sigma * A / DAHL.fc
    f_max = DAHL.fc * np.tanh(a)  # steady peak: F_max = fc tanh(sigma A / fc)
    closed = 2 * (2 * A * DAHL.fc - (f_max + DAHL.fc) * DAHL.fc / DAHL.sigma * (1 - np.exp(-2 * a)))
    assert closed == pytest.approx(1.6818, abs=1e-3)
    assert zc.max() == pytest.approx(f_max, rel=1e-9)
    assert area > 0
    assert area == pytest.approx(closed, rel=1e-5)
    assert trapz(DAHL.dissipation_rate(zc, dc, ddc), tc) == pytest.approx(closed, rel=1e-4)


def test_dahl_exact_matches_ode_and_is_rate_independent():
    t, d, _ = sine_path(0.008, 1.0, 2, 2000)
    exact = DAHL.run(d, t)
    ode = DAHL.torque(d, integrate_states(DAHL, d, t))
    np.testing.assert_allclose(ode, exact, rtol=0, atol=2e-3 * DAHL.fc)
    # the same path ten times faster gives the same torques
    np.testing.assert_allclose(DAHL.run(d, t / 10), exact, rtol=0, atol=1e-12)
    # exponent != 1 has no exact form and goes through the ODE; i -> 1 agrees
    near = Dahl(sigma=2e4, fc=60.0, k0=1e3, exponent=1.0 + 1e-9)
    np.testing.assert_allclose(near.run(d, t), exact, rtol=0, atol=0.12)


def test_bouc_wen_loop_area_equals_dissipation_and_bound():
    A, per = 0.01, 4000
    t, d, dd = sine_path(A, 1.0, 3, per)
    z = BW.run_states(d, t)
    tc, dc, ddc, zc = last_cycle(per, t, d, dd, z)
    area = loop_area(BW.torque(dc, zc), dc)
    dissipated = trapz(BW.dissipation_rate(zc, dc, ddc), tc)
    assert area > 0.5  # J; a fat loop: (1 - alpha) k z_max 2A ~ 0.8 J
    assert area == pytest.approx(dissipated, rel=1e-5)
    # |z| never exceeds the Bouc-Wen bound (A / (beta + gamma))^(1/n)
    assert np.abs(z).max() <= BW.A / (BW.beta + BW.gamma) * (1 + 1e-6)
    # rate independence: same loop at 20 Hz
    z_fast = BW.run_states(d, t / 20)
    np.testing.assert_allclose(z_fast, z, rtol=0, atol=1e-7)


def test_bouc_wen_elastic_limit():
    # alpha = 1: a linear spring, no loop
    el = BoucWen(k=1e4, alpha=1.0, beta=150.0, gamma=50.0)
    t, d, _ = sine_path(0.01, 1.0, 1, 1000)
    np.testing.assert_allclose(el.run(d, t), 1e4 * d, rtol=1e-12)
    assert abs(loop_area(el.run(d, t), d)) < 1e-12


def test_backlash_forwards_state():
    b = Backlash(gap=2e-3, spring=MS)
    assert b.n_states == 3
    t, d, _ = sine_path(0.01, 1.0, 2, 2000)
    np.testing.assert_allclose(b.run(d, t), MS.run(b.engaged(d), t), rtol=1e-14)
    dz = b.state_derivative(np.zeros(3), 5e-4, 1.0)  # inside the gap: the element does not move
    np.testing.assert_array_equal(dz, np.zeros(3))


def test_bad_parameters():
    with pytest.raises(InputError):
        MaxwellSlip(k=(1e4, 2e4), f=(1.0,))
    with pytest.raises(InputError):
        BoucWen(k=1e4, alpha=1.5, beta=1.0, gamma=1.0)
    with pytest.raises(InputError):
        BoucWen(k=1e4, alpha=0.5, beta=-1.0, gamma=0.5)
    with pytest.raises(InputError):
        Dahl(sigma=0.0, fc=1.0)
    with pytest.raises(InputError):
        MS.run_states(np.zeros(3), np.zeros(3))
