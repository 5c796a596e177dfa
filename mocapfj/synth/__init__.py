"""Synthetic recordings whose truth is known: a PA-10-like arm with marker clusters, a camera
ring, occlusion by ray casting, 2D detections, noisy 3D markers, calibration images and blob
clips; a lone flexible joint seen by one marker cluster for robustness grids (:mod:`.hinge`)
(docs/formats.md for the bundle they produce; docs/conventions.md for frames)."""

from .cameras import ring_rig
from .hinge import HingeCase, first_row_case, sample_cases, simulate_hinge, small_grid, write_hinge_bundle
from .images import BlobClip, BoardView, board_points, board_texture, render_blob_clip, render_board_view
from .markers import DEFAULT_CLUSTERS, MarkerLayout, marker_positions, place_markers
from .render import Rendering, has_embree, marker_visibility, render_markers
from .robot_mesh import (PA10_6DOF_ROWS, PA10_MDH, TABLE_HEIGHT_M, ArmGeometry, base_pose, forward_kinematics,
                         mdh_transform, pa10_geometry, posed_meshes)
from .toy import TOY_TRUTH, toy_recording

__all__ = [
    "toy_recording", "TOY_TRUTH",
    "HingeCase", "simulate_hinge", "write_hinge_bundle", "sample_cases", "first_row_case", "small_grid",
    "PA10_MDH", "PA10_6DOF_ROWS", "TABLE_HEIGHT_M", "ArmGeometry", "mdh_transform", "base_pose",
    "forward_kinematics", "pa10_geometry", "posed_meshes",
    "DEFAULT_CLUSTERS", "MarkerLayout", "place_markers", "marker_positions",
    "ring_rig", "Rendering", "render_markers", "marker_visibility", "has_embree",
    "BoardView", "BlobClip", "board_points", "board_texture", "render_board_view", "render_blob_clip",
]
