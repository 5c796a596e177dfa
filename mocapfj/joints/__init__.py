"""Joint axes and centres from marker clusters, per-frame link angles, stream synchronisation and deflection.

- :mod:`.axis`: hinge fits (Gamage-Lasenby, Halvorsen bias-compensated, maximum likelihood).
- :mod:`.crlb`: Cramér-Rao bounds for the axis, the centre and the angle.
- :mod:`.angles`: closed-form per-frame angle of one joint (seed 000 eq. 13) with outlier rejection.
- :mod:`.segments`: rigid clusters (Kabsch, templates), SCoRE and SARA for two moving segments.
- :mod:`.chain`: batched Gauss-Newton for the joints of a chain (Pinocchio model).
- :mod:`.sync`: common time base and deflection delta = q_m - q.

See docs/architecture.md for what this package owns and may import.
"""

from .angles import joint_angles, outlier_threshold, predict_markers
from .axis import fit_gamage_lasenby, fit_halvorsen, fit_hinge_ml
from .chain import ChainAngles, ChainModel, solve_chain
from .crlb import Crlb, angle_crlb, angle_crlb_cov, hinge_crlb
from .segments import cluster_template, fit_sara, fit_score, kabsch, to_parent_frame
from .sync import deflection, resolver_quantum

__all__ = [
    "fit_gamage_lasenby", "fit_halvorsen", "fit_hinge_ml",
    "Crlb", "hinge_crlb", "angle_crlb", "angle_crlb_cov",
    "joint_angles", "predict_markers", "outlier_threshold",
    "kabsch", "cluster_template", "to_parent_frame", "fit_score", "fit_sara",
    "ChainModel", "ChainAngles", "solve_chain",
    "deflection", "resolver_quantum",
]
