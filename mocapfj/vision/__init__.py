"""Camera model and projection, calibration targets, detection, calibration, triangulation and tracking.

See docs/architecture.md for what this package owns and may import.
"""

from .camera import camera_centre_world, in_image, look_at_camera, project_points, project_rig
from .boards import BoardDetection, board_points, board_symmetry, detect_board

__all__ = ["project_points", "project_rig", "in_image", "camera_centre_world", "look_at_camera"]
__all__ += ["BoardDetection", "board_points", "board_symmetry", "detect_board"]
