"""Identification: signal conditioning, least squares with statistics, the two-step method, spring models, excitation, FRF.

- :mod:`.ls`: least squares with seed 003 eq. 15-17 statistics; CV % across trials.
- :mod:`.conditioning`: zero-phase filtering, central differences, parallel decimation.
- :mod:`.idim`: the IDIM-LS procedure of the EMPS benchmark (published table reproduced).
- :mod:`.regressor`: n-link joint torque regressor (Pinocchio) and base parameters.
- :mod:`.twostep`: seed 000 two-step method and the one-step baseline.
- :mod:`.motorfirst`: motor equation first, then the link equation (for noisy mocap link angles).
- :mod:`.springs`: spring and hysteresis models fitted to (deflection, spring torque), selection.
- :mod:`.friction`: friction from constant-velocity sweeps (seed 001 eq. 7, seed 002 eq. 18) and pre-sliding.
- :mod:`.excitation`: Fourier motor references (seed 000 eq. 9) minimising the regressor's condition number (eq. 8).

See docs/architecture.md for what this package owns and may import.
"""

from .conditioning import decimate_parallel, derivatives, lowpass, resample_to
from .excitation import (ExcitationDesign, design_excitation, reference_condition, reference_motion,
                         simulated_condition, write_reference)
from .friction import (FrictionFit, PreslidingFit, SweepPoints, fit_extended_stribeck, fit_presliding,
                       fit_stribeck, sweep_points)
from .idim import IDIM_MODELS, idim_cross_validation, idim_ls, idim_observation, idim_regressor, load_emps_mat
from .ls import cv_pct, ls_fit, unidentifiable_columns
from .motorfirst import MotorFirstResult, identify_joint_motor_first
from .regressor import base_from_standard, base_parameters, load_pin_model, nlink_regressor, standard_parameters
from .springs import (SpringFit, SpringSelection, bouc_wen_states, fit_backlash, fit_bouc_wen, fit_cubic, fit_linear,
                      fit_piecewise, select_spring_model)
from .twostep import TwoStepResult, controller_on, identify_joint, one_step_regressor, step1_regressor

__all__ = [
    "ls_fit", "cv_pct", "unidentifiable_columns",
    "lowpass", "derivatives", "decimate_parallel", "resample_to",
    "idim_ls", "idim_observation", "idim_cross_validation", "idim_regressor", "load_emps_mat", "IDIM_MODELS",
    "nlink_regressor", "standard_parameters", "base_parameters", "base_from_standard", "load_pin_model",
    "identify_joint", "TwoStepResult", "identify_joint_motor_first", "MotorFirstResult", "controller_on", "step1_regressor", "one_step_regressor",
    "select_spring_model", "SpringFit", "SpringSelection", "fit_linear", "fit_cubic", "fit_piecewise",
    "fit_backlash", "fit_bouc_wen", "bouc_wen_states",
    "ExcitationDesign", "design_excitation", "reference_condition", "reference_motion", "simulated_condition",
    "write_reference",
    "sweep_points", "SweepPoints", "fit_stribeck", "fit_extended_stribeck", "fit_presliding", "FrictionFit",
    "PreslidingFit",
]
