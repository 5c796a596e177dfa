"""Drivetrain effects: transmission error spectrum, balancer torque, coupling, clock shift, gain."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj.dynamics import Drivetrain, GravityBalancer, JointCoupling, TransmissionError, shift_signal
from mocapfj.errors import InputError


def test_transmission_error_is_periodic_in_wave_generator_angle():
    N = 50.0
    te = TransmissionError(gear_ratio=N, amplitudes=(3e-5, 8e-5), phases=(0.4, -1.1))
    # one wave-generator turn = 2 pi / N of q_m
    q_m = np.linspace(-0.3, 0.3, 1001)
    np.testing.assert_allclose(te.error(q_m + 2 * np.pi / N), te.error(q_m), rtol=0, atol=1e-17)
    # spectrum over one wave-generator turn: amplitude 3e-5 at order 1, 8e-5 at order 2
    M = 256
    q_m = np.arange(M) * 2 * np.pi / (N * M)
    spec = np.fft.rfft(te.error(q_m)) * 2 / M
    np.testing.assert_allclose(np.abs(spec[[1, 2]]), [3e-5, 8e-5], rtol=1e-12)
    # sin(x + phi) has FFT phase phi - pi/2
    np.testing.assert_allclose(np.angle(spec[[1, 2]]), [0.4 - np.pi / 2, -1.1 - np.pi / 2], atol=1e-9)
    assert np.abs(spec[3:]).max() < 1e-18


def test_transmission_error_derivative():
    te = TransmissionError(gear_ratio=100.0, amplitudes=(2e-5, 5e-5), phases=(0.0, 0.7))
    q_m = np.linspace(0.0, 0.1, 37)
    h = 1e-7
    fd = (te.error(q_m + h) - te.error(q_m - h)) / (2 * h)
    np.testing.assert_allclose(te.derivative(q_m), fd, rtol=1e-6, atol=1e-12)
    # with zero phases e'(0) = sum a_k n_k N = 2e-5 * 100 + 5e-5 * 2 * 100
    te0 = TransmissionError(gear_ratio=100.0, amplitudes=(2e-5, 5e-5), phases=(0.0, 0.0))
    assert te0.derivative(0.0) == pytest.approx(0.012, rel=1e-14)


def test_balancer_torque_is_minus_potential_gradient():
    bal = GravityBalancer(k=2e4, a=0.1, b=0.3, free_length=0.15, q0=0.2)
    q = np.linspace(-2.5, 2.5, 41)
    h = 1e-6
    grad = (bal.potential(q + h) - bal.potential(q - h)) / (2 * h)
    np.testing.assert_allclose(bal.torque(q), -grad, rtol=1e-7, atol=1e-9)
    assert bal.torque(0.2) == 0.0
    # by hand at phi = 90 deg: L = sqrt(0.1^2 + 0.3^2), tau = -k (L - L0) a b / L
    L = np.hypot(0.1, 0.3)
    assert bal.torque(0.2 + np.pi / 2) == pytest.approx(-2e4 * (L - 0.15) * 0.03 / L, rel=1e-12)
    with pytest.raises(InputError):
        GravityBalancer(k=1.0, a=0.2, b=0.2)


def test_coupling_torque_and_checks():
    C = np.array([[0.0, 0.05, 0.0], [0.02, 0.0, 0.01], [0.0, 0.03, 0.0]])
    c = JointCoupling(C, kind="acceleration")
    x = np.random.default_rng(0).normal(size=(10, 3))
    np.testing.assert_allclose(c.torque(x), x @ C.T, rtol=1e-15)
    c.check_square(3)
    with pytest.raises(InputError):
        JointCoupling(np.eye(3)).check_square(3)
    with pytest.raises(InputError):
        c.torque(np.zeros((10, 2)))
    with pytest.raises(InputError):
        JointCoupling(C, kind="velocity")
    # external neighbours onto one joint: (1, 2) matrix
    ext = JointCoupling([[0.1, -0.2]])
    assert ext.torque(np.array([1.0, 2.0])) == pytest.approx([-0.3])


def test_shift_signal_delays_a_sine():
    t = np.arange(0, 2, 1e-3)
    w = 2 * np.pi * 3.0
    x = np.stack([np.sin(w * t), np.cos(w * t)], axis=1)
    y = shift_signal(t, x, 0.0123)
    ok = t >= t[0] + 0.0123
    assert np.isnan(y[~ok]).all() and np.isfinite(y[ok]).all()
    np.testing.assert_allclose(y[ok, 0], np.sin(w * (t[ok] - 0.0123)), atol=2e-9)
    np.testing.assert_allclose(y[ok, 1], np.cos(w * (t[ok] - 0.0123)), atol=2e-9)
    # a whole number of samples is exact, also linear; a negative delay advances
    y5 = shift_signal(t, x, 5e-3, kind="linear")
    np.testing.assert_allclose(y5[5:], x[:-5], atol=1e-12)
    np.testing.assert_allclose(shift_signal(t, x[:, 0], -5e-3)[:-5], x[5:, 0], atol=1e-12)
    with pytest.raises(InputError):
        shift_signal(t, np.where(t > 1, np.nan, x[:, 0]), 1e-3)


def test_drivetrain_defaults_and_gain_check():
    d = Drivetrain()
    assert d.transmission_error is None and d.balancer is None and d.torque_gain == 1.0
    with pytest.raises(InputError):
        Drivetrain(torque_gain=0.0)
