"""Projection with analytic Jacobians, and undistortion of pixels.

The camera model is :mod:`mocapfj.vision.camera`'s (OpenCV's ``projectPoints``, conventions in
docs/conventions.md). For bundle adjustment the parameters of one camera are

- pose: rotation vector ``r`` (3,) and translation ``t`` (3,) of ``p_cam = R(r) p_world + t``;
- intrinsics: ``fx, fy, cx, cy, k1, k2, p1, p2, k3`` (:data:`INTRINSIC_NAMES`); further OpenCV
  coefficients (k4, k5, k6, s1..s4) enter the projection and its point and pose derivatives but
  are held fixed. A tilted sensor (tau_x, tau_y) is not supported here.

Derivatives, with x = X/Z, y = Y/Z, r2 = x^2 + y^2, radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) /
(1 + k4 r2 + k5 r2^2 + k6 r2^3) and the distorted (xd, yd) of the camera module:

    d(xd, yd)/d(x, y)  from the product rule on the distortion polynomial (:func:`distort`)
    d(x, y)/d p_cam    = [[1/Z, 0, -X/Z^2], [0, 1/Z, -Y/Z^2]]
    d p_cam/d p_world  = R
    d p_cam/d t        = I
    d p_cam/d r        = -R [p_world]x (r r^T + (R^T - I) [r]x) / |r|^2

the last from Gallego and Yezzi (2015), eq. (9) (-[p_world]x at r = 0). Checked against finite
differences and against the Jacobian ``cv2.projectPoints`` returns (tests/vision/test_projection.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..types import Camera

__all__ = ["INTRINSIC_NAMES", "ProjectionJacobians", "camera_parameters", "distort", "project_batch",
           "project_jacobians", "rotation_jacobian", "undistort_points", "normalized_from_pixels"]

INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
"""Order of the intrinsic parameters in :func:`project_batch` and its Jacobian."""


def _skew(v: np.ndarray) -> np.ndarray:
    """[v]x for v (..., 3): (..., 3, 3)."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def _rotation(r: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation vectors (C, 3) to matrices (C, 3, 3)."""
    th = np.sqrt(np.einsum("ci,ci->c", r, r))
    small = th < 1e-12
    ths = np.where(small, 1.0, th)
    K = _skew(r / ths[:, None])
    s, c = np.sin(th)[:, None, None], np.cos(th)[:, None, None]
    R = np.eye(3) + s * K + (1.0 - c) * (K @ K)
    if small.any():
        R[small] = np.eye(3) + _skew(r[small])
    return R


def rotation_jacobian(r) -> tuple[np.ndarray, np.ndarray]:
    """R(r) and the matrix M of d(R(r) p)/dr = -R [p]x M (Gallego and Yezzi 2015, eq. 9).

    Parameters
    ----------
    r : (C, 3) float
        Rotation vectors, rad.

    Returns
    -------
    R : (C, 3, 3)
    M : (C, 3, 3)
        (r r^T + (R^T - I) [r]x) / |r|^2, the identity at r = 0.
    """
    r = np.atleast_2d(np.asarray(r, dtype=np.float64))
    R = _rotation(r)
    th2 = np.einsum("ci,ci->c", r, r)
    small = th2 < 1e-20
    th2s = np.where(small, 1.0, th2)
    M = (np.einsum("ci,cj->cij", r, r) + (np.swapaxes(R, 1, 2) - np.eye(3)) @ _skew(r)) / th2s[:, None, None]
    if small.any():
        M[small] = np.eye(3)
    return R, M


def distort(xy, dist14) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's distortion of normalised coordinates, without sensor tilt, and its 2 x 2 Jacobian.

    Parameters
    ----------
    xy : (N, 2) float
        Undistorted normalised coordinates (X/Z, Y/Z).
    dist14 : (14,) or (N, 14) float
        k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 (tau_x, tau_y ignored).

    Returns
    -------
    xy_d : (N, 2) float
    J : (N, 2, 2) float
        d(xd, yd) / d(x, y).
    """
    x, y = xy[..., 0], xy[..., 1]
    d = np.asarray(dist14, dtype=np.float64)
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = (d[..., i] for i in range(12))
    r2 = x * x + y * y
    a = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    b = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    da = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    db = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    radial = a / b
    drad = (da * b - a * db) / (b * b)
    xyp = x * y
    xd = x * radial + 2.0 * p1 * xyp + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xyp + r2 * (s3 + s4 * r2)
    tx = s1 + 2.0 * s2 * r2
    ty = s3 + 2.0 * s4 * r2
    J = np.empty(x.shape + (2, 2))
    J[..., 0, 0] = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x + 2.0 * x * tx
    J[..., 0, 1] = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * y * tx
    J[..., 1, 0] = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * x * ty
    J[..., 1, 1] = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x + 2.0 * y * ty
    return np.stack([xd, yd], axis=-1), J


def camera_parameters(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A camera's bundle-adjustment parameters.

    Returns
    -------
    rvec : (3,)  rotation vector of R_cam_world, rad
    tvec : (3,)  t_cam_world, m
    intrinsics : (9,)  fx, fy, cx, cy, k1, k2, p1, p2, k3 (:data:`INTRINSIC_NAMES`)
    extra : (9,)  k4, k5, k6, s1, s2, s3, s4, tau_x, tau_y (held fixed; tau must be 0)
    """
    from ..rotations import rotvec_from_matrix

    d = np.zeros(14)
    if camera.dist.size not in (0, 4, 5, 8, 12, 14):
        raise InputError(None, f"camera {camera.name!r} dist", "a length in (0, 4, 5, 8, 12, 14)", camera.dist.size)
    d[: camera.dist.size] = camera.dist
    if d[12] != 0.0 or d[13] != 0.0:
        raise InputError(None, f"camera {camera.name!r} dist", "no sensor tilt (tau_x = tau_y = 0) for calibration",
                         d[12:].tolist())
    K = camera.K
    intr = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], d[0], d[1], d[2], d[3], d[4]])
    return rotvec_from_matrix(camera.R_cam_world), camera.t_cam_world.copy(), intr, d[5:].copy()


@dataclass(frozen=True, eq=False)
class ProjectionJacobians:
    """Pixels and their derivatives for N observations.

    Attributes
    ----------
    xy_px : (N, 2) float
        Pixels; NaN where the point is not in front of its camera.
    d_point : (N, 2, 3) float
        d xy_px / d p_world, px per m.
    d_pose : (N, 2, 6) float
        d xy_px / d (r, t): rotation vector (px per rad), translation (px per m).
    d_intrinsics : (N, 2, 9) float
        d xy_px / d (fx, fy, cx, cy, k1, k2, p1, p2, k3).
    z_cam : (N,) float
        Depth of each point in its camera, m.
    """

    xy_px: np.ndarray
    d_point: np.ndarray
    d_pose: np.ndarray
    d_intrinsics: np.ndarray
    z_cam: np.ndarray


def project_batch(rvecs, tvecs, intrinsics, extra, camera_index, p_world, *,
                  jacobians: bool = True) -> ProjectionJacobians:
    """Project N points, each through its own camera, with analytic Jacobians.

    Parameters
    ----------
    rvecs, tvecs : (C, 3) float
        Each camera's pose, world to camera (rad, m).
    intrinsics : (C, 9) float
        fx, fy, cx, cy, k1, k2, p1, p2, k3 per camera.
    extra : (C, 9) float
        k4, k5, k6, s1, s2, s3, s4, tau_x, tau_y per camera (fixed; tau ignored: must be 0).
    camera_index : (N,) int
        Which camera sees each point.
    p_world : (N, 3) float
        The points, world frame, m.
    jacobians : bool
        False: only ``xy_px`` and ``z_cam`` are filled (the derivatives are None).
    """
    rvecs = np.atleast_2d(np.asarray(rvecs, dtype=np.float64))
    tvecs = np.atleast_2d(np.asarray(tvecs, dtype=np.float64))
    intr = np.atleast_2d(np.asarray(intrinsics, dtype=np.float64))
    ext = np.atleast_2d(np.asarray(extra, dtype=np.float64))
    ci = np.asarray(camera_index, dtype=np.intp)
    p = np.asarray(p_world, dtype=np.float64)
    R, M = rotation_jacobian(rvecs)
    RM = R @ M
    n = p.shape[0]
    uv = np.empty((n, 2))
    z = np.empty(n)
    if jacobians:
        d_point = np.empty((n, 2, 3))
        d_pose = np.empty((n, 2, 6))
        d_in = np.empty((n, 2, 9))
    # per camera (few cameras, many points): scalar coefficients and 3 x 3 matrix products; points
    # sorted by camera (as bundle adjustment passes them) are taken as slices
    ordered = R.shape[0] == 1 or bool(np.all(ci[1:] >= ci[:-1]))
    bounds = np.searchsorted(ci, np.arange(R.shape[0] + 1)) if ordered and R.shape[0] > 1 else None
    for c in range(R.shape[0]):
        if R.shape[0] == 1:
            idx = slice(None)
        elif bounds is not None:
            idx = slice(int(bounds[c]), int(bounds[c + 1]))
        else:
            idx = np.flatnonzero(ci == c)
        if isinstance(idx, np.ndarray) and not idx.size or isinstance(idx, slice) and idx.start == idx.stop is not None:
            continue
        out = _project_one(R[c], RM[c], tvecs[c], intr[c], ext[c], p[idx], jacobians)
        uv[idx], z[idx] = out[0], out[1]
        if jacobians:
            d_point[idx], d_pose[idx], d_in[idx] = out[2:]
    if not jacobians:
        return ProjectionJacobians(uv, None, None, None, z)
    return ProjectionJacobians(uv, d_point, d_pose, d_in, z)


def _project_one(R, RM, t, intr, extra, p, jacobians):
    """One camera's share of :func:`project_batch`: (uv, z[, d_point, d_pose, d_intrinsics])."""
    n = p.shape[0]
    w = p @ R.T                                             # R p
    pc = w + t
    z = pc[:, 2]
    in_front = z > 0.0
    zs = np.where(in_front, z, 1.0)
    xy = pc[:, :2] / zs[:, None]
    d14 = np.concatenate([intr[4:9], extra])
    xyd, Jd = distort(xy, d14)
    fx, fy = intr[0], intr[1]
    uv = xyd * (fx, fy) + intr[2:4]
    uv[~in_front] = np.nan
    if not jacobians:
        return uv, z
    # d uv / d p_cam = diag(f) Jd d(x, y)/d p_cam, d(x, y)/d p_cam = [[1, 0, -x], [0, 1, -y]] / z
    inv_z = 1.0 / zs
    duv_dpc = np.empty((n, 2, 3))
    duv_dpc[:, 0, :2] = Jd[:, 0] * (fx * inv_z)[:, None]
    duv_dpc[:, 1, :2] = Jd[:, 1] * (fy * inv_z)[:, None]
    duv_dpc[:, :, 2] = -(duv_dpc[:, :, 0] * xy[:, 0:1] + duv_dpc[:, :, 1] * xy[:, 1:2])
    d_point = (duv_dpc.reshape(-1, 3) @ R).reshape(n, 2, 3)        # 2-D products: far faster than batched
    # d p_cam / d r = -R [p]x M = -[R p]x (R M); a^T [w]x = (a x w)^T
    d_pose = np.empty((n, 2, 6))
    d_pose[:, :, :3] = -(np.cross(duv_dpc, w[:, None, :]).reshape(-1, 3) @ RM).reshape(n, 2, 3)
    d_pose[:, :, 3:] = duv_dpc
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    b = 1.0 + r2 * (d14[5] + r2 * (d14[6] + r2 * d14[7]))
    d_in = np.zeros((n, 2, 9))
    d_in[:, 0, 0] = xyd[:, 0]
    d_in[:, 1, 1] = xyd[:, 1]
    d_in[:, 0, 2] = 1.0
    d_in[:, 1, 3] = 1.0
    g = r2 / b
    for col in (4, 5, 8):                                    # k1, k2, k3: r2, r2^2, r2^3
        d_in[:, 0, col] = fx * x * g
        d_in[:, 1, col] = fy * y * g
        g = g * r2 if col != 5 else g * r2
    d_in[:, 0, 6] = fx * 2.0 * x * y                          # p1
    d_in[:, 1, 6] = fy * (r2 + 2.0 * y * y)
    d_in[:, 0, 7] = fx * (r2 + 2.0 * x * x)                   # p2
    d_in[:, 1, 7] = fy * 2.0 * x * y
    bad = ~in_front
    if bad.any():
        for a in (d_point, d_pose, d_in):
            a[bad] = np.nan
    return uv, z, d_point, d_pose, d_in


def project_jacobians(camera: Camera, p_world) -> ProjectionJacobians:
    """Project world points (N, 3) m through `camera`, with the Jacobians of :class:`ProjectionJacobians`."""
    p = np.asarray(p_world, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(None, "p_world", "an array of shape (N, 3)", f"shape {p.shape}")
    r, t, intr, extra = camera_parameters(camera)
    return project_batch(r[None], t[None], intr[None], extra[None], np.zeros(p.shape[0], np.intp), p)


def normalized_from_pixels(camera: Camera, xy_px, *, iterations: int = 20, tol: float = 1e-14) -> np.ndarray:
    """Undistorted normalised coordinates (X/Z, Y/Z) of pixels: the inverse of the distortion.

    Newton's method on ``distort(x) = ((u - cx) / fx, (v - cy) / fy)`` with the analytic 2 x 2
    Jacobian of :func:`distort` (OpenCV's ``undistortPoints`` uses a fixed-point iteration),
    started at the distorted coordinates; a sensor tilt is removed first with the inverse of its
    homography. Converges in a few steps wherever the distortion is invertible; pixels where it
    does not converge (beyond the fold of a strong radial polynomial) come back NaN.

    Parameters
    ----------
    camera : Camera
    xy_px : (..., 2) float
        Pixels (OpenCV convention); NaN stays NaN.

    Returns
    -------
    (..., 2) float
        Normalised coordinates in the camera frame.
    """
    from .camera import tilt_matrix

    xy = np.asarray(xy_px, dtype=np.float64)
    if xy.ndim < 1 or xy.shape[-1] != 2:
        raise InputError(None, "xy_px", "an array of shape (..., 2)", f"shape {xy.shape}")
    shape = xy.shape
    xy = xy.reshape(-1, 2)
    d = np.zeros(14)
    d[: camera.dist.size] = camera.dist
    K = camera.K
    target = np.stack([(xy[:, 0] - K[0, 2]) / K[0, 0], (xy[:, 1] - K[1, 2]) / K[1, 1]], axis=1)
    if d[12] != 0.0 or d[13] != 0.0:
        Minv = np.linalg.inv(tilt_matrix(d[12], d[13]))
        h = np.column_stack([target, np.ones(len(target))]) @ Minv.T
        target = h[:, :2] / h[:, 2:3]
    x = target.copy()
    for _ in range(int(iterations)):
        f, J = distort(x, d)
        e = target - f
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.stack([J[:, 1, 1] * e[:, 0] - J[:, 0, 1] * e[:, 1],
                             J[:, 0, 0] * e[:, 1] - J[:, 1, 0] * e[:, 0]], axis=1) / det[:, None]
        x = x + step
        if not np.nanmax(np.abs(step), initial=0.0) > tol:
            break
    f, J = distort(x, d)
    det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
    bad = ~((np.abs(f - target).max(axis=1) < 1e-9) & (det > 0.0))
    x[bad] = np.nan
    return x.reshape(shape)


def undistort_points(camera: Camera, xy_px, *, iterations: int = 20) -> np.ndarray:
    """Pixels with the distortion removed, in the same camera matrix K: (..., 2) px.

    Equivalent to ``cv2.undistortPoints(xy, K, dist, P=K)`` (or ``cv2.undistortImagePoints``),
    by Newton's method (:func:`normalized_from_pixels`).
    """
    n = normalized_from_pixels(camera, xy_px, iterations=iterations)
    K = camera.K
    return np.stack([K[0, 0] * n[..., 0] + K[0, 2], K[1, 1] * n[..., 1] + K[1, 2]], axis=-1)
