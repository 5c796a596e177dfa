"""AprilTags (36h11 by default) on links: corners with ids in each image, and a 6-DoF pose per frame.

**Detection** (:func:`detect_tags`): OpenCV's ArUco detector with its AprilTag dictionary and the
AprilTag corner refinement (``cv2.aruco.CORNER_REFINE_APRILTAG``, the AprilTag library's own edge
fit; Olson 2011, Wang and Olson 2016), run on the image and on copies enlarged 1.5x and 2x
(bicubic): small tags of 10-20 px that the native image's quad detection misses are found on the
enlarged ones. Detections of one tag at several scales are merged, the smallest scale kept.
OpenCV's AprilTag refinement returns corners with the origin at the top-left pixel's corner; they
are moved to docs/conventions.md's pixel centres (-0.5 px) and scaled back. The corner order is
OpenCV's: top-left, top-right, bottom-right, bottom-left of the printed tag (the AprilTag library
lists them in the opposite winding).

**Tag clusters**: a tag of known size is a cluster of four markers, its corners
(:func:`mocapfj.io.clusters.tag_template`): their detections carry point ids 4 id + corner, are
triangulated from every camera that saw them (:mod:`mocapfj.vision.triangulate`), and the square
fitted to the four points (Kabsch 1976) is the tag's pose per frame (:func:`tag_poses`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from ..types import Detections
from .track import rigid_fit

__all__ = ["TagDetections", "detect_tags", "tag_poses", "TAG_DICTIONARIES"]

TAG_DICTIONARIES = {"tag36h11": "DICT_APRILTAG_36h11", "tag25h9": "DICT_APRILTAG_25h9", "tag16h5": "DICT_APRILTAG_16h5"}


@dataclass(frozen=True, eq=False)
class TagDetections:
    """Tags found in one image (or a stack: `frame`).

    Attributes
    ----------
    frame : (n,) int
    ids : (n,) int
    corners_px : (n, 4, 2) float
        OpenCV's corner order, pixel centres at integers.
    side_px : (n,) float
        Mean side length, pixels.
    scale : (n,) float
        Enlargement of the image the tag was found in.
    """

    frame: np.ndarray
    ids: np.ndarray
    corners_px: np.ndarray
    side_px: np.ndarray
    scale: np.ndarray

    def __len__(self) -> int:
        return int(self.ids.size)

    def detections(self, camera: int, frame_offset: int = 0) -> Detections:
        """Corners as labelled detections of `camera`: point_id = 4 id + corner (0..3)."""
        n = self.ids.size
        return Detections(frame=np.repeat(self.frame, 4) + int(frame_offset), camera=np.full(4 * n, int(camera)),
                          xy_px=self.corners_px.reshape(-1, 2),
                          point_id=(4 * self.ids[:, None] + np.arange(4)[None]).ravel())

    def to_dict(self) -> dict:
        return {"n_tags": len(self), "ids": sorted(set(self.ids.tolist())),
                "side_px_median": float(np.median(self.side_px)) if len(self) else None}


def _detector(family: str):
    name = TAG_DICTIONARIES.get(family)
    if name is None:
        raise InputError(None, "family", f"one of {', '.join(TAG_DICTIONARIES)}", repr(family))
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)), params)


def _grey(image) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (3, 4):
        a = cv2.cvtColor(a, cv2.COLOR_BGR2GRAY if a.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if a.ndim != 2:
        raise InputError(None, "image", "a grey (H, W) or colour (H, W, 3) image", f"shape {a.shape}")
    if a.dtype != np.uint8:
        if a.dtype.kind not in "uif":
            raise InputError(None, "image", "grey levels", f"dtype {a.dtype}")
        top = float(a.max()) if a.size else 1.0
        a = np.clip(a.astype(np.float64) * (255.0 / (top if top > 0 else 1.0)), 0, 255).astype(np.uint8)
    return a


def detect_tags(image, *, family: str = "tag36h11", scales=(1.0, 1.5, 2.0), frame: int = 0) -> TagDetections:
    """AprilTags in one image: ids and refined corners (module docstring).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) array
    family : {"tag36h11", "tag25h9", "tag16h5"}
    scales : sequence of float
        Enlargements to search, the first kept where a tag is found at several.
    frame : int
        Frame number recorded in the result.

    Returns
    -------
    TagDetections
    """
    grey = _grey(image)
    det = _detector(family)
    ids_all, corners_all, scale_all = [], [], []
    for s in scales:
        img = grey if s == 1.0 else cv2.resize(grey, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC)
        corners, ids, _ = det.detectMarkers(img)
        if ids is None:
            continue
        c = np.array([q.reshape(4, 2) for q in corners], dtype=np.float64) / s - 0.5
        ids_all.append(ids.ravel().astype(np.int64))
        corners_all.append(c)
        scale_all.append(np.full(len(c), float(s)))
    if not ids_all:
        return TagDetections(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 4, 2)), np.zeros(0), np.zeros(0))
    ids = np.concatenate(ids_all)
    corners = np.concatenate(corners_all)
    scale = np.concatenate(scale_all)
    side = np.linalg.norm(corners - np.roll(corners, -1, axis=1), axis=2).mean(axis=1)
    centre = corners.mean(axis=1)
    # the same tag at several scales: same id, centres within half a side; keep the first scale
    d = np.linalg.norm(centre[:, None] - centre[None], axis=2)
    same = (ids[:, None] == ids[None]) & (d < 0.5 * np.minimum(side[:, None], side[None]))
    earlier = np.tril(same, -1).any(axis=1)
    keep = ~earlier
    return TagDetections(np.full(int(keep.sum()), int(frame)), ids[keep], corners[keep], side[keep], scale[keep])


def tag_poses(corners_world, size_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pose of a square tag from its four triangulated corners, per frame.

    Parameters
    ----------
    corners_world : (T, 4, 3) float
        Corners in OpenCV's order, world frame, metres; NaN where missing.
    size_m : float
        The tag's side, metres.

    Returns
    -------
    R_world_tag : (T, 3, 3)
    t_world_tag : (T, 3)
        p_world = R_world_tag p_tag + t_world_tag, with the tag frame of
        :func:`mocapfj.io.clusters.tag_template` (origin at the centre, x right, y down, z into
        the tag); NaN where fewer than three corners are present.
    rms_m : (T,)
        RMS distance of the present corners from the fitted square, metres.
    """
    from ..io.clusters import tag_template

    q = np.asarray(corners_world, dtype=np.float64)
    if q.ndim != 3 or q.shape[1:] != (4, 3):
        raise InputError(None, "corners_world", "shape (T, 4, 3)", f"shape {q.shape}")
    tpl = tag_template(size_m)
    w = np.isfinite(q[..., 0]).astype(np.float64)
    T = q.shape[0]
    R, t = rigid_fit(np.broadcast_to(tpl, (T, 4, 3)), q, w)
    pred = np.einsum("nij,kj->nki", R, tpl) + t[:, None]
    with np.errstate(invalid="ignore"):
        rms = np.sqrt(np.nansum(np.sum((pred - q) ** 2, axis=2) * w, axis=1) / w.sum(axis=1))
    bad = w.sum(axis=1) < 3
    R[bad], t[bad], rms[bad] = np.nan, np.nan, np.nan
    return R, t, rms
