"""Shared flexible-joint equations: inverses, layout, coupling, and energy conservation (signs)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from mocapfj.dynamics import (CoulombViscous, Dahl, Drivetrain, GravityBalancer, JointCoupling, LinearSpring,
                              MaxwellSlip, NLinkModel, SingleJoint, TorqueInput, TransmissionError, simulate)
from mocapfj.errors import InputError

URDF = """<?xml version="1.0"?><robot name="arm2"><link name="base_link"/>
  <link name="l1"><inertial><origin xyz="0.2 0 0"/><mass value="3"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.15 0 0"/><mass value="2"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <joint name="a" type="revolute"><parent link="base_link"/><child link="l1"/><origin xyz="0 0 0"/>
    <axis xyz="0 -1 0"/><limit lower="-3.2" upper="3.2" effort="100" velocity="10"/></joint>
  <joint name="b" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/>
    <axis xyz="0 -1 0"/><limit lower="-3.2" upper="3.2" effort="100" velocity="10"/></joint>
</robot>"""
RNG = np.random.default_rng(11)


def arm(**kw):
    base = dict(motor_inertia=[0.4, 0.1], springs=[LinearSpring(4e3), LinearSpring(2e3)])
    base.update(kw)
    return NLinkModel.from_urdf(URDF, **base)


def test_link_and_motor_equations_invert():
    te = TransmissionError(50.0, (3e-5, 6e-5), (0.1, 0.2))
    m = arm(frictions=[CoulombViscous(1.0, 2.0, smoothing=0.05), CoulombViscous(0.5, 1.0, smoothing=0.05)],
            drivetrains=[Drivetrain(balancer=GravityBalancer(1e4, 0.05, 0.2, 0.1)),
                         Drivetrain(transmission_error=te, torque_gain=0.9)],
            coupling=JointCoupling([[0.0, 0.02], [0.03, 0.0]]), motor_damping=[1.0, 0.5])
    q, qd, tau_s = RNG.normal(size=(6, 2)), RNG.normal(size=(6, 2)), RNG.normal(0, 20, (6, 2))
    qdd = m.link_acceleration(q, qd, tau_s)
    np.testing.assert_allclose(m.link_torque(q, qd, qdd), tau_s, rtol=1e-12, atol=1e-11)
    # (M - C) q'' = rhs with the acceleration coupling
    rhs = tau_s + m.balancer_torque(q) - m.nonlinear_effects(q, qd) - m.friction_torque(q, qd)
    lhs = np.einsum("tij,tj->ti", m.mass_matrix(q) - np.array([[0.0, 0.02], [0.03, 0.0]]), qdd)
    np.testing.assert_allclose(lhs, rhs, rtol=1e-12, atol=1e-11)
    q_m, qd_m, u = RNG.normal(size=(6, 2)), RNG.normal(size=(6, 2)), RNG.normal(0, 20, (6, 2))
    qdd_m = m.motor_acceleration(q_m, qd_m, tau_s, u)
    np.testing.assert_allclose(m.motor_torque(q_m, qd_m, qdd_m, tau_s), u, rtol=1e-12, atol=1e-11)
    # by hand, joint b: J q_m'' = g u - B q_m' - (1 + e') tau_s
    want = (0.9 * u[:, 1] - 0.5 * qd_m[:, 1] - (1 + te.derivative(q_m[:, 1])) * tau_s[:, 1]) / 0.1
    np.testing.assert_allclose(qdd_m[:, 1], want, rtol=1e-12)


def test_spring_state_layout_and_deflection_coupling():
    ms, dahl = MaxwellSlip(k=(1e4, 2e4, 3e4), f=(1.0, 2.0, 3.0)), Dahl(sigma=1e4, fc=5.0)
    m = arm(springs=[ms, dahl], coupling=JointCoupling([[0.0, 100.0], [100.0, 0.0]], kind="deflection"),
            joint_damping=[3.0, 0.0])
    assert m.spring_slices == (slice(0, 3), slice(3, 4)) and m.n_spring_states == 4
    z = np.array([0.5, -1.0, 2.0, 1.5])
    q, qd, q_m, qd_m = np.array([0.1, 0.2]), np.array([0.3, -0.1]), np.array([0.1002, 0.1995]), np.array([0.5, 0.0])
    tau, delta, delta_dot = m.spring_torque(q, qd, q_m, qd_m, z)
    np.testing.assert_allclose(delta, [2e-4, -5e-4], atol=1e-15)
    np.testing.assert_allclose(delta_dot, [0.2, 0.1], atol=1e-15)
    want = np.array([1.5 + 3.0 * 0.2 + 100.0 * -5e-4, 1.5 + 100.0 * 2e-4])
    np.testing.assert_allclose(tau, want, rtol=1e-12)
    dz = m.spring_state_derivative(z, delta, delta_dot)
    np.testing.assert_allclose(dz[:3], ms.state_derivative(z[:3], delta[0], delta_dot[0]), rtol=1e-15)
    np.testing.assert_allclose(dz[3:], dahl.state_derivative(z[3:], delta[1], delta_dot[1]), rtol=1e-15)


def test_energy_is_conserved_in_the_undamped_arm():
    # the signs of tau_s in the link and motor equations make K delta^2 / 2 a potential
    m = arm()
    t = np.linspace(0.0, 0.25, 251)
    r = simulate(m, t, TorqueInput(lambda tt: 0.0), q0=[0.3, -0.4], qd0=[0.0, 0.0], q_m0=[0.31, -0.41],
                 qd_m0=[0.5, -0.2], rtol=1e-9, atol=1e-11, max_step=5e-3)
    M = m.mass_matrix(r.q)
    kinetic = 0.5 * np.einsum("ti,tij,tj->t", r.qd, M, r.qd) + 0.5 * (np.array([0.4, 0.1]) * r.qd_m**2).sum(1)
    data = m.model.createData()
    gravity = np.array([pin.computePotentialEnergy(m.model, data, q) for q in r.q])
    spring = 0.5 * (np.array([4e3, 2e3]) * r.delta**2).sum(1)
    energy = kinetic + gravity + spring
    assert np.ptp(spring) > 0.1  # energy moves between the terms
    assert np.ptp(energy) < 1e-6 * np.abs(energy).max()  # achieves 4e-8; a sign error gives O(1)


def test_energy_with_transmission_error_and_balancer():
    # e(q_m) in the deflection with (1 + e') tau_s on the motor: still conservative
    te = TransmissionError(20.0, (2e-3, 1e-3), (0.0, 0.5))
    bal = GravityBalancer(k=4e3, a=0.1, b=0.3, free_length=0.1)
    m = SingleJoint(I=0.2, J=0.05, spring=LinearSpring(2e3), mgly=5.0,
                    drivetrain=Drivetrain(transmission_error=te, balancer=bal))
    t = np.linspace(0.0, 0.5, 501)
    r = simulate(m, t, TorqueInput(lambda tt: 0.0), q0=[0.0], qd0=[1.0], q_m0=[0.0], qd_m0=[1.0],
                 rtol=1e-9, atol=1e-11, max_step=5e-3)
    q, qm = r.q[:, 0], r.q_m[:, 0]
    energy = (0.5 * 0.2 * r.qd[:, 0] ** 2 + 0.5 * 0.05 * r.qd_m[:, 0] ** 2 + 5.0 * np.sin(q)
              + bal.potential(q) + 0.5 * 2e3 * (qm + te.error(qm) - q) ** 2)
    assert np.ptp(r.delta[:, 0] - (qm - q)) > 1e-3  # the transmission error is active
    # achieves 1e-10; without the (1 + e') factor on the motor side the energy drifts by 2.4e-4
    assert np.ptp(energy) < 1e-8 * np.abs(energy).max()


def test_static_motor_angle_with_deflection_coupling():
    C = np.array([[0.0, 300.0], [150.0, 0.0]])
    m = arm(coupling=JointCoupling(C, kind="deflection"))
    q = np.array([0.2, 0.5])
    q_m = m.static_motor_angle(q)
    d = q_m - q
    np.testing.assert_allclose(np.array([4e3, 2e3]) * d + C @ d, m.gravity(q), rtol=1e-10)
    np.testing.assert_allclose(m.static_link_angle(q_m), q, atol=1e-10)


@pytest.mark.parametrize("bad", [np.zeros(3), np.zeros((4, 1))])
def test_joint_axis_is_checked(bad):
    with pytest.raises(InputError, match="last axis"):
        arm().friction_torque(bad, bad)


def test_state_derivatives_assemble_the_equations():
    m = arm(springs=[Dahl(sigma=1e4, fc=5.0), LinearSpring(2e3)], joint_damping=[2.0, 1.0])
    q, qd, qm, qdm = RNG.normal(size=(4, 2))
    z, u = np.array([1.2]), np.array([3.0, -1.0])
    tau_s, delta, delta_dot = m.spring_torque(q, qd, qm, qdm, z)
    dx = m.state_derivative(np.concatenate([q, qd, qm, qdm, z]), u)
    np.testing.assert_allclose(dx[:2], qd)
    np.testing.assert_allclose(dx[2:4], m.link_acceleration(q, qd, tau_s))
    np.testing.assert_allclose(dx[4:6], qdm)
    np.testing.assert_allclose(dx[6:8], m.motor_acceleration(qm, qdm, tau_s, u))
    np.testing.assert_allclose(dx[8:], m.spring_state_derivative(z, delta, delta_dot))
    dl = m.link_state_derivative(np.concatenate([q, qd, z]), qm, qdm)
    np.testing.assert_allclose(dl, np.concatenate([dx[:4], dx[8:]]))
