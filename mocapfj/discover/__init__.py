"""Mismatch discovery: compare a model with a recording, locate the mismatch, name the physics it
leaves out, model it and show the fit improve (docs/discovery.md).

- :mod:`.model`: the joint model, model files, output-error simulation and fit %.
- :mod:`.residuals`: the spring and link equation-error residuals.
- :mod:`.effects`: the effect library (signatures, fits, augmentations, explanations).
- :mod:`.engine`: locate, search, select, prove.
"""

from ..stages import make_stage_callable
from .effects import EFFECTS
from .engine import Discovery, JointSignals, discover, locate
from .model import JointModel, fit_pct, read_model_file, simulate_joint, write_model_file

__all__ = ["EFFECTS", "Discovery", "JointSignals", "discover", "locate", "JointModel", "fit_pct", "read_model_file",
           "simulate_joint", "write_model_file"]

make_stage_callable(__name__)   # mocapfj.discover(...) is the API function (mocapfj.api)
