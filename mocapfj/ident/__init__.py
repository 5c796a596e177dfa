"""Identification: signal conditioning, least squares with statistics, flexible-joint estimators,
spring models, friction, excitation design, n-link and rigid robots.

- :mod:`.joint`: :func:`identify_joint`, one joint from its signals (the method chosen, its
  spring selected): an :class:`IdentifiedJoint` (:mod:`.result`).
- :mod:`.ls`: least squares with the statistics of Jubien, Abba and Gautier (2014), eq. 15-17.
- :mod:`.conditioning`: zero-phase filtering, central differences, parallel decimation, a joint's
  signals on one clock.
- :mod:`.idim`: the IDIM-LS procedure of the EMPS benchmark (Janot, Gautier and Brunot 2019).
- :mod:`.twostep`: the two-step method of Lightcap and Banks (2007) and the one-step baseline.
- :mod:`.motorfirst`: the motor equation first, then the link equation.
- :mod:`.springs`: spring and hysteresis models fitted to (deflection, spring torque), selection.
- :mod:`.friction`: friction from constant-velocity sweeps.
- :mod:`.excitation`: Fourier motor references minimising the regressor's condition number.
- :mod:`.regressor`, :mod:`.nlink`, :mod:`.rigid`: n-link robots through Pinocchio (imported on
  first use: Pinocchio takes seconds to load).
- :mod:`.algebraic`, :mod:`.decrement`, :mod:`.precompensation`: omega0 and zeta from a fraction of
  a period, the logarithmic decrement, model-based pre-compensation (Oueslati et al. 2012); :mod:`.clamped`:
  stiffness with the end-effector clamped (Jubien, Abba and Gautier 2014). Imported on first use.
- :mod:`.multisine`, :mod:`.frf`, :mod:`.frf_fit`: multisine excitation, the FRF from periodic data
  and the two-inertia joint fitted to it (Makarov et al. 2012); :mod:`.frf_single`: the FRF of a
  single record (local polynomial method, Welch's H1) and a rational model with its modes.
  Imported on first use.

See docs/architecture.md for what this package owns and may import.
"""

from importlib import import_module

from .conditioning import (check_signals, controller_on, decimate_parallel, derivatives, joint_signals, lowpass,
                           resample_to)
from .excitation import (ExcitationDesign, design_excitation, reference_condition, reference_motion,
                         simulated_condition, write_reference)
from .friction import (FrictionFit, PreslidingFit, SweepPoints, fit_extended_stribeck, fit_presliding,
                       fit_stribeck, sweep_points)
from .idim import IDIM_MODELS, idim_cross_validation, idim_ls, idim_observation, idim_regressor, load_emps_mat
from .joint import IDENTIFY_METHODS, identify_joint, identify_signals, spring_pairs
from .ls import cv_pct, ls_fit, unidentifiable_columns
from .motorfirst import MotorFirstResult, identify_motor_first
from .result import (PARAMETER_NAMES, Identification, IdentifiedJoint, JointSummary, Parameter, RigidIdentification,
                     SpringResult)
from .springs import (SpringFit, SpringSelection, bouc_wen_states, fit_backlash, fit_bouc_wen, fit_cubic, fit_linear,
                      fit_piecewise, select_spring_model)
from .twostep import TwoStepResult, identify_two_step, one_step_regressor, step1_regressor

_LAZY = {"base_from_standard": "regressor", "base_parameters": "regressor", "load_pin_model": "regressor",
         "nlink_regressor": "regressor", "standard_parameters": "regressor",
         "NLinkResult": "nlink", "identify_nlink_motor_first": "nlink", "identify_nlink_joints": "nlink",
         "identify_rigid": "rigid", "identify_rigid_log": "rigid", "RIGID_FRICTION_MODELS": "rigid",
         "algebraic_estimate": "algebraic", "algebraic_sliding": "algebraic", "log_decrement": "decrement",
         "SecondOrderEstimate": "algebraic", "precompensate": "precompensation", "identify_clamped": "clamped",
         "fit_clamped": "clamped", "mdh_model": "clamped", "ClampedStiffness": "clamped",
         "Multisine": "multisine", "design_multisine": "multisine", "multisine_realisations": "multisine",
         "write_multisine_reference": "multisine", "FRF": "frf", "estimate_frf": "frf", "FRFFit": "frf_fit",
         "fit_two_inertia": "frf_fit", "two_inertia_frf": "frf_fit", "two_inertia_modes": "frf_fit",
         "estimate_frf_lpm": "frf_single", "estimate_frf_welch": "frf_single", "SingleRecordFRF": "frf_single",
         "fit_rational": "frf_single", "rational_frf": "frf_single", "RationalFit": "frf_single"}

__all__ = [
    "identify_joint", "identify_signals", "IDENTIFY_METHODS", "spring_pairs",
    "IdentifiedJoint", "Identification", "JointSummary", "Parameter", "SpringResult", "RigidIdentification",
    "PARAMETER_NAMES",
    "ls_fit", "cv_pct", "unidentifiable_columns",
    "lowpass", "derivatives", "decimate_parallel", "resample_to", "controller_on", "check_signals", "joint_signals",
    "idim_ls", "idim_observation", "idim_cross_validation", "idim_regressor", "load_emps_mat", "IDIM_MODELS",
    "identify_two_step", "TwoStepResult", "step1_regressor", "one_step_regressor",
    "identify_motor_first", "MotorFirstResult",
    "select_spring_model", "SpringFit", "SpringSelection", "fit_linear", "fit_cubic", "fit_piecewise",
    "fit_backlash", "fit_bouc_wen", "bouc_wen_states",
    "ExcitationDesign", "design_excitation", "reference_condition", "reference_motion", "simulated_condition",
    "write_reference",
    "sweep_points", "SweepPoints", "fit_stribeck", "fit_extended_stribeck", "fit_presliding", "FrictionFit",
    "PreslidingFit",
    *_LAZY,
]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
