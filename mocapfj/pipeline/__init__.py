"""Composition of the stages for the CLI and for batch runs. Plain functions on plain data.

- :mod:`.core`: summaries, simulate, demo, joints (calibration, angles, deflection), a joint's
  signals on one clock.
- :mod:`.identify`: identification of joints, recordings and repeated recordings.
- :mod:`.discover`: discovery of what a model misses in a recording.
"""

from .core import (STEP1, auto_calibrate_joint, calibrate_joint, calibrate_joint_angles, default_scenario,
                   fit_sara_geometry, inspect_path, joint_frame_markers, joint_signals, markers_in_parent_frame,
                   run_demo, run_joints, run_simulate, sara_angles, summarize_markers, summarize_recording)
from .discover import _discovery_signals, run_discover
from .identify import IDENTIFY_METHODS, _spring_pairs, identify_recording, identify_signals, run_identify

__all__ = ["STEP1", "auto_calibrate_joint", "calibrate_joint", "calibrate_joint_angles", "default_scenario",
           "fit_sara_geometry", "inspect_path", "joint_frame_markers", "joint_signals", "markers_in_parent_frame",
           "run_demo", "run_joints", "run_simulate", "sara_angles", "summarize_markers", "summarize_recording",
           "run_discover", "IDENTIFY_METHODS", "identify_recording", "identify_signals", "run_identify",
           "_discovery_signals", "_spring_pairs"]
