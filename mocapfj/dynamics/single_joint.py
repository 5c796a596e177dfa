"""One rigid link on one flexible joint: Lightcap and Banks (2007), eq. (4), with any friction, spring and drivetrain.

    I q'' - mglx sin(q) + mgly cos(q) + F(q, q') = tau_s + tau_bal(q)      (link)
    J q_m'' + b q_m' + (1 + e'(q_m)) tau_s = g u                            (motor)
    tau_s = f(delta, z) + d delta',    delta = q_m + e(q_m) - q               (spring)

Lightcap and Banks (2007), eq. (4) is the case F = c sign(q') + v q', f = k delta, d = 0, e = 0, tau_bal = 0,
g = 1. The equations themselves live in :class:`.flexjoint.FlexibleJointModel`; joint arrays
keep a joint axis of length 1 last, e.g. q (T, 1), like ``ControllerLog.q_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ..errors import InputError
from ..validate import check_scalar
from .drivetrain import Drivetrain
from .flexjoint import FlexibleJointModel
from .friction import CoulombViscous, Friction
from .springs import SpringElement

__all__ = ["SingleJoint"]


@dataclass(frozen=True, eq=False)
class SingleJoint(FlexibleJointModel):
    """Parameters of the single-joint flexible model (Lightcap and Banks (2007), eq. 4, Table I for magnitudes).

    Attributes
    ----------
    I : float
        Link inertia about the joint axis, kg m^2 (> 0).
    J : float
        Motor (rotor) inertia on the link side, J_rotor N^2, kg m^2 (> 0).
    spring : SpringElement
        tau_s = f(delta, z): any spring of :mod:`.springs` or :mod:`.hysteresis`.
    mglx, mgly : float
        Gravity moments, N m: gravity torque G(q) = -mglx sin q + mgly cos q.
    b : float
        Motor viscous friction, N m s / rad.
    friction : Friction
        Link friction F(q, q'); default none.
    d : float
        Joint damping in parallel with the spring, N m s / rad (not in Lightcap and Banks (2007); default 0).
    drivetrain : Drivetrain
        Transmission error, balancer, drive gain; default ideal.
    name : str
        Joint name used in logs.
    """

    I: float
    J: float
    spring: SpringElement
    mglx: float = 0.0
    mgly: float = 0.0
    b: float = 0.0
    friction: Friction = field(default_factory=lambda: CoulombViscous(0.0, 0.0))
    d: float = 0.0
    drivetrain: Drivetrain = field(default_factory=Drivetrain)
    name: str = "j1"

    n_joints = 1

    def __post_init__(self) -> None:
        for n in ("I", "J"):
            object.__setattr__(self, n, check_scalar(getattr(self, n), n, positive=True))
        for n in ("b", "d"):
            object.__setattr__(self, n, check_scalar(getattr(self, n), n, nonneg=True))
        for n in ("mglx", "mgly"):
            object.__setattr__(self, n, check_scalar(getattr(self, n), n))
        if not isinstance(self.spring, SpringElement):
            raise InputError(None, "spring", "a spring element (mocapfj.dynamics.springs)", type(self.spring).__name__)
        if not isinstance(self.friction, Friction):
            raise InputError(None, "friction", "a friction model (mocapfj.dynamics.friction)", type(self.friction).__name__)
        if not isinstance(self.drivetrain, Drivetrain):
            raise InputError(None, "drivetrain", "a Drivetrain", type(self.drivetrain).__name__)

    # attributes of FlexibleJointModel
    @property
    def joint_names(self) -> tuple[str, ...]:
        return (self.name,)

    @property
    def frictions(self) -> tuple[Friction, ...]:
        return (self.friction,)

    @property
    def springs(self) -> tuple[SpringElement, ...]:
        return (self.spring,)

    @property
    def drivetrains(self) -> tuple[Drivetrain, ...]:
        return (self.drivetrain,)

    @cached_property
    def motor_inertia(self) -> np.ndarray:
        return np.array([self.J])

    @cached_property
    def motor_damping(self) -> np.ndarray:
        return np.array([self.b])

    @cached_property
    def joint_damping(self) -> np.ndarray:
        return np.array([self.d])

    @property
    def coupling(self):
        return None

    # rigid-link terms
    def gravity(self, q) -> np.ndarray:
        """G(q) = -mglx sin q + mgly cos q, N m, same shape as `q` (rad; any shape)."""
        q = np.asarray(q, dtype=np.float64)
        return -self.mglx * np.sin(q) + self.mgly * np.cos(q)

    def mass_matrix(self, q) -> np.ndarray:
        """M = [[I]], (..., 1, 1) kg m^2 for q (..., 1)."""
        q = self._joints(q, "q")
        return np.full(q.shape + (1,), self.I)

    def nonlinear_effects(self, q, qd) -> np.ndarray:
        """C q' + G(q) = G(q) for one joint, (..., 1) N m."""
        return self.gravity(q)

    def natural_frequency(self) -> float:
        """sqrt(k (1/I + 1/J)) in rad/s for a linear spring k: the locked-free mode of eq. (4)
        without gravity, friction or damping (the motor and link swing against each other)."""
        k = getattr(self.spring, "k", None)
        if k is None:
            raise InputError(None, "spring", "a LinearSpring (stiffness k)", type(self.spring).__name__)
        return math.sqrt(k * (1.0 / self.I + 1.0 / self.J))

    def with_friction_smoothing(self, eps: float) -> "SingleJoint":
        """A copy whose friction uses tanh(q'/eps) instead of sign(q') (for stiff integration)."""
        return replace(self, friction=self.friction.with_smoothing(eps))

