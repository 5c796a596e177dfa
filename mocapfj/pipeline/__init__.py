"""Files over the stages, for the CLI and for batch runs: each function runs the Python API
(:mod:`mocapfj.api`) and writes its results under ``--out``; no maths here.

- :mod:`.core`: summaries (``inspect``), ``simulate``, the joints stage's files.
- :mod:`.run`: ``run`` (every stage into a run directory, resumable); :mod:`.demo`: ``demo``.
- :mod:`.identify`: ``identify`` (identify.json, Table-I-style tables).
- :mod:`.discover`: ``discover`` (discovery.json, model.toml, residuals.csv).
- :mod:`.calibrate`: ``calibrate-camera`` (camera.toml, intrinsics.json, detections.json, coverage.png) and
  ``calibrate-rig`` (rig.toml, calibrate_rig.json, detections.csv).
- :mod:`.triangulate`: ``triangulate`` (markers.c3d, triangulate.json, tag_poses.csv).
- :mod:`.algebraic`: ``algebraic`` (algebraic.json, sliding.csv) and ``precompensate`` (command.csv,
  precompensate.json); :mod:`.clamped`: ``clamped`` (clamped.json, table.md).
- :mod:`.batch`: ``batch`` (one Dask task per recording; batch.json, batch.csv, trials.csv, batch.md).
"""

from .core import (default_scenario, inspect_path, run_joints, run_simulate, summarize_markers, summarize_recording,
                   write_joints)
from .demo import run_demo
from .discover import run_discover, write_discovery
from .identify import run_identify, write_tables
from .calibrate import run_calibrate_camera, run_calibrate_rig
from .triangulate import run_triangulate
from .run import run_pipeline

__all__ = ["default_scenario", "inspect_path", "run_demo", "run_joints", "run_simulate", "summarize_markers",
           "summarize_recording", "write_joints", "run_discover", "run_identify", "write_tables"]
__all__ += ["run_calibrate_camera", "run_calibrate_rig"]
__all__ += ["run_triangulate", "run_pipeline", "write_discovery"]
from .algebraic import run_algebraic, run_precompensate
from .clamped import run_clamped

__all__ += ["run_algebraic", "run_precompensate", "run_clamped"]
from .view import run_view

__all__ += ["run_view"]
from .batch import run_batch

__all__ += ["run_batch"]

from .report import run_report

__all__ += ["run_report"]
