"""Unlabelled 2D blobs of several cameras to 3D marker candidates, with ghost rejection.

A passive marker is a blob in every camera that sees it, with nothing saying which blob of one
camera is which blob of another. Pairs of blobs that satisfy the epipolar constraint of two
cameras meet in 3D, but so do pairs of different markers whose blobs happen to lie on each
other's epipolar lines: *ghosts*. A ghost is a point where no marker is; the other cameras show
nothing there. So every candidate is judged by its support, the cameras with a blob where it
projects (Chen, Armstrong and Raftopoulos 1994; Pribanic et al. 2009 review the same
matching-and-verification scheme of commercial systems):

1. For each pair of cameras (widest angle between their optical axes first), every two
   still-unassigned blobs of the same frame whose epipolar distances in both images are below
   `epipolar_px` are triangulated (the two views' normal equations, as in
   :mod:`mocapfj.vision.triangulate`), in front of both cameras.
2. Each candidate is projected into the other cameras; the nearest unassigned blob within
   `gate_px` of the projection, if any, supports it (a sorted search over (frame, x), vectorised).
3. Candidates claiming the same blob compete: one is accepted when it is the best (most views,
   then the smallest reprojection error) for every blob it claims; those that lost a blob are
   dropped; repeated until none is left. Accepted blobs leave the pool.
4. Sweeps over all pairs accept candidates of at least 4 views, then 3; ghosts, which rarely
   collect a third view by chance, meet the true markers' blobs already taken.
5. Two-view candidates are accepted last and only where unambiguous: both blobs have exactly one
   epipolar partner among all remaining blobs of all cameras.
6. The accepted blob sets are triangulated with :func:`mocapfj.vision.triangulate.triangulate`
   (Gauss-Newton, robust views, covariance).

Everything runs over all frames at once; Python loops run over camera pairs and rounds only, the
frame-by-frame pairing and support search are compiled (numba, imported on first use).
Conventions: docs/conventions.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..types import Detections, Rig
from .projection import rotation_jacobian
from .triangulate import (Triangulation, dlt_feature_matrix, rig_parameters, solve_dlt, rig_sigma_px, triangulate,
                          undistortion_table)

__all__ = ["Candidates", "match_detections"]

@dataclass(frozen=True, eq=False)
class Candidates:
    """3D marker candidates from unlabelled detections.

    Attributes
    ----------
    frame : (K,) int
        Frame of each candidate.
    triangulation : Triangulation
        Its points (K, 3) with covariance, the views used, residuals.
    detection : (C, K) int
        Row of `Detections` each camera contributed, -1 where none.
    stats : dict
        Counts: detections, non-finite detections ignored, detections assigned, candidates per sweep,
        two-view candidates, pairs rejected as ghosts (support too low), conflicts lost.
    """

    frame: np.ndarray
    triangulation: Triangulation
    detection: np.ndarray
    stats: dict = field(default_factory=dict)

    @property
    def p_world(self) -> np.ndarray:
        return self.triangulation.p_world

    def to_dict(self) -> dict:
        return dict(self.stats) | {"triangulation": self.triangulation.to_dict()}


def _pair_order(rig: Rig) -> list[tuple[int, int]]:
    """Camera pairs, the widest angle between their viewing directions first."""
    C = len(rig.cameras)
    z = np.stack([c.R_cam_world[2] for c in rig.cameras])
    pairs = [(a, b) for a in range(C) for b in range(a + 1, C)]
    angle = [abs(float(np.clip(z[a] @ z[b], -1, 1))) for a, b in pairs]       # |cos|: 0 is best
    return [pairs[k] for k in np.argsort(angle, kind="stable")]


def _essential(rig: Rig, a: int, b: int) -> np.ndarray:
    """E with x_b^T E x_a = 0 for normalised homogeneous coordinates."""
    Ra, ta = rig.cameras[a].R_cam_world, rig.cameras[a].t_cam_world
    Rb, tb = rig.cameras[b].R_cam_world, rig.cameras[b].t_cam_world
    R = Rb @ Ra.T
    t = tb - R @ ta
    tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    return tx @ R


def _edges_py(fs_a, fs_b, free_a, free_b, nrm_a, nrm_b, E, f_a, f_b, eps, out_i, out_j):  # pragma: no cover - compiled
    """Free detection pairs of the same frame within eps px of each other's epipolar lines, frame
    by frame (compiled by :func:`_kernels`); writes them when out_i is long enough, returns the
    count. The line in b is E x_a, the line in a E^T x_b (normalised homogeneous coordinates),
    distances in pixels with the focal lengths f_a, f_b."""
    cnt = 0
    cap = out_i.shape[0]
    for f in range(fs_a.shape[0] - 1):
        b0, b1 = fs_b[f], fs_b[f + 1]
        if b0 == b1:
            continue
        for i in range(fs_a[f], fs_a[f + 1]):
            if not free_a[i]:
                continue
            x0, x1 = nrm_a[i, 0], nrm_a[i, 1]
            l0 = E[0, 0] * x0 + E[0, 1] * x1 + E[0, 2]
            l1 = E[1, 0] * x0 + E[1, 1] * x1 + E[1, 2]
            l2 = E[2, 0] * x0 + E[2, 1] * x1 + E[2, 2]
            nb = math.sqrt(l0 * l0 + l1 * l1)
            for j in range(b0, b1):
                if not free_b[j]:
                    continue
                y0, y1 = nrm_b[j, 0], nrm_b[j, 1]
                alg = abs(y0 * l0 + y1 * l1 + l2)
                if not (alg / nb * f_b < eps):
                    continue
                m0 = E[0, 0] * y0 + E[1, 0] * y1 + E[2, 0]
                m1 = E[0, 1] * y0 + E[1, 1] * y1 + E[2, 1]
                if alg / math.sqrt(m0 * m0 + m1 * m1) * f_a < eps:
                    if cnt < cap:
                        out_i[cnt] = i
                        out_j[cnt] = j
                    cnt += 1
    return cnt


def _support_py(R, tv, intr, d14, a, b, X, fi, fstart, free, xy, off, gate, sets, cost):  # pragma: no cover - compiled
    """The support of candidates X (n, 3) of frames fi (dense) from camera pair (a, b) (compiled by
    :func:`_kernels`): each is projected into every other camera c (the model of
    :func:`~mocapfj.vision.projection.project_batch`, NaN behind the camera) and takes the free
    detection of that frame within `gate` px when it is the only one there (two blobs within the
    gate, markers that nearly overlap in this camera, support nothing: either could be the
    marker's). Detections of all cameras are concatenated (camera c from off[c]), sorted by frame
    then x; fstart (C, F + 1) the first detection of each frame. Writes sets[c, k] (index within
    camera c, or -1) and cost[k] (the sum of the squared distances, in camera order)."""
    C = R.shape[0]
    for k in range(X.shape[0]):
        cost[k] = 0.0
        q0, q1, q2 = X[k, 0], X[k, 1], X[k, 2]
        f = fi[k]
        for c in range(C):
            if c == a or c == b:
                continue
            sets[c, k] = -1
            Z = R[c, 2, 0] * q0 + R[c, 2, 1] * q1 + R[c, 2, 2] * q2 + tv[c, 2]
            if not Z > 0.0:
                continue
            x = (R[c, 0, 0] * q0 + R[c, 0, 1] * q1 + R[c, 0, 2] * q2 + tv[c, 0]) / Z
            y = (R[c, 1, 0] * q0 + R[c, 1, 1] * q1 + R[c, 1, 2] * q2 + tv[c, 1]) / Z
            k1, k2, p1, p2, k3 = d14[c, 0], d14[c, 1], d14[c, 2], d14[c, 3], d14[c, 4]
            k4, k5, k6, s1, s2, s3, s4 = d14[c, 5], d14[c, 6], d14[c, 7], d14[c, 8], d14[c, 9], d14[c, 10], d14[c, 11]
            r2 = x * x + y * y
            radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            xyp = x * y
            xd = x * radial + 2.0 * p1 * xyp + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2)
            yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xyp + r2 * (s3 + s4 * r2)
            u = xd * intr[c, 0] + intr[c, 2]
            v = yd * intr[c, 1] + intr[c, 3]
            if not (np.isfinite(u) and np.isfinite(v)):
                continue
            count = 0
            best = -1
            bd = np.inf
            for j in range(fstart[c, f], fstart[c, f + 1]):
                dx = xy[j, 0] - u
                if dx < -gate:
                    continue
                if dx > gate:
                    break
                if not free[j]:
                    continue
                dy = xy[j, 1] - v
                d = math.sqrt(dx * dx + dy * dy)
                if d < gate:
                    count += 1
                    if d < bd:
                        bd = d
                        best = j
            if count == 1:
                sets[c, k] = best - off[c]
                cost[k] += bd * bd


def _bucket_order_py(bucket, x, n_buckets, order, start):  # pragma: no cover - compiled
    """Rows with bucket >= 0 ordered by bucket (counting sort, stable), then by x within a bucket
    (insertion sort: a bucket holds a dozen rows); start (n_buckets + 1) the first row of each
    bucket in `order`. Compiled by :func:`_kernels`; rows with a NaN x must have bucket -1."""
    for i in range(start.shape[0]):
        start[i] = 0
    for i in range(bucket.shape[0]):
        if bucket[i] >= 0:
            start[bucket[i] + 1] += 1
    for b in range(n_buckets):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    for i in range(bucket.shape[0]):
        b = bucket[i]
        if b >= 0:
            order[fill[b]] = i
            fill[b] += 1
    for b in range(n_buckets):
        for k in range(start[b] + 1, start[b + 1]):
            r = order[k]
            v = x[r]
            m = k - 1
            while m >= start[b] and x[order[m]] > v:
                order[m + 1] = order[m]
                m -= 1
            order[m + 1] = r


_EDGES = _SUPPORT = _ORDER = None


def _kernels():
    """The compiled epipolar pairing and support search (numba, imported on first use): a frame
    holds a dozen blobs per camera, and numpy's all-pairs arrays of every frame at once cost more
    than the pairs themselves."""
    global _EDGES, _SUPPORT, _ORDER
    if _EDGES is None:
        from numba import njit
        _EDGES = njit(cache=True)(_edges_py)
        _SUPPORT = njit(cache=True)(_support_py)
        _ORDER = njit(cache=True)(_bucket_order_py)
    return _EDGES, _SUPPORT, _ORDER


class _Pool:
    """The detections, per camera sorted by (frame, x), with an 'unassigned' mask; frames are
    numbered densely (``fidx``) and ``fstart[c, f]`` is the first detection of camera c in frame f
    in the concatenation of all cameras' detections (camera c from ``off[c]``: ``xy_all``,
    ``free_all``, of which ``xy[c]``, ``free[c]`` are views)."""

    def __init__(self, rig: Rig, det: Detections, ok: np.ndarray):
        self.C = len(rig.cameras)
        frames, dense = np.unique(det.frame, return_inverse=True)
        dense = dense.ravel()
        self.n_frames = int(frames.size)
        # one order for all cameras: (camera, frame, x), a counting sort over (camera, frame)
        bucket = np.where(ok, det.camera.astype(np.int64) * self.n_frames + dense, -1)
        order = np.empty(int(ok.sum()), np.int64)
        start = np.empty(self.C * self.n_frames + 1, np.int64)
        _kernels()[2](bucket, np.ascontiguousarray(det.xy_px[:, 0], dtype=np.float64), self.C * self.n_frames,
                      order, start)
        self.off = start[::self.n_frames].astype(np.int64) if self.n_frames else np.zeros(self.C + 1, np.int64)
        self.xy_all = np.ascontiguousarray(det.xy_px[order], dtype=np.float64)
        self.free_all = np.zeros(order.size, bool)
        fid = dense[order]
        self.fstart = np.empty((self.C, self.n_frames + 1), np.int64)
        self.rows, self.frame, self.xy, self.nrm, self.free, self.fidx = [], [], [], [], [], []
        for c in range(self.C):
            sl = slice(int(self.off[c]), int(self.off[c + 1]))
            self.rows.append(order[sl])
            self.frame.append(det.frame[order[sl]])
            self.fidx.append(fid[sl])
            self.fstart[c] = start[c * self.n_frames:(c + 1) * self.n_frames + 1]
            self.xy.append(self.xy_all[sl])
            self.nrm.append(undistortion_table(rig.cameras[c]).normalized(self.xy[c]))
            self.free_all[sl] = np.isfinite(self.nrm[c][:, 0])
            self.free.append(self.free_all[sl])

    def free_index(self, c: int) -> np.ndarray:
        return np.flatnonzero(self.free[c])


def _epipolar_edges(rig, pool: _Pool, a: int, b: int, eps_px: float):
    """Free detection pairs (index in a, index in b) of the same frame within eps_px of each
    other's epipolar lines (both images)."""
    edges = _kernels()[0]
    E = _essential(rig, a, b)
    fs_a = pool.fstart[a] - pool.off[a]
    fs_b = pool.fstart[b] - pool.off[b]
    args = (fs_a, fs_b, pool.free[a], pool.free[b], pool.nrm[a], pool.nrm[b], E,
            float(rig.cameras[a].K[0, 0]), float(rig.cameras[b].K[0, 0]), float(eps_px))
    guess = 2 * int(min(pool.free[a].sum(), pool.free[b].sum())) + 16
    ia, ib = np.empty(guess, np.int64), np.empty(guess, np.int64)
    n = edges(*args, ia, ib)
    if n > guess:
        ia, ib = np.empty(n, np.int64), np.empty(n, np.int64)
        edges(*args, ia, ib)
    return ia[:n], ib[:n]


def _two_view_points(rig, G, pool, a, b, ia, ib):
    """Points of the pairs (linear, two views; G the rig's :func:`dlt_feature_matrix` as (C, 4, 9)),
    in front of both cameras: (X, ok)."""
    m = np.zeros((ia.size, 9))
    for c, idx in ((a, ia), (b, ib)):
        x, y = pool.nrm[c][idx, 0], pool.nrm[c][idx, 1]
        m += np.stack([x * x + y * y, x, y, np.ones_like(x)], axis=1) @ G[c]
    X, det = solve_dlt(m)
    ok = det > 0
    for c in (a, b):
        cam = rig.cameras[c]
        with np.errstate(invalid="ignore"):
            ok &= (X @ cam.R_cam_world[2] + cam.t_cam_world[2]) > 0
    return X, ok


def _resolve(claims: np.ndarray, n_views: np.ndarray, cost: np.ndarray) -> tuple[np.ndarray, int]:
    """Accept candidates that are the best claimant of every detection they claim, drop those that
    lost one, repeat. claims: (C, K) global detection ids (-1 none). Returns accepted (K,) bool and
    the number dropped."""
    C, K = claims.shape
    accepted = np.zeros(K, bool)
    alive = np.ones(K, bool)
    # priority: more views first, then lower cost: rank of each candidate
    rank = np.empty(K, np.int64)
    rank[np.lexsort((cost, -n_views))] = np.arange(K)
    dropped = 0
    for _ in range(50):
        if not alive.any():
            break
        cam, cand = np.nonzero((claims >= 0) & alive[None])
        d = claims[cam, cand]
        u, inv = np.unique(d, return_inverse=True)
        best = np.full(u.size, np.iinfo(np.int64).max)
        np.minimum.at(best, inv, rank[cand])
        lost = rank[cand] != best[inv]
        loser = np.zeros(K, bool)
        loser[cand[lost]] = True
        win = alive & ~loser
        accepted |= win
        # detections taken by winners knock out the other claimants
        taken = np.zeros(u.size, bool)
        taken[inv[win[cand]]] = True
        knocked = np.zeros(K, bool)
        knocked[cand[taken[inv] & ~win[cand]]] = True
        dropped += int((knocked & alive & ~win).sum())
        alive &= ~win & ~knocked
    dropped += int(alive.sum())
    return accepted, dropped


def match_detections(rig: Rig, det: Detections, *, sigma_px: float | None = None, epipolar_px: float | None = None,
                     gate_px: float | None = None, two_view: bool = True) -> Candidates:
    """3D candidates from unlabelled detections of all frames (module docstring).

    Parameters
    ----------
    rig : Rig
        C cameras; detections must name cameras 0..C-1.
    det : Detections
        Blobs per frame and camera (point_id ignored).
    sigma_px : float, optional
        Pixel noise SD; default the rig's ``sigma_px``, else 0.3 px for the gates and the residuals'
        estimate for the covariance (:func:`mocapfj.vision.triangulate.triangulate`).
    epipolar_px : float, optional
        Largest epipolar distance of a pair, px; default max(5 sigma, 1 px).
    gate_px : float, optional
        Largest distance from a candidate's projection to a supporting blob, px; default
        max(5 sigma, 1 px).
    two_view : bool
        Accept unambiguous two-view candidates (step 5).

    Returns
    -------
    Candidates
    """
    if not isinstance(det, Detections):
        raise InputError(None, "det", "Detections", type(det).__name__)
    C = len(rig.cameras)
    if det.camera.size and int(det.camera.max()) >= C:
        raise InputError(None, "detections camera", f"camera numbers 0..{C - 1} (the rig has {C} cameras)",
                         f"camera {int(det.camera.max())}")
    sig = sigma_px if sigma_px is not None else (rig_sigma_px(rig) or 0.3)
    eps = epipolar_px if epipolar_px is not None else max(5.0 * sig, 1.0)
    gate = gate_px if gate_px is not None else max(5.0 * sig, 1.0)
    finite = np.isfinite(det.xy_px).all(axis=1)
    pool = _Pool(rig, det, finite)
    params = rig_parameters(rig)
    offsets = np.cumsum([0] + [r.size for r in pool.rows])       # global detection id = offset[c] + index
    accepted_sets: list[np.ndarray] = []                          # (C, k) per-camera index, -1
    accepted_frames: list[np.ndarray] = []
    stats = {"n_detections": int(det.frame.size), "n_nonfinite": int((~finite).sum()), "ghost_pairs": 0,
             "conflicts_lost": 0}
    pairs = _pair_order(rig)
    support = _kernels()[1]
    G = dlt_feature_matrix(rig).reshape(C, 4, 9)
    rv, tv, intr, extra = params
    R = np.ascontiguousarray(rotation_jacobian(rv)[0])
    d14 = np.ascontiguousarray(np.concatenate([intr[:, 4:9], extra], axis=1))
    tv, intr = np.ascontiguousarray(tv), np.ascontiguousarray(intr)
    for min_views in (4, 3):
        n_sweep = 0
        for a, b in pairs:
            ia, ib = _epipolar_edges(rig, pool, a, b, eps)
            if not ia.size:
                continue
            X, ok = _two_view_points(rig, G, pool, a, b, ia, ib)
            ia, ib, X = ia[ok], ib[ok], X[ok]
            fr = pool.frame[a][ia]
            fi = pool.fidx[a][ia]
            sets = np.full((C, ia.size), -1)
            sets[a], sets[b] = ia, ib
            cost = np.zeros(ia.size)
            support(R, tv, intr, d14, a, b, np.ascontiguousarray(X), fi, pool.fstart, pool.free_all, pool.xy_all,
                    pool.off, float(gate), sets, cost)
            nv = (sets >= 0).sum(axis=0)
            strong = nv >= min_views
            stats["ghost_pairs"] += int((nv == 2).sum()) if min_views == 3 else 0
            if not strong.any():
                continue
            sets, fr, nv, cost = sets[:, strong], fr[strong], nv[strong], cost[strong]
            claims = np.where(sets >= 0, sets + offsets[:-1, None], -1)
            acc, lost = _resolve(claims, nv, cost / nv)
            stats["conflicts_lost"] += lost
            for c in range(C):
                taken = sets[c, acc]
                pool.free[c][taken[taken >= 0]] = False
            accepted_sets.append(sets[:, acc])
            accepted_frames.append(fr[acc])
            n_sweep += int(acc.sum())
        stats[f"accepted_{min_views}plus"] = n_sweep
    n_two = 0
    if two_view:
        edges = []
        for a, b in pairs:
            ia, ib = _epipolar_edges(rig, pool, a, b, eps)
            if ia.size:
                X, ok = _two_view_points(rig, G, pool, a, b, ia, ib)
                edges.append((a, b, ia[ok], ib[ok]))
        if edges:
            ga = np.concatenate([offsets[a] + ia for a, b, ia, ib in edges])
            gb = np.concatenate([offsets[b] + ib for a, b, ia, ib in edges])
            deg = np.bincount(np.concatenate([ga, gb]), minlength=int(offsets[-1]))
            start = 0
            for a, b, ia, ib in edges:
                n = ia.size
                unique = (deg[ga[start:start + n]] == 1) & (deg[gb[start:start + n]] == 1)
                start += n
                if unique.any():
                    sets = np.full((C, int(unique.sum())), -1)
                    sets[a], sets[b] = ia[unique], ib[unique]
                    accepted_sets.append(sets)
                    accepted_frames.append(pool.frame[a][ia[unique]])
                    pool.free[a][ia[unique]] = False
                    pool.free[b][ib[unique]] = False
                    n_two += int(unique.sum())
    stats["accepted_2"] = n_two
    sets = np.concatenate(accepted_sets, axis=1) if accepted_sets else np.full((C, 0), -1)
    frames = np.concatenate(accepted_frames) if accepted_frames else np.zeros(0, np.int64)
    order = np.argsort(frames, kind="stable")
    sets, frames = sets[:, order], frames[order]
    xy = np.full((C, frames.size, 2), np.nan)
    rows = np.full((C, frames.size), -1)
    for c in range(C):
        has = sets[c] >= 0
        xy[c, has] = pool.xy[c][sets[c, has]]
        rows[c, has] = pool.rows[c][sets[c, has]]
    tri = triangulate(rig, xy, sigma_px=sigma_px, iterations=1)       # the linear start is close
    rows = np.where(tri.used, rows, -1)
    stats["n_assigned"] = int((rows >= 0).sum())
    stats["n_candidates"] = int(np.isfinite(tri.p_world[:, 0]).sum())
    stats["frames"] = int(np.unique(det.frame).size)
    stats["sigma_px"] = float(sig)
    stats["epipolar_px"] = float(eps)
    stats["gate_px"] = float(gate)
    return Candidates(frame=frames, triangulation=tri, detection=rows, stats=stats)
