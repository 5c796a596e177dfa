"""Single flexible joint (Lightcap and Banks (2007), eq. 4): statics, free vibration, drivetrain effects in simulation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from mocapfj.dynamics import (CoulombViscous, Drivetrain, GravityBalancer, LinearSpring, PrescribedMotor, SingleJoint,
                              TorqueInput, TransmissionError, simulate)
from mocapfj.errors import InputError

# Lightcap and Banks (2007), Table I magnitudes (joint 2 flavour, lighter link so that tests run fast)
K = 1.19e4


def joint(**kw):
    base = dict(I=1.0, J=0.5, spring=LinearSpring(K), mglx=-7.8, mgly=111.64, b=2.0)
    base.update(kw)
    return SingleJoint(**base)


def hold(q_m):
    return PrescribedMotor(lambda t: (q_m + 0 * np.asarray(t), 0 * np.asarray(t), 0 * np.asarray(t)))


def test_gravity_expression():
    m = joint()
    q = np.linspace(-3, 3, 13)
    np.testing.assert_allclose(m.gravity(q), 7.8 * np.sin(q) + 111.64 * np.cos(q), rtol=1e-14)
    assert m.mass_matrix(np.zeros((4, 1))).shape == (4, 1, 1)


@pytest.mark.parametrize("q", [-1.2, 0.0, 0.4, 1.5])
def test_static_deflection_is_gravity_over_k(q):
    m = joint()
    g = 7.8 * np.sin(q) + 111.64 * np.cos(q)  # -mglx sin q + mgly cos q
    q_m = m.static_motor_angle(np.array([q]))
    assert q_m[0] - q == pytest.approx(g / K, rel=1e-12, abs=1e-15)
    # and back: the link comes to rest at q when the motor is held at q_m
    assert m.static_link_angle(q_m)[0] == pytest.approx(q, abs=1e-12)


def test_static_link_angle_with_free_play_near_rest():
    """A dead zone of 1.56 mrad with the motor nearly at the gravity-free angle: the root solver
    stalls in the flat stretch (a grid recording of the discovery benchmark); the bracket finds the
    engaged side, where k (|delta| - gap/2) holds gravity."""
    from mocapfj.dynamics import Backlash
    gap, k = 1.5558e-3, 12383.64
    m = SingleJoint(I=5.28, J=14.98, spring=Backlash(gap, LinearSpring(k)), mglx=117.2, mgly=-8.218)
    q_m = np.array([0.00246635])
    q = m.static_link_angle(q_m)[0]
    g = -117.2 * np.sin(q) - 8.218 * np.cos(q)
    delta = q_m[0] - q
    assert abs(delta) > gap / 2
    assert k * (delta - np.sign(delta) * gap / 2) == pytest.approx(g, rel=1e-9)


def test_static_deflection_in_simulation_after_damping_out():
    m = joint(friction=CoulombViscous(c=0.0, v=6.0), d=40.0)
    q_m0 = 0.7
    t = np.linspace(0.0, 1.5, 1501)
    r = simulate(m, t, hold(q_m0), q0=[q_m0], qd0=[0.0])  # released undeflected: it swings, then settles
    assert np.ptp(r.delta[:200]) > 5e-3  # it did move
    q_end = r.q[-1, 0]
    q_star = brentq(lambda q: K * (q_m0 - q) - (7.8 * np.sin(q) + 111.64 * np.cos(q)), q_m0 - 0.1, q_m0 + 0.1, xtol=1e-15)
    assert q_end == pytest.approx(q_star, abs=1e-8)
    g = 7.8 * np.sin(q_end) + 111.64 * np.cos(q_end)
    assert r.delta[-1, 0] == pytest.approx(g / K, rel=1e-5)
    assert r.tau_s[-1, 0] == pytest.approx(g, rel=1e-5)
    assert r.u[-1, 0] == pytest.approx(g, rel=1e-5)  # the held motor carries the spring torque
    assert abs(r.qdd[-1, 0]) < 1e-4


def test_free_vibration_frequency():
    # link and motor both free, no gravity, friction or damping: omega = sqrt(k (1/I + 1/J))
    m = SingleJoint(I=1.0, J=0.5, spring=LinearSpring(K))
    w = m.natural_frequency()
    assert w == pytest.approx(np.sqrt(K * 3.0), rel=1e-14)  # 188.9 rad/s, 30.07 Hz
    t = np.arange(0.0, 0.5, 2e-4)
    r = simulate(m, t, TorqueInput(lambda tt: 0.0), q0=[0.0], qd0=[0.0], q_m0=[1e-3], qd_m0=[0.0],
                 rtol=1e-10, atol=1e-13)
    d = r.delta[:, 0]
    i = np.nonzero(np.sign(d[:-1]) != np.sign(d[1:]))[0]
    tz = t[i] - d[i] * (t[i + 1] - t[i]) / (d[i + 1] - d[i])  # interpolated zero crossings
    period = 2 * (tz[-1] - tz[0]) / (tz.size - 1)
    assert tz.size >= 25
    assert 2 * np.pi / period == pytest.approx(w, rel=5e-3)
    assert 2 * np.pi / period == pytest.approx(w, rel=1e-6)  # what it actually achieves (~4e-9)
    # momentum I q' + J q_m' stays zero, amplitude stays 1e-3
    assert np.abs(1.0 * r.qd[:, 0] + 0.5 * r.qd_m[:, 0]).max() < 1e-7
    assert np.abs(d).max() == pytest.approx(1e-3, rel=1e-5)


def test_drive_gain_scales_the_logged_torque():
    traj = PrescribedMotor(lambda t: (0.3 * np.sin(2 * t), 0.6 * np.cos(2 * t), -1.2 * np.sin(2 * t)))
    t = np.linspace(0, 1, 201)
    ideal = simulate(joint(), t, traj)
    weak = simulate(joint(drivetrain=Drivetrain(torque_gain=1.25)), t, traj)
    np.testing.assert_allclose(weak.q, ideal.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(weak.u * 1.25, ideal.u, rtol=1e-10, atol=1e-9)


def test_transmission_error_shows_in_the_link_angle():
    N, a1, a2 = 50.0, 2e-5, 5e-5
    te = TransmissionError(gear_ratio=N, amplitudes=(a1, a2), phases=(0.3, 1.0))
    m = SingleJoint(I=0.2, J=0.05, spring=LinearSpring(5e4), d=20.0, drivetrain=Drivetrain(transmission_error=te))
    v = 0.05  # rad/s link side: wave generator at 0.4 Hz, quasi-static for a 80 Hz joint
    traj = PrescribedMotor(lambda t: (v * t, v + 0 * t, 0 * t))
    t = np.linspace(0, 2.5, 1001)  # one wave-generator turn
    r = simulate(m, t, traj, qd0=[v * (1 + te.derivative(0.0))])
    # the link follows the flexspline q_m + e(q_m); the spring barely deflects
    np.testing.assert_allclose(r.q[:, 0] - r.q_m[:, 0], te.error(r.q_m[:, 0]), rtol=0, atol=0.01 * (a1 + a2))
    assert np.ptp(r.q[:, 0] - r.q_m[:, 0]) > 1.5 * a2


def test_balancer_reduces_the_holding_torque():
    bal = GravityBalancer(k=5e4, a=0.1, b=0.4, free_length=0.2, q0=0.0)
    m = joint(drivetrain=Drivetrain(balancer=bal))
    q = np.array([0.5])
    want = (7.8 * np.sin(0.5) + 111.64 * np.cos(0.5) - bal.torque(0.5)) / K
    assert m.static_motor_angle(q)[0] - 0.5 == pytest.approx(want, rel=1e-12)


def test_parameters_are_checked():
    with pytest.raises(InputError):
        joint(I=0.0)
    with pytest.raises(InputError):
        joint(spring="stiff")
    with pytest.raises(InputError):
        joint(b=-1.0)
    m = joint(friction=CoulombViscous(1.0, 0.1)).with_friction_smoothing(0.01)
    assert m.friction.smoothing == 0.01
