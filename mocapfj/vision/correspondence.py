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

Everything runs over all frames at once; Python loops run over camera pairs and rounds only.
Conventions: docs/conventions.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..types import Detections, Rig
from .projection import project_batch
from .triangulate import (Triangulation, dlt_feature_matrix, rig_parameters, solve_dlt, rig_sigma_px, triangulate,
                          undistortion_table)

__all__ = ["Candidates", "match_detections"]

_BIG = 1 << 15       # key = frame * _BIG + x: pixel columns below 16384


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


def _ragged_pairs(fa: np.ndarray, fb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All (i, j) with fa[i] == fb[j]; fb sorted."""
    lo = np.searchsorted(fb, fa, "left")
    hi = np.searchsorted(fb, fa, "right")
    cnt = hi - lo
    i = np.repeat(np.arange(fa.size), cnt)
    starts = np.cumsum(cnt) - cnt
    j = np.arange(i.size) - np.repeat(starts, cnt) + np.repeat(lo, cnt)
    return i, j


class _Pool:
    """The detections, per camera sorted by (frame, x), with an 'unassigned' mask."""

    def __init__(self, rig: Rig, det: Detections, ok: np.ndarray):
        self.C = len(rig.cameras)
        self.rows, self.frame, self.xy, self.nrm, self.free = [], [], [], [], []
        for c in range(self.C):
            rows = np.flatnonzero(ok & (det.camera == c))
            order = np.lexsort((det.xy_px[rows, 0], det.frame[rows]))
            rows = rows[order]
            self.rows.append(rows)
            self.frame.append(det.frame[rows])
            self.xy.append(det.xy_px[rows])
            self.nrm.append(undistortion_table(rig.cameras[c]).normalized(det.xy_px[rows]))
            self.free.append(np.isfinite(self.nrm[c][:, 0]))

    def free_index(self, c: int) -> np.ndarray:
        return np.flatnonzero(self.free[c])

    def nearest(self, c: int, frame: np.ndarray, xy: np.ndarray, gate: float) -> tuple[np.ndarray, np.ndarray]:
        """The free detection of camera c in `frame` within `gate` px of `xy`, when it is the only
        one there: (index or -1, distance). Two blobs within the gate (markers that nearly overlap
        in this camera) support nothing: either could be the marker's."""
        idx = self.free_index(c)
        out = np.full(frame.size, -1)
        dist = np.full(frame.size, np.inf)
        if not idx.size or not frame.size:
            return out, dist
        keys = self.frame[c][idx] * _BIG + self.xy[c][idx, 0]
        with np.errstate(invalid="ignore"):
            q_ok = np.isfinite(xy).all(axis=1) & (xy[:, 0] > -gate - 1) & (xy[:, 0] < _BIG - gate - 1)
        q = np.where(q_ok, frame * _BIG + np.nan_to_num(xy[:, 0]), -1e18)
        lo = np.searchsorted(keys, q - gate, "left")
        hi = np.searchsorted(keys, q + gate, "right")
        hi = np.where(q_ok, hi, lo)
        count = np.zeros(frame.size, int)
        for k in range(int((hi - lo).max(initial=0))):
            j = lo + k
            live = j < hi
            jj = idx[np.minimum(j, idx.size - 1)]
            d = np.linalg.norm(self.xy[c][jj] - xy, axis=1)
            inside = live & (d < gate)
            count += inside
            better = inside & (d < dist)
            out[better] = jj[better]
            dist[better] = d[better]
        out[count > 1] = -1
        dist[count > 1] = np.inf
        return out, dist


def _epipolar_edges(rig, pool: _Pool, a: int, b: int, eps_px: float):
    """Free detection pairs (index in a, index in b) of the same frame within eps_px of each
    other's epipolar lines (both images)."""
    ia, ib = pool.free_index(a), pool.free_index(b)
    if not ia.size or not ib.size:
        return np.zeros(0, int), np.zeros(0, int)
    i, j = _ragged_pairs(pool.frame[a][ia], pool.frame[b][ib])
    if not i.size:
        return np.zeros(0, int), np.zeros(0, int)
    ia, ib = ia[i], ib[j]
    E = _essential(rig, a, b)
    xa = np.column_stack([pool.nrm[a][ia], np.ones(ia.size)])
    xb = np.column_stack([pool.nrm[b][ib], np.ones(ib.size)])
    lb = xa @ E.T                               # line in b
    la = xb @ E                                 # line in a
    alg = np.abs(np.einsum("ni,ni->n", xb, lb))
    fa = rig.cameras[a].K[0, 0]
    fb = rig.cameras[b].K[0, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        db = alg / np.hypot(lb[:, 0], lb[:, 1]) * fb
        da = alg / np.hypot(la[:, 0], la[:, 1]) * fa
    keep = (db < eps_px) & (da < eps_px)
    return ia[keep], ib[keep]


def _two_view_points(rig, params, pool, a, b, ia, ib):
    """Points of the pairs (linear, two views), in front of both cameras: (X, ok)."""
    G = dlt_feature_matrix(rig).reshape(len(rig.cameras), 4, 9)
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
    for min_views in (4, 3):
        n_sweep = 0
        for a, b in pairs:
            ia, ib = _epipolar_edges(rig, pool, a, b, eps)
            if not ia.size:
                continue
            X, ok = _two_view_points(rig, params, pool, a, b, ia, ib)
            ia, ib, X = ia[ok], ib[ok], X[ok]
            fr = pool.frame[a][ia]
            sets = np.full((C, ia.size), -1)
            sets[a], sets[b] = ia, ib
            cost = np.zeros(ia.size)
            for c in range(C):
                if c in (a, b):
                    continue
                pj = project_batch(*params, np.full(ia.size, c), X, jacobians=False)
                j, d = pool.nearest(c, fr, pj.xy_px, gate)
                sets[c] = j
                cost += np.where(j >= 0, d**2, 0.0)
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
                X, ok = _two_view_points(rig, params, pool, a, b, ia, ib)
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
