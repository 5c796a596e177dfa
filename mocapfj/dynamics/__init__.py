"""Flexible-joint dynamics: friction, springs and hysteresis, drivetrain effects, models, simulation.

The model is Lightcap and Banks (2007), eq. (1) and, for one joint, eq. (4), in the signs of docs/conventions.md:

    M(q) q'' + C(q, q') q' + G(q) + F(q, q') = tau_s        (links)
    J q_m'' + B q_m' + tau_s = u                              (motors, link side)
    tau_s = f(delta, history),  delta = q_m - q               (springs, Lightcap and Banks (2007), eq. 7)

- :mod:`.friction`: F(q, q') models sharing ``torque(qd, q=None)``, ``smoothing``, ``params``.
- :mod:`.springs`, :mod:`.hysteresis`: f(delta, z) elements sharing one state protocol
  (``n_states``, ``initial_state``, ``state_derivative``, ``torque``, ``run``).
- :mod:`.drivetrain`: transmission error, gravity balancer, joint coupling, drive gain, clock shift.
- :mod:`.single_joint`, :mod:`.nlink`: the models (shared equations in :mod:`.flexjoint`).
- :mod:`.simulate`: ``simulate(model, t, drive)`` and ``controller_log(result, ...)``.

Example
-------
>>> import numpy as np
>>> from mocapfj.dynamics import SingleJoint, LinearSpring, PrescribedMotor, simulate
>>> m = SingleJoint(I=1.0, J=0.5, spring=LinearSpring(k=1e4), mgly=20.0, b=1.0, d=5.0)
>>> r = simulate(m, np.linspace(0, 0.2, 201), PrescribedMotor(lambda t: (0.0 * t, 0.0 * t, 0.0 * t)))
>>> bool(abs(r.tau_s[-1, 0] - m.gravity(r.q[-1, 0])) < 1e-6)
True
"""

from importlib import import_module

from .drivetrain import Drivetrain, GravityBalancer, JointCoupling, PositionTorque, TransmissionError, shift_signal
from .flexjoint import FlexibleJointModel
from .friction import (AsymmetricCoulombViscous, AsymmetricStribeck, CoulombViscous, ExtendedStribeck, Friction,
                       PositionDependent, Stribeck)
from .hysteresis import BoucWen, Dahl, MaxwellSlip, integrate_states
from .joint_model import JointModel
from .simulate import PID, PrescribedMotor, SimulationResult, TorqueInput, controller_log, resample, simulate
from .single_joint import SingleJoint
from .spec import FRICTION_MODELS, SPRING_MODELS, element_from_table, element_to_table
from .springs import Backlash, CubicSpring, LinearSpring, PiecewiseSpring, SpringElement

__all__ = [
    # friction
    "Friction", "CoulombViscous", "AsymmetricCoulombViscous", "Stribeck", "AsymmetricStribeck",
    "ExtendedStribeck", "PositionDependent",
    # springs and hysteresis
    "SpringElement", "LinearSpring", "CubicSpring", "PiecewiseSpring", "Backlash",
    "BoucWen", "Dahl", "MaxwellSlip", "integrate_states",
    # drivetrain
    "TransmissionError", "GravityBalancer", "PositionTorque", "JointCoupling", "Drivetrain", "shift_signal",
    # models
    "FlexibleJointModel", "SingleJoint", "NLinkModel", "JointModel",
    # simulation
    "PrescribedMotor", "PID", "TorqueInput", "SimulationResult", "simulate", "resample", "controller_log",
    # model tables
    "FRICTION_MODELS", "SPRING_MODELS", "element_from_table", "element_to_table",
]


def __getattr__(name: str):
    # the n-link model needs Pinocchio, which takes seconds to import: load it on first use
    if name == "NLinkModel":
        return import_module(".nlink", __name__).NLinkModel
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
