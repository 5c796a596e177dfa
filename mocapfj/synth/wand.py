"""A calibration wand waved through a rig's volume, and the L-frame on the floor, with truth.

What a mocap system's cameras report during a wand calibration: per camera and frame the
centroids of the wand's marker blobs (2D, pixels), with

- the wand moving smoothly (its centre on a sum of slow sinusoids inside a box, its direction
  turning at about 3 rad/s (at 100 frames per second) about a changing axis);
- visibility: markers behind a camera or outside its image are not seen, and the person waving
  the wand occludes them (a vertical cylinder of radius 0.2 m, 1.85 m tall, standing 0.5 m from the
  wand on a slowly turning side);
- blobs closer than `merge_px` merge into one (at their mean): what a blob detector returns;
- Gaussian pixel noise and randomly missed detections.

The L-frame's markers stand still at their nominal positions (:attr:`mocapfj.types.Wand.lframe_m`),
so the rig's world is the L-frame's: a calibration that sets its axes from the L-frame should
return the rig's true extrinsics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..types import Detections, Rig, Wand
from ..vision.camera import camera_centre_world, in_image, project_points

__all__ = ["WandWave", "wand_wave", "lframe_detections"]


@dataclass(frozen=True, eq=False)
class WandWave:
    """Simulated wand calibration data.

    Attributes
    ----------
    detections : Detections
        Blob centroids (frame, camera, xy_px); point_id is the marker index when labelled, else -1
        (rows of one camera and frame then sorted by x, not by marker).
    markers_world : (F, K, 3)
        True marker positions, m.
    visible : (C, F, K) bool
        Which markers each camera saw as a blob of their own (not merged, not missed).
    """

    detections: Detections
    markers_world: np.ndarray
    visible: np.ndarray


def _smooth(n: int, rng: np.random.Generator, n_terms: int = 4, period_frames=(150.0, 900.0)) -> np.ndarray:
    """(n, 3) sums of sinusoids with random periods and phases, amplitude ~1 per axis."""
    t = np.arange(n, dtype=np.float64)
    out = np.zeros((n, 3))
    for _ in range(n_terms):
        period = rng.uniform(*period_frames, 3)
        phase = rng.uniform(0.0, 2.0 * np.pi, 3)
        out += np.sin(2.0 * np.pi * t[:, None] / period + phase)
    return out / np.sqrt(n_terms / 2.0)


def _occluded(cam_centre: np.ndarray, p: np.ndarray, body_xy: np.ndarray, radius: float, height: float) -> np.ndarray:
    """Whether the segment from the camera to each point (F, K, 3) crosses a vertical cylinder
    (axis at body_xy (F, 2), from z = 0 to `height`)."""
    d = p - cam_centre                                      # (F, K, 3)
    o = cam_centre[:2] - body_xy[:, None, :]                # (F, 1, 2)
    a = d[..., 0] ** 2 + d[..., 1] ** 2
    b = 2.0 * (o[..., 0] * d[..., 0] + o[..., 1] * d[..., 1])
    c = o[..., 0] ** 2 + o[..., 1] ** 2 - radius**2
    disc = b * b - 4.0 * a * c
    ok = disc > 0.0
    sq = np.sqrt(np.where(ok, disc, 0.0))
    a = np.where(a > 0, a, 1.0)
    hit = np.zeros(p.shape[:2], bool)
    for s in ((-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)):
        z = cam_centre[2] + s * d[..., 2]
        hit |= ok & (s > 0.0) & (s < 1.0) & (z > 0.0) & (z < height)
    return hit


def _blobs(rig: Rig, p: np.ndarray, visible_geo: np.ndarray, rng, noise_px, p_miss, merge_px, labelled):
    """Detections of points p (F, K, 3) seen where visible_geo (C, F, K)."""
    C = len(rig.cameras)
    F, K = p.shape[:2]
    frames, cams, xys, ids = [], [], [], []
    vis_out = np.zeros((C, F, K), bool)
    for c, cam in enumerate(rig.cameras):
        xy, front = project_points(cam, p)
        vis = visible_geo[c] & front & in_image(cam, xy, 2.0) & (rng.random((F, K)) >= p_miss)
        # blobs closer than merge_px merge: one blob at their mean, which is no marker's own
        merged = np.zeros((F, K), bool)
        mixed = np.zeros((F, K), bool)
        xy_m = xy.copy()
        for i in range(K):
            for j in range(i + 1, K):
                close = (vis[:, i] & vis[:, j] & ~merged[:, i] & ~merged[:, j]
                         & (np.linalg.norm(xy[:, i] - xy[:, j], axis=1) < merge_px))
                xy_m[close, i] = 0.5 * (xy[close, i] + xy[close, j])
                merged[close, j] = True
                mixed[close, i] = True
        keep = vis & ~merged
        vis_out[c] = keep & ~mixed
        f_idx, k_idx = np.nonzero(keep)
        pts = xy_m[f_idx, k_idx] + rng.normal(0.0, noise_px, (f_idx.size, 2))
        frames.append(f_idx)
        cams.append(np.full(f_idx.size, c))
        xys.append(pts)
        ids.append(k_idx if labelled else np.full(f_idx.size, -1))
    frame = np.concatenate(frames)
    camera = np.concatenate(cams)
    xy = np.concatenate(xys)
    pid = np.concatenate(ids)
    order = np.lexsort((pid if labelled else xy[:, 0], frame, camera))
    return Detections(frame[order], camera[order], xy[order], pid[order]), vis_out


def wand_wave(rig: Rig, wand: Wand, n_frames: int, rng: np.random.Generator, *, noise_px: float = 0.2,
              p_miss: float = 0.02, centre=(0.0, 0.0, 1.1), half_extent_m=(0.9, 0.9, 0.55),
              occluder: bool = True, merge_px: float = 4.0, labelled: bool = False) -> WandWave:
    """Simulate `n_frames` frames of a wand waved through the volume of `rig`.

    Parameters
    ----------
    rig : Rig
    wand : Wand
    n_frames : int
    rng : numpy.random.Generator
    noise_px : float
        SD of the Gaussian noise on each blob coordinate.
    p_miss : float
        Probability that a visible marker's blob is missed.
    centre, half_extent_m : (3,) float
        The wand's centre stays inside centre +- half_extent_m (m).
    occluder : bool
        Simulate the body of the person waving the wand.
    merge_px : float
        Blobs closer than this merge into one.
    labelled : bool
        Give each blob its marker index (point_id); otherwise -1.
    """
    if n_frames < 1:
        raise InputError(None, "n_frames", "at least 1 frame", n_frames)
    centre = np.asarray(centre, dtype=np.float64)
    half = np.asarray(half_extent_m, dtype=np.float64)
    c_t = centre + half * np.tanh(_smooth(n_frames, rng))
    # direction: a smooth rotation path (angular velocity from sinusoids, about 3 rad/s at 100 Hz)
    omega = 0.03 * _smooth(n_frames, rng, period_frames=(100.0, 600.0))
    rot = Rotation.from_rotvec(rng.normal(0.0, 1.0, 3))
    u = np.empty((n_frames, 3))
    for f in range(n_frames):
        u[f] = rot.apply([1.0, 0.0, 0.0])
        rot = Rotation.from_rotvec(omega[f]) * rot
    mid = 0.5 * wand.length_m
    p = c_t[:, None, :] + (wand.markers_m[None, :, None] - mid) * u[:, None, :]
    C = len(rig.cameras)
    visible = np.ones((C, n_frames, wand.markers_m.size), bool)
    if occluder:
        # the person walks round the volume, about one turn in 6-15 s (at 100 frames per second)
        side = (2.0 * np.pi * np.arange(n_frames) / rng.uniform(600.0, 1500.0) + 0.5 * _smooth(n_frames, rng)[:, 0]
                + rng.uniform(0.0, 2.0 * np.pi))
        body = c_t[:, :2] + 0.5 * np.column_stack([np.cos(side), np.sin(side)])
        for c, cam in enumerate(rig.cameras):
            visible[c] &= ~_occluded(camera_centre_world(cam), p, body, 0.2, 1.85)
    det, vis = _blobs(rig, p, visible, rng, noise_px, p_miss, merge_px, labelled)
    return WandWave(det, p, vis)


def lframe_detections(rig: Rig, wand: Wand, n_frames: int, rng: np.random.Generator, *, noise_px: float = 0.2,
                      labelled: bool = False) -> Detections:
    """`n_frames` frames of the still L-frame at its nominal positions (the world it defines)."""
    if wand.lframe_m is None:
        raise InputError(None, "wand.lframe_m", "an L-frame", "none")
    p = np.broadcast_to(wand.lframe_m, (n_frames,) + wand.lframe_m.shape).copy()
    det, _ = _blobs(rig, p, np.ones((len(rig.cameras),) + p.shape[:2], bool), rng, noise_px, 0.0, 4.0, labelled)
    return det
