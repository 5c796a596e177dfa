"""The flexible-joint equations shared by the single-joint and the n-link models (Lightcap and Banks (2007), eq. 1).

    M(q) q'' + C(q, q') q' + G(q) + F(q, q') = tau_s + tau_bal(q) + tau_ext        (link)
    J q_m'' + B q_m' + (1 + e'(q_m)) tau_s = g u                                   (motor)
    tau_s = f(delta, z) + D delta' [+ coupling],   delta = q_m + e(q_m) - q        (spring)

with per-joint friction F, spring elements f (stateful or not, :mod:`.springs`), joint damping
D, and the drivetrain effects of :mod:`.drivetrain`: transmission error e, balancer torque
tau_bal, drive gain g (the motor makes g u when u is commanded). Without those effects this is
exactly Lightcap and Banks (2007), eq. (1), and for one joint eq. (4). Joint arrays have the joint axis last:
q (..., n); leading axes (e.g. time) broadcast. Spring states of all joints are stacked in one
vector z (..., n_z), joint j owning ``z[..., spring_slices[j]]``.

Subclasses provide ``mass_matrix(q)``, ``nonlinear_effects(q, qd)`` (C q' + G), ``gravity(q)``
and the per-joint attributes listed in :class:`FlexibleJointModel`.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from scipy.optimize import brentq, root

from ..errors import InputError

__all__ = ["FlexibleJointModel"]


class FlexibleJointModel:
    """Mixin with the motor, spring and drivetrain side of the flexible-joint model.

    Subclass attributes: ``n_joints``, ``joint_names``, ``frictions``, ``springs``,
    ``drivetrains`` (tuples of length n), ``motor_inertia`` J, ``motor_damping`` B,
    ``joint_damping`` D ((n,) arrays, kg m^2, N m s/rad, N m s/rad) and ``coupling``
    (a JointCoupling or None).
    """

    # ---- layout -------------------------------------------------------------------------------
    @cached_property
    def spring_slices(self) -> tuple[slice, ...]:
        """Per joint, the slice of the stacked spring-state vector it owns."""
        out, i = [], 0
        for s in self.springs:
            out.append(slice(i, i + s.n_states))
            i += s.n_states
        return tuple(out)

    @property
    def n_spring_states(self) -> int:
        return sum(s.n_states for s in self.springs)

    def initial_spring_state(self) -> np.ndarray:
        """(n_z,) virgin states of all springs."""
        parts = [np.asarray(s.initial_state(), dtype=np.float64) for s in self.springs]
        return np.concatenate(parts) if parts else np.zeros(0)

    def _joints(self, x, name: str) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.shape[-1:] != (self.n_joints,):
            raise InputError(None, name, f"an array with last axis n_joints = {self.n_joints}", f"shape {x.shape}")
        return x

    @cached_property
    def _gains(self) -> np.ndarray:
        return np.array([d.torque_gain for d in self.drivetrains])

    @cached_property
    def _plain(self) -> tuple[bool, bool]:
        """(no transmission error anywhere, no balancer anywhere): fast paths for the ODE."""
        return (all(d.transmission_error is None for d in self.drivetrains),
                all(d.balancer is None for d in self.drivetrains))

    # ---- drivetrain ---------------------------------------------------------------------------
    def transmission(self, q_m) -> tuple[np.ndarray, np.ndarray]:
        """Flexspline angle q_m + e(q_m) and ratio 1 + e'(q_m), both (..., n), from q_m (..., n) rad."""
        q_m = self._joints(q_m, "q_m")
        if self._plain[0]:
            return q_m, np.ones_like(q_m)
        q_out, ratio = q_m.copy(), np.ones_like(q_m)
        for j, d in enumerate(self.drivetrains):
            if d.transmission_error is not None:
                q_out[..., j] += d.transmission_error.error(q_m[..., j])
                ratio[..., j] += d.transmission_error.derivative(q_m[..., j])
        return q_out, ratio

    def balancer_torque(self, q) -> np.ndarray:
        """Gravity-balancer torques on the links, (..., n) N m."""
        q = self._joints(q, "q")
        out = np.zeros_like(q)
        if self._plain[1]:
            return out
        for j, d in enumerate(self.drivetrains):
            if d.balancer is not None:
                out[..., j] = d.balancer.torque(q[..., j])
        return out

    def friction_torque(self, q, qd) -> np.ndarray:
        """Link friction F(q, q'), (..., n) N m."""
        q, qd = self._joints(q, "q"), self._joints(qd, "qd")
        if self.n_joints == 1:
            return self.frictions[0].torque(qd[..., 0], q[..., 0])[..., None]
        return np.stack([f.torque(qd[..., j], q[..., j]) for j, f in enumerate(self.frictions)], axis=-1)

    # ---- spring ---------------------------------------------------------------------------------
    def spring_torque(self, q, qd, q_m, qd_m, z) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """tau_s, delta, delta' (each (..., n)) from link and motor states and spring states z (..., n_z)."""
        q, qd, qd_m = self._joints(q, "q"), self._joints(qd, "qd"), self._joints(qd_m, "qd_m")
        z = np.asarray(z, dtype=np.float64)
        q_out, ratio = self.transmission(q_m)
        delta = q_out - q
        delta_dot = ratio * qd_m - qd
        parts = [s.torque(delta[..., j], z[..., sl]) for j, (s, sl) in enumerate(zip(self.springs, self.spring_slices))]
        tau = (parts[0][..., None] if self.n_joints == 1 else np.stack(parts, axis=-1)) + self.joint_damping * delta_dot
        if self.coupling is not None and self.coupling.kind == "deflection":
            tau = tau + self.coupling.torque(delta)
        return tau, delta, delta_dot

    def spring_state_derivative(self, z, delta, delta_dot) -> np.ndarray:
        """dz/dt (..., n_z) of all spring states."""
        z = np.asarray(z, dtype=np.float64)
        parts = [s.state_derivative(z[..., sl], delta[..., j], delta_dot[..., j])
                 for j, (s, sl) in enumerate(zip(self.springs, self.spring_slices)) if s.n_states]
        return np.concatenate(parts, axis=-1) if parts else np.zeros(z.shape)

    # ---- the two equations ---------------------------------------------------------------------
    def _effective_mass(self, q) -> np.ndarray:
        M = self.mass_matrix(q)
        if self.coupling is not None and self.coupling.kind == "acceleration":
            M = M - self.coupling.matrix
        return M

    def link_acceleration(self, q, qd, tau_s, tau_ext=None) -> np.ndarray:
        """q'' (..., n) rad/s^2 from the link equation, given tau_s (and tau_ext) (..., n) N m."""
        q, qd = self._joints(q, "q"), self._joints(qd, "qd")
        rhs = tau_s + self.balancer_torque(q) - self.nonlinear_effects(q, qd) - self.friction_torque(q, qd)
        if tau_ext is not None:
            rhs = rhs + tau_ext
        M = self._effective_mass(q)
        if self.n_joints == 1:
            return rhs / M[..., 0]
        return np.linalg.solve(M, rhs[..., None])[..., 0]

    def link_torque(self, q, qd, qdd, tau_ext=None) -> np.ndarray:
        """Spring torque tau_s (..., n) N m that makes the link move as given (Lightcap and Banks (2007), eq. 7)."""
        q, qd, qdd = self._joints(q, "q"), self._joints(qd, "qd"), self._joints(qdd, "qdd")
        Mqdd = (self._effective_mass(q) @ qdd[..., None])[..., 0]
        tau = Mqdd + self.nonlinear_effects(q, qd) + self.friction_torque(q, qd) - self.balancer_torque(q)
        return tau if tau_ext is None else tau - tau_ext

    def motor_acceleration(self, q_m, qd_m, tau_s, u) -> np.ndarray:
        """q_m'' (..., n) rad/s^2 from the motor equation with commanded torque u (..., n) N m."""
        ratio = 1.0 if self._plain[0] else self.transmission(q_m)[1]
        return (self._gains * u - self.motor_damping * qd_m - ratio * tau_s) / self.motor_inertia

    def motor_torque(self, q_m, qd_m, qdd_m, tau_s) -> np.ndarray:
        """Commanded torque u (..., n) N m that moves the motor as given (inverse motor equation)."""
        ratio = 1.0 if self._plain[0] else self.transmission(q_m)[1]
        return (self.motor_inertia * qdd_m + self.motor_damping * qd_m + ratio * tau_s) / self._gains

    # ---- right-hand sides of the state equations ----------------------------------------------
    def state_derivative(self, x, u, tau_ext=None) -> np.ndarray:
        """dx/dt for x = [q, q', q_m, q_m', z] (4n + n_z,) with commanded motor torques u (n,) N m.

        The full model: links, motors and spring states (what a motor-side simulation integrates).
        """
        n, x = self.n_joints, np.asarray(x, dtype=np.float64)
        q, qd, qm, qdm, z = x[:n], x[n:2 * n], x[2 * n:3 * n], x[3 * n:4 * n], x[4 * n:]
        tau_s, delta, delta_dot = self.spring_torque(q, qd, qm, qdm, z)
        return np.concatenate([qd, self.link_acceleration(q, qd, tau_s, tau_ext), qdm,
                               self.motor_acceleration(qm, qdm, tau_s, u),
                               self.spring_state_derivative(z, delta, delta_dot)])

    def link_state_derivative(self, x, q_m, qd_m, tau_ext=None) -> np.ndarray:
        """dx/dt for x = [q, q', z] (2n + n_z,) with the motors moving as given, q_m, q_m' (n,).

        The motor equation then only yields u (``motor_torque``); Lightcap and Banks (2007), eq. (10) is this
        right-hand side for the single joint of eq. (4).
        """
        n, x = self.n_joints, np.asarray(x, dtype=np.float64)
        q, qd, z = x[:n], x[n:2 * n], x[2 * n:]
        tau_s, delta, delta_dot = self.spring_torque(q, qd, q_m, qd_m, z)
        return np.concatenate([qd, self.link_acceleration(q, qd, tau_s, tau_ext),
                               self.spring_state_derivative(z, delta, delta_dot)])

    # ---- statics --------------------------------------------------------------------------------
    def holding_torque(self, q) -> np.ndarray:
        """Spring torque that holds the links still at q: G(q) - tau_bal(q), (..., n) N m."""
        q = self._joints(q, "q")
        return self.gravity(q) - self.balancer_torque(q)

    def static_link_angle(self, q_m, z=None, q_guess=None) -> np.ndarray:
        """Link angles (n,) rad at rest with the motors held at q_m (n,): tau_s = G(q) - tau_bal(q).

        Springs are evaluated at state `z` (default: virgin). Solved with scipy.optimize.root.
        """
        q_m = self._joints(q_m, "q_m")
        z = self.initial_spring_state() if z is None else np.asarray(z, dtype=np.float64)
        zero = np.zeros(self.n_joints)

        def residual(q):
            return self.spring_torque(q, zero, q_m, zero, z)[0] - self.holding_torque(q)

        sol = root(residual, q_m.copy() if q_guess is None else np.asarray(q_guess, dtype=np.float64),
                   method="hybr", options={"xtol": 1e-15})
        scale = 1.0 + np.max(np.abs(self.holding_torque(sol.x)))
        if np.max(np.abs(residual(sol.x))) <= 1e-9 * scale:
            return sol.x
        # a spring with a flat stretch (free play) stalls hybr at q = q_m: bracket each joint's root
        # instead (its spring torque falls as q_j rises past q_m,j; gravity changes slower), the
        # others held, joint after joint until the torques balance (the joints couple through
        # gravity, |dG/dq| / k of the springs per sweep: a two-joint arm with free play on its
        # elbow, hinge grid's two-joint seed 39000, stalled hybr and failed its recording)
        q = q_m.copy()
        for _ in range(100):
            for j in range(self.n_joints):
                def f(x, j=j):
                    qq = q.copy()
                    qq[j] = x
                    return float(residual(qq)[j])
                h = 1e-4
                while f(q_m[j] - h) * f(q_m[j] + h) > 0:
                    h *= 2.0
                    if h > 1.0:
                        raise RuntimeError(f"no static equilibrium found within 1 rad of q_m: {sol.message}")
                q[j] = brentq(f, q_m[j] - h, q_m[j] + h, xtol=1e-15, rtol=1e-14)
            scale = 1.0 + np.max(np.abs(self.holding_torque(q)))
            if np.max(np.abs(residual(q))) <= 1e-9 * scale:
                return q
        raise RuntimeError(f"no static equilibrium found: {sol.message}")

    def static_motor_angle(self, q, z=None) -> np.ndarray:
        """Motor angles q_m (n,) rad (link side) that hold the links at rest at q (n,) rad.

        Inverts each spring (assumed increasing in delta) by bracketing and brentq, then the
        transmission error by fixed-point iteration. Joint damping plays no part at rest;
        deflection coupling is included by a joint root solve.
        """
        q = self._joints(q, "q")
        z = self.initial_spring_state() if z is None else np.asarray(z, dtype=np.float64)
        target = self.holding_torque(q)
        delta = np.empty(self.n_joints)
        for j, (s, sl) in enumerate(zip(self.springs, self.spring_slices)):
            def f(d, s=s, sl=sl, j=j):
                return float(s.torque(np.float64(d), z[sl])) - target[j]
            h = 1e-3
            while f(-h) > 0 or f(h) < 0:
                h *= 2.0
                if h > 1e3:
                    raise RuntimeError(f"joint {self.joint_names[j]}: spring cannot hold {target[j]:.6g} N m")
            delta[j] = brentq(f, -h, h, xtol=1e-15, rtol=1e-14)
        if self.coupling is not None and self.coupling.kind == "deflection":
            def residual(d):
                parts = [s.torque(d[j], z[sl]) for j, (s, sl) in enumerate(zip(self.springs, self.spring_slices))]
                return np.asarray(parts, dtype=np.float64) + self.coupling.torque(d) - target
            delta = root(residual, delta, method="hybr", options={"xtol": 1e-15}).x
        q_m = q + delta
        for _ in range(100):
            q_out, _ = self.transmission(q_m)
            step = (q + delta) - q_out
            q_m = q_m + step
            if np.max(np.abs(step)) < 1e-15:
                break
        return q_m
