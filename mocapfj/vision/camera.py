"""Pinhole camera with OpenCV distortion: projection of world points into pixels.

Conventions (docs/conventions.md): world-to-camera extrinsics, p_cam = R_cam_world p_world +
t_cam_world; camera frame x right, y down, z forward (OpenCV); pixel coordinates with the origin
at the centre of the top-left pixel. Distortion follows OpenCV's ``projectPoints`` exactly
(Bradski & Kaehler, "Learning OpenCV"; OpenCV calib3d documentation):

    x' = X/Z, y' = Y/Z, r^2 = x'^2 + y'^2
    x'' = x' (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
          + 2 p1 x'y' + p2 (r^2 + 2 x'^2) + s1 r^2 + s2 r^4
    y'' = y' (...) + p1 (r^2 + 2 y'^2) + 2 p2 x'y' + s3 r^2 + s4 r^4
    [x''', y'''] = tilt(tau_x, tau_y) applied to (x'', y'')
    u = fx x''' + cx,  v = fy y''' + cy

with coefficients ordered (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tau_x, tau_y]]]]).
Like OpenCV, the model has no skew: ``K[0, 1]`` must be 0.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..types import Camera, Rig

__all__ = [
    "DIST_LENGTHS",
    "project_points",
    "project_rig",
    "in_image",
    "camera_centre_world",
    "look_at_camera",
    "tilt_matrix",
]

DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
"""Distortion vector lengths OpenCV accepts (0 = no distortion)."""


def _check_camera(camera: Camera) -> np.ndarray:
    """Return the 14 distortion coefficients of `camera` (zero-padded); raise on a bad model."""
    d = camera.dist
    if d.size not in DIST_LENGTHS:
        raise InputError(None, f"camera {camera.name!r} dist", f"a length in {DIST_LENGTHS}", d.size)
    if camera.K[0, 1] != 0.0 or np.any(camera.K[2] != (0.0, 0.0, 1.0)) or camera.K[1, 0] != 0.0:
        raise InputError(None, f"camera {camera.name!r} K", "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]",
                         camera.K.tolist())
    out = np.zeros(14)
    out[: d.size] = d
    return out


def tilt_matrix(tau_x: float, tau_y: float) -> np.ndarray:
    """OpenCV's ``computeTiltProjectionMatrix`` (Scheimpflug sensor tilt), (3, 3)."""
    cx, sx, cy, sy = np.cos(tau_x), np.sin(tau_x), np.cos(tau_y), np.sin(tau_y)
    rot_x = np.array([[1.0, 0.0, 0.0], [0.0, cx, sx], [0.0, -sx, cx]])
    rot_y = np.array([[cy, 0.0, -sy], [0.0, 1.0, 0.0], [sy, 0.0, cy]])
    rot_xy = rot_y @ rot_x
    proj_z = np.array([[rot_xy[2, 2], 0.0, -rot_xy[0, 2]],
                       [0.0, rot_xy[2, 2], -rot_xy[1, 2]],
                       [0.0, 0.0, 1.0]])
    return proj_z @ rot_xy


def project_points(camera: Camera, p_world) -> tuple[np.ndarray, np.ndarray]:
    """Project world points into the pixels of `camera`.

    Parameters
    ----------
    camera : Camera
        Pinhole camera with OpenCV distortion (module docstring).
    p_world : (..., 3) float
        Points in the world frame, metres; any leading shape, e.g. (N, 3) or (T, M, 3).

    Returns
    -------
    xy_px : (..., 2) float
        Pixel coordinates (origin at the centre of the top-left pixel); NaN for points that are
        not in front of the camera.
    in_front : (...,) bool
        True where the point has positive depth (z_cam > 0).

    Agrees with ``cv2.projectPoints`` to rounding error for points in front of the camera.
    """
    p = np.asarray(p_world, dtype=np.float64)
    if p.ndim < 1 or p.shape[-1] != 3:
        raise InputError(None, "p_world", "an array of shape (..., 3)", f"shape {p.shape}")
    d = _check_camera(camera)
    p_cam = p @ camera.R_cam_world.T + camera.t_cam_world
    z = p_cam[..., 2]
    in_front = z > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        x = p_cam[..., 0] / z
        y = p_cam[..., 1] / z
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4, tau_x, tau_y = d
    r2 = x * x + y * y
    r4 = r2 * r2
    radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xy = x * y
    xd = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x) + s1 * r2 + s2 * r4
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy + s3 * r2 + s4 * r4
    if tau_x != 0.0 or tau_y != 0.0:
        m = tilt_matrix(tau_x, tau_y)
        w = m[2, 0] * xd + m[2, 1] * yd + m[2, 2]
        xd, yd = ((m[0, 0] * xd + m[0, 1] * yd + m[0, 2]) / w,
                  (m[1, 0] * xd + m[1, 1] * yd + m[1, 2]) / w)
    K = camera.K
    xy_px = np.stack([K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=-1)
    xy_px[~in_front] = np.nan
    return xy_px, in_front


def project_rig(rig: Rig, p_world) -> tuple[np.ndarray, np.ndarray]:
    """Project world points through every camera of `rig`.

    Parameters
    ----------
    rig : Rig
    p_world : (..., 3) float
        World points, metres.

    Returns
    -------
    xy_px : (C, ..., 2) float
        Pixels per camera, NaN behind the camera.
    in_front : (C, ...) bool
    """
    out = [project_points(cam, p_world) for cam in rig.cameras]
    return np.stack([o[0] for o in out]), np.stack([o[1] for o in out])


def in_image(camera: Camera, xy_px, margin_px: float = 0.0) -> np.ndarray:
    """True where pixel positions lie inside the image, `margin_px` away from its border.

    Parameters
    ----------
    camera : Camera
    xy_px : (..., 2) float
        Pixel coordinates; NaN counts as outside.
    margin_px : float
        Required distance from the outer edge of the image (pixel edges at -0.5 and W - 0.5).

    Returns
    -------
    (...,) bool
    """
    xy = np.asarray(xy_px, dtype=np.float64)
    w, h = camera.size
    lo = -0.5 + margin_px
    with np.errstate(invalid="ignore"):
        return ((xy[..., 0] >= lo) & (xy[..., 0] <= w - 0.5 - margin_px)
                & (xy[..., 1] >= lo) & (xy[..., 1] <= h - 0.5 - margin_px))


def camera_centre_world(camera: Camera) -> np.ndarray:
    """Optical centre of `camera` in the world frame, (3,) metres: -R_cam_world^T t_cam_world."""
    return -camera.R_cam_world.T @ camera.t_cam_world


def look_at_camera(name: str, position_world, target_world, up_world=(0.0, 0.0, 1.0), *,
                   fx: float, size: tuple[int, int], fy: float | None = None,
                   principal_px: tuple[float, float] | None = None, dist=()) -> Camera:
    """A camera at `position_world` whose optical axis passes through `target_world`.

    Parameters
    ----------
    name : str
    position_world, target_world : (3,) float
        Optical centre and a point on the optical axis, world frame, metres.
    up_world : (3,) float
        World direction that appears upward in the image (must not be parallel to the axis).
    fx : float
        Focal length in pixels; `fy` defaults to `fx` (square pixels).
    size : (width, height) int
        Image size in pixels.
    principal_px : (cx, cy) float, optional
        Principal point; defaults to the image centre ((W - 1) / 2, (H - 1) / 2).
    dist : (k,) float
        OpenCV distortion coefficients, k in DIST_LENGTHS.

    Returns
    -------
    Camera with R_cam_world rows = camera x (right), y (down), z (forward) axes in world frame.
    """
    c = np.asarray(position_world, dtype=np.float64).reshape(3)
    z = np.asarray(target_world, dtype=np.float64).reshape(3) - c
    if not np.linalg.norm(z) > 0:
        raise InputError(None, "target_world", "a point different from position_world", z.tolist())
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up_world, dtype=np.float64).reshape(3))
    if not np.linalg.norm(x) > 1e-9:
        raise InputError(None, "up_world", "a direction not parallel to the optical axis", up_world)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    w, h = int(size[0]), int(size[1])
    cx, cy = principal_px if principal_px is not None else ((w - 1) / 2.0, (h - 1) / 2.0)
    fy = fx if fy is None else fy
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    cam = Camera(name=name, size=(w, h), K=K, dist=np.asarray(dist, dtype=np.float64),
                 R_cam_world=R, t_cam_world=-R @ c)
    _check_camera(cam)
    return cam
