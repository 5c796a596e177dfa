"""mocapfj: measure flexible-joint robots with motion capture and identify their joint dynamics.

Conventions (units, frames, signs) are in docs/conventions.md; file formats in docs/formats.md.
"""

from .errors import InputError
from .types import (WORLD, Board, Camera, ControllerLog, Detections, JointAngles, JointGeometry, JointSpec,
                    MarkerTrajectories, Recording, Rig)

__version__ = "0.1.0"

__all__ = ["InputError", "WORLD", "Board", "Camera", "ControllerLog", "Detections", "JointAngles", "JointGeometry", "JointSpec",
           "MarkerTrajectories", "Recording", "Rig", "__version__"]
