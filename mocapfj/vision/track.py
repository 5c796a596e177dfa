"""Unlabelled 3D points over time to labelled marker trajectories, from rigid clusters.

The points of each frame (from :mod:`mocapfj.vision.correspondence`) carry no identity. The
clusters' rigid geometry names them, and time joins the frames where geometry alone cannot:

1. **Linking** (all frames at once): each point is predicted into the next frame at constant
   velocity (its velocity from a first, nearest-neighbour linking) and linked to the nearest point
   there when the two are each other's nearest, within `max_speed_m_s` of motion and a 5 mm
   prediction gate, and at most half as far as the second nearest (the ratio test: two markers
   that pass close by are not linked rather than linked wrongly). The links are solved as an
   assignment per frame (``scipy.optimize.linear_sum_assignment`` on the gated distances) only
   where the mutual nearest neighbours conflict. Chains of links are *tracklets*.
2. **Geometry, frame by frame** (all frames at once): for every cluster, every triangle of its
   template whose three side lengths appear among a frame's points (within `tol_m`) fixes a pose
   (Kabsch 1976); the pose predicts the cluster's other markers, the nearest points within `tol_m`
   join, and the pose is refitted. Per frame and cluster the hypothesis with the most markers wins;
   a tie between different assignments names nothing. A point two clusters claim keeps the claim
   with more markers, or none.
3. **Labels along tracklets**: a tracklet takes the label its frames voted for. A tracklet whose
   frames voted for two labels in turn has been linked across two markers (a swap): it is cut
   where the votes change, each part takes its own label, the frames between the two runs stay
   unlabelled, and the swap is counted as repaired. A label on two points of one frame goes to
   the one geometry voted for, or to none.
4. **Rigid check**: per frame and cluster, Kabsch fits the template to the labelled markers;
   a marker more than `tol_m` from the fit (with three or more present), or a pair whose distance
   differs from the template's by more than `tol_m` (two present), loses its label. Occlusions
   give NaN, never a wrong marker.
5. **Gaps**: a marker missing for at most `max_gap_s` while three or more of its cluster's markers
   are present is filled from the cluster's rigid fit of that frame (not a spline across the gap);
   longer gaps stay NaN and are reported.

Conventions: world frame, metres, time axis first (docs/conventions.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import combinations, permutations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from ..types import MarkerCluster, MarkerTrajectories

__all__ = ["Labelling", "label_points", "link_points", "fit_clusters", "fill_gaps", "cluster_symmetry", "rigid_fit"]


# --- rigid fits, batched --------------------------------------------------------------------------

def _kabsch_py(p, q, w, R, t):  # pragma: no cover - compiled
    """Weighted rigid fits q ~ R p + t of a batch (compiled by :func:`_kabsch_kernel`), by Horn's
    (1987) unit quaternion: the eigenvector of the largest eigenvalue of the symmetric 4 x 4 matrix
    of the weighted cross-covariance, found by cyclic Jacobi rotations. A proper rotation always
    (the optimum Kabsch's reflection-corrected SVD gives), without a 3 x 3 SVD per fit (LAPACK
    takes about 3 us for one). Entries with w = 0 are ignored (q may be NaN there)."""
    n, K = p.shape[0], p.shape[1]
    N = np.empty((4, 4))
    V = np.empty((4, 4))
    for m in range(n):
        sw = 0.0
        pc0 = pc1 = pc2 = qc0 = qc1 = qc2 = 0.0
        for k in range(K):
            wk = w[m, k]
            if wk == 0.0:
                continue
            sw += wk
            pc0 += wk * p[m, k, 0]
            pc1 += wk * p[m, k, 1]
            pc2 += wk * p[m, k, 2]
            qc0 += wk * q[m, k, 0]
            qc1 += wk * q[m, k, 1]
            qc2 += wk * q[m, k, 2]
        if not sw > 0.0:
            for i in range(3):
                for j in range(3):
                    R[m, i, j] = 1.0 if i == j else 0.0
                t[m, i] = np.nan
            continue
        pc0 /= sw
        pc1 /= sw
        pc2 /= sw
        qc0 /= sw
        qc1 /= sw
        qc2 /= sw
        sxx = sxy = sxz = syx = syy = syz = szx = szy = szz = 0.0
        for k in range(K):
            wk = w[m, k]
            if wk == 0.0:
                continue
            a0 = p[m, k, 0] - pc0
            a1 = p[m, k, 1] - pc1
            a2 = p[m, k, 2] - pc2
            b0 = wk * (q[m, k, 0] - qc0)
            b1 = wk * (q[m, k, 1] - qc1)
            b2 = wk * (q[m, k, 2] - qc2)
            sxx += a0 * b0
            sxy += a0 * b1
            sxz += a0 * b2
            syx += a1 * b0
            syy += a1 * b1
            syz += a1 * b2
            szx += a2 * b0
            szy += a2 * b1
            szz += a2 * b2
        N[0, 0] = sxx + syy + szz
        N[0, 1] = N[1, 0] = syz - szy
        N[0, 2] = N[2, 0] = szx - sxz
        N[0, 3] = N[3, 0] = sxy - syx
        N[1, 1] = sxx - syy - szz
        N[1, 2] = N[2, 1] = sxy + syx
        N[1, 3] = N[3, 1] = szx + sxz
        N[2, 2] = -sxx + syy - szz
        N[2, 3] = N[3, 2] = syz + szy
        N[3, 3] = -sxx - syy + szz
        for i in range(4):
            for j in range(4):
                V[i, j] = 1.0 if i == j else 0.0
        scale = 0.0
        for i in range(4):
            for j in range(4):
                scale += N[i, j] * N[i, j]
        for sweep in range(30):                      # cyclic Jacobi (Golub and Van Loan, 8.5)
            off = 0.0
            for i in range(4):
                for j in range(i + 1, 4):
                    off += N[i, j] * N[i, j]
            if not off > 1e-30 * scale:
                break
            for i in range(3):
                for j in range(i + 1, 4):
                    if N[i, j] == 0.0:
                        continue
                    theta = (N[j, j] - N[i, i]) / (2.0 * N[i, j])
                    tt = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                    c = 1.0 / math.sqrt(tt * tt + 1.0)
                    s = tt * c
                    for k in range(4):               # N <- J^T N J, V <- V J
                        nki = N[k, i]
                        nkj = N[k, j]
                        N[k, i] = c * nki - s * nkj
                        N[k, j] = s * nki + c * nkj
                    for k in range(4):
                        nik = N[i, k]
                        njk = N[j, k]
                        N[i, k] = c * nik - s * njk
                        N[j, k] = s * nik + c * njk
                    for k in range(4):
                        vki = V[k, i]
                        vkj = V[k, j]
                        V[k, i] = c * vki - s * vkj
                        V[k, j] = s * vki + c * vkj
        best = 0
        for i in range(1, 4):
            if N[i, i] > N[best, best]:
                best = i
        qw, qx, qy, qz = V[0, best], V[1, best], V[2, best], V[3, best]
        nq = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        qw /= nq
        qx /= nq
        qy /= nq
        qz /= nq
        R[m, 0, 0] = qw * qw + qx * qx - qy * qy - qz * qz
        R[m, 0, 1] = 2.0 * (qx * qy - qw * qz)
        R[m, 0, 2] = 2.0 * (qx * qz + qw * qy)
        R[m, 1, 0] = 2.0 * (qx * qy + qw * qz)
        R[m, 1, 1] = qw * qw - qx * qx + qy * qy - qz * qz
        R[m, 1, 2] = 2.0 * (qy * qz - qw * qx)
        R[m, 2, 0] = 2.0 * (qx * qz - qw * qy)
        R[m, 2, 1] = 2.0 * (qy * qz + qw * qx)
        R[m, 2, 2] = qw * qw - qx * qx - qy * qy + qz * qz
        t[m, 0] = qc0 - (R[m, 0, 0] * pc0 + R[m, 0, 1] * pc1 + R[m, 0, 2] * pc2)
        t[m, 1] = qc1 - (R[m, 1, 0] * pc0 + R[m, 1, 1] * pc1 + R[m, 1, 2] * pc2)
        t[m, 2] = qc2 - (R[m, 2, 0] * pc0 + R[m, 2, 1] * pc1 + R[m, 2, 2] * pc2)


_KABSCH = None


def _kabsch_kernel():
    """The compiled rigid fits (numba, imported on first use)."""
    global _KABSCH
    if _KABSCH is None:
        from numba import njit
        _KABSCH = njit(cache=True)(_kabsch_py)
    return _KABSCH


def rigid_fit(p: np.ndarray, q: np.ndarray, w: np.ndarray):
    """Weighted rigid fits q ~ R p + t for a batch (Kabsch 1976; solved by Horn's 1987 quaternion,
    :func:`_kabsch_py`): p (n, K, 3) template, q (n, K, 3) points (NaN where absent), w (n, K)
    weights (0 = absent). Returns R (n, 3, 3), t (n, 3); t NaN where no weight."""
    p = np.ascontiguousarray(np.broadcast_to(p, np.shape(q)), dtype=np.float64)
    q = np.ascontiguousarray(q, dtype=np.float64)
    w = np.ascontiguousarray(w, dtype=np.float64)
    n = q.shape[0]
    R = np.empty((n, 3, 3))
    t = np.empty((n, 3))
    _kabsch_kernel()(p, q, w, R, t)
    return R, t


def fit_clusters(xyz: np.ndarray, labels: Sequence[str], clusters: Sequence[MarkerCluster], frames=None):
    """Per frame and cluster, the rigid fit of the template to the present markers.

    Parameters
    ----------
    xyz : (T, M, 3) float
        Labelled markers, NaN where missing.
    labels : M str
    clusters : sequence of MarkerCluster
    frames : (T,) bool, optional
        Fit only these frames (the others' outputs are NaN, n_present still counted).

    Returns
    -------
    predicted : (T, M, 3) float
        Each marker of a cluster where the cluster's fit exists (three or more of its markers
        present, not all on one line), else NaN; markers of no cluster NaN.
    residual : (T, M) float
        Distance of each present marker from its cluster's fit, m (NaN without a fit).
    n_present : (T, M) int
        Markers of the same cluster present in the frame.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    T, M = xyz.shape[:2]
    index = {s: i for i, s in enumerate(labels)}
    predicted = np.full((T, M, 3), np.nan)
    residual = np.full((T, M), np.nan)
    n_present = np.zeros((T, M), int)
    for c in clusters:
        cols = [index.get(s, -1) for s in c.labels]
        have = [k for k, i in enumerate(cols) if i >= 0]
        if len(have) < 3:
            continue
        idx = np.array([cols[k] for k in have])
        tpl = c.template_m[have]
        q = xyz[:, idx]
        w = np.isfinite(q[..., 0]).astype(np.float64)
        n = w.sum(axis=1).astype(int)
        n_present[:, idx] = n[:, None]
        ok = n >= 3
        if frames is not None:
            ok &= np.asarray(frames, dtype=bool)
        if not ok.any():
            continue
        R, t = rigid_fit(np.broadcast_to(tpl, (int(ok.sum()),) + tpl.shape), q[ok], w[ok])
        pred = np.einsum("nij,kj->nki", R, tpl) + t[:, None]
        # a fit from markers on (nearly) one line leaves a rotation free: no fit (judged once per
        # pattern of present markers)
        pattern = (w[ok] > 0) @ (1 << np.arange(len(have)))
        for code in np.unique(pattern):
            sel = tpl[[(code >> k) & 1 == 1 for k in range(len(have))]]
            sv = np.linalg.svd(sel - sel.mean(axis=0), compute_uv=False)
            if sv[1] < 1e-3 * max(sv[0], 1e-12):
                pred[pattern == code] = np.nan
        rows = np.flatnonzero(ok)
        predicted[rows[:, None], idx[None]] = pred
        residual[rows[:, None], idx[None]] = np.linalg.norm(pred - q[ok], axis=2)
    return predicted, residual, n_present


def cluster_symmetry(cluster: MarkerCluster, tol_m: float) -> tuple[int, ...] | None:
    """A relabelling of the cluster's markers that its template cannot tell from the identity
    (the rigid fit of the permuted template within `tol_m` RMS), or None. Such a cluster's labels
    cannot be found from geometry."""
    tpl = cluster.template_m
    K = tpl.shape[0]
    if K > 7:
        return None
    d = np.linalg.norm(tpl[:, None] - tpl[None], axis=2)
    for perm in permutations(range(K)):
        if perm == tuple(range(K)):
            continue
        if np.abs(d[np.ix_(perm, perm)] - d).max() > 2 * tol_m:
            continue
        R, t = rigid_fit(tpl[None], tpl[list(perm)][None], np.ones((1, K)))
        rms = np.sqrt(np.mean(np.sum((tpl @ R[0].T + t[0] - tpl[list(perm)]) ** 2, axis=1)))
        if rms < tol_m:
            return perm
    return None


# --- linking ---------------------------------------------------------------------------------------

def _padded(frame: np.ndarray, p: np.ndarray, n_frames: int):
    """Per frame slots: pos (T, P, 3) NaN-padded, sample index (T, P) -1, slot of each sample."""
    order = np.argsort(frame, kind="stable")
    f = frame[order]
    start = np.searchsorted(f, np.arange(n_frames))
    slot_sorted = np.arange(f.size) - start[f]
    P = int(slot_sorted.max(initial=-1)) + 1
    pos = np.full((n_frames, max(P, 1), 3), np.nan)
    idx = np.full((n_frames, max(P, 1)), -1)
    pos[f, slot_sorted] = p[order]
    idx[f, slot_sorted] = order
    slot = np.empty(frame.size, int)
    slot[order] = slot_sorted
    return pos, idx, slot


def _mutual_py(A, B, gate_rows, pregate, gate, ratio, out_t, out_i, out_j, conflict):  # pragma: no cover - compiled
    """Mutual nearest neighbours between the points A[t] (P, 3) and B[t] (Q, 3) of every t, within
    `gate`, passing the ratio test both ways (compiled by :func:`_mutual_kernel`). With `pregate`,
    distances not below gate_rows[t, i] count as absent first. Writes the links (t, i, j), flags
    the t where a gated pair of two unlinked points remains (``conflict``) and returns the count.
    Ties go to the first index, the second nearest may equal the nearest (np.argmin,
    np.partition)."""
    T1, P = A.shape[0], A.shape[1]
    Q = B.shape[1]
    D = np.empty((P, Q))
    j1 = np.empty(P, np.int64)
    d1 = np.empty(P)
    d2 = np.empty(P)
    i1 = np.empty(Q, np.int64)
    e1 = np.empty(Q)
    e2 = np.empty(Q)
    la = np.empty(P, np.bool_)
    lb = np.empty(Q, np.bool_)
    cnt = 0
    for t in range(T1):
        for j in range(Q):
            i1[j] = 0
            e1[j] = np.inf
            e2[j] = np.inf
            lb[j] = False
        for i in range(P):
            m1 = np.inf
            m2 = np.inf
            arg = 0
            la[i] = False
            for j in range(Q):
                dx = A[t, i, 0] - B[t, j, 0]
                dy = A[t, i, 1] - B[t, j, 1]
                dz = A[t, i, 2] - B[t, j, 2]
                d = math.sqrt(dx * dx + dy * dy + dz * dz)
                if not np.isfinite(d):
                    d = np.inf
                elif pregate and not (d < gate_rows[t, i]):
                    d = np.inf
                D[i, j] = d
                if d < m1:
                    m2 = m1
                    m1 = d
                    arg = j
                elif d < m2:
                    m2 = d
                if d < e1[j]:
                    e2[j] = e1[j]
                    e1[j] = d
                    i1[j] = i
                elif d < e2[j]:
                    e2[j] = d
            j1[i] = arg
            d1[i] = m1
            d2[i] = m2
        for i in range(P):
            if not (d1[i] < gate):
                continue
            j = j1[i]
            if i1[j] == i and d1[i] <= ratio * d2[i] and e1[j] <= ratio * e2[j]:
                out_t[cnt] = t
                out_i[cnt] = i
                out_j[cnt] = j
                cnt += 1
                la[i] = True
                lb[j] = True
        for i in range(P):
            if la[i]:
                continue
            for j in range(Q):
                if not lb[j] and np.isfinite(D[i, j]):
                    conflict[t] = True
    return cnt


_MUTUAL = None


def _mutual_kernel():
    """The compiled mutual-nearest-neighbour search (numba, imported on first use): a frame's
    distances, nearest and second nearest in one pass, where numpy held (T, P, P, 3) arrays."""
    global _MUTUAL
    if _MUTUAL is None:
        from numba import njit
        _MUTUAL = njit(cache=True)(_mutual_py)
    return _MUTUAL


def _mutual(A, B, gate_rows, pregate: bool, gate: float, ratio: float):
    """(t, i, j) of the accepted links and the conflict flags (T - 1,) of :func:`_mutual_py`."""
    T1, P = A.shape[:2]
    out = [np.empty(T1 * P, np.int64) for _ in range(3)]
    conflict = np.zeros(T1, bool)
    n = _mutual_kernel()(A, B, gate_rows, pregate, float(gate), float(ratio), *out, conflict)
    return out[0][:n], out[1][:n], out[2][:n], conflict


def link_points(frame, p_world, n_frames: int, *, rate_hz: float, max_speed_m_s: float = 3.0,
                gate_m: float = 0.005, ratio: float = 0.5) -> np.ndarray:
    """Tracklet id of each point (first linking step of the module docstring).

    Parameters
    ----------
    frame : (n,) int
    p_world : (n, 3) float
    n_frames : int
    rate_hz : float
    max_speed_m_s : float
        Fastest marker speed considered (first linking gate = max_speed / rate).
    gate_m : float
        Gate around the constant-velocity prediction, m.
    ratio : float
        A link's distance must be at most `ratio` times the second nearest's, both ways.

    Returns
    -------
    (n,) int
        Tracklet ids 0..; points of one tracklet are in consecutive frames.
    """
    frame = np.asarray(frame, dtype=np.int64)
    p = np.asarray(p_world, dtype=np.float64)
    n = frame.size
    if n == 0:
        return np.zeros(0, int)
    pos, idx, slot = _padded(frame, p, n_frames)
    step = max_speed_m_s / rate_hz
    B = np.ascontiguousarray(pos[1:])
    # pass 1: nearest neighbours without prediction, for velocities
    t, i, j, _ = _mutual(np.ascontiguousarray(pos[:-1]), B, np.zeros((1, 1)), False, step, ratio)
    vel = np.zeros_like(pos)
    vel[t + 1, j] = pos[t + 1, j] - pos[t, i]
    has_vel = np.zeros(pos.shape[:2], bool)
    has_vel[t + 1, j] = True
    # pass 2: constant-velocity prediction
    pred = pos + vel
    gate = np.where(has_vel[:-1], gate_m, step)
    t, i, j, conflict = _mutual(np.ascontiguousarray(pred[:-1]), B, gate, True, np.inf, ratio)
    # conflicts: points of frame t and t + 1 left unlinked with gated candidates between them are
    # assigned per frame (linear_sum_assignment), each link still passing the ratio test
    free_a = np.isfinite(pos[:-1, :, 0]).copy()
    free_b = np.isfinite(pos[1:, :, 0]).copy()
    free_a[t, i] = False
    free_b[t, j] = False
    extra = []
    for f in np.flatnonzero(conflict):
        D2f = np.linalg.norm(pred[f][:, None] - pos[f + 1][None], axis=2)
        D2f = np.where(D2f < gate[f][:, None], D2f, np.inf)
        cand = np.isfinite(D2f) & free_a[f][:, None] & free_b[f][None, :]
        rows = np.flatnonzero(cand.any(axis=1))
        cols = np.flatnonzero(cand.any(axis=0))
        sub = D2f[np.ix_(rows, cols)]
        r, c = linear_sum_assignment(np.where(np.isfinite(sub), sub, 1e6))
        for rr, cc in zip(r, c):
            d = sub[rr, cc]
            if not np.isfinite(d):
                continue
            others = np.r_[np.delete(D2f[rows[rr]], cols[cc]), np.delete(D2f[:, cols[cc]], rows[rr])]
            if d <= ratio * others.min(initial=np.inf):
                extra.append((f, rows[rr], cols[cc]))
    if extra:
        e = np.array(extra)
        t, i, j = np.r_[t, e[:, 0]], np.r_[i, e[:, 1]], np.r_[j, e[:, 2]]
    src = idx[t, i]
    dst = idx[t + 1, j]
    g = coo_matrix((np.ones(src.size), (src, dst)), shape=(n, n)).tocsr()
    _, tid = connected_components(g, directed=False)
    return tid


# --- geometric votes ----------------------------------------------------------------------------------

def _triangles(tpl: np.ndarray):
    """Triangles (a, b, c) of a template with area, the best conditioned first."""
    out = []
    for a, b, c in combinations(range(tpl.shape[0]), 3):
        area = 0.5 * np.linalg.norm(np.cross(tpl[b] - tpl[a], tpl[c] - tpl[a]))
        out.append((area, (a, b, c)))
    out.sort(reverse=True)
    return [t for area, t in out if area > 1e-5]


def _triad(p: np.ndarray) -> np.ndarray:
    """Orthonormal frames (n, 3, 3) (columns) of triangles p (n, 3, 3): the first side, the
    in-plane perpendicular, the normal."""
    e1 = p[:, 1] - p[:, 0]
    e3 = np.cross(e1, p[:, 2] - p[:, 0])
    e1 = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    e3 = e3 / np.linalg.norm(e3, axis=1, keepdims=True)
    return np.stack([e1, np.cross(e3, e1), e3], axis=2)


def _pair_distances_py(pos, D):  # pragma: no cover - compiled
    """Distances D (T, P, P) between the points of every frame (inf where a point is absent) and
    the number of pairs i < j closer than 15 m (compiled by :func:`_pair_kernels`)."""
    T, P = pos.shape[0], pos.shape[1]
    cnt = 0
    for t in range(T):
        for i in range(P):
            for j in range(P):
                dx = pos[t, i, 0] - pos[t, j, 0]
                dy = pos[t, i, 1] - pos[t, j, 1]
                dz = pos[t, i, 2] - pos[t, j, 2]
                d = math.sqrt(dx * dx + dy * dy + dz * dz)
                if not np.isfinite(d):
                    d = np.inf
                D[t, i, j] = d
                if j > i and d < 15.0:
                    cnt += 1
    return cnt


def _pair_sort_py(D, key, ti, ii, jj):  # pragma: no cover - compiled
    """The pairs i < j of each frame closer than 15 m, sorted by key = t * 16 + d within the frame
    (stable: ties in the order i, then j), frames in order: the order of one stable sort of all
    keys, as frames' keys do not overlap."""
    T, P = D.shape[0], D.shape[1]
    kb = np.empty(P * (P - 1) // 2 + 1)
    ib = np.empty(P * (P - 1) // 2 + 1, np.int64)
    jb = np.empty(P * (P - 1) // 2 + 1, np.int64)
    cnt = 0
    for t in range(T):
        m = 0
        for i in range(P):
            for j in range(i + 1, P):
                d = D[t, i, j]
                if d < 15.0:
                    kb[m] = t * 16.0 + d
                    ib[m] = i
                    jb[m] = j
                    m += 1
        order = np.argsort(kb[:m], kind="mergesort")
        for r in range(m):
            o = order[r]
            key[cnt] = kb[o]
            ti[cnt] = t
            ii[cnt] = ib[o]
            jj[cnt] = jb[o]
            cnt += 1


_PAIRS = None


def _pair_kernels():
    """The compiled distances and sorted pairs of :class:`_PairIndex` (numba, imported on first use)."""
    global _PAIRS
    if _PAIRS is None:
        from numba import njit
        _PAIRS = (njit(cache=True)(_pair_distances_py), njit(cache=True)(_pair_sort_py))
    return _PAIRS


class _PairIndex:
    """Distances between the points of every frame, and the pairs of each frame sorted by distance
    (key = frame * 16 m + distance, ascending), for finding a template's side lengths."""

    def __init__(self, pos: np.ndarray):
        T, P = pos.shape[:2]
        self.T, self.P = T, P
        distances, sort = _pair_kernels()
        self.D = np.empty((T, P, P))
        n = distances(np.ascontiguousarray(pos, dtype=np.float64), self.D)
        self.key = np.empty(n)
        self.t, self.i, self.j = (np.empty(n, np.int64) for _ in range(3))
        sort(self.D, self.key, self.t, self.i, self.j)

    def near(self, length: float, tol: float, frames: np.ndarray):
        """(t, i, j), both orders, of the pairs of `frames` at `length` +- tol."""
        lo = np.searchsorted(self.key, frames * 16.0 + length - tol, "left")
        hi = np.searchsorted(self.key, frames * 16.0 + length + tol, "right")
        cnt = hi - lo
        idx = np.repeat(lo - np.cumsum(np.r_[0, cnt[:-1]]), cnt) + np.arange(int(cnt.sum()))
        t, i, j = self.t[idx], self.i[idx], self.j[idx]
        return np.r_[t, t], np.r_[i, j], np.r_[j, i]


def _unique_rows(a: np.ndarray, *, return_index: bool = False, return_inverse: bool = False):
    """``np.unique(a, axis=0, ...)`` of an integer array (n, k), by one int64 key per row (the
    columns offset to 0 and weighted as digits) where its range fits, which sorts a 1-D array
    instead of rows: the same rows in the same (lexicographic) order, the same first indices."""
    a = np.asarray(a, dtype=np.int64)
    if a.ndim != 2 or not a.shape[0]:
        return np.unique(a, axis=0, return_index=return_index, return_inverse=return_inverse)
    lo = a.min(axis=0)
    span = a.max(axis=0) - lo + 1
    if float(np.prod(span.astype(np.float64))) >= 2.0**62:
        out = np.unique(a, axis=0, return_index=return_index, return_inverse=return_inverse)
        if return_inverse:
            out = out[:-1] + (out[-1].ravel(),)
        return out
    mult = np.ones(a.shape[1], np.int64)
    for k in range(a.shape[1] - 2, -1, -1):
        mult[k] = mult[k + 1] * span[k + 1]
    key = (a - lo) @ mult
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    out = (a[first],)
    if return_index:
        out += (first,)
    if return_inverse:
        out += (inv.ravel(),)
    return out if len(out) > 1 else out[0]


def _cluster_votes(index: _PairIndex, pos, cluster: MarkerCluster, tol: float):
    """Hypotheses of one cluster in every frame: (t, assignment (h, K) slots or -1, SSE of the fit m^2).

    Each template triangle whose side lengths a frame's points show within `tol` places the
    template (the triangles' frames, no fit); the other markers take the only point within `tol`
    of their predictions; the hypotheses, once each, are then fitted by Kabsch and kept when every
    marker lies within `tol` of the fit. Frames with a hypothesis of all K markers are not searched
    with further triangles."""
    tpl = cluster.template_m
    K = tpl.shape[0]
    T, P = pos.shape[:2]
    D = index.D
    d_t = np.linalg.norm(tpl[:, None] - tpl[None], axis=2)
    hyp_t, hyp_a = [], []
    complete = np.zeros(T, bool)
    for a, b, c in _triangles(tpl):
        tt, ii, jj = index.near(d_t[a, b], tol, np.flatnonzero(~complete))
        if not tt.size:
            continue
        ok_k = (np.abs(D[tt, jj] - d_t[b, c]) < tol) & (np.abs(D[tt, ii] - d_t[a, c]) < tol)   # (n, P)
        r, kk = np.nonzero(ok_k)
        tt, ii, jj = tt[r], ii[r], jj[r]
        keep = (kk != ii) & (kk != jj)
        tt, ii, jj, kk = tt[keep], ii[keep], jj[keep], kk[keep]
        if not tt.size:
            continue
        n = tt.size
        assign = np.full((n, K), -1)
        assign[:, a], assign[:, b], assign[:, c] = ii, jj, kk
        tri_q = pos[tt[:, None], assign[:, [a, b, c]]]
        tri_p = tpl[[a, b, c]]
        R = _triad(tri_q) @ _triad(tri_p[None])[0].T
        t = tri_q.mean(axis=1) - tri_p.mean(axis=0) @ np.swapaxes(R, 1, 2)
        pred = np.einsum("nij,kj->nki", R, tpl) + t[:, None]                       # (n, K, 3)
        rows = np.arange(n)
        used = np.zeros((n, P), bool)
        for col in (a, b, c):
            used[rows, assign[:, col]] = True
        for k in range(K):                   # the other markers: the only point within tol
            if k in (a, b, c):
                continue
            dk = np.linalg.norm(pos[tt] - pred[:, k:k + 1], axis=2)                 # (n, P)
            dk = np.where(used | ~np.isfinite(dk), np.inf, dk)
            within = dk < tol
            one = within.sum(axis=1) == 1
            best = np.argmax(within, axis=1)
            assign[one, k] = best[one]
            used[rows[one], best[one]] = True
        complete[tt[(assign >= 0).all(axis=1)]] = True
        hyp_t.append(tt)
        hyp_a.append(assign)
    if not hyp_t:
        return np.zeros(0, int), np.zeros((0, K), int), np.zeros(0)
    key = _unique_rows(np.column_stack([np.concatenate(hyp_t), np.concatenate(hyp_a)]))
    t, assign = key[:, 0], key[:, 1:]
    n = t.size
    w = (assign >= 0).astype(np.float64)
    qq = pos[t[:, None], np.maximum(assign, 0)]
    R, tr = rigid_fit(np.broadcast_to(tpl, (n, K, 3)), qq, w)
    pred = np.einsum("nij,kj->nki", R, tpl) + tr[:, None]
    err = np.where(w > 0, np.linalg.norm(pred - qq, axis=2), 0.0)
    good = err.max(axis=1) < tol
    return t[good], assign[good], (err**2).sum(axis=1)[good]


def _frame_votes(pos, tid_slot, clusters, label_index, tol, window: int = 25):
    """Per slot (T, P): the label geometry votes for (-1 none) and the number of markers of the
    winning hypothesis (0 none).

    Per frame and cluster the hypotheses with the most markers compete. When they all place the
    same points (a nearly symmetric template: only the labels differ), the frames whose points
    belong to the same tracklets decide together: in each frame, the assignment of labels to
    tracklets with the least fit error summed over the group's frames within `window` frames of it
    (K tol^2 for a frame where it does not fit) wins, when it beats the next by 25 noise variances
    (the noise variance from the fits themselves); else the frame names nothing. A window, not the
    whole group, so that tracklets which swap markers halfway are judged on each side. Frames
    whose best hypotheses place different points name nothing."""
    T, P = pos.shape[:2]
    vote = np.full((T, P), -1)
    strength = np.zeros((T, P), int)
    contested = np.zeros((T, P), bool)
    index = _PairIndex(pos)
    for c in clusters:
        t, assign, sse = _cluster_votes(index, pos, c, tol)
        if not t.size:
            continue
        K = assign.shape[1]
        found = (assign >= 0).sum(axis=1)
        # keep, per frame, the hypotheses with the most markers (_cluster_votes gave each once,
        # sorted by frame)
        top = np.zeros(T, int)
        np.maximum.at(top, t, found)
        best = found == top[t]
        t, assign, sse, found = t[best], assign[best], sse[best], found[best]
        # the same points in every hypothesis of a frame?
        pts = np.sort(np.where(assign >= 0, assign, P), axis=1)
        lead = np.r_[0, np.flatnonzero(t[1:] != t[:-1]) + 1]
        grp = np.cumsum(np.r_[True, t[1:] != t[:-1]]) - 1
        same = np.ones(lead.size, bool)
        np.logical_and.at(same, grp, (pts == pts[lead[grp]]).all(axis=1))
        keep = same[grp]
        t, assign, sse, found, grp = t[keep], assign[keep], sse[keep], found[keep], grp[keep]
        if not t.size:
            continue
        # labels -> tracklets; frames with the same tracklet set form a group, in which each
        # assignment of labels to tracklets is a hypothesis, judged on a window of the group's frames
        trk = np.where(assign >= 0, tid_slot[t[:, None], np.maximum(assign, 0)], -1)
        members = np.sort(trk, axis=1)
        _, gid = _unique_rows(members, return_inverse=True)
        gid = gid.ravel()
        _, hid = _unique_rows(np.column_stack([gid, trk]), return_inverse=True)
        hid = hid.ravel()
        gid_h = np.zeros(hid.max() + 1, int)
        gid_h[hid] = gid
        first_h = np.full(gid.max() + 1, np.iinfo(np.int64).max)
        np.minimum.at(first_h, gid_h, np.arange(gid_h.size))
        hl = hid - first_h[gid]                                   # hypothesis index within its group
        n_h = np.bincount(gid_h)                                  # hypotheses per group
        _, gf = np.unique(gid * T + t, return_inverse=True)       # group-frames, by group then time
        gf = gf.ravel()
        n_gf = gf.max() + 1
        g_of_gf = np.zeros(n_gf, int)
        g_of_gf[gf] = gid
        H = int(hl.max()) + 1
        cost = np.full((n_gf, H), K * tol**2)                     # absent in a frame: K tol^2
        cost[gf, hl] = sse
        valid = np.arange(H)[None] < n_h[g_of_gf][:, None]
        cost[~valid] = 0.0
        S = np.vstack([np.zeros((1, H)), np.cumsum(cost, axis=0)])
        g_start = np.searchsorted(g_of_gf, g_of_gf, "left")
        g_end = np.searchsorted(g_of_gf, g_of_gf, "right") - 1
        i = np.arange(n_gf)
        lo = np.maximum(i - window, g_start)
        hi = np.minimum(i + window, g_end)
        wsum = np.where(valid, S[hi + 1] - S[lo], np.inf)
        best = np.argmin(wsum, axis=1)
        w2 = wsum.copy()
        w2[i, best] = np.inf
        # the noise variance: the median over frames of the best fit's SSE per degree of freedom
        dof = np.maximum(3 * found - 6, 1)
        frame_best = np.full(T, np.inf)
        np.minimum.at(frame_best, t, sse / dof)
        sigma2 = max(float(np.median(frame_best[np.isfinite(frame_best)])), 1e-12)
        decisive = (w2.min(axis=1) - wsum[i, best]) > 25.0 * sigma2
        use = decisive[gf] & (hl == best[gf])
        tw, aw, fw = t[use], assign[use], found[use]
        for k in range(K):
            has = aw[:, k] >= 0
            ts, ss = tw[has], aw[has, k]
            lab = label_index[c.labels[k]]
            prev = vote[ts, ss]
            stronger = fw[has] > strength[ts, ss]
            tie = (fw[has] == strength[ts, ss]) & (prev >= 0) & (prev != lab)
            contested[ts[tie], ss[tie]] = True
            vote[ts[stronger], ss[stronger]] = lab
            strength[ts[stronger], ss[stronger]] = fw[has][stronger]
    vote[contested] = -1
    strength[contested] = 0
    return vote, strength


# --- labelling ---------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Labelling:
    """Labelled trajectories from unlabelled points.

    Attributes
    ----------
    markers : MarkerTrajectories
        (T, M, 3) metres, NaN where missing; ``residual`` the points' ray residuals (m), 0 where a
        gap was filled from the rigid fit (C3D's "modelled" value).
    camera_mask : (T, M) int
        Bit c set when camera c saw the marker (0 where filled or missing).
    filled : (T, M) bool
        Samples filled from the cluster's rigid fit.
    long_gaps : tuple of dict
        Gaps longer than the fill limit, or without a rigid fit: label, first frame, frames.
    point_label : (n,) int
        Label index given to each input point (-1 none).
    stats : dict
        Counts: points, labelled, tracklets, swaps repaired, labels removed by the rigid check,
        samples filled, long gaps.
    """

    markers: MarkerTrajectories
    camera_mask: np.ndarray
    filled: np.ndarray
    long_gaps: tuple
    point_label: np.ndarray
    stats: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        xyz = self.markers.xyz
        missing = ~np.isfinite(xyz[..., 0])
        return dict(self.stats) | {
            "labels": list(self.markers.labels), "n_frames": int(xyz.shape[0]),
            "nan_share": float(missing.mean()) if missing.size else math.nan,
            "nan_share_by_label": {s: float(missing[:, i].mean()) for i, s in enumerate(self.markers.labels)},
            "long_gaps": [dict(g) for g in self.long_gaps]}


def _runs(mask: np.ndarray):
    """Runs of True in each column of mask (T, M): (column, start, length)."""
    T, M = mask.shape
    pad = np.zeros((T + 2, M), bool)
    pad[1:-1] = mask
    d = np.diff(pad.astype(np.int8), axis=0)
    s_t, s_m = np.nonzero(d == 1)
    e_t, e_m = np.nonzero(d == -1)
    o1 = np.lexsort((s_t, s_m))
    o2 = np.lexsort((e_t, e_m))
    return s_m[o1], s_t[o1], e_t[o2] - s_t[o1]


def fill_gaps(xyz: np.ndarray, labels: Sequence[str], clusters: Sequence[MarkerCluster], max_gap_frames: int):
    """Fill gaps of at most `max_gap_frames` from the cluster's rigid fit of each frame.

    Returns
    -------
    xyz : (T, M, 3) float
        With the short gaps filled where three or more of the cluster's markers were present.
    filled : (T, M) bool
    long_gaps : list of dict
        Gaps left (wholly or partly) open: label, start_frame, n_frames, reason (longer than the
        limit, or frames without a rigid fit) and filled_frames.
    """
    xyz = np.array(xyz, dtype=np.float64)
    missing = ~np.isfinite(xyz[..., 0])
    pred, _, _ = fit_clusters(xyz, labels, clusters, frames=missing.any(axis=1))
    col, start, length = _runs(missing)
    short = length <= max_gap_frames
    fillable = missing & np.isfinite(pred[..., 0])
    gap_id = np.full(missing.shape, -1)
    for k in np.flatnonzero(short):                          # one slice per gap, not per frame
        gap_id[start[k]:start[k] + length[k], col[k]] = k
    fill = fillable & (gap_id >= 0)
    xyz[fill] = pred[fill]
    long_gaps = []
    for k in range(col.size):
        n_fill = int(fill[start[k]:start[k] + length[k], col[k]].sum())
        if short[k] and n_fill == length[k]:
            continue
        long_gaps.append({"label": labels[col[k]], "start_frame": int(start[k]), "n_frames": int(length[k]),
                          "reason": "longer than the fill limit" if not short[k] else "no rigid fit in some frames",
                          "filled_frames": n_fill})
    return xyz, fill, long_gaps


def label_points(frame, p_world, clusters: Sequence[MarkerCluster], *, n_frames: int, rate_hz: float,
                 first_frame: int = 0, residual_m=None, camera_mask=None, tol_m: float = 0.003,
                 max_speed_m_s: float = 3.0, max_gap_s: float = 0.1, tracklet=None) -> Labelling:
    """Label unlabelled 3D points with the clusters' markers (module docstring).

    Parameters
    ----------
    frame : (n,) int
        Frame of each point, 0..n_frames-1.
    p_world : (n, 3) float
        Points, metres (NaN rows are ignored).
    clusters : sequence of MarkerCluster
        Labels unique across clusters. A template that a relabelling maps onto itself within 50 um
        is refused (:func:`cluster_symmetry`); one within `tol_m` is labelled over time (frames of
        a tracklet group decide together) and named in ``stats["nearly_symmetric_clusters"]``.
    n_frames : int
    rate_hz : float
    first_frame : int
        Frame index of frame 0 on the mocap clock (t = (first_frame + i) / rate_hz).
    residual_m : (n,) float, optional
        Each point's residual (ray distance), m.
    camera_mask : (n,) int, optional
        Each point's camera bits.
    tol_m : float
        Geometric tolerance: template distances, rigid-fit residuals, m.
    max_speed_m_s : float
        Fastest marker speed for linking.
    max_gap_s : float
        Longest gap filled from the rigid fit.
    tracklet : (n,) int, optional
        Tracklet ids from elsewhere (e.g. the unlabelled trajectories of another system's C3D, which
        may hold swaps) instead of this module's linking.

    Returns
    -------
    Labelling
    """
    frame = np.asarray(frame, dtype=np.int64)
    p = np.asarray(p_world, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or frame.shape != (p.shape[0],):
        raise InputError(None, "p_world", "(n, 3) points with an (n,) frame index", f"shapes {p.shape}, {frame.shape}")
    if frame.size and (frame.min() < 0 or frame.max() >= n_frames):
        raise InputError(None, "frame", f"frames 0..{n_frames - 1}", f"{int(frame.min())}..{int(frame.max())}")
    if not clusters:
        raise InputError(None, "clusters", "at least one rigid cluster to label from", "none")
    labels = [s for c in clusters for s in c.labels]
    if len(set(labels)) != len(labels):
        raise InputError(None, "clusters", "each label in one cluster", "a label in two clusters")
    nearly = [c.name for c in clusters if cluster_symmetry(c, tol_m) is not None]
    for c in clusters:
        sym = cluster_symmetry(c, 5e-5)
        if sym is not None:
            raise InputError(None, f"cluster {c.name!r}", "a template whose markers geometry can tell apart",
                             "a symmetric template (" + ", ".join(f"{c.labels[i]}->{c.labels[j]}" for i, j in
                                                                   enumerate(sym) if i != j) + ")",
                             hint="move a marker so that its distances to the others differ by a few mm")
    label_index = {s: i for i, s in enumerate(labels)}
    M = len(labels)
    n = frame.size
    res = np.zeros(n) if residual_m is None else np.asarray(residual_m, dtype=np.float64)
    cmask = np.zeros(n, np.int64) if camera_mask is None else np.asarray(camera_mask, dtype=np.int64)
    finite = np.isfinite(p).all(axis=1)
    keep = np.flatnonzero(finite)
    frame_k, p_k = frame[keep], p[keep]
    pos, idx, slot = _padded(frame_k, p_k, n_frames)
    if tracklet is None:
        tid = link_points(frame_k, p_k, n_frames, rate_hz=rate_hz, max_speed_m_s=max_speed_m_s)
    else:
        tid = np.unique(np.asarray(tracklet, dtype=np.int64)[keep], return_inverse=True)[1].ravel()
    tid_slot = np.full(idx.shape, -1)
    tid_slot[frame_k, slot] = tid
    vote, strength = _frame_votes(pos, tid_slot, clusters, label_index, tol_m)
    v = vote[frame_k, slot]                                           # per point
    s = strength[frame_k, slot]
    # labels along tracklets: order points by (tracklet, frame); runs of equal votes
    order = np.lexsort((frame_k, tid))
    tv = v[order]
    tt = tid[order]
    voted = tv >= 0
    lab = np.full(order.size, -1)
    swaps = 0
    if voted.any():
        vi = np.flatnonzero(voted)
        # previous and next vote within the same tracklet, for every point
        prev_idx = np.full(order.size, -1)
        prev_idx[vi] = vi
        prev_idx = np.maximum.accumulate(prev_idx)
        next_idx = np.full(order.size, order.size)
        next_idx[vi] = vi
        next_idx = np.minimum.accumulate(next_idx[::-1])[::-1]
        pv = np.where(prev_idx >= 0, tv[np.maximum(prev_idx, 0)], -1)
        pv = np.where((prev_idx >= 0) & (tt[np.maximum(prev_idx, 0)] == tt), pv, -1)
        nv = np.where(next_idx < order.size, tv[np.minimum(next_idx, order.size - 1)], -1)
        nv = np.where((next_idx < order.size) & (tt[np.minimum(next_idx, order.size - 1)] == tt), nv, -1)
        # a point takes its own vote; unvoted points the vote on both sides when they agree, or
        # the only one (tracklet ends)
        lab = np.where(voted, tv, np.where((pv == nv) | (nv < 0), pv, np.where(pv < 0, nv, -1)))
        # a lone vote against a long run is noise: a run of one vote between two runs of another
        # label in the same tracklet is outvoted
        w = np.flatnonzero(voted)
        wl = tv[w]
        wt = tt[w]
        lone = np.zeros(w.size, bool)
        if w.size >= 3:
            lone[1:-1] = (wl[1:-1] != wl[:-2]) & (wl[:-2] == wl[2:]) & (wt[:-2] == wt[1:-1]) & (wt[1:-1] == wt[2:])
            lab[w[lone]] = wl[:-2][lone[1:-1]] if lone[1:-1].any() else lab[w[lone]]
        changes = (wl[1:] != wl[:-1]) & (wt[1:] == wt[:-1]) & ~lone[1:] & ~lone[:-1]
        swaps = int(changes.sum())
    point_label = np.full(keep.size, -1)
    point_label[order] = lab
    # one point per label and frame: geometry's vote first, else none
    key = frame_k * M + point_label
    lab_ok = point_label >= 0
    uk, inv, cnt = np.unique(key[lab_ok], return_inverse=True, return_counts=True)
    dup = cnt[inv] > 1
    if dup.any():
        li = np.flatnonzero(lab_ok)
        own = (v[li] == point_label[li])
        n_own = np.bincount(inv, own.astype(int), uk.size)
        # keep a duplicated label on the point geometry voted for when it is the only such point
        drop = dup & ~(own & (n_own[inv] == 1))
        point_label[li[drop]] = -1
    # the rigid check
    xyz = np.full((n_frames, M, 3), np.nan)
    src = np.full((n_frames, M), -1)
    lab_ok = point_label >= 0
    xyz[frame_k[lab_ok], point_label[lab_ok]] = p_k[lab_ok]
    src[frame_k[lab_ok], point_label[lab_ok]] = keep[lab_ok]
    removed = 0
    todo = np.ones(n_frames, bool)
    for _ in range(3):
        _, resid, npres = fit_clusters(xyz, labels, clusters, frames=todo)
        bad = (resid > tol_m) & (npres >= 3)
        # a marker of a fit that fails: drop the worst one of each failing frame and cluster, then refit
        if not bad.any():
            break
        worst = np.zeros_like(bad)
        for c in clusters:
            cols = np.array([label_index[s] for s in c.labels])
            r = np.where(bad[:, cols], resid[:, cols], -1.0)
            has = (r > 0).any(axis=1)
            worst[np.flatnonzero(has), cols[np.argmax(r[has], axis=1)]] = True
        xyz[worst] = np.nan
        src[worst] = -1
        removed += int(worst.sum())
        todo = worst.any(axis=1)
    for c in clusters:                              # two markers present: their distance must fit
        cols = np.array([label_index[s] for s in c.labels])
        present = np.isfinite(xyz[:, cols, 0])
        two = present.sum(axis=1) == 2
        if not two.any():
            continue
        d_t = np.linalg.norm(c.template_m[:, None] - c.template_m[None], axis=2)
        rows = np.flatnonzero(two)
        pk = np.argsort(~present[rows], axis=1, kind="stable")[:, :2]
        a, b = cols[pk[:, 0]], cols[pk[:, 1]]
        d = np.linalg.norm(xyz[rows, a] - xyz[rows, b], axis=1)
        bad = np.abs(d - d_t[pk[:, 0], pk[:, 1]]) > tol_m
        for col in (a, b):
            xyz[rows[bad], col[bad]] = np.nan
            src[rows[bad], col[bad]] = -1
        removed += 2 * int(bad.sum())
    final_label = np.full(n, -1)
    ok_src = src >= 0
    final_label[src[ok_src]] = np.nonzero(ok_src)[1]
    residual = np.full((n_frames, M), np.nan)
    mask = np.zeros((n_frames, M), np.int64)
    residual[ok_src] = res[src[ok_src]]
    mask[ok_src] = cmask[src[ok_src]]
    max_gap = int(round(max_gap_s * rate_hz))
    xyz, filled, long_gaps = fill_gaps(xyz, labels, clusters, max_gap)
    residual[filled] = 0.0
    t = (first_frame + np.arange(n_frames)) / rate_hz
    markers = MarkerTrajectories(t=t, xyz=xyz, labels=tuple(labels), rate_hz=rate_hz, residual=residual)
    stats = {"n_points": int(finite.sum()), "n_labelled": int(ok_src.sum()),
             "n_unlabelled": int(finite.sum() - ok_src.sum()), "n_tracklets": int(tid.max(initial=-1) + 1),
             "swaps_repaired": swaps, "removed_by_rigid_check": removed, "gaps_filled": int(filled.sum()),
             "n_long_gaps": len(long_gaps), "tol_m": tol_m, "max_gap_frames": max_gap,
             "nearly_symmetric_clusters": nearly}
    return Labelling(markers=markers, camera_mask=mask, filled=filled, long_gaps=tuple(long_gaps),
                     point_label=final_label, stats=stats)
