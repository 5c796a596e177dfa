"""Joint axes and centres from marker clusters, per-frame link angles, stream synchronisation and deflection.

- :mod:`.axis`: hinge fits (Gamage-Lasenby, Halvorsen bias-compensated, maximum likelihood).
- :mod:`.crlb`: Cramér-Rao bounds for the axis, the centre and the angle.
- :mod:`.angles`: closed-form per-frame angle of one joint (Lightcap and Banks (2007), eq. 13) with outlier rejection.
- :mod:`.segments`: rigid clusters (Kabsch, templates), SCoRE and SARA for two moving segments.
- :mod:`.chain`: batched Gauss-Newton for the joints of a chain (Pinocchio model).
- :mod:`.sync`: common time base and deflection delta = q_m - q.
- :mod:`.calibrate`: a recording joint's markers in its parent's frame, the hinge fit chosen
  per joint (``auto``: maximum likelihood, or SARA where the markers are not a hinge).
- :mod:`.stage`: :func:`calibrate_joints`, the joints stage of a recording: a :class:`JointsResult`.

See docs/architecture.md for what this package owns and may import.
"""

from ..stages import make_stage_callable
from .angles import joint_angles, outlier_threshold, predict_markers
from .axis import fit_gamage_lasenby, fit_halvorsen, fit_hinge_ml
from .calibrate import (CALIBRATION_METHODS, ParentFrame, auto_calibrate_joint, calibrate_joint, fit_sara_geometry,
                        markers_in_parent_frame, sara_angles, solve_angles)
from .chain import ChainAngles, ChainModel, solve_chain
from .crlb import Crlb, angle_crlb, angle_crlb_cov, hinge_crlb
from .segments import cluster_template, fit_sara, fit_score, kabsch, to_parent_frame
from .stage import JointResult, JointsResult, calibrate_joints
from .sync import deflection, resolver_quantum

__all__ = [
    "fit_gamage_lasenby", "fit_halvorsen", "fit_hinge_ml",
    "Crlb", "hinge_crlb", "angle_crlb", "angle_crlb_cov",
    "joint_angles", "predict_markers", "outlier_threshold",
    "kabsch", "cluster_template", "to_parent_frame", "fit_score", "fit_sara",
    "ChainModel", "ChainAngles", "solve_chain",
    "deflection", "resolver_quantum",
    "calibrate_joints", "JointsResult", "JointResult", "CALIBRATION_METHODS", "ParentFrame", "calibrate_joint",
    "auto_calibrate_joint", "fit_sara_geometry", "sara_angles", "solve_angles", "markers_in_parent_frame",
]

make_stage_callable(__name__)   # mocapfj.joints(...) is the API function (mocapfj.api)
