"""mocapfj: measure flexible-joint robots with motion capture and identify their joint dynamics.

The Python API (:mod:`mocapfj.api`), in memory, one typed result per stage::

    import mocapfj
    rec = mocapfj.load("bundle")
    cal = mocapfj.joints(rec)           # axes, centres, link angles, deflections
    ident = mocapfj.identify(rec)       # joint parameters, spring, model
    found = mocapfj.discover(rec, model=ident, validation="bundle2")

Conventions (units, frames, signs) are in docs/conventions.md; file formats in docs/formats.md.
"""

from importlib import import_module

from .api import identify, identify_joint, load, signals
from .errors import InputError
from .types import (WORLD, Board, Camera, ControllerLog, Detections, JointAngles, JointGeometry, JointSignals,
                    JointSpec, MarkerTrajectories, Recording, Rig)

__version__ = "0.1.0"

__all__ = ["load", "joints", "signals", "identify", "identify_joint", "discover", "InputError", "WORLD", "Board",
           "Camera", "ControllerLog", "Detections", "JointAngles", "JointGeometry", "JointSignals", "JointSpec",
           "MarkerTrajectories", "Recording", "Rig", "__version__"]


def __getattr__(name: str):
    # mocapfj.joints and mocapfj.discover are stage packages that are also callable (mocapfj.api);
    # imported on first use so that 'import mocapfj' (and 'mocapfj --help') stays fast
    if name in ("joints", "discover"):
        return import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
