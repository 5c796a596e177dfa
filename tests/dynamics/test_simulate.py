"""Forward simulation and the controller log: tracking, hysteresis states, quantisation, noise."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

import mocapfj.dynamics
from mocapfj.dynamics import (PID, CoulombViscous, Dahl, LinearSpring, MaxwellSlip, PrescribedMotor, SingleJoint,
                              TorqueInput, controller_log, resample, simulate)
from mocapfj.errors import InputError
from mocapfj.types import ControllerLog

W = 2 * np.pi * 0.25  # slow reference: 0.25 Hz


def reference(t):
    return 0.5 * np.sin(W * t), 0.5 * W * np.cos(W * t)


def model(**kw):
    base = dict(I=1.0, J=0.5, spring=LinearSpring(1e4), b=1.0, friction=CoulombViscous(0.0, 2.0))
    base.update(kw)
    return SingleJoint(**base)


def test_package_docstring_example_runs():
    assert doctest.testmod(mocapfj.dynamics, raise_on_error=False).failed == 0


def test_pd_tracks_a_slow_reference():
    kp, kd = 3000.0, 150.0
    t = np.linspace(0.0, 4.0, 2001)
    r = simulate(model(), t, PID(reference, kp=kp, kd=kd))
    # quasi-static error of a PD loop: ((I + J) q_ref'' + (v + b) q_ref') / kp, at most 1.40e-3 rad
    bound = (1.5 * 0.5 * W**2 + 3.0 * 0.5 * W) / kp
    assert bound == pytest.approx(1.402e-3, rel=1e-3)
    settled = t > 0.5
    e_motor = reference(t)[0] - r.q_m[:, 0]
    assert np.abs(e_motor[settled]).max() < 1.1 * bound
    assert np.abs(e_motor[settled]).max() > 0.5 * bound  # the bound is tight, not vacuous
    # the link lags the motor by the spring deflection, tau_s / k
    e_link = reference(t)[0] - r.q[:, 0]
    assert np.abs(e_link[settled]).max() < 1.1 * bound + np.abs(r.tau_s).max() / 1e4
    np.testing.assert_allclose(r.u[:, 0], kp * e_motor + kd * (reference(t)[1] - r.qd_m[:, 0]), rtol=1e-12)


def test_pid_holds_against_gravity_with_static_deflection():
    m = model(mgly=50.0, d=30.0)
    hold = lambda t: (0.3 + 0 * np.asarray(t), 0 * np.asarray(t))  # noqa: E731
    t = np.linspace(0.0, 3.0, 1501)
    r = simulate(m, t, PID(hold, kp=4000.0, kd=200.0, ki=20000.0))
    assert r.q_m[-1, 0] == pytest.approx(0.3, abs=1e-6)  # the integral removes the static error
    g = 50.0 * np.cos(r.q[-1, 0])
    assert r.delta[-1, 0] == pytest.approx(g / 1e4, rel=1e-4)
    assert r.u[-1, 0] == pytest.approx(g, rel=1e-4)


def test_torque_saturation():
    r = simulate(model(), np.linspace(0, 0.5, 101), PID(reference, kp=1e5, kd=0.0, u_max=5.0),
                 q_m0=[0.2], q0=[0.2])
    assert np.abs(r.u).max() == pytest.approx(5.0)


@pytest.mark.parametrize("spring", [MaxwellSlip(k=(1e4, 2e4), f=(5.0, 15.0), k0=2e3), Dahl(sigma=3e4, fc=20.0, k0=3e3)])
def test_hysteresis_states_in_simulation_match_run(spring):
    m = model(spring=spring, d=5.0)
    traj = PrescribedMotor(lambda t: (0.2 * np.sin(4 * t), 0.8 * np.cos(4 * t), -3.2 * np.sin(4 * t)))
    t = np.linspace(0.0, 2.0, 2001)
    r = simulate(m, t, traj, q0=[0.0], qd0=[0.8])
    assert r.z.shape == (t.size, spring.n_states)
    # the operator run along the simulated deflection reproduces the simulated spring torque
    # (run takes the path as linear between the 1 ms samples and so cuts the turning points:
    # 3e-4 of the peak torque for Dahl, 3e-10 for Maxwell-slip whose reversals are elastic)
    replay = spring.run(r.delta[:, 0], t)
    np.testing.assert_allclose(r.tau_s[:, 0] - 5.0 * (r.qd_m[:, 0] - r.qd[:, 0]), replay,
                               rtol=0, atol=5e-4 * np.abs(replay).max())
    # the link-side loop tau_s(delta) encloses positive area (energy goes into the joint)
    d, tau = r.delta[1000:, 0], spring.torque(r.delta[1000:, 0], r.z[1000:])
    assert np.sum(0.5 * (tau[1:] + tau[:-1]) * np.diff(d)) > 0


def test_controller_log_quantisation_noise_and_rate():
    m = model()
    t = np.linspace(0.0, 2.0, 4001)  # 2 kHz
    r = simulate(m, t, PID(reference, kp=3000.0, kd=150.0), max_step=2e-3)
    quantum = 1e-4
    log = controller_log(r, 500.0, rng=np.random.default_rng(7), quantum_rad=quantum, current_noise_sd=0.2)
    assert isinstance(log, ControllerLog) and log.joint_names == ("j1",)
    assert log.n_samples == 1001 and np.diff(log.t) == pytest.approx(np.full(1000, 2e-3))
    truth = resample(r, log.t)
    k = log.q_m[:, 0] / quantum
    np.testing.assert_allclose(k, np.round(k), rtol=0, atol=1e-6)  # integer multiples
    assert np.abs(log.q_m - truth.q_m).max() <= quantum / 2 + 1e-15
    steps = np.abs(np.diff(log.q_m[:, 0]))
    assert steps[steps > 0].min() == pytest.approx(quantum, rel=1e-9)  # the quantisation step
    noise = log.tau[:, 0] - truth.u[:, 0]
    assert noise.std() == pytest.approx(0.2, rel=0.07)  # 1001 samples: SE of the SD ~2.2 %
    assert abs(noise.mean()) < 4 * 0.2 / np.sqrt(noise.size)
    # deterministic in the generator; the truth only when asked for
    again = controller_log(r, 500.0, rng=np.random.default_rng(7), quantum_rad=quantum, current_noise_sd=0.2)
    np.testing.assert_array_equal(again.tau, log.tau)
    assert dict(log.extra) == {}
    with_truth = controller_log(r, 500.0, rng=np.random.default_rng(7), include_truth=True)
    np.testing.assert_allclose(with_truth.extra["q_true_j1"], truth.q[:, 0], rtol=1e-15)
    np.testing.assert_allclose(with_truth.q_m, truth.q_m, rtol=1e-15)


def test_resolver_bits_give_the_link_side_quantum():
    r = simulate(model(), np.linspace(0, 1, 1001), PID(reference, kp=3000.0, kd=150.0))
    log = controller_log(r, 1000.0, rng=np.random.default_rng(0), resolver_bits=12, gear_ratio=50.0)
    quantum = 2 * np.pi / (4096 * 50.0)  # 3.07e-5 rad
    steps = np.abs(np.diff(log.q_m[:, 0]))
    assert steps[steps > 0].min() == pytest.approx(quantum, rel=1e-9)


def test_resample_at_own_times_is_identity():
    r = simulate(model(), np.linspace(0, 0.5, 251), TorqueInput(lambda t: 0.1 + 0 * np.asarray(t)))
    s = resample(r, r.t)
    for name in ("q", "qd", "qdd", "q_m", "u", "tau_s", "delta"):
        np.testing.assert_allclose(getattr(s, name), getattr(r, name), rtol=1e-15, atol=1e-18)
    # with a constant torque on a free joint the centre of inertia accelerates at u / (I + J)
    com = (1.0 * r.qdd[:, 0] + 0.5 * r.qdd_m[:, 0]) / 1.5
    np.testing.assert_allclose(com + (2.0 * r.qd[:, 0] + 1.0 * r.qd_m[:, 0]) / 1.5, 0.1 / 1.5, rtol=1e-9)


def test_bad_arguments():
    r = simulate(model(), np.linspace(0, 0.1, 11), TorqueInput(lambda t: 0.0))
    with pytest.raises(InputError, match="rng"):
        controller_log(r, 100.0, rng=np.random.RandomState(0))  # type: ignore[arg-type]
    with pytest.raises(InputError):
        controller_log(r, 100.0, rng=np.random.default_rng(0), quantum_rad=1e-4, resolver_bits=12, gear_ratio=50.0)
    with pytest.raises(InputError):
        controller_log(r, 100.0, rng=np.random.default_rng(0), resolver_bits=12)
    with pytest.raises(InputError, match="drive"):
        simulate(model(), np.linspace(0, 1, 11), reference)
    with pytest.raises(InputError, match="t"):
        simulate(model(), np.array([0.0, 0.0, 1.0]), TorqueInput(lambda t: 0.0))
    with pytest.raises(InputError, match="q0"):
        simulate(model(), np.linspace(0, 1, 11), TorqueInput(lambda t: 0.0), q0=[0.0, 1.0])


def test_external_torque_deflects_a_held_joint():
    m = model(d=40.0)
    held = PrescribedMotor(lambda t: (0 * np.asarray(t), 0 * np.asarray(t), 0 * np.asarray(t)))
    r = simulate(m, np.linspace(0, 1.0, 501), held, q0=[0.0], qd0=[0.0], tau_ext=lambda t: 25.0 + 0 * np.asarray(t))
    assert r.delta[-1, 0] == pytest.approx(-25.0 / 1e4, rel=1e-6)  # the spring holds the external torque
    assert r.qdd[-1, 0] == pytest.approx(0.0, abs=1e-4)


def test_prescribed_motor_from_samples_matches_the_function():
    f = lambda t: (0.3 * np.sin(3 * t), 0.9 * np.cos(3 * t), -2.7 * np.sin(3 * t))  # noqa: E731
    ts = np.linspace(0, 1.2, 1201)
    sampled = PrescribedMotor.from_samples(ts, f(ts)[0])
    for k in range(3):  # the spline and its derivatives inside the span
        np.testing.assert_allclose(sampled.trajectory(ts[100:-100])[k], f(ts[100:-100])[k], atol=1e-6 * 10**k)
    t = np.linspace(0.1, 1.0, 451)
    a, b = simulate(model(), t, sampled), simulate(model(), t, PrescribedMotor(f))
    np.testing.assert_allclose(a.q, b.q, atol=1e-8)


def test_an_evaluation_budget_stops_an_integration_that_would_not_end():
    """A narrow Bouc-Wen loop on a stiff joint: with a budget of 200 evaluations the run stops with
    a RuntimeError naming the budget, instead of running on."""
    from mocapfj.dynamics import BoucWen, CoulombViscous, PrescribedMotor, SingleJoint, simulate

    m = SingleJoint(I=6.15, J=12.57, spring=BoucWen(k=1.19e4, alpha=0.7, beta=5e4, gamma=5e4), mglx=111.6,
                    friction=CoulombViscous(9.0, 18.0, smoothing=1e-3))
    t = np.arange(0.0, 2.0, 1e-3)
    drive = PrescribedMotor.from_samples(t, 0.5 * np.sin(2 * np.pi * 0.5 * t))
    with pytest.raises(RuntimeError, match="200 derivative evaluations"):
        simulate(m, t, drive, max_evals=200)
