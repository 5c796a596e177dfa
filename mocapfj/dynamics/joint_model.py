"""One joint's flexible-joint model as identification reports it and discovery augments it: the
parameters of Lightcap and Banks (2007) eq. (4) (docs/conventions.md) with its friction and spring
elements and the drivetrain and measurement terms discovery may add. ``single_joint()`` gives the
:class:`.single_joint.SingleJoint` that :func:`.simulate.simulate` integrates.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .drivetrain import Drivetrain, PositionTorque, TransmissionError
from .friction import CoulombViscous
from .single_joint import SingleJoint
from .spec import element_to_table
from .springs import LinearSpring

__all__ = ["JointModel"]


@dataclass(frozen=True)
class JointModel:
    """One joint: Lightcap and Banks (2007) eq. (4) with its elements (SI, link side, docs/conventions.md).

    name, gear_ratio; I, J (kg m^2), mglx, mgly (N m), b (N m s/rad); friction (a
    :mod:`.friction` model), spring (a :mod:`.springs` or :mod:`.hysteresis` element);
    transmission_error, position_torque (a balancer or gravity-model correction), torque_gain
    (actual / logged torque), delay_s (the mocap samples are this late on the controller clock),
    coupling {source joint: inertia kg m^2}; robot: the URDF robot the joint belongs to
    (:class:`mocapfj.discover.context.Robot`) or None: the link's inertia, gravity and the other
    links' torques then come from the robot, I, mglx and mgly being added to them.
    """

    name: str
    gear_ratio: float
    I: float
    J: float
    mglx: float
    mgly: float
    b: float
    friction: object = field(default_factory=lambda: CoulombViscous(0.0, 0.0))
    spring: object = field(default_factory=lambda: LinearSpring(1.0))
    transmission_error: TransmissionError | None = None
    position_torque: PositionTorque | None = None
    torque_gain: float = 1.0
    delay_s: float = 0.0
    coupling: dict = field(default_factory=dict)
    robot: object = None

    def single_joint(self, smoothing: float = 1e-3) -> SingleJoint:
        """The dynamics model. A friction law with its own smoothing (a tanh law, eps > 0) keeps it;
        an exact sign law is smoothed with tanh(q'/smoothing) for the integrator."""
        own = float(getattr(self.friction, "smoothing", 0.0) or 0.0)
        dt = Drivetrain(transmission_error=self.transmission_error, balancer=self.position_torque,
                        torque_gain=self.torque_gain)
        return SingleJoint(I=self.I, J=self.J, spring=self.spring, mglx=self.mglx, mgly=self.mgly, b=self.b,
                           friction=self.friction.with_smoothing(own if own > 0 else smoothing), drivetrain=dt, name=self.name)

    def stiffness(self, lo: float = -0.01, hi: float = 0.01) -> float:
        """The spring's mean slope over deflections lo..hi (default +-10 mrad), N m / rad (its
        linear equivalent there)."""
        d = np.linspace(lo, hi, 201)
        tau = np.asarray(self.spring.run(d, np.arange(d.size) * 1e-3)
                         if hasattr(self.spring, "run") and getattr(self.spring, "n_states", 0) else self.spring.torque(d))
        return float(np.polyfit(d, tau, 1)[0])

    def to_table(self) -> dict:
        out = {"name": self.name, "gear_ratio": self.gear_ratio, "I": self.I, "J": self.J, "mglx": self.mglx,
               "mgly": self.mgly, "b": self.b, "friction": element_to_table(self.friction),
               "spring": element_to_table(self.spring)}
        if self.transmission_error is not None:
            te = self.transmission_error
            out["transmission_error"] = {"amplitudes_rad": list(te.amplitudes), "phases_rad": list(te.phases),
                                         "orders": list(te.orders)}
        if self.position_torque is not None:
            out["position_torque"] = self.position_torque.params
        if self.torque_gain != 1.0:
            out["torque_gain"] = self.torque_gain
        if self.delay_s != 0.0:
            out["delay_s"] = self.delay_s
        if self.coupling:
            out["coupling"] = dict(self.coupling)
        if self.robot is not None:
            out["urdf_joint"] = self.robot.urdf_joints[self.robot.joints.index(self.name)]
        return out

    def with_(self, **changes) -> "JointModel":
        return replace(self, **changes)
