"""Points seen by several calibrated cameras: batched N-view triangulation with uncertainty.

Every function takes the observations of N points in C cameras as one array ``xy_px`` (C, N, 2)
(pixels, OpenCV convention, docs/conventions.md), NaN where a camera did not see a point, so that
any subset of cameras can see any point and no Python loop runs over points (the per-point
passes are compiled).

1. **Undistortion** by a table per camera (:class:`UndistortionTable`): a fitted approximate
   inverse of the distortion (radial and tangential terms, least squares) plus a bilinearly
   interpolated grid of what it leaves against the exact inverse (Newton's method,
   :func:`mocapfj.vision.projection.normalized_from_pixels`). The grid is refined until the error
   at the cells' centres and edge midpoints, where a bilinear interpolant errs most, is below
   ``tol_px`` (1e-3 px by default), and that bound is recorded.
2. **Linear triangulation** (:func:`triangulate_linear`): the DLT's equations
   ``(x P3 - P1) X~ = 0``, ``(y P3 - P2) X~ = 0`` for each view (Hartley and Zisserman 2003, §12.2),
   with X~ = (X, 1) (their inhomogeneous variant). The normal matrix of a point is
   ``sum_c (x^2 + y^2) P3 P3^T - x (P3 P1^T + P1 P3^T) - y (P3 P2^T + P2 P3^T) + P1 P1^T + P2 P2^T``,
   linear in the features (x^2 + y^2, x, y, 1) of each view with fixed 4 x 9 blocks per camera
   (:func:`dlt_feature_matrix`), solved in closed form. Undistortion, sum and solve run in one
   compiled pass per point (numba, imported on first use as in :mod:`mocapfj.dynamics`).
3. **Gauss-Newton** on the reprojection error in pixels (:func:`triangulate`), with the analytic
   point Jacobian of the camera model of :mod:`mocapfj.vision.projection` (its distortion and
   distortion Jacobian, :func:`~mocapfj.vision.projection.distort`); all points at once, each
   step one compiled pass over every point's views.
4. **Robust camera subsets**: points with a view beyond the gate are triangulated again from every
   pair of their cameras at once (the pairs' normal matrices are sums of the views'), every pair's
   point is projected into every camera, and the pair with the least truncated cost (MSAC; Torr and
   Zisserman 2000) sets the inliers, which are refined again. Exhaustive over pairs and vectorised:
   the same input gives the same answer.
5. **Covariance** ``sigma^2 (J^T J)^-1`` of each point from the pixel noise sigma (the rig's
   ``sigma_px``, an argument, or the pooled residuals), the first-order error propagation of the
   refinement's Jacobian J (Hartley and Zisserman 2003, §5.2).

Conventions: world-to-camera extrinsics, metres, pixels 0-based at pixel centres (docs/conventions.md).
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..types import Camera, Rig
from .projection import camera_parameters, normalized_from_pixels, project_batch, rotation_jacobian

__all__ = ["UndistortionTable", "undistortion_table", "triangulate_linear", "triangulate", "Triangulation",
           "observation_array", "rig_sigma_px", "dlt_feature_matrix", "solve_dlt", "rig_parameters"]

_CHUNK = 32768
_IU = (np.array([0, 0, 0, 1, 1, 2, 0, 1, 2]), np.array([0, 1, 2, 1, 2, 2, 3, 3, 3]))
"""The 9 entries of the 4 x 4 normal matrix the linear solve needs: a00 a01 a02 a11 a12 a22 and the
last column b0 b1 b2."""


# --- undistortion table ---------------------------------------------------------------------------

def _approximate_inverse(coef: np.ndarray, xd: np.ndarray, yd: np.ndarray):
    """The fitted approximate inverse of the distortion at distorted normalised coordinates:
    radial x_d (1 + c1 r^2 + c2 r^4 + c3 r^6) plus tangential terms q1, q2 of Brown's form."""
    c1, c2, c3, q1, q2 = coef
    r2 = xd * xd + yd * yd
    g = 1.0 + r2 * (c1 + r2 * (c2 + r2 * c3))
    xy2 = 2.0 * xd * yd
    return xd * g + q1 * xy2 + q2 * (r2 + 2.0 * xd * xd), yd * g + q1 * (r2 + 2.0 * yd * yd) + q2 * xy2


def _fit_inverse(xd: np.ndarray, yd: np.ndarray, xn: np.ndarray, yn: np.ndarray) -> np.ndarray:
    """Least-squares coefficients (c1, c2, c3, q1, q2) of :func:`_approximate_inverse` from
    distorted (xd, yd) to undistorted (xn, yn) coordinates (finite pairs only)."""
    ok = np.isfinite(xn) & np.isfinite(yn)
    xd, yd, xn, yn = xd[ok], yd[ok], xn[ok], yn[ok]
    if xd.size < 10:
        return np.zeros(5)
    r2 = xd * xd + yd * yd
    Ax = np.stack([xd * r2, xd * r2**2, xd * r2**3, 2 * xd * yd, r2 + 2 * xd * xd], axis=1)
    Ay = np.stack([yd * r2, yd * r2**2, yd * r2**3, r2 + 2 * yd * yd, 2 * xd * yd], axis=1)
    coef, *_ = np.linalg.lstsq(np.vstack([Ax, Ay]), np.r_[xn - xd, yn - yd], rcond=None)
    return coef if np.isfinite(coef).all() else np.zeros(5)


@dataclass(frozen=True, eq=False)
class UndistortionTable:
    """Undistorted normalised coordinates of pixels: a fitted approximate inverse of the distortion
    plus a bilinearly interpolated table of what it leaves on a pixel grid.

    The approximate inverse (radial in r^2, r^4, r^6 and tangential, least squares over the grid)
    takes up most of the inverse's curvature, so that the table of its residual, whose bilinear
    error scales with that curvature, meets the bound on a coarse grid (32-64 px instead of 4-8):
    small enough to stay in the processor's cache, which random pixels otherwise miss.

    Attributes
    ----------
    camera : Camera
    x0_px, y0_px : float
        Pixel position of grid node (0, 0).
    step_px : float
        Grid spacing, pixels.
    xn, yn : (ny, nx) float
        Normalised coordinates (X/Z, Y/Z) at the nodes; NaN where the distortion cannot be inverted.
    max_error_px : float
        Largest error found at the cells' centres and edge midpoints (the worst places of a
        bilinear interpolant), converted to pixels with the focal length.
    coef : (5,) float
        The approximate inverse's c1, c2, c3, q1, q2 (:func:`_approximate_inverse`).
    """

    camera: Camera
    x0_px: float
    y0_px: float
    step_px: float
    xn: np.ndarray
    yn: np.ndarray
    max_error_px: float
    coef: np.ndarray = field(default_factory=lambda: np.zeros(5))

    def __post_init__(self) -> None:
        K = self.camera.K
        ny, nx = self.xn.shape
        gx = self.x0_px + self.step_px * np.arange(nx)
        gy = self.y0_px + self.step_px * np.arange(ny)
        xd = ((gx - K[0, 2]) / K[0, 0])[None].repeat(ny, 0)
        yd = ((gy - K[1, 2]) / K[1, 1])[:, None].repeat(nx, 1)
        ax, ay = _approximate_inverse(self.coef, xd, yd)
        # the tables of the residuals, as the compiled kernels read them
        object.__setattr__(self, "rx", np.ascontiguousarray((self.xn - ax).ravel()))
        object.__setattr__(self, "ry", np.ascontiguousarray((self.yn - ay).ravel()))

    def normalized(self, xy_px) -> np.ndarray:
        """Normalised coordinates (..., 2) of pixels (..., 2); NaN stays NaN. Pixels outside the
        table (beyond the image by more than a cell), or in a cell it cannot interpolate, are
        undistorted exactly by Newton's method."""
        xy = np.ascontiguousarray(xy_px, dtype=np.float64)
        shape = xy.shape
        xy = xy.reshape(-1, 2)
        ny, nx = self.xn.shape
        K = self.camera.K
        out = np.empty(xy.shape)
        redo = np.zeros(xy.shape[0], bool)
        _normalized_kernel()(xy, self.rx, self.ry, nx, ny, self.x0_px, self.y0_px, 1.0 / self.step_px,
                             np.array([K[0, 2], K[1, 2], 1.0 / K[0, 0], 1.0 / K[1, 1]]), self.coef, out, redo)
        if redo.any():
            out[redo] = normalized_from_pixels(self.camera, xy[redo])
        return out.reshape(shape)


_TABLES: dict = {}
_TABLES_MAX = 64


def undistortion_table(camera: Camera, *, tol_px: float = 1e-3, step_px: float = 64.0,
                       min_step_px: float = 1.0) -> UndistortionTable:
    """The undistortion table of `camera`, its grid refined until its error is below `tol_px`.

    The grid spans the image and a margin of two cells (at most 16 px) beyond it; its step starts
    at `step_px` and is halved (not below `min_step_px`; once or twice, as the error's scaling with
    step^2 predicts) while the error at the cells' centres and edge midpoints exceeds `tol_px` and
    shrinks with the step (it does not where the distortion folds over inside the grid). The error
    found is recorded either way.
    Tables depend on the intrinsics only (size, K, distortion) and are cached by them.
    """
    key = (camera.size, camera.K.tobytes(), camera.dist.tobytes(), float(tol_px), float(step_px), float(min_step_px))
    cached = _TABLES.get(key)
    if cached is not None:
        return cached
    w, h = camera.size
    K = camera.K
    f = float(min(K[0, 0], K[1, 1]))
    step = float(step_px)
    coef = None
    prev = math.inf
    # where a bilinear interpolant errs most: the cells' centres (curvatures of one sign) and the
    # midpoints of their edges (of opposite signs)
    sub = np.array([[0.5, 0.5], [0.5, 0.0], [0.0, 0.5]])
    while True:
        m = min(2 * step, 16.0)                        # the grid's margin beyond the image, px
        gx = -0.5 - m + step * np.arange(math.ceil((w + 2 * m) / step) + 1)
        gy = -0.5 - m + step * np.arange(math.ceil((h + 2 * m) / step) + 1)
        X, Y = np.meshgrid(gx, gy)
        n = normalized_from_pixels(camera, np.stack([X, Y], axis=-1))
        if coef is None:                                # fitted once, over the image
            inside = (X >= -0.5) & (X <= w - 0.5) & (Y >= -0.5) & (Y <= h - 0.5)
            coef = _fit_inverse(((X - K[0, 2]) / K[0, 0])[inside], ((Y - K[1, 2]) / K[1, 1])[inside],
                                n[..., 0][inside], n[..., 1][inside])
        table = UndistortionTable(camera, float(gx[0]), float(gy[0]), step, n[..., 0].copy(), n[..., 1].copy(),
                                  math.nan, coef)
        cx, cy = np.meshgrid(gx[:-1], gy[:-1])
        mid = np.concatenate([np.stack([cx.ravel() + step * a, cy.ravel() + step * b], axis=1) for a, b in sub])
        err = np.abs(table.normalized(mid) - normalized_from_pixels(camera, mid)).max(axis=1) * f
        worst = float(np.nanmax(err, initial=0.0))
        if worst <= tol_px or step / 2 < min_step_px or not worst < 0.7 * prev:
            break                 # the bound holds, or the grid is at its finest, or the error does
        prev = worst              # not shrink with the step (no smooth inverse there: a fold)
        # the bilinear error scales with step^2: halve as often as that predicts, at most twice
        halvings = min(2, max(1, math.ceil(math.log2(math.sqrt(worst / tol_px))))) if math.isfinite(worst) else 1
        step = max(step / 2**halvings, min_step_px)
    for a in (table.xn, table.yn):
        a.setflags(write=False)
    table = UndistortionTable(camera, table.x0_px, table.y0_px, step, table.xn, table.yn, worst, coef)
    if len(_TABLES) >= _TABLES_MAX:
        _TABLES.pop(next(iter(_TABLES)))
    _TABLES[key] = table
    return table


# --- input ------------------------------------------------------------------------------------

def _shape_checked(rig: Rig, xy_px, where: str) -> np.ndarray:
    """xy (C, N, 2) float64 after the rig and shape checks."""
    if not isinstance(rig, Rig):
        raise InputError(None, "rig", "a Rig", type(rig).__name__)
    xy = np.asarray(xy_px, dtype=np.float64)
    n_cam = len(rig.cameras)
    if xy.ndim != 3 or xy.shape[2] != 2:
        raise InputError(where, "xy_px", "an array of shape (C, N, 2): pixels per camera and point", f"shape {xy.shape}")
    if xy.shape[0] != n_cam:
        raise InputError(where, "cameras", f"{n_cam} cameras (the rig's)", f"{xy.shape[0]} cameras in the observations")
    return xy


def _observations(rig: Rig, xy_px, where: str) -> tuple[np.ndarray, np.ndarray, int]:
    """(xy (C, N, 2) float64, valid (C, N) bool, number of non-finite pixels ignored)."""
    xy = _shape_checked(rig, xy_px, where)
    fin = np.isfinite(xy)
    f0, f1 = fin[..., 0], fin[..., 1]
    finite = f0 & f1
    n_bad = int(np.count_nonzero(f0 ^ f1))                   # one coordinate NaN, or an inf
    if not finite.all():
        rest = xy[~finite]
        n_bad += int(np.count_nonzero(np.isinf(rest).all(axis=1)))
    return xy, finite, n_bad


def rig_sigma_px(rig: Rig) -> float | None:
    """The rig file's pixel noise (``[metadata] sigma_px``), or None when it has none."""
    v = rig.metadata.get("sigma_px") if isinstance(rig.metadata, dict) else None
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) and v > 0 else None


# --- linear step ----------------------------------------------------------------------------------

def dlt_feature_matrix(rig: Rig) -> np.ndarray:
    """(4C, 9): row 4c + k maps feature k of camera c, (x^2 + y^2, x, y, 1), to the 9 entries."""
    out = np.zeros((4 * len(rig.cameras), 9))
    for c, cam in enumerate(rig.cameras):
        P = np.hstack([cam.R_cam_world, cam.t_cam_world[:, None]])
        p1, p2, p3 = P
        mats = (np.outer(p3, p3), -(np.outer(p3, p1) + np.outer(p1, p3)), -(np.outer(p3, p2) + np.outer(p2, p3)),
                np.outer(p1, p1) + np.outer(p2, p2))
        for k, m in enumerate(mats):
            out[4 * c + k] = m[_IU]
    return out


def solve_dlt(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """X (n, 3) from the 9 normal-matrix entries (9, n) or (n, 9) last axis; and det (n,).

    A X = -b with A = [[a00 a01 a02] [a01 a11 a12] [a02 a12 a22]] by the adjugate."""
    a, b, c, e, f, h, r0, r1, r2 = (m[..., k] for k in range(9))
    A11 = e * h - f * f
    A12 = c * f - b * h
    A13 = b * f - c * e
    A22 = a * h - c * c
    A23 = b * c - a * f
    A33 = a * e - b * b
    det = a * A11 + b * A12 + c * A13
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = -1.0 / det
        x = np.stack([(A11 * r0 + A12 * r1 + A13 * r2) * inv, (A12 * r0 + A22 * r1 + A23 * r2) * inv,
                      (A13 * r0 + A23 * r1 + A33 * r2) * inv], axis=-1)
    return x, det


def _normalized_views(rig: Rig, xy: np.ndarray, valid: np.ndarray, sl: slice, tables) -> np.ndarray:
    """Features (4C, n) of points `sl`: (x^2 + y^2, x, y, 1) per camera, zero where unseen."""
    n = sl.stop - sl.start
    feats = np.zeros((4 * len(rig.cameras), n))
    for c in range(len(rig.cameras)):
        v = valid[c, sl]
        if not v.any():
            continue
        nrm = tables[c].normalized(xy[c, sl])
        ok = v & np.isfinite(nrm[:, 0])
        x = np.where(ok, nrm[:, 0], 0.0)
        y = np.where(ok, nrm[:, 1], 0.0)
        feats[4 * c] = x * x + y * y
        feats[4 * c + 1] = x
        feats[4 * c + 2] = y
        feats[4 * c + 3] = ok
    return feats


def _undistort_py(u, v, tx, ty, base, nx, ny, x0, y0, inv, kc, coef):  # pragma: no cover - compiled
    """One pixel (u, v) to normalised coordinates by a camera's table (as
    :meth:`UndistortionTable.normalized`): the bilinear residual table (tx, ty from flat index
    `base`, nx x ny nodes from (x0, y0) at 1 / inv px) plus the approximate inverse (kc: cx, cy,
    1/fx, 1/fy; coef: k1, k2, k3, p1, p2). (x, y, ok): ok False beyond the table or in a cell it
    cannot interpolate."""
    gx = (u - x0) * inv
    gy = (v - y0) * inv
    if not (gx >= 0.0 and gx < nx - 1 and gy >= 0.0 and gy < ny - 1):
        return 0.0, 0.0, False
    ix = int(gx)
    iy = int(gy)
    ax = gx - ix
    ay = gy - iy
    i0 = base + iy * nx + ix
    i2 = i0 + nx
    a = tx[i0]
    top = a + ax * (tx[i0 + 1] - a)
    b = tx[i2]
    x = top + ay * (b + ax * (tx[i2 + 1] - b) - top)
    a = ty[i0]
    top = a + ax * (ty[i0 + 1] - a)
    b = ty[i2]
    y = top + ay * (b + ax * (ty[i2 + 1] - b) - top)
    if not (np.isfinite(x) and np.isfinite(y)):
        return 0.0, 0.0, False
    xd = (u - kc[0]) * kc[2]
    yd = (v - kc[1]) * kc[3]
    r2 = xd * xd + yd * yd
    g = 1.0 + r2 * (coef[0] + r2 * (coef[1] + r2 * coef[2]))
    xy2 = 2.0 * xd * yd
    x += xd * g + coef[3] * xy2 + coef[4] * (r2 + 2.0 * xd * xd)
    y += yd * g + coef[3] * (r2 + 2.0 * yd * yd) + coef[4] * xy2
    return x, y, True


def _linear_py(xy, w, use_w, tx, ty, off, nx, ny, x0, y0, inv, kc, coef, G, out, n_views,
               outside):  # pragma: no cover - compiled
    """The linear step of points (compiled by :func:`_linear_kernel`): per point, each finite view
    is undistorted by its camera's table (as :meth:`UndistortionTable.normalized`: the approximate
    inverse plus the residual table, bilinear), its features (x^2 + y^2, x, y, 1) (times its
    weight) enter the 9 normal-matrix entries through G (C, 4, 9), and the 3 x 3 system is solved
    by the adjugate (as :func:`solve_dlt`). A view beyond its table, or in a cell the table cannot
    interpolate, sets ``outside``: the caller redoes that point."""
    C, N = xy.shape[0], xy.shape[1]
    m = np.empty(9)
    for n in range(N):
        for k in range(9):
            m[k] = 0.0
        nv = 0
        for c in range(C):
            u = xy[c, n, 0]
            v = xy[c, n, 1]
            if not (np.isfinite(u) and np.isfinite(v)):
                continue
            nv += 1
            x, y, ok = _undistort(u, v, tx, ty, off[c], nx[c], ny[c], x0[c], y0[c], inv[c], kc[c], coef[c])
            if not ok:
                outside[n] = True
                continue
            wt = w[c, n] if use_w else 1.0
            f0 = (x * x + y * y) * wt
            f1 = x * wt
            f2 = y * wt
            for k in range(9):
                m[k] += f0 * G[c, 0, k] + f1 * G[c, 1, k] + f2 * G[c, 2, k] + wt * G[c, 3, k]
        n_views[n] = nv
        a_, b_, c_, e_, f_, h_, r0, r1, r2 = m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8]
        A11 = e_ * h_ - f_ * f_
        A12 = c_ * f_ - b_ * h_
        A13 = b_ * f_ - c_ * e_
        A22 = a_ * h_ - c_ * c_
        A23 = b_ * c_ - a_ * f_
        A33 = a_ * e_ - b_ * b_
        det = a_ * A11 + b_ * A12 + c_ * A13
        if nv < 2 or det == 0.0:
            out[n, 0] = out[n, 1] = out[n, 2] = np.nan
            continue
        iv = -1.0 / det
        out[n, 0] = (A11 * r0 + A12 * r1 + A13 * r2) * iv
        out[n, 1] = (A12 * r0 + A22 * r1 + A23 * r2) * iv
        out[n, 2] = (A13 * r0 + A23 * r1 + A33 * r2) * iv


def _normalized_py(xy, rx, ry, nx, ny, x0, y0, inv, kc, coef, out, redo):  # pragma: no cover - compiled
    """Normalised coordinates of pixels xy (n, 2) of one camera (compiled by :func:`_normalized_kernel`;
    the arithmetic of :func:`_linear_py`'s undistortion). NaN pixels give NaN; pixels beyond the
    table or in a cell it cannot interpolate set ``redo``."""
    for n in range(xy.shape[0]):
        u = xy[n, 0]
        v = xy[n, 1]
        out[n, 0] = out[n, 1] = np.nan
        if not (np.isfinite(u) and np.isfinite(v)):
            continue
        x, y, ok = _undistort(u, v, rx, ry, 0, nx, ny, x0, y0, inv, kc, coef)
        if not ok:
            redo[n] = True
            continue
        out[n, 0] = x
        out[n, 1] = y


_NORMALIZED = None
_undistort = None       # compiled by _undistort_compiled(): a module global, so numba's disk cache holds


def _undistort_compiled():
    """Compile the one-pixel undistortion both kernels inline (numba imported on first use)."""
    global _undistort
    if _undistort is None:
        from numba import njit
        _undistort = njit(cache=True, inline="always")(_undistort_py)


def _normalized_kernel():
    """The compiled undistortion of one camera's pixels (numba, imported on first use)."""
    global _NORMALIZED
    if _NORMALIZED is None:
        from numba import njit
        _undistort_compiled()
        _NORMALIZED = njit(cache=True, nogil=True)(_normalized_py)
    return _NORMALIZED


_LINEAR = None


def _linear_kernel():
    """The compiled linear step (numba is imported on first use, as elsewhere in mocapfj): the
    undistortion, the features and the 3 x 3 solve of a point in one pass over its views, where
    numpy would pass over every intermediate array (about 30 passes per view)."""
    global _LINEAR
    if _LINEAR is None:
        from numba import njit
        _undistort_compiled()
        _LINEAR = njit(cache=True, nogil=True)(_linear_py)
    return _LINEAR


def _packed_tables(tables):
    """The tables of the cameras as the kernel takes them: xn, yn concatenated, offsets, sizes,
    origins, inverse steps."""
    key = tuple(id(t) for t in tables)
    hit = _PACKED.get(key)
    if hit is not None and all(a is b for a, b in zip(hit[0], tables)):
        return hit[1]
    sizes = [t.xn.size for t in tables]
    packed = (np.concatenate([t.rx for t in tables]), np.concatenate([t.ry for t in tables]),
              np.cumsum([0] + sizes[:-1]).astype(np.int64), np.array([t.xn.shape[1] for t in tables], np.int64),
              np.array([t.xn.shape[0] for t in tables], np.int64), np.array([t.x0_px for t in tables]),
              np.array([t.y0_px for t in tables]), np.array([1.0 / t.step_px for t in tables]),
              np.array([[t.camera.K[0, 2], t.camera.K[1, 2], 1.0 / t.camera.K[0, 0], 1.0 / t.camera.K[1, 1]]
                        for t in tables]), np.stack([t.coef for t in tables]))
    if len(_PACKED) >= 16:
        _PACKED.pop(next(iter(_PACKED)))
    _PACKED[key] = (list(tables), packed)
    return packed


_PACKED: dict = {}


def triangulate_linear(rig: Rig, xy_px, *, weights=None, workers: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Linear (DLT) triangulation of N points from any subset of C cameras each.

    Parameters
    ----------
    rig : Rig
        C calibrated cameras.
    xy_px : (C, N, 2) float
        Pixels, NaN where a camera did not see the point (a view counts when both coordinates
        are finite).
    weights : (C, N) float, optional
        Weight of each view (e.g. 1 / sigma^2); default 1.
    workers : int, optional
        Threads over chunks of 32768 points (the compiled kernel releases the GIL); default the
        number of cores. The result does not depend on it.

    Returns
    -------
    p_world : (N, 3) float
        Metres; NaN for points seen by fewer than two cameras.
    n_views : (N,) int
        Views used.
    """
    xy = _shape_checked(rig, xy_px, "triangulate_linear")
    tables = [undistortion_table(c) for c in rig.cameras]
    packed = _packed_tables(tables)
    G = dlt_feature_matrix(rig).reshape(-1, 4, 9)
    C, n = xy.shape[:2]
    out = np.empty((n, 3))
    n_views = np.zeros(n, np.int64)
    outside = np.zeros(n, bool)
    use_w = weights is not None
    wts = np.zeros((C, 1))
    if use_w:                         # a writable (C, n) array: the kernel's one compiled signature
        wts = np.asarray(weights, dtype=np.float64)
        if wts.shape != (C, n) or not wts.flags.writeable:
            wts = np.broadcast_to(wts, (C, n)).copy()
    kernel = _linear_kernel()

    def chunk(s):
        sl = slice(s, min(n, s + _CHUNK))
        kernel(xy[:, sl], wts[:, sl] if use_w else wts, use_w, *packed, G, out[sl], n_views[sl], outside[sl])

    starts = range(0, n, _CHUNK)
    workers = os.cpu_count() or 1 if workers is None else int(workers)
    if workers > 1 and n > _CHUNK:
        with ThreadPoolExecutor(max_workers=workers) as ex:
            list(ex.map(chunk, starts))
    else:
        for s in starts:
            chunk(s)
    if outside.any():                  # views beyond the tables: undistorted exactly, in numpy
        idx = np.flatnonzero(outside)
        sub = xy[:, idx]
        valid = np.isfinite(sub).all(axis=2)
        F = _normalized_views(rig, sub, valid, slice(0, idx.size), tables)
        if use_w:
            F *= np.repeat(np.where(valid, wts[:, idx], 0.0), 4, axis=0)
        out[idx] = solve_dlt((G.reshape(-1, 9).T @ F).T)[0]
        out[idx[n_views[idx] < 2]] = np.nan
    return out, n_views


# --- refinement -----------------------------------------------------------------------------------

def rig_parameters(rig: Rig):
    """Stacked bundle-adjustment parameters of the rig's cameras, as :func:`project_batch` takes them:
    (rvecs (C, 3), tvecs (C, 3), intrinsics (C, 9), extra (C, 9))."""
    ps = [camera_parameters(c) for c in rig.cameras]
    return tuple(np.stack([p[k] for p in ps]) for k in range(4))


def _gn_step_py(R, tv, intr, d14, xy, use, w, p, Hn, res, zz):  # pragma: no cover - compiled
    """One Gauss-Newton step of every point (compiled by :func:`_gn_kernel`): for each used view the
    projection and its point Jacobian (the camera model of :func:`~mocapfj.vision.projection.project_batch`
    without sensor tilt: :func:`~mocapfj.vision.projection.distort`'s distortion and distortion
    Jacobian J_dist, and d uv / d p = diag(f) J_dist [[1, 0, -x], [0, 1, -y]] / Z R, in scalar
    arithmetic), H = sum w J^T J and g = sum w J^T r
    over the views in camera order (as the bincount did), the step -H^-1 g (0 where det H <= 0),
    and the residuals predicted linearly at the new point. Writes p, Hn (N, 9), res (C, N, 2) and
    zz (C, N) of the used views; returns the largest |step|."""
    C, N = use.shape
    Jl = np.empty((C, 2, 3))
    rl = np.empty((C, 2))
    gl = np.empty(C, np.bool_)
    smax = 0.0
    for n in range(N):
        for k in range(9):
            Hn[n, k] = 0.0
        if not np.isfinite(p[n, 0]):
            continue
        q0, q1, q2 = p[n, 0], p[n, 1], p[n, 2]
        h = Hn[n]
        for c in range(C):
            if not use[c, n]:
                continue
            X = R[c, 0, 0] * q0 + R[c, 0, 1] * q1 + R[c, 0, 2] * q2 + tv[c, 0]
            Y = R[c, 1, 0] * q0 + R[c, 1, 1] * q1 + R[c, 1, 2] * q2 + tv[c, 1]
            Z = R[c, 2, 0] * q0 + R[c, 2, 1] * q1 + R[c, 2, 2] * q2 + tv[c, 2]
            zz[c, n] = Z
            zs = Z if Z > 0.0 else np.nan
            x = X / zs
            y = Y / zs
            k1, k2, p1, p2, k3 = d14[c, 0], d14[c, 1], d14[c, 2], d14[c, 3], d14[c, 4]
            k4, k5, k6, s1, s2, s3, s4 = d14[c, 5], d14[c, 6], d14[c, 7], d14[c, 8], d14[c, 9], d14[c, 10], d14[c, 11]
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
            j00 = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x + 2.0 * x * tx
            j01 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * y * tx
            j10 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * x * ty
            j11 = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x + 2.0 * y * ty
            fx, fy = intr[c, 0], intr[c, 1]
            r0 = (fx * xd + intr[c, 2]) - xy[c, n, 0]
            r1 = (fy * yd + intr[c, 3]) - xy[c, n, 1]
            for row in range(2):
                f = fx if row == 0 else fy
                a0 = f * (j00 if row == 0 else j10) / zs
                a1 = f * (j01 if row == 0 else j11) / zs
                a2 = -(a0 * x + a1 * y)
                for k in range(3):
                    Jl[c, row, k] = a0 * R[c, 0, k] + a1 * R[c, 1, k] + a2 * R[c, 2, k]
            good = np.isfinite(r0) and np.isfinite(r1)
            gl[c] = good
            if not good:
                for row in range(2):
                    for k in range(3):
                        Jl[c, row, k] = 0.0
                r0 = 0.0
                r1 = 0.0
            rl[c, 0] = r0
            rl[c, 1] = r1
            ww = w[c, n] if good else 0.0
            J0, J1 = Jl[c, 0], Jl[c, 1]
            h[0] += ww * (J0[0] * J0[0] + J1[0] * J1[0])
            h[1] += ww * (J0[0] * J0[1] + J1[0] * J1[1])
            h[2] += ww * (J0[0] * J0[2] + J1[0] * J1[2])
            h[3] += ww * (J0[1] * J0[1] + J1[1] * J1[1])
            h[4] += ww * (J0[1] * J0[2] + J1[1] * J1[2])
            h[5] += ww * (J0[2] * J0[2] + J1[2] * J1[2])
            h[6] += ww * (J0[0] * r0 + J1[0] * r1)
            h[7] += ww * (J0[1] * r0 + J1[1] * r1)
            h[8] += ww * (J0[2] * r0 + J1[2] * r1)
        a_, b_, c_, e_, f_, hh, g0, g1, g2 = h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]
        A11 = e_ * hh - f_ * f_
        A12 = c_ * f_ - b_ * hh
        A13 = b_ * f_ - c_ * e_
        A22 = a_ * hh - c_ * c_
        A23 = b_ * c_ - a_ * f_
        A33 = a_ * e_ - b_ * b_
        det = a_ * A11 + b_ * A12 + c_ * A13
        s0 = s1_ = s2_ = 0.0
        if det > 0.0:
            iv = -1.0 / det
            s0 = (A11 * g0 + A12 * g1 + A13 * g2) * iv
            s1_ = (A12 * g0 + A22 * g1 + A23 * g2) * iv
            s2_ = (A13 * g0 + A23 * g1 + A33 * g2) * iv
        p[n, 0] += s0
        p[n, 1] += s1_
        p[n, 2] += s2_
        m = max(abs(s0), abs(s1_), abs(s2_))
        if m > smax:
            smax = m
        for c in range(C):
            if not use[c, n]:
                continue
            if gl[c]:
                res[c, n, 0] = rl[c, 0] + (Jl[c, 0, 0] * s0 + Jl[c, 0, 1] * s1_ + Jl[c, 0, 2] * s2_)
                res[c, n, 1] = rl[c, 1] + (Jl[c, 1, 0] * s0 + Jl[c, 1, 1] * s1_ + Jl[c, 1, 2] * s2_)
            else:
                res[c, n, 0] = res[c, n, 1] = np.nan
    return smax


_GN = None


def _gn_kernel():
    """The compiled Gauss-Newton step (numba, imported on first use): the projection, Jacobian
    and normal equations of a point's views in one pass."""
    global _GN
    if _GN is None:
        from numba import njit
        _GN = njit(cache=True)(_gn_step_py)
    return _GN


def _gauss_newton(params, xy, use, w, p, iterations: int):
    """Gauss-Newton on the weighted reprojection error of points p (N, 3) over views `use` (C, N).

    Each step takes a fresh Jacobian; after the last step the residuals are the linear prediction
    r + J step (exact to second order in a step that is already below the noise) and H the last
    Jacobian's, so that `iterations` steps cost `iterations` projections. The steps run compiled
    (:func:`_gn_step_py`).

    Returns p, H (N, 3, 3) = sum w J^T J, residuals r (C, N, 2) px (NaN where not used or behind the
    camera), depth z (C, N)."""
    C, N = use.shape
    rv, tv, intr, extra = params
    R = np.ascontiguousarray(rotation_jacobian(rv)[0])
    d14 = np.ascontiguousarray(np.concatenate([intr[:, 4:9], extra], axis=1))
    p = np.array(p, dtype=np.float64, order="C")
    use = np.ascontiguousarray(use)
    w = np.ascontiguousarray(np.broadcast_to(w, (C, N)), dtype=np.float64)
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    Hn = np.zeros((N, 9))
    res = np.full((C, N, 2), np.nan)
    zz = np.full((C, N), np.nan)
    step = _gn_kernel()
    for it in range(max(int(iterations), 1)):
        if not step(R, np.ascontiguousarray(tv), np.ascontiguousarray(intr), d14, xy, use, w, p, Hn, res, zz) > 1e-10:
            break
    H = np.empty((N, 3, 3))
    for k in range(6):
        i, j = _IU[0][k], _IU[1][k]
        H[:, i, j] = Hn[:, k]
        H[:, j, i] = Hn[:, k]
    return p, H, res, zz


def _pair_hypotheses(rig: Rig, params, xy, valid, w, tables, gate_px: float):
    """For each point, the inlier views (C, n) of the best two-view hypothesis (MSAC over all pairs of
    its cameras), and whether another hypothesis with other inliers costs nearly as little (n,)."""
    C, N = valid.shape
    G = dlt_feature_matrix(rig).reshape(C, 4, 9)
    F = _normalized_views(rig, xy, valid, slice(0, N), tables).reshape(C, 4, N)
    contrib = np.einsum("ckn,ckj->cnj", F * np.where(valid, w, 0.0)[:, None, :], G)   # (C, N, 9)
    pairs = [(a, b) for a in range(C) for b in range(a + 1, C)]
    costs = np.full((len(pairs), N), np.inf)
    inliers = np.zeros((len(pairs), C, N), bool)
    for k, (a, b) in enumerate(pairs):                 # C(C-1)/2 camera pairs, all points at once
        idx = np.flatnonzero(valid[a] & valid[b])
        if not idx.size:
            continue
        X, det = solve_dlt(contrib[a, idx] + contrib[b, idx])
        ok = det > 0
        idx, X = idx[ok], X[ok]
        ci = np.repeat(np.arange(C), idx.size)
        pj = project_batch(*params, ci, np.tile(X, (C, 1)), jacobians=False)
        r = np.linalg.norm(pj.xy_px.reshape(C, idx.size, 2) - xy[:, idx], axis=2)
        seen = valid[:, idx]
        inl = seen & (r < gate_px)
        # truncated quadratic: an outlier (or a view behind the camera) costs gate^2
        cost = np.where(seen, np.minimum(np.nan_to_num(r, nan=np.inf), gate_px) ** 2, 0.0).sum(axis=0)
        enough = inl.sum(axis=0) >= 2
        costs[k, idx[enough]] = cost[enough]
        inliers[k][:, idx[enough]] = inl[:, enough]
    best = np.argmin(costs, axis=0)
    cols = np.arange(N)
    best_cost = costs[best, cols]
    best_in = inliers[best, :, cols].T                                     # (C, N)
    # another hypothesis within half a gate^2 whose inliers neither hold nor are held by the best's
    near = costs < best_cost[None] + 0.5 * gate_px**2
    extra_views = (inliers & ~best_in[None]).any(axis=1)
    missing_views = (~inliers & best_in[None]).any(axis=1)
    ambiguous = (near & extra_views & missing_views).any(axis=0)
    best_in[:, ~np.isfinite(best_cost)] = False
    return best_in, ambiguous


@dataclass(frozen=True, eq=False)
class Triangulation:
    """Triangulated points with their uncertainty.

    Attributes
    ----------
    p_world : (N, 3) float
        Points in the world frame, metres; NaN where fewer than two views remained.
    cov : (N, 3, 3) float
        Covariance of each point, m^2 (first order, from the pixel noise `sigma_px`); NaN where p is.
    used : (C, N) bool
        Views used for each point (the camera mask).
    residual_px : (C, N, 2) float
        Reprojection residual of every view at the final point (projection minus observation), px;
        NaN where the camera did not see the point; present for rejected views too.
    ray_residual_m : (N,) float
        RMS over used views of the distance from the point to each view's ray (|residual| times
        depth over focal length), metres: the residual a mocap system reports.
    sigma_px : float
        Pixel noise SD the covariance assumes.
    sigma_source : str
        Where sigma came from: "argument", "rig" (its [metadata] sigma_px) or "residuals".
    n_unseen : int
        Points seen by fewer than two cameras: NaN.
    n_rejected : int
        Points seen by two or more cameras left NaN by the robust selection: fewer than two views
        agreed, or two hypotheses with other views fitted about equally well (``n_ambiguous`` of
        them): a point is left out rather than placed on a guess.
    n_ambiguous : int
        Of those, points where two camera subsets with different views fitted about equally well.
    n_inconsistent : int
        Points whose views each passed the gate but whose chi-square (with sigma) lies beyond its
        1e-6 tail: NaN (counted in ``n_rejected``).
    n_nonfinite : int
        Non-finite pixel observations ignored.
    n_outlier_views : int
        Views set aside by the robust selection.
    table_error_px : float
        Largest error of the undistortion tables of the linear step, px.
    """

    p_world: np.ndarray
    cov: np.ndarray
    used: np.ndarray
    residual_px: np.ndarray
    ray_residual_m: np.ndarray
    sigma_px: float
    sigma_source: str
    n_unseen: int
    n_rejected: int
    n_ambiguous: int
    n_inconsistent: int
    n_nonfinite: int
    n_outlier_views: int
    table_error_px: float
    extra: dict = field(default_factory=dict)

    @property
    def n_views(self) -> np.ndarray:
        """Views used per point, (N,) int."""
        return self.used.sum(axis=0)

    @property
    def sd_m(self) -> np.ndarray:
        """Predicted RMS 3D error of each point, sqrt(trace(cov)), (N,) metres."""
        return np.sqrt(np.trace(self.cov, axis1=1, axis2=2))

    def reprojection_rms_px(self) -> float:
        """RMS of the used views' residuals (both coordinates), px."""
        r = self.residual_px[self.used]
        return float(np.sqrt(np.mean(r**2))) if r.size else math.nan

    def to_dict(self) -> dict:
        ok = np.isfinite(self.p_world[:, 0])
        sd = self.sd_m[ok]
        return {"n_points": int(ok.size), "n_triangulated": int(ok.sum()), "n_unseen": self.n_unseen,
                "n_rejected": self.n_rejected, "n_ambiguous": self.n_ambiguous, "n_inconsistent": self.n_inconsistent,
                "n_nonfinite": self.n_nonfinite, "n_outlier_views": self.n_outlier_views,
                "reprojection_rms_px": self.reprojection_rms_px(), "sigma_px": self.sigma_px,
                "sigma_source": self.sigma_source, "views_mean": float(self.n_views[ok].mean()) if ok.any() else math.nan,
                "predicted_sd_median_mm": float(np.median(sd) * 1e3) if sd.size else math.nan,
                "table_error_px": self.table_error_px} | dict(self.extra)


def _inverse_sym3(H: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Inverses (N, 3, 3) of symmetric 3 x 3 matrices H by the adjugate (as :func:`solve_dlt`),
    NaN where not `ok` or det H <= 0 (a batched LU per 3 x 3 matrix costs 10x more)."""
    a, b, c, e, f, h = H[:, 0, 0], H[:, 0, 1], H[:, 0, 2], H[:, 1, 1], H[:, 1, 2], H[:, 2, 2]
    A11 = e * h - f * f
    A12 = c * f - b * h
    A13 = b * f - c * e
    A22 = a * h - c * c
    A23 = b * c - a * f
    A33 = a * e - b * b
    with np.errstate(invalid="ignore", divide="ignore"):
        det = a * A11 + b * A12 + c * A13
        good = ok & (det > 0)
        inv = np.where(good, 1.0 / np.where(good, det, 1.0), np.nan)
    cov = np.empty(H.shape)
    for (i, j), A in zip(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)), (A11, A12, A13, A22, A23, A33)):
        cov[:, i, j] = cov[:, j, i] = A * inv
    return cov


def triangulate(rig: Rig, xy_px, *, sigma_px=None, robust: bool = True, gate_px: float | None = None,
                iterations: int = 2) -> Triangulation:
    """N points from any subset of C cameras each: linear start, Gauss-Newton, robust views, covariance.

    Parameters
    ----------
    rig : Rig
        C calibrated cameras.
    xy_px : (C, N, 2) float
        Pixels; NaN where a camera did not see the point (a view with one coordinate NaN or an
        infinite coordinate is ignored and counted in ``n_nonfinite``).
    sigma_px : float or (C, N) float, optional
        SD of the pixel noise of each coordinate. Default: the rig's ``[metadata] sigma_px``, else
        estimated from the residuals (pooled over all points, degrees of freedom 2 n_views - 3).
        Relative values weight the views; the covariance scales with them.
    robust : bool
        Set aside views beyond the gate (module docstring, step 4).
    gate_px : float, optional
        Residual beyond which a view is an outlier, px; default max(5 sigma, 1 px) (with sigma
        from the rig or the argument; 1.5 px when sigma is to be estimated).
    iterations : int
        Gauss-Newton steps at most (it stops when the steps fall below 1e-10 m); from the linear
        start two leave the error a millionth of the noise's.

    Returns
    -------
    Triangulation
    """
    xy, valid, n_bad = _observations(rig, xy_px, "triangulate")
    C, N = valid.shape
    source = "argument"
    if sigma_px is None:
        s = rig_sigma_px(rig)
        source = "rig" if s is not None else "residuals"
        sig = np.full((C, N), 1.0 if s is None else s)
    else:
        sig = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), (C, N)).copy()
        if not (np.isfinite(sig[valid]).all() and (sig[valid] > 0).all()):
            raise InputError(None, "sigma_px", "positive finite pixel noise SDs", "a non-positive or non-finite value")
    scalar_sigma = float(np.median(sig[valid])) if valid.any() else 1.0
    w = 1.0 / sig**2
    tables = [undistortion_table(c) for c in rig.cameras]
    p, _ = triangulate_linear(rig, xy, weights=w)           # views with both coordinates finite
    params = rig_parameters(rig)
    use = valid & (valid.sum(axis=0) >= 2)[None]
    p, H, res, z = _gauss_newton(params, xy, use, w, p, iterations)
    guess = 1.0
    if source == "residuals":               # a robust first guess: 1.4826 x the median absolute residual
        r_used = np.abs(res[use & (use.sum(axis=0) >= 3)[None]])
        guess = 1.4826 * float(np.median(r_used)) if r_used.size else 0.3
    if gate_px is None:
        gate_px = max(5.0 * (guess if source == "residuals" else scalar_sigma), 1.0)
    n_out = n_ambiguous = 0
    n_seen2 = int((valid.sum(axis=0) >= 2).sum())
    if robust:
        rn = np.linalg.norm(res, axis=2)
        flagged = (use & ~(rn < gate_px)).any(axis=0)
        if flagged.any():
            idx = np.flatnonzero(flagged)
            sub_use, ambiguous = _pair_hypotheses(rig, params, xy[:, idx], valid[:, idx], w[:, idx], tables, gate_px)
            sub_use[:, ambiguous] = False
            n_ambiguous = int(ambiguous.sum())
            for _ in range(2):                 # refine on the inliers, then take back views that fit
                pf, _ = triangulate_linear(rig, np.where(sub_use[..., None], xy[:, idx], np.nan), weights=w[:, idx])
                pf, Hf, rf, zf = _gauss_newton(params, xy[:, idx], sub_use, w[:, idx], pf, iterations)
                ci = np.repeat(np.arange(C), idx.size)
                pj = project_batch(*params, ci, np.tile(np.nan_to_num(pf), (C, 1)), jacobians=False)
                rr = np.linalg.norm(pj.xy_px.reshape(C, idx.size, 2) - xy[:, idx], axis=2)
                new_use = valid[:, idx] & (rr < gate_px) & np.isfinite(pf[:, 0])[None]
                new_use &= (new_use.sum(axis=0) >= 2)[None] & ~ambiguous[None]
                if np.array_equal(new_use, sub_use):
                    break
                sub_use = new_use
            pf[sub_use.sum(axis=0) < 2] = np.nan
            p[idx], H[idx], z[:, idx] = pf, Hf, zf
            # residuals of every view that saw the point, at the final point
            res[:, idx] = np.where(valid[:, idx, None], pj.xy_px.reshape(C, idx.size, 2) - xy[:, idx], np.nan)
            n_out = int((use[:, idx] & ~sub_use).sum())
            use[:, idx] = sub_use
    use &= np.isfinite(p[:, 0])[None]
    ok = use.sum(axis=0) >= 2
    n_inconsistent = 0
    if robust:
        from scipy.special import chdtri                 # chi2.isf, without importing scipy.stats (1 s)
        # views that each pass the gate but together do not fit (a blob of another marker near this
        # one's projection): the point's chi-square beyond its 1e-6 tail is left NaN
        chi2 = np.where(use, w * (res**2).sum(axis=2), 0.0).sum(axis=0) / guess**2
        dof = 2 * use.sum(axis=0) - 3
        dofs, inv_d = np.unique(dof, return_inverse=True)     # a few distinct degrees of freedom
        limit = np.where(dofs >= 1, chdtri(np.maximum(dofs, 1), 1e-6), np.inf)[inv_d.ravel()]
        bad = ok & (chi2 > limit)
        n_inconsistent = int(bad.sum())
        ok &= ~bad
        use &= ok[None]
    p[~ok] = np.nan
    if source == "residuals":
        dof = 2 * use.sum() - 3 * ok.sum()
        rr = np.where(use, (res**2).sum(axis=2), 0.0).sum()
        s2 = rr / dof if dof > 0 else math.nan
        scalar_sigma = float(math.sqrt(s2)) if math.isfinite(s2) else math.nan
        H = H / (scalar_sigma**2 if math.isfinite(scalar_sigma) else math.nan)
    cov = _inverse_sym3(H, ok)
    f = np.array([0.5 * (c.K[0, 0] + c.K[1, 1]) for c in rig.cameras])[:, None]
    dist_m = np.linalg.norm(res, axis=2) * z / f
    with np.errstate(invalid="ignore"):
        ray = np.sqrt(np.where(use, dist_m**2, 0.0).sum(axis=0) / use.sum(axis=0))
    ray[~ok] = np.nan
    return Triangulation(p_world=p, cov=cov, used=use, residual_px=res, ray_residual_m=ray,
                         sigma_px=scalar_sigma, sigma_source=source, n_unseen=N - n_seen2,
                         n_rejected=int(n_seen2 - ok.sum()), n_ambiguous=n_ambiguous, n_inconsistent=n_inconsistent,
                         n_nonfinite=n_bad, n_outlier_views=n_out,
                         table_error_px=max(t.max_error_px for t in tables), extra={})


def observation_array(frame, camera, point, xy_px, n_cameras: int, where: str = "detections"):
    """Labelled 2D observations as the (C, K, 2) array of :func:`triangulate`.

    Parameters
    ----------
    frame, camera, point : (n,) int
        Frame, camera and point id of each observation (point ids >= 0).
    xy_px : (n, 2) float
    n_cameras : int

    Returns
    -------
    xy : (C, K, 2) float
        NaN where unseen; K = number of distinct (frame, point) keys.
    keys : (K, 2) int
        (frame, point) of each column, sorted.

    A camera that saw the same point twice in a frame is refused, naming the first such row.
    """
    frame = np.asarray(frame, dtype=np.int64)
    camera = np.asarray(camera, dtype=np.int64)
    point = np.asarray(point, dtype=np.int64)
    xy_px = np.asarray(xy_px, dtype=np.float64)
    if camera.size and (camera.min() < 0 or camera.max() >= n_cameras):
        raise InputError(where, "camera", f"camera numbers 0..{n_cameras - 1} (the rig has {n_cameras})",
                         f"camera {int(camera.max() if camera.max() >= n_cameras else camera.min())}")
    pairs = np.stack([frame, point], axis=1)
    keys, col = np.unique(pairs, axis=0, return_inverse=True)
    col = col.ravel()
    flat = camera * len(keys) + col
    uniq, first, counts = np.unique(flat, return_index=True, return_counts=True)
    if (counts > 1).any():
        dup = uniq[counts > 1][0]
        rows = np.flatnonzero(flat == dup)
        raise InputError(where, f"row {int(rows[1])} (frame {int(frame[rows[1]])}, camera {int(camera[rows[1]])}, "
                         f"point_id {int(point[rows[1]])})", "one detection per camera, frame and point_id",
                         f"a second one (first at row {int(rows[0])})")
    xy = np.full((n_cameras, len(keys), 2), np.nan)
    xy[camera, col] = xy_px
    return xy, keys
