"""Synthetic board co-observations for rig calibration, with truth.

A calibration board is held at `n_frames` poses in the volume a rig watches; every camera that
sees its printed face within `max_angle_deg` of head-on, with the board in front of it and its
corners inside the image, detects the corners with Gaussian pixel noise. The result is what a
board detector returns for synchronised views: :class:`mocapfj.types.Detections` with
``point_id`` the board's corner ids (:func:`mocapfj.synth.images.board_points`), and the true
board poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..types import Board, Detections, Rig
from ..vision.camera import camera_centre_world, in_image, project_points
from .images import board_points

__all__ = ["BoardObservations", "board_observations"]


@dataclass(frozen=True, eq=False)
class BoardObservations:
    """Simulated board detections of a rig.

    Attributes
    ----------
    detections : Detections
        frame = pose index, camera = camera number, point_id = corner id, xy_px with noise.
    R_world_board : (F, 3, 3)
    t_world_board : (F, 3)
        The true board poses, m.
    xy_true_px : (N, 2)
        Noise-free pixels of the detections' rows.
    """

    detections: Detections
    R_world_board: np.ndarray
    t_world_board: np.ndarray
    xy_true_px: np.ndarray


def board_observations(rig: Rig, board: Board, n_frames: int, rng: np.random.Generator, *, noise_px: float = 0.3,
                       centre=None, half_extent_m=(0.5, 0.5, 0.4), max_angle_deg: float = 60.0,
                       tilt_deg: float = 25.0, min_points: int = 6, partial: bool | None = None,
                       margin_px: float = 2.0) -> BoardObservations:
    """Board poses in the rig's volume and the noisy corners each camera detects.

    Parameters
    ----------
    rig : Rig
    board : Board
    n_frames : int
        Board poses.
    rng : numpy.random.Generator
    noise_px : float
        SD of the Gaussian noise on each pixel coordinate.
    centre : (3,) float, optional
        Centre of the volume, m (default: the point nearest to every camera's optical axis).
    half_extent_m : (3,) float
        Board centres are uniform in centre +- this box, m.
    max_angle_deg : float
        A camera sees the board when the angle between the board's printed face normal and the
        direction to the camera is below this.
    tilt_deg : float
        Each pose faces the bisector of two neighbouring cameras (by azimuth), tilted by up to
        this much, with any in-plane rotation.
    min_points : int
        Views with fewer corners are not detected.
    partial : bool, optional
        Whether a view with some corners outside the image is detected with the rest (default:
        True for ChArUco and AprilTag grids, False for chessboards).
    """
    ids_all, p_board = board_points(board)
    partial = board.type != "chessboard" if partial is None else partial
    centres = np.stack([camera_centre_world(c) for c in rig.cameras])
    if centre is None:
        # least-squares point nearest to all optical axes
        A = np.zeros((3, 3))
        b = np.zeros(3)
        for cam, c in zip(rig.cameras, centres):
            z = cam.R_cam_world[2]
            P = np.eye(3) - np.outer(z, z)
            A += P
            b += P @ c
        centre = np.linalg.solve(A, b)
    centre = np.asarray(centre, dtype=np.float64)
    az = np.arctan2(centres[:, 1] - centre[1], centres[:, 0] - centre[0])
    order = np.argsort(az)
    p_mid_board = p_board.mean(axis=0)
    frames, cams, ids, xy_true = [], [], [], []
    Rs, ts = [], []
    for f in range(int(n_frames)):
        pos = centre + rng.uniform(-1.0, 1.0, 3) * np.asarray(half_extent_m)
        k = int(rng.integers(len(order)))
        a, b = order[k], order[(k + 1) % len(order)]
        da = centres[a] - pos
        db = centres[b] - pos
        toward = da / np.linalg.norm(da) + db / np.linalg.norm(db)
        z = -toward / np.linalg.norm(toward)                 # printed face (-z) towards the cameras
        z = Rotation.from_rotvec(rng.normal(0, 1, 3) * np.radians(tilt_deg) / np.sqrt(3)).apply(z)
        x = np.cross([0.0, 0.0, 1.0], z)
        x /= np.linalg.norm(x)
        R = np.column_stack([x, np.cross(z, x), z]) @ Rotation.from_rotvec(
            [0, 0, rng.uniform(-np.pi, np.pi)]).as_matrix()
        t = pos - R @ p_mid_board
        Rs.append(R)
        ts.append(t)
        p_world = p_board @ R.T + t
        for c, cam in enumerate(rig.cameras):
            to_cam = centres[c] - pos
            if -R[:, 2] @ to_cam / np.linalg.norm(to_cam) < np.cos(np.radians(max_angle_deg)):
                continue
            xy, front = project_points(cam, p_world)
            ok = front & in_image(cam, xy, margin_px)
            if (not partial and not ok.all()) or ok.sum() < min_points:
                continue
            frames.append(np.full(int(ok.sum()), f))
            cams.append(np.full(int(ok.sum()), c))
            ids.append(ids_all[ok])
            xy_true.append(xy[ok])
    if frames:
        xy_true = np.concatenate(xy_true)
        det = Detections(frame=np.concatenate(frames), camera=np.concatenate(cams),
                         xy_px=xy_true + rng.normal(0.0, noise_px, xy_true.shape), point_id=np.concatenate(ids))
    else:
        xy_true = np.zeros((0, 2))
        det = Detections(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0, np.int64))
    return BoardObservations(det, np.array(Rs).reshape(-1, 3, 3), np.array(ts).reshape(-1, 3), xy_true)
