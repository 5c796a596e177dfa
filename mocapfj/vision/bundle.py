"""Sparse bundle adjustment with an analytic Jacobian, and the covariance of its camera parameters.

Observations are pixels ``xy_px[n]`` of a 3D point seen by camera ``camera[n]``. The point
belongs to a group (``group[n]``) whose parameters place it in the world, in one of three ways:

- ``"rigid"``: a rigid object (a calibration board at one frame) with pose (rotation vector w,
  translation tau), ``p = R(w) local[n] + tau``, 6 parameters per group;
- ``"point"``: a free point, ``p = X``, 3 parameters per group (``local`` unused);
- ``"wand"``: markers on a straight wand at known distances ``s = local[n, 0]`` from its first
  marker: ``p = c + s u``, u = (u0 + a e1 + b e2) / |u0 + a e1 + b e2| with a fixed basis
  (u0, e1, e2) per group: 5 parameters (c, a, b), so the wand keeps its length exactly.

Cameras carry a pose (rotation vector, translation; world to camera) and the intrinsics of
:data:`mocapfj.vision.projection.INTRINSIC_NAMES`; any of them can be held fixed per camera (the
gauge: camera 0's pose). The residuals ``projection - xy_px`` are minimised by
``scipy.optimize.least_squares`` (trust region reflective, LSMR on the sparse Jacobian of
:mod:`mocapfj.vision.projection` chained through the group parameters; Triggs et al. 2000) with a
robust loss (graduated: first at a scale of 3 robust SDs of the starting residuals when
those are large); observations beyond 4.5 robust SDs are then dropped and the problem is solved again
without the robust loss, from which come the residual SD sigma and the covariance of the camera
parameters, sigma^2 (J^T J)^-1, by the Schur complement of the group blocks (Triggs et al. 2000,
§6; Hartley and Zisserman 2003, A6.7).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.optimize import least_squares
from scipy.sparse.linalg import LinearOperator

from ..errors import InputError
from .projection import INTRINSIC_NAMES, project_batch, rotation_jacobian

__all__ = ["BundleResult", "bundle_adjust", "POSE_NAMES", "wand_basis", "wand_points"]

POSE_NAMES = ("rx", "ry", "rz", "tx", "ty", "tz")
_K = {"rigid": 6, "point": 3, "wand": 5}
OUTLIER_SDS = 4.5
"""Observations whose residual exceeds this many robust SDs (per component) are outliers."""


@dataclass(frozen=True, eq=False)
class BundleResult:
    """Solution of :func:`bundle_adjust`.

    Attributes
    ----------
    rvecs, tvecs : (C, 3)
        World-to-camera rotation vectors (rad) and translations (m).
    intrinsics : (C, 9)
        fx, fy, cx, cy, k1, k2, p1, p2, k3.
    groups : (G, k)
        Group parameters (rigid: w, tau; point: X; wand: c, a, b in its basis).
    residual_px : (N, 2)
        projection - observation at the solution.
    inlier : (N,) bool
        False for observations dropped as outliers (or behind their camera at the start).
    sigma_px : float
        Residual SD per pixel coordinate: sqrt(sum r^2 / (2 N_inliers - n_parameters)).
    covariance : (P, P)
        Covariance of the free camera parameters (columns named by `names`), sigma^2 times the
        inverse of the Schur complement of J^T J.
    names : tuple of (camera, parameter) pairs
        The free camera parameters, in the order of `covariance`.
    n_parameters : int
        Free parameters in the final solve (cameras and groups).
    nfev : int
        Residual evaluations of both solves.
    initial_rms_px, rms_px : float
        RMS of the residual vector over the inliers at the start and at the solution.
    points_world : (N, 3)
        Each observation's 3D point at the solution, m.
    """

    rvecs: np.ndarray
    tvecs: np.ndarray
    intrinsics: np.ndarray
    groups: np.ndarray
    residual_px: np.ndarray
    inlier: np.ndarray
    sigma_px: float
    covariance: np.ndarray
    names: tuple
    n_parameters: int
    nfev: int
    initial_rms_px: float
    rms_px: float
    points_world: np.ndarray

    def std(self, camera: int, name: str) -> float:
        """SD of one camera parameter (0 for a parameter held fixed)."""
        try:
            k = self.names.index((camera, name))
        except ValueError:
            return 0.0
        return float(np.sqrt(self.covariance[k, k]))


def wand_basis(u0: np.ndarray) -> np.ndarray:
    """Per group a right-handed basis (u0, e1, e2) (G, 3, 3), rows, from unit directions u0 (G, 3)."""
    u0 = u0 / np.linalg.norm(u0, axis=1, keepdims=True)
    helper = np.where((np.abs(u0[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    e1 = np.cross(u0, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return np.stack([u0, e1, np.cross(u0, e1)], axis=1)


def wand_points(groups: np.ndarray, basis: np.ndarray, s: np.ndarray, group_index) -> np.ndarray:
    """Marker positions (N, 3) of wand groups (G, 5) at distances s (N,) along their wands."""
    v = basis[:, 0] + groups[:, 3:4] * basis[:, 1] + groups[:, 4:5] * basis[:, 2]
    u = v / np.linalg.norm(v, axis=1, keepdims=True)
    return groups[group_index, :3] + s[:, None] * u[group_index]


class _Problem:
    """Parameter layout, residuals and the sparse Jacobian of one bundle-adjustment problem."""

    def __init__(self, kind, camera, group, local, xy, rvecs, tvecs, intr, extra, groups, pose_free, intr_free,
                 basis):
        self.kind, self.k = kind, _K[kind]
        self.camera, self.group, self.local, self.xy = camera, group, local, xy
        self.r0, self.t0, self.i0, self.extra = rvecs, tvecs, intr, extra
        self.basis = basis
        C = rvecs.shape[0]
        self.C, self.G = C, groups.shape[0]
        free = np.concatenate([np.repeat(pose_free[:, None], 6, axis=1), intr_free], axis=1)   # (C, 15)
        cols = np.full((C, 15), -1)
        cols[free] = np.arange(int(free.sum()))
        self.cam_cols, self.free = cols, free
        self.nc = int(free.sum())
        self.names = tuple((c, (POSE_NAMES + INTRINSIC_NAMES)[q]) for c in range(C) for q in range(15) if free[c, q])
        self.x0 = np.concatenate([self._cam_vector(rvecs, tvecs, intr)[free], groups.ravel()])
        self._pattern = (None, None)

    def _cam_vector(self, r, t, i):
        return np.concatenate([r, t, i], axis=1)

    def unpack(self, x):
        full = self._cam_vector(self.r0, self.t0, self.i0).copy()
        full[self.free] = x[: self.nc]
        return full[:, :3], full[:, 3:6], full[:, 6:], x[self.nc:].reshape(self.G, self.k)

    def points(self, groups, rows):
        g = self.group[rows]
        if self.kind == "point":
            return groups[g]
        if self.kind == "rigid":
            R, _ = rotation_jacobian(groups[:, :3])
            b = self.local[rows]
            return (R[g] @ b[:, :, None])[:, :, 0] + groups[g, 3:]
        return wand_points(groups, self.basis, self.local[rows, 0], g)

    def project(self, x, rows, jac):
        r, t, i, groups = self.unpack(x)
        p = self.points(groups, rows)
        return project_batch(r, t, i, self.extra, self.camera[rows], p, jacobians=jac), groups

    def residual(self, x, rows):
        pj, _ = self.project(x, rows, False)
        return (pj.xy_px - self.xy[rows]).ravel()

    def jacobian(self, x, rows) -> sp.csr_matrix:
        pj, groups = self.project(x, rows, True)
        g = self.group[rows]
        dp = pj.d_point
        n = len(rows)
        block = np.empty((n, 2, 15 + self.k))
        block[:, :, :6] = pj.d_pose
        block[:, :, 6:15] = pj.d_intrinsics
        ds = block[:, :, 15:]
        if self.kind == "point":
            ds[...] = dp
        elif self.kind == "rigid":
            # dp/dw = -R [b]x M = -[R b]x (R M); a^T [v]x = (a x v)^T
            R, M = rotation_jacobian(groups[:, :3])
            RM = R @ M
            Rb = (R[g] @ self.local[rows][:, :, None])[:, :, 0]
            ds[:, :, :3] = -(np.cross(dp, Rb[:, None, :]) @ RM[g])
            ds[:, :, 3:] = dp
        else:
            B = self.basis
            v = B[:, 0] + groups[:, 3:4] * B[:, 1] + groups[:, 4:5] * B[:, 2]
            nv = np.linalg.norm(v, axis=1)
            u = v / nv[:, None]
            P = (np.eye(3) - np.einsum("gi,gj->gij", u, u)) / nv[:, None, None]
            s = self.local[rows, 0]
            du = np.stack([np.einsum("gij,gj->gi", P, B[:, 1]), np.einsum("gij,gj->gi", P, B[:, 2])], axis=2)  # (G,3,2)
            ds[:, :, :3] = dp
            ds[:, :, 3:] = (dp @ du[g]) * s[:, None, None]
        flat, indices, indptr = self._sparsity(rows)
        return sp.csr_matrix((block.reshape(-1)[flat], indices, indptr), shape=(2 * n, self.nc + self.G * self.k))

    def _sparsity(self, rows):
        """Which entries of the dense (n, 2, 15 + k) block are Jacobian entries, and the CSR pattern
        (kept while the rows stay the same: every solve of one pass)."""
        last, pattern = self._pattern
        if last is not None and last.shape == rows.shape and np.array_equal(last, rows):
            return pattern
        g = self.group[rows]
        col = np.concatenate([self.cam_cols[self.camera[rows]], self.nc + g[:, None] * self.k + np.arange(self.k)],
                             axis=1)
        valid = col >= 0
        mask = np.broadcast_to(valid[:, None, :], (len(rows), 2, col.shape[1]))
        flat = np.flatnonzero(mask.reshape(-1))
        indices = np.broadcast_to(col[:, None, :], mask.shape)[mask]
        indptr = np.concatenate([[0], np.cumsum(np.repeat(valid.sum(axis=1), 2))])
        pattern = (flat, indices.astype(np.int32), indptr.astype(np.int32))
        self._pattern = (rows.copy(), pattern)
        return pattern

    def solve(self, x0, rows, loss, f_scale, max_nfev, rounds: int = 60):
        """least_squares in whitened variables z, x = x_k + T_k z, T_k from :func:`_whitening` at x_k.

        A round ends when least_squares converges or after 8 evaluations; the next round whitens again
        at its solution (from a poor start the first whitening no longer fits the solution's Jacobian, and LSMR
        slows down); the rounds stop when one lowers the cost by less than 1e-10 of itself."""
        x = x0
        nfev = 0
        cost = np.inf
        for _ in range(rounds):
            res = self._solve_round(x, rows, loss, f_scale, max_nfev)
            nfev += res.nfev
            x = res.x
            done = not res.cost < cost * (1.0 - 1e-10) or res.nfev <= 2
            cost = min(cost, res.cost)
            if done:
                break
        res.nfev = nfev
        return res

    def _solve_round(self, x0, rows, loss, f_scale, max_nfev):
        J0 = self.jacobian(x0, rows)
        if loss != "linear":                  # whiten the Jacobian the loss will weight (IRLS weights rho')
            z = (self.residual(x0, rows) / f_scale) ** 2
            J0 = sp.diags(np.sqrt(_RHO1[loss](z))) @ J0
        T = _whitening(J0.tocsr(), self.nc, self.k)
        Tt = T.T.tocsr()
        n = x0.size

        def fun(z):
            return self.residual(x0 + T @ z, rows)

        def jac(z):
            J = self.jacobian(x0 + T @ z, rows)
            Jt = J.T.tocsr()
            return LinearOperator(J.shape, matvec=lambda v: J @ (T @ v), rmatvec=lambda u: Tt @ (Jt @ u),
                                  matmat=lambda V: J @ (T @ V), rmatmat=lambda U: Tt @ (Jt @ U), dtype=np.float64)

        z0 = np.zeros(n)
        # the trust region starts as large as any Gauss-Newton step can be (|J T dz| = |dz| <= |r|)
        scale = max(float(np.linalg.norm(fun(z0))), 1.0)
        res = least_squares(fun, z0, jac=jac, method="trf", tr_solver="lsmr", loss=loss, f_scale=f_scale,
                            x_scale=scale, max_nfev=max_nfev or 8, ftol=1e-10, xtol=1e-10, gtol=1e-10,
                            tr_options={"regularize": False, "atol": 1e-6, "btol": 1e-6})
        res.x = x0 + T @ res.x
        return res


_RHO1 = {"soft_l1": lambda z: (1.0 + z) ** -0.5, "huber": lambda z: np.where(z <= 1.0, 1.0, z ** -0.5),
         "cauchy": lambda z: 1.0 / (1.0 + z), "arctan": lambda z: 1.0 / (1.0 + z * z)}


def _blocks(J: sp.csr_matrix, nc: int, k: int):
    """J^T J split into Hcc (nc, nc) dense, Hcs (nc, G k) sparse and the group blocks (G, k, k)."""
    Jc, Js = J[:, :nc], J[:, nc:]
    Hcc = (Jc.T @ Jc).toarray()
    Hcs = (Jc.T @ Js).tocsr()
    Hss = (Js.T @ Js).tocoo()
    G = Js.shape[1] // k
    B = np.zeros((G, k, k))
    np.add.at(B, (Hss.row // k, Hss.row % k, Hss.col % k), Hss.data)
    return Hcc, Hcs, B


def _inv_sqrt(H: np.ndarray, inverse: bool = False) -> np.ndarray:
    """H^(-1/2) (or H^-1) of symmetric matrices (..., m, m); directions with eigenvalue below 1e-12 of
    the largest (unobserved parameters) are left unscaled (or out of the inverse)."""
    w, V = np.linalg.eigh(H)
    top = np.max(w, axis=-1, keepdims=True)
    ok = w > 1e-12 * np.maximum(top, 1e-300)
    ws = np.where(ok, w, 1.0)
    f = np.where(ok, 1.0 / ws, 0.0) if inverse else 1.0 / np.sqrt(ws)
    return np.einsum("...ij,...j,...kj->...ik", V, f, V)


def _block_diag(B: np.ndarray) -> sp.csr_matrix:
    G, k, _ = B.shape
    return sp.bsr_matrix((B, np.arange(G), np.arange(G + 1)), shape=(G * k, G * k)).tocsr()


def _whitening(J: sp.csr_matrix, nc: int, k: int) -> sp.csr_matrix:
    """T with (J T)^T (J T) = I: the camera parameters whitened by the Schur complement S of the group
    blocks, the groups by their own blocks and decoupled from the cameras.

        T = [[S^-1/2, 0], [-B^-1 Hsc S^-1/2, B^-1/2]]

    Solving for z in x = x0 + T z hands LSMR an orthonormal Jacobian at x0, so each trust-region
    step is a Gauss-Newton step in a few LSMR iterations: the exact Schur-complement solve of
    bundle adjustment (Triggs et al. 2000, §6.1), done once per solve as a change of variables."""
    Hcc, Hcs, B = _blocks(J, nc, k)
    Binv = _block_diag(_inv_sqrt(B, inverse=True))
    S = Hcc - (Hcs @ Binv @ Hcs.T).toarray()
    Tc = _inv_sqrt(0.5 * (S + S.T)) if nc else np.zeros((0, 0))
    W = -(Binv @ Hcs.T.tocsr()) @ Tc
    return sp.bmat([[sp.csr_matrix(Tc), None], [sp.csr_matrix(W), _block_diag(_inv_sqrt(B))]], format="csr")


def _camera_covariance(J: sp.csr_matrix, nc: int, k: int, sigma: float) -> np.ndarray:
    """sigma^2 S^-1, S the Schur complement of the group blocks in J^T J (Triggs et al. 2000, §6)."""
    Hcc, Hcs, B = _blocks(J, nc, k)
    S = Hcc - (Hcs @ _block_diag(_inv_sqrt(B, inverse=True)) @ Hcs.T).toarray()
    S = 0.5 * (S + S.T)
    try:
        return sigma**2 * np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return np.full_like(S, np.inf)


def bundle_adjust(kind: str, camera, group, local, xy_px, rvecs, tvecs, intrinsics, extra, groups, *,
                  pose_free, intr_free, basis=None, loss: str = "soft_l1", f_scale_px: float = 1.0,
                  max_nfev: int | None = None, outlier_sds: float = OUTLIER_SDS) -> BundleResult:
    """Minimise the reprojection error over cameras and groups; see the module docstring.

    Parameters
    ----------
    kind : {"rigid", "point", "wand"}
    camera, group : (N,) int
        Camera and group of each observation.
    local : (N, 3) float
        The point in its group's frame (rigid: board coordinates, m; wand: (s, 0, 0), s the
        distance from the wand's first marker, m; point: ignored).
    xy_px : (N, 2) float
        Observed pixels.
    rvecs, tvecs, intrinsics, extra : (C, 3), (C, 3), (C, 9), (C, 9)
        Starting cameras (:func:`mocapfj.vision.projection.camera_parameters`).
    groups : (G, k)
        Starting group parameters.
    pose_free : (C,) bool
        Cameras whose pose is estimated (the gauge holds at least one fixed).
    intr_free : (C, 9) bool
        Intrinsics estimated, per camera.
    basis : (G, 3, 3), for kind "wand"
        :func:`wand_basis` of the starting directions.
    loss, f_scale_px : robust loss of ``least_squares`` and its scale (px) for the first solve.
    """
    if kind not in _K:
        raise InputError(None, "kind", f"one of {list(_K)}", kind)
    camera = np.asarray(camera, dtype=np.intp)
    order = np.argsort(camera, kind="stable")          # by camera: projection works on slices
    back = np.empty_like(order)
    back[order] = np.arange(order.size)
    camera = camera[order]
    group = np.asarray(group, dtype=np.intp)[order]
    xy = np.asarray(xy_px, dtype=np.float64)[order]
    local = np.zeros((len(camera), 3)) if local is None else np.asarray(local, dtype=np.float64)[order]
    prob = _Problem(kind, camera, group, local, xy, np.asarray(rvecs, float), np.asarray(tvecs, float),
                    np.asarray(intrinsics, float), np.asarray(extra, float), np.asarray(groups, float),
                    np.asarray(pose_free, bool), np.asarray(intr_free, bool), basis)
    rows = np.arange(len(camera))
    r0 = prob.residual(prob.x0, rows).reshape(-1, 2)
    inlier = np.isfinite(r0).all(axis=1)
    rows = rows[inlier]
    initial_rms = float(np.sqrt(np.mean(r0[inlier] ** 2)))
    # graduated robustness: a start far from the minimum (residuals of tens of px) is first
    # solved with the loss's scale at 3 robust SDs of its own residuals, so that the robust loss
    # does not freeze the good observations of a poor start in a wrong basin; then at f_scale_px.
    x, nfev = prob.x0, 0
    start_scale = 3.0 * 1.4826 * float(np.median(np.abs(r0[inlier]))) if rows.size else 0.0
    scales = ([start_scale] if loss != "linear" and start_scale > 2.0 * f_scale_px else []) + [f_scale_px]
    for f_scale in scales:
        res = prob.solve(x, rows, loss, f_scale, max_nfev)
        x, nfev = res.x, nfev + res.nfev
    r = prob.residual(res.x, np.arange(len(camera))).reshape(-1, 2)
    robust_sd = 1.4826 * np.median(np.abs(r[rows]))
    with np.errstate(invalid="ignore"):
        inlier &= np.linalg.norm(r, axis=1) <= outlier_sds * max(robust_sd, 1e-6)
    rows = np.flatnonzero(inlier)
    res = prob.solve(x, rows, "linear", 1.0, max_nfev)
    nfev += res.nfev
    r = prob.residual(res.x, np.arange(len(camera))).reshape(-1, 2)
    J = prob.jacobian(res.x, rows)
    used = np.unique(group[rows])
    n_par = prob.nc + used.size * prob.k
    dof = max(2 * rows.size - n_par, 1)
    sigma = float(np.sqrt(np.sum(r[rows] ** 2) / dof))
    # groups that lost every observation have zero blocks: pinv leaves them out
    cov = _camera_covariance(J, prob.nc, prob.k, sigma)
    rv, tv, iv, gr = prob.unpack(res.x)
    return BundleResult(rvecs=rv, tvecs=tv, intrinsics=iv, groups=gr, residual_px=r[back], inlier=inlier[back],
                        sigma_px=sigma, covariance=cov, names=prob.names, n_parameters=n_par, nfev=nfev,
                        initial_rms_px=initial_rms, rms_px=float(np.sqrt(np.mean(r[rows] ** 2))),
                        points_world=prob.points(gr, np.arange(len(camera)))[back])
