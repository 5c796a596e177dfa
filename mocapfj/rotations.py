"""Rotations: the one place mocapfj builds, applies and takes apart rotation matrices.

Right-handed rotations about a unit axis n by an angle q (rad), Rodrigues' formula
``R(n, q) = I + sin q [n]x + (1 - cos q) [n]x^2`` (docs/conventions.md: rotations are matrices or
rotation vectors, never Euler angles). Rotation vectors (axis x angle, OpenCV's ``rvec``) convert
through scipy's :class:`~scipy.spatial.transform.Rotation`. Everything is batched: leading
dimensions broadcast, no loops.
"""

from __future__ import annotations

import numpy as np
from .errors import InputError

__all__ = ["skew", "matrix_from_axis_angle", "rotate", "matrix_from_rotvec", "rotvec_from_matrix", "twist_angle"]


def _unit(axis) -> np.ndarray:
    n = np.asarray(axis, dtype=np.float64)
    if n.shape[-1:] != (3,):
        raise InputError(None, "axis", "shape (3,) or (..., 3)", f"shape {n.shape}")
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    if not np.all(norm > 0):
        raise InputError(None, "axis", "a non-zero direction", "a zero vector")
    return n / norm


def skew(n) -> np.ndarray:
    """Cross-product matrices K (..., 3, 3) of vectors n (..., 3): K @ a = n x a."""
    n = np.asarray(n, dtype=np.float64)
    K = np.zeros(n.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -n[..., 2], n[..., 1], -n[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = n[..., 2], -n[..., 1], n[..., 0]
    return K


def matrix_from_axis_angle(axis, q) -> np.ndarray:
    """Rotation matrices R(n, q) (..., 3, 3) about `axis` (3,) or (..., 3) (normalised here) by
    `q` (rad, scalar or (...,)); axis and angle broadcast over their leading dimensions."""
    n = _unit(axis)
    q = np.asarray(q, dtype=np.float64)
    shape = np.broadcast_shapes(n.shape[:-1], q.shape)
    K = skew(np.broadcast_to(n, shape + (3,)))
    s, c1 = np.sin(q)[..., None, None], (1.0 - np.cos(q))[..., None, None]
    return np.eye(3) + s * K + c1 * (K @ K)


def rotate(axis, q, v) -> np.ndarray:
    """R(n, q) v for vectors v (..., 3): `q` (...) and `v` broadcast; the axis is one (3,) unit
    direction (normalised here). ``rotate(n, q[:, None], a[None])`` rotates P template points
    a (P, 3) by each of T angles q (T,), giving (T, P, 3)."""
    n = _unit(axis)
    if n.ndim != 1:
        raise InputError(None, "axis", "one direction of shape (3,)", f"shape {n.shape}")
    q = np.asarray(q, dtype=np.float64)[..., None]
    v = np.asarray(v, dtype=np.float64)
    c, s = np.cos(q), np.sin(q)
    return v * c + (v @ skew(n).T) * s + n * (v @ n)[..., None] * (1.0 - c)


def matrix_from_rotvec(r) -> np.ndarray:
    """Rotation vector(s) (3,) or (N, 3) (axis x angle, rad; OpenCV's rvec) to matrices."""
    from scipy.spatial.transform import Rotation     # scipy.spatial costs 0.2 s to import: on first use

    return Rotation.from_rotvec(np.asarray(r, dtype=np.float64)).as_matrix()


def rotvec_from_matrix(R) -> np.ndarray:
    """Rotation matrices (3, 3) or (N, 3, 3) to rotation vectors (axis x angle, rad)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_rotvec()


def twist_angle(R, axis) -> np.ndarray:
    """Angle of the rotations R (T, 3, 3) about `axis` (3,): the twist of their swing-twist split,
    unwrapped over time, rad; NaN where R is NaN.

    With the quaternion (w, v) of R, the twist about n is 2 atan2(v . n, w).
    """
    R = np.asarray(R, dtype=np.float64)
    n = _unit(axis)
    ok = np.isfinite(R[:, 0, 0])
    w = 1.0 + R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2]                                       # 4 w^2
    vx, vy, vz = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]  # 4 w v
    q = 2.0 * np.arctan2(vx * n[0] + vy * n[1] + vz * n[2], w)
    q[ok] = np.unwrap(q[ok])
    q[~ok] = np.nan
    return q
