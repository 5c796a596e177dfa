"""Camera images for a synthetic recording: calibration views of a board, and a blob clip.

For the vision stages (intrinsics, rig calibration, blob detection) and the demo, written on
request (`mocapfj simulate --images`) into ``images/`` of a bundle with their truth:

- ``board_view<k>_cam<c>.png``: the board at pose k seen by camera c (only cameras that see its
  printed face within 65 deg of head-on and at least 80 % of its features), and
  ``board_truth.json``: the board table, each pose (R_world_board, t_world_board) and per image
  the feature ids and their true pixel positions;
- ``blobs_cam<c>_f<frame>.png``: the first frames of the recording as bright marker blobs on a
  dark background (occluded markers not drawn), and ``blobs_truth.json``: true centroids.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from ..io import to_jsonable
from ..io.atomic import write_bytes_atomic, write_text_atomic
from ..types import Board, Rig
from ..vision.camera import camera_centre_world
from .images import board_points, render_blob_clip, render_board_view
from .markers import marker_positions
from .render import marker_visibility
from .robot_mesh import base_pose, forward_kinematics, pa10_geometry

__all__ = ["DEFAULT_BOARD", "board_poses", "write_board_views", "write_blob_clip"]

DEFAULT_BOARD = Board("charuco", 7, 5, square_m=0.06, marker_m=0.042, dictionary="DICT_5X5_100")
"""7 x 5 ChArUco, 60 mm squares, 42 mm markers (0.7 of the square: OpenCV's corner refinement
is most accurate there)."""


def board_poses(rig: Rig, n: int, rng: np.random.Generator, centre=(0.45, 0.0, 1.15)) -> list[tuple[np.ndarray, np.ndarray]]:
    """n board poses (R_world_board, t_world_board) in the workspace, each turned towards a camera.

    The board frame has z into the board, so its printed face looks along -z. Pose k faces
    camera k mod C with up to 25 deg of tilt and any in-plane rotation.
    """
    centres = np.stack([camera_centre_world(c) for c in rig.cameras])
    out = []
    for k in range(n):
        p = np.asarray(centre) + rng.uniform([-0.2, -0.25, -0.15], [0.2, 0.25, 0.25])
        toward = centres[k % len(centres)] - p
        toward /= np.linalg.norm(toward)
        z = -toward  # printed face (-z) towards the camera
        tilt = Rotation.from_rotvec(rng.normal(0, 1, 3) * np.radians(25) / np.sqrt(3))
        z = tilt.apply(z)
        x = np.cross([0.0, 0.0, 1.0], z)
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z])
        R = R @ Rotation.from_rotvec([0, 0, rng.uniform(-np.pi, np.pi)]).as_matrix()
        out.append((R, p))
    return out


def _png(path: Path, image: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover
        raise RuntimeError(f"PNG encoding failed for {path}")
    write_bytes_atomic(path, buf.tobytes())


def write_board_views(out: Path, rig: Rig, board: Board, n_views: int, rng: np.random.Generator) -> dict:
    """Render and write the board views; returns the truth written to board_truth.json."""
    out.mkdir(parents=True, exist_ok=True)
    ids_all, p_board = board_points(board)
    truth = {"board": {k: v for k, v in vars(board).items() if v is not None}, "poses": [], "images": []}
    for k, (R, t) in enumerate(board_poses(rig, n_views, rng)):
        truth["poses"].append({"view": k, "R_world_board": R, "t_world_board": t})
        centre = R @ p_board.mean(axis=0) + t
        for c, cam in enumerate(rig.cameras):
            to_cam = camera_centre_world(cam) - centre
            facing = -R[:, 2] @ to_cam / np.linalg.norm(to_cam)
            if facing < np.cos(np.radians(65)):
                continue
            view = render_board_view(cam, board, R, t, noise_sd=2.0, blur_sigma_px=0.7, rng=rng)
            if view.in_view.mean() < 0.8:
                continue
            name = f"board_view{k:02d}_cam{c}.png"
            _png(out / name, view.image)
            truth["images"].append({"file": name, "view": k, "camera": c, "ids": view.ids[view.in_view],
                                    "corners_px": view.corners_px[view.in_view]})
    write_text_atomic(out / "board_truth.json", json.dumps(to_jsonable(truth), indent=1) + "\n")
    return truth


def write_blob_clip(out: Path, rig: Rig, layout, q_full: np.ndarray, rng: np.random.Generator) -> dict:
    """Render the first frames (arm poses q_full (F, 6)) as blob images per camera, with truth."""
    out.mkdir(parents=True, exist_ok=True)
    geometry = pa10_geometry()
    T = forward_kinematics(q_full, T_world_base=base_pose())
    p = marker_positions(layout, T)
    visible = marker_visibility(rig, p, T, geometry)
    truth = {"labels": list(layout.labels), "cameras": []}
    for c, cam in enumerate(rig.cameras):
        clip = render_blob_clip(cam, p, visible=visible[c], rng=rng)
        for f in range(clip.images.shape[0]):
            _png(out / f"blobs_cam{c}_f{f:03d}.png", clip.images[f])
        truth["cameras"].append({"camera": c, "centroids_px": clip.centroids_px, "drawn": clip.drawn})
    write_text_atomic(out / "blobs_truth.json", json.dumps(to_jsonable(truth)) + "\n")
    return truth
