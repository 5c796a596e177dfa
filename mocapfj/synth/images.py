"""Rendered camera images with known truth: calibration boards and bright marker blobs.

Boards (chessboard, ChArUco, AprilTag grid) are drawn as a texture at `px_per_m` texels per
metre and seen through a `Camera` (with its distortion) at a board pose: each image pixel is
sampled on a `supersample` x `supersample` grid, every sample is undistorted to a camera ray
(pixel centres exactly, sub-pixel samples by linear interpolation between them), the ray meets
the board plane (the inverse of the plane's homography), and the texture is read there; the
samples are averaged (box-filter anti-aliasing). Marker blobs are anti-aliased bright discs on a
dark background at the projected marker positions.

The returned truths are exact projections of the board features. Measured against them
(tests/synth/test_images.py): findChessboardCornersSB within 0.06 px; ArUco/AprilTag corners
from ArucoDetector sit about 0.2 px inside the true tag outline with CORNER_REFINE_SUBPIX, and
with CORNER_REFINE_APRILTAG they come out shifted by about +0.45 px in x and y (a pixel-corner
origin) -- detector conventions, not rendering errors.

Board frame (docs/conventions.md): origin at the top-left corner of the pattern as printed, x
along the columns, y along the rows (down the printed page), z into the board, metres. A camera whose rotation from the
board frame is the identity sees the board from the front, upright. A quiet zone of `margin_m`
surrounds the pattern.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from ..types import Board, Camera
from ..vision.boards import aruco_dictionary, board_points, charuco_board
from ..vision.camera import in_image, project_points

__all__ = ["BoardView", "BlobClip", "board_points", "board_texture", "render_board_view", "render_blob_clip"]

def _extent(board: Board) -> tuple[float, float]:
    """Width and height of the printed pattern (without quiet zone), metres."""
    if board.type == "chessboard":
        return (board.columns + 1) * board.square_m, (board.rows + 1) * board.square_m
    if board.type == "charuco":
        return board.columns * board.square_m, board.rows * board.square_m
    if board.type == "aprilgrid":
        pitch = board.tag_m + board.spacing_m
        return board.columns * pitch - board.spacing_m, board.rows * pitch - board.spacing_m
    raise InputError(None, "board.type", "chessboard, charuco or aprilgrid", board.type)


def _texels(length_m: float, px_per_m: float, what: str) -> int:
    n = length_m * px_per_m
    if abs(n - round(n)) > 1e-6 or round(n) < 1:
        raise InputError(None, what, f"a whole number of texels at px_per_m={px_per_m}", f"{n} texels",
                         hint="choose px_per_m so that board sizes fall on whole texels")
    return int(round(n))


def board_texture(board: Board, px_per_m: float = 10000.0, margin_m: float | None = None) -> tuple[np.ndarray, int]:
    """The printed board as a grey image, 0 = black, 255 = white.

    Parameters
    ----------
    board : Board
    px_per_m : float
        Texels per metre; every board dimension must be a whole number of texels.
    margin_m : float, optional
        Quiet zone around the pattern (white; black for an inverted ChArUco board); default one
        square (one tag for aprilgrid).

    Returns
    -------
    texture : (H, W) uint8
        Texel (r, c) covers board x in [(c - margin_px) / px_per_m, (c + 1 - margin_px) / px_per_m),
        and likewise y with r.
    margin_px : int
        The quiet zone in texels: board (0, 0) is the top-left corner of texel (margin_px, margin_px).
    """
    if margin_m is None:
        margin_m = board.tag_m if board.type == "aprilgrid" else board.square_m
    m = _texels(margin_m, px_per_m, "margin_m")
    if board.type == "chessboard":
        s = _texels(board.square_m, px_per_m, "square_m")
        j, i = np.indices((board.rows + 1, board.columns + 1))
        pattern = np.where((i + j) % 2 == 0, 0, 255).astype(np.uint8)
        pattern = np.kron(pattern, np.ones((s, s), dtype=np.uint8))
    elif board.type == "charuco":
        s = _texels(board.square_m, px_per_m, "square_m")
        _texels(board.marker_m, px_per_m, "marker_m")
        pattern = charuco_board(board).generateImage((board.columns * s, board.rows * s), marginSize=0, borderBits=1)
        if board.inverted:
            pattern = 255 - pattern
    elif board.type == "aprilgrid":
        tag = _texels(board.tag_m, px_per_m, "tag_m")
        pitch = tag + _texels(board.spacing_m, px_per_m, "spacing_m")
        d = aruco_dictionary(board)
        pattern = np.full((board.rows * pitch - pitch + tag, board.columns * pitch - pitch + tag), 255, np.uint8)
        for k in range(board.rows * board.columns):
            r, c = divmod(k, board.columns)
            pattern[r * pitch:r * pitch + tag, c * pitch:c * pitch + tag] = \
                cv2.aruco.generateImageMarker(d, k, tag, borderBits=1)
    else:
        raise InputError(None, "board.type", "chessboard, charuco or aprilgrid", board.type)
    quiet = 0 if (board.type == "charuco" and board.inverted) else 255
    return np.pad(pattern, m, constant_values=quiet), m


@dataclass(frozen=True, eq=False)
class BoardView:
    """One rendered view of a board.

    Attributes
    ----------
    image : (H, W) uint8
    ids : (N,) int
        Feature ids (`board_points`).
    corners_px : (N, 2) float
        True pixel positions of the features (through the camera's distortion).
    in_view : (N,) bool
        Feature in front of the camera and inside the image.
    """

    image: np.ndarray
    ids: np.ndarray
    corners_px: np.ndarray
    in_view: np.ndarray


def _board_camera(camera: Camera, R_world_board, t_world_board) -> Camera:
    """`camera` re-posed so that its 'world' is the board frame (p_cam = R p_board + t)."""
    Rwb = np.asarray(R_world_board, dtype=np.float64).reshape(3, 3)
    twb = np.asarray(t_world_board, dtype=np.float64).reshape(3)
    return dataclasses.replace(camera, R_cam_world=camera.R_cam_world @ Rwb,
                               t_cam_world=camera.R_cam_world @ twb + camera.t_cam_world)


def _upsample(g: np.ndarray, s: int, axis: int) -> np.ndarray:
    """Linear interpolation of grid values at pixel centres (padded by one pixel on both sides
    along `axis`) to the s sub-pixel sample positions of each inner pixel."""
    g = np.moveaxis(g, axis, 0)
    n = g.shape[0] - 2
    out = np.empty((n, s) + g.shape[1:])
    for k, o in enumerate((np.arange(s) + 0.5) / s - 0.5):
        nb = g[2:] if o >= 0 else g[:-2]
        out[:, k] = (1.0 - abs(o)) * g[1:-1] + abs(o) * nb
    return np.moveaxis(out.reshape((n * s,) + g.shape[1:]), 0, axis)


def _sample_board(cam_b: Camera, grey: np.ndarray, m: int, px_per_m: float, x0: int, x1: int, y0: int, y1: int,
                  s: int, background: float) -> np.ndarray:
    """Box-filtered board texture over image pixels [y0, y1) x [x0, x1), (y1 - y0, x1 - x0) float.

    Pixel centres are undistorted exactly (cv2.undistortPoints, iterated to 1e-10); the sub-pixel
    samples interpolate those rays linearly (error ~ 1e-5 px for mocap-lens distortion).
    """
    uu, vv = np.meshgrid(np.arange(x0 - 1, x1 + 1, dtype=np.float64), np.arange(y0 - 1, y1 + 1, dtype=np.float64))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-10)
    pix = np.stack([uu.ravel(), vv.ravel()], axis=1)[:, None, :]
    xn = cv2.undistortPoints(pix, cam_b.K, cam_b.dist if cam_b.dist.size else None, criteria=crit)
    xn = _upsample(_upsample(xn.reshape(uu.shape + (2,)), s, 0), s, 1).reshape(-1, 2)
    R, t = cam_b.R_cam_world, cam_b.t_cam_world
    n = R[:, 2]                                                                # board normal, camera frame
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (n @ t) / (xn[:, 0] * n[0] + xn[:, 1] * n[1] + n[2])            # ray (x, y, 1) meets the board
    valid = np.isfinite(lam) & (lam > 0)
    q = [lam * xn[:, 0] - t[0], lam * xn[:, 1] - t[1], lam - t[2]]            # camera frame, from board origin
    maps = []
    for axis in (0, 1):                                                        # board x, y = R^T q
        pb = q[0] * R[0, axis] + q[1] * R[1, axis] + q[2] * R[2, axis]
        maps.append(np.where(valid, pb * px_per_m + m - 0.5, -10.0).astype(np.float32))
    mx, my = maps
    shape = ((y1 - y0) * s, (x1 - x0) * s)
    samp = cv2.remap(grey, mx.reshape(shape), my.reshape(shape), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=float(background))
    return samp.reshape(y1 - y0, s, x1 - x0, s).mean(axis=(1, 3))


def render_board_view(camera: Camera, board: Board, R_world_board, t_world_board, *, px_per_m: float = 10000.0,
                      margin_m: float | None = None, supersample: int = 4, levels=(30, 220),
                      background: int = 100, blur_sigma_px: float = 0.0, noise_sd: float = 0.0,
                      rng: np.random.Generator | None = None) -> BoardView:
    """Render `board` at pose (R_world_board, t_world_board) as seen by `camera`.

    Parameters
    ----------
    camera : Camera
        With its extrinsics (world to camera); pass identity extrinsics for a board pose given
        in the camera frame.
    board : Board
    R_world_board : (3, 3) float, t_world_board : (3,) float
        Board pose: p_world = R_world_board p_board + t_world_board, metres.
    px_per_m, margin_m
        Texture resolution and quiet zone (`board_texture`).
    supersample : int
        Samples per pixel along each axis (anti-aliasing).
    levels : (black, white) int
        Grey levels of the printed black and white.
    background : int
        Grey level where the board is not.
    blur_sigma_px : float
        Optional Gaussian optical blur, pixels (0 = none).
    noise_sd : float
        SD of additive Gaussian grey-level noise (needs `rng`).
    rng : numpy.random.Generator, optional

    Returns
    -------
    BoardView
    """
    if noise_sd > 0 and rng is None:
        raise InputError(None, "rng", "a numpy Generator when noise_sd > 0", None)
    cam_b = _board_camera(camera, R_world_board, t_world_board)
    ids, p_board = board_points(board)
    corners, front = project_points(cam_b, p_board)
    tex, m = board_texture(board, px_per_m, margin_m)
    if max(tex.shape) >= 32767:                                               # cv2.remap's source limit
        raise InputError(None, "px_per_m", "a texture under 32767 texels a side", f"{tex.shape[::-1]} texels",
                         hint="lower px_per_m for a board this large")
    w, h = camera.size
    # region of interest: the projected outline of the board (with its quiet zone)
    th, tw = tex.shape
    edge = np.linspace(0.0, 1.0, 64)
    frame = np.concatenate([np.stack([edge * tw, 0 * edge], 1), np.stack([edge * tw, 0 * edge + th], 1),
                            np.stack([0 * edge, edge * th], 1), np.stack([0 * edge + tw, edge * th], 1)])
    outline, ok = project_points(cam_b, np.c_[(frame - m) / px_per_m, np.zeros(len(frame))])
    if ok.all():
        x0, y0 = np.clip(np.floor(outline.min(axis=0)) - 2, 0, [w, h]).astype(int)
        x1, y1 = np.clip(np.ceil(outline.max(axis=0)) + 3, 0, [w, h]).astype(int)
    else:
        x0, y0, x1, y1 = 0, 0, w, h
    image = np.full((h, w), float(background))
    lo, hi = levels
    grey = (lo + (hi - lo) / 255.0 * tex.astype(np.float32)).astype(np.float32)
    s = int(supersample)
    rows_per_block = max(1, 2_000_000 // max(1, (x1 - x0) * s * s))
    for r0 in range(y0, y1 if x1 > x0 else y0, rows_per_block):
        r1 = min(y1, r0 + rows_per_block)
        image[r0:r1, x0:x1] = _sample_board(cam_b, grey, m, px_per_m, x0, x1, r0, r1, s, background)
    if blur_sigma_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur_sigma_px)
    if noise_sd > 0:
        image = image + rng.normal(0.0, noise_sd, image.shape)
    image = np.clip(np.rint(image), 0, 255).astype(np.uint8)
    return BoardView(image=image, ids=ids, corners_px=corners, in_view=front & in_image(camera, corners))


@dataclass(frozen=True, eq=False)
class BlobClip:
    """A short clip of bright marker blobs.

    Attributes
    ----------
    images : (T, H, W) uint8
    centroids_px : (T, M, 2) float
        True blob centres (projected marker centres), pixels; NaN where no blob was drawn.
    drawn : (T, M) bool
        Blob drawn: marker visible (if a mask was given), in front, and its disc entirely inside
        the image.
    """

    images: np.ndarray
    centroids_px: np.ndarray
    drawn: np.ndarray


def render_blob_clip(camera: Camera, p_world, *, radius_px: float = 4.0, visible=None, peak: int = 240,
                     background: int = 12, noise_sd: float = 1.0, supersample: int = 8,
                     rng: np.random.Generator | None = None) -> BlobClip:
    """Render markers as anti-aliased bright discs on a dark background.

    Parameters
    ----------
    camera : Camera
    p_world : (T, M, 3) float
        Marker centres, world frame, metres.
    radius_px : float
        Disc radius, pixels.
    visible : (T, M) bool, optional
        Which markers this camera sees (e.g. ``Rendering.visible[c]``); default all.
    peak, background : int
        Grey levels of a fully covered pixel and of the background.
    noise_sd : float
        SD of additive Gaussian grey-level noise (needs `rng` when > 0).
    supersample : int
        Coverage samples per pixel along each axis.
    rng : numpy.random.Generator, optional

    Returns
    -------
    BlobClip
    """
    p = np.asarray(p_world, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] != 3:
        raise InputError(None, "p_world", "shape (T, M, 3)", f"shape {p.shape}")
    if noise_sd > 0 and rng is None:
        raise InputError(None, "rng", "a numpy Generator when noise_sd > 0", None)
    xy, front = project_points(camera, p)
    drawn = front & in_image(camera, xy, margin_px=radius_px + 1.0)
    if visible is not None:
        drawn &= np.asarray(visible, dtype=bool)
    w, h = camera.size
    half = int(np.ceil(radius_px)) + 1
    k = np.arange(-half, half + 1)
    s = int(supersample)
    off = (np.arange(s) + 0.5) / s - 0.5
    images = np.empty((p.shape[0], h, w), dtype=np.uint8)
    for f in range(p.shape[0]):
        frame = np.full((h, w), float(background))
        c = xy[f, drawn[f]]                                                    # (n, 2)
        if len(c):
            base = np.rint(c).astype(int)                                      # (n, 2)
            dx = (base[:, 0, None] + k[None] - c[:, 0, None])[:, None, :, None, None] + off[None, None, None, None, :]
            dy = (base[:, 1, None] + k[None] - c[:, 1, None])[:, :, None, None, None] + off[None, None, None, :, None]
            cover = ((dx * dx + dy * dy) <= radius_px**2).mean(axis=(3, 4))   # (n, rows, cols)
            val = background + (peak - background) * cover
            rows = base[:, 1, None, None] + k[None, :, None]
            cols = base[:, 0, None, None] + k[None, None, :]
            np.maximum.at(frame, (np.broadcast_to(rows, val.shape), np.broadcast_to(cols, val.shape)), val)
        if noise_sd > 0:
            frame += rng.normal(0.0, noise_sd, frame.shape)
        images[f] = np.clip(np.rint(frame), 0, 255).astype(np.uint8)
    centroids = np.where(drawn[..., None], xy, np.nan)
    return BlobClip(images=images, centroids_px=centroids, drawn=drawn)
