"""n rigid links on flexible joints, rigid-body terms from a URDF through Pinocchio (Lightcap and Banks (2007), eq. 1).

    M(q) q'' + C(q, q') q' + G(q) + F(q, q') = tau_s + tau_bal(q)      (links, Pinocchio)
    J q_m'' + B q_m' + (1 + e'(q_m)) tau_s = g u                         (motors, diagonal J, B)

M comes from ``pin.crba``, C q' + G from ``pin.nonLinearEffects`` (RNEA with zero acceleration),
G from ``pin.computeGeneralizedGravity``. Notes (shared/notes/api-notes.md, Pinocchio 4.1): URDF
``<dynamics damping friction>`` are parsed but ignored by the dynamics, so friction is modelled
here per joint; a URDF armature would be added to M by Pinocchio, so keep rotor inertia in J
only. Only 1-DoF joints (revolute, continuous, prismatic with nq = nv) are accepted.

The Pinocchio ``Data`` workspace makes an instance not thread-safe; build one model per thread.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from os import PathLike

import numpy as np
import pinocchio as pin

from ..errors import InputError
from .drivetrain import Drivetrain, JointCoupling
from .flexjoint import FlexibleJointModel
from .friction import CoulombViscous, Friction
from .springs import SpringElement

__all__ = ["NLinkModel"]


def _per_joint(name: str, value, n: int, *, nonneg: bool, positive: bool = False) -> np.ndarray:
    a = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy() if np.ndim(value) == 0 \
        else np.asarray(value, dtype=np.float64)
    if a.shape != (n,) or not np.isfinite(a).all() or (nonneg and (a < 0).any()) or (positive and (a <= 0).any()):
        want = "positive" if positive else "non-negative" if nonneg else "finite"
        raise InputError(None, name, f"{n} {want} numbers (or one for all joints)", value)
    a.setflags(write=False)
    return a


class NLinkModel(FlexibleJointModel):
    """Flexible-joint robot: Pinocchio rigid bodies plus per-joint motors, springs and friction.

    Build with :meth:`from_urdf`. Joint arrays are (..., n) in Pinocchio's joint order
    (``joint_names``); single configurations are (n,), batches (T, n) are evaluated one
    configuration at a time through Pinocchio.

    Parameters
    ----------
    model : pinocchio.Model
    motor_inertia : (n,) or float
        J, link-side rotor inertias, kg m^2 (> 0).
    springs : n SpringElement
    motor_damping : (n,) or float
        B, N m s / rad.
    frictions : n Friction or None
        Link friction per joint; None: none.
    drivetrains : n Drivetrain or None
    joint_damping : (n,) or float
        D in parallel with each spring, N m s / rad.
    coupling : JointCoupling or None
        Square (n, n) with zero diagonal.
    """

    def __init__(self, model: "pin.Model", motor_inertia, springs: Sequence[SpringElement], *,
                 motor_damping=0.0, frictions: Sequence[Friction] | None = None,
                 drivetrains: Sequence[Drivetrain] | None = None, joint_damping=0.0,
                 coupling: JointCoupling | None = None) -> None:
        if model.nq != model.nv or any(j.nq != 1 for j in model.joints[1:]):
            raise InputError(None, "urdf", "a chain of 1-DoF joints (nq == nv, no floating base)",
                             f"nq={model.nq}, nv={model.nv}")
        n = model.nv
        self.model = model
        self._data = model.createData()
        self.n_joints = n
        self.joint_names = tuple(str(s) for s in model.names[1:])
        self.motor_inertia = _per_joint("motor_inertia", motor_inertia, n, nonneg=True, positive=True)
        self.motor_damping = _per_joint("motor_damping", motor_damping, n, nonneg=True)
        self.joint_damping = _per_joint("joint_damping", joint_damping, n, nonneg=True)
        springs = tuple(springs)
        frictions = tuple(CoulombViscous(0.0, 0.0) for _ in range(n)) if frictions is None else tuple(frictions)
        drivetrains = tuple(Drivetrain() for _ in range(n)) if drivetrains is None else tuple(drivetrains)
        for name, seq, kind in (("springs", springs, SpringElement), ("frictions", frictions, Friction),
                                ("drivetrains", drivetrains, Drivetrain)):
            if len(seq) != n or not all(isinstance(x, kind) for x in seq):
                raise InputError(None, name, f"{n} {kind.__name__} objects, one per joint", f"{len(seq)} items")
        self.springs, self.frictions, self.drivetrains = springs, frictions, drivetrains
        if coupling is not None:
            coupling.check_square(n)
        self.coupling = coupling

    @classmethod
    def from_urdf(cls, urdf: str | PathLike[str], motor_inertia, springs: Sequence[SpringElement], *,
                  gravity=(0.0, 0.0, -9.81), **kwargs) -> "NLinkModel":
        """Build from a URDF file path or a URDF XML string (starts with '<').

        gravity : (3,) m/s^2 in the URDF world frame. Other keywords as in the constructor.
        """
        from ..io.urdf import build_pin_model

        model = build_pin_model(urdf)
        g = np.asarray(gravity, dtype=np.float64)
        if g.shape != (3,) or not np.isfinite(g).all():
            raise InputError(None, "gravity", "a (3,) vector in m/s^2", gravity)
        model.gravity.linear = g
        return cls(model, motor_inertia, springs, **kwargs)

    # ---- rigid-body terms --------------------------------------------------------------------------
    def _each(self, fn, *arrays):
        first = arrays[0]
        if first.ndim == 1:
            return fn(*arrays)
        lead = first.shape[:-1]
        flat = [a.reshape(-1, self.n_joints) for a in arrays]
        out = np.stack([fn(*row) for row in zip(*flat)])  # one Pinocchio call per configuration
        return out.reshape(lead + out.shape[1:])

    def mass_matrix(self, q) -> np.ndarray:
        """M(q), (..., n, n) kg m^2 (pin.crba; symmetric, positive definite)."""
        q = self._joints(q, "q")
        return self._each(lambda qi: pin.crba(self.model, self._data, qi).copy(), q)

    def nonlinear_effects(self, q, qd) -> np.ndarray:
        """C(q, q') q' + G(q), (..., n) N m (pin.nonLinearEffects)."""
        q, qd = self._joints(q, "q"), self._joints(qd, "qd")
        return self._each(lambda qi, vi: pin.nonLinearEffects(self.model, self._data, qi, vi).copy(), q, qd)

    def gravity(self, q) -> np.ndarray:
        """G(q), (..., n) N m: the torque that holds the rigid links still."""
        q = self._joints(q, "q")
        return self._each(lambda qi: pin.computeGeneralizedGravity(self.model, self._data, qi).copy(), q)

    def coriolis(self, q, qd) -> np.ndarray:
        """C(q, q') q', (..., n) N m."""
        return self.nonlinear_effects(q, qd) - self.gravity(q)

    def with_friction_smoothing(self, eps: float) -> "NLinkModel":
        """A copy whose frictions use tanh(q'/eps) instead of sign(q')."""
        return NLinkModel(self.model.copy(), self.motor_inertia, self.springs, motor_damping=self.motor_damping,
                          frictions=[f.with_smoothing(eps) for f in self.frictions], drivetrains=self.drivetrains,
                          joint_damping=self.joint_damping, coupling=self.coupling)

    def natural_frequencies(self, q, stiffness=None) -> np.ndarray:
        """Undamped natural frequencies (2n,) rad/s of the model linearised at rest at q (n,).

        Linear springs only (or pass `stiffness` (n,) N m/rad): the 2n x 2n problem
        [[K, -K], [-K, K + dG/dq]] v = w^2 diag(J, M) v with link-side gravity stiffness dG/dq by
        finite differences. Zero-frequency rigid modes appear as 0.
        """
        q = self._joints(q, "q")
        n = self.n_joints
        K = np.diag(stiffness if stiffness is not None else [getattr(s, "k", math.nan) for s in self.springs])
        if not np.isfinite(K).all():
            raise InputError(None, "stiffness", "linear springs or an explicit (n,) stiffness")
        h = 1e-6
        dG = np.stack([(self.gravity(q + h * e) - self.gravity(q - h * e)) / (2 * h) for e in np.eye(n)], axis=1)
        stiff = np.block([[K, -K], [-K, K + dG]])
        mass = np.block([[np.diag(self.motor_inertia), np.zeros((n, n))], [np.zeros((n, n)), self.mass_matrix(q)]])
        w2 = np.linalg.eigvals(np.linalg.solve(mass, stiff)).real
        return np.sqrt(np.sort(np.clip(w2, 0.0, None)))
