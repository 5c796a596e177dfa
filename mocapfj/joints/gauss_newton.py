"""The batched numerical core of :mod:`.chain`: forward kinematics, normal equations, Cholesky and
Gauss-Newton over many frames at once (no per-frame Python loop). Its functions take a
:class:`.chain.ChainModel` (duck-typed here: this module does not import `chain`)."""

from __future__ import annotations

import numpy as np

__all__ = ["chain_fk", "subtree_sums", "normal_equations", "BatchCholesky", "gauss_newton", "evaluate_chain"]

_RCOND = 1e-10      # smallest Cholesky pivot of the Jacobi-scaled normal matrix of a solvable frame
_MAX_STEP = 0.5     # rad: Gauss-Newton steps are scaled down to at most this per joint
_CHUNK = 1024       # frames per batch: keeps the working arrays in cache
_CHORD = 1e-3       # rad: below this step size Gauss-Newton keeps the normal matrix (chord method)


def chain_fk(model, q: np.ndarray, with_markers: bool = True):
    """Axis-aligned joint frames in the world, R (n+1, 3, 3, F), t (n+1, 3, F) (slot n is the
    root), and marker positions y (M, 3, F): R_j = R_parent G_j Rz(q_j), t_j = R_parent g_j + t_parent."""
    n, F = q.shape
    c, s = np.cos(q), np.sin(q)
    R = np.empty((n + 1, 3, 3, F))
    t = np.empty((n + 1, 3, F))
    R[n], t[n] = model.T_world_root[:3, :3, None], model.T_world_root[:3, 3, None]
    Gg = np.concatenate([model.R_parent_joint, model.t_parent_joint[:, :, None]], axis=2)    # (n, 3, 4)
    for j in range(n):
        p = model.parent[j]                                               # -1 is the root slot n
        A = Gg[j].T @ R[p]                                                # (3, 4, F): [R_p G | R_p g]
        t[j] = A[:, 3] + t[p]
        R[j, :, 0] = c[j] * A[:, 0] + s[j] * A[:, 1]
        R[j, :, 1] = c[j] * A[:, 1] - s[j] * A[:, 0]
        R[j, :, 2] = A[:, 2]
    if not with_markers:
        return R, t, None
    y = np.empty((len(model.labels), 3, F))
    for k in np.unique(model.marker_joint):
        idx = np.flatnonzero(model.marker_joint == k)
        y[idx] = np.swapaxes(model.p_joint[idx] @ R[k], 0, 1) + t[k][None]
    return R, t, y


def batched_cross(a, b):
    """Cross product along axis 1 of (K, 3, F) arrays."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def subtree_sums(model, X: np.ndarray) -> np.ndarray:
    """Sums of X (M, K, F) over the markers each joint moves, (n, K, F): per link group, then
    accumulated from the leaves to the root (no BLAS: threaded tiny products stall on busy cores)."""
    out = np.zeros((model.n_joints,) + X.shape[1:])
    for k in np.unique(model.marker_joint[model.marker_joint >= 0]):
        out[k] = X[model.marker_joint == k].sum(axis=0)
    for j in range(model.n_joints - 1, -1, -1):
        if model.parent[j] >= 0:
            out[model.parent[j]] += out[j]
    return out


def normal_equations(model, q, v, w, with_A: bool = True):
    """Gauss-Newton normal equations of Lightcap and Banks (2007), eq. (13) with marker weights w (M, F).

    A = J^T W J and b = J^T W (v - y), with J_mj = n_j x (y_m - o_j) for the joints j upstream of
    marker m (n_j, o_j: world axis and origin of joint j), are summed from marker moments instead
    of forming J: with d_j = y - o_j and (a x b).(c x d) = (a.c)(b.d) - (a.d)(b.c),
    A_jk = (n_j.n_k) sum d_j.d_k - sum (n_j.d_k)(n_k.d_j) over the markers moved by both joints,
    which needs only sum 1, sum y and sum y y^T of those markers; b_j = n_j . sum d_j x r.
    Coordinates are centred on the frame's mean marker to limit cancellation.

    Returns A (n, n, F) (None unless `with_A`), b (n, F) and the residuals r (M, 3, F) = v - y.
    """
    R, t, y = chain_fk(model, q)
    n, F = q.shape
    M = y.shape[0]
    r = v - y
    cen = y.mean(axis=0)
    yc = y - cen
    o = t[:n] - cen                                                       # (n, 3, F) joint origins
    nz = R[:n, :, 2]                                                      # (n, 3, F) world axes
    rw = r * w[:, None]
    yr = subtree_sums(model, np.concatenate([batched_cross(yc, rw), rw], axis=1))
    b = (nz * (yr[:, :3] - batched_cross(o, yr[:, 3:]))).sum(1)                 # (n, F); yr: sums of y x r, r
    if not with_A:
        return None, b, r
    feat = np.empty((M, 10, F))                           # w [1, y, yx yx, yy yy, yz yz, yx yy, yx yz, yy yz]
    feat[:, 0] = w
    feat[:, 1:4] = yc * w[:, None]
    feat[:, 4:7] = feat[:, 1:4] * yc
    feat[:, 7:9] = feat[:, 1:2] * yc[:, 1:3]
    feat[:, 9] = feat[:, 2] * yc[:, 2]
    mom = subtree_sums(model, feat)                                      # (n, 10, F)
    jj, kk = np.triu_indices(n)                                           # pairs j <= k; A is symmetric
    up = model.moves_joint
    rel = up[kk, jj] | up[jj, kk]                                         # markers moved by both: those of
    mp = mom[np.where(up[kk, jj], kk, jj)]                                # the deeper joint (none if unrelated)
    if not rel.all():
        mp[~rel] = 0.0
    N, S, Qd, Qo = mp[:, 0], mp[:, 1:4], mp[:, 4:7], mp[:, 7:10]
    oJ, oK, nJ, nK = o[jj], o[kk], nz[jj], nz[kk]                        # (P, 3, F)
    D = Qd.sum(1) - (S * (oJ + oK)).sum(1) + N * (oJ * oK).sum(1)        # sum d_j . d_k
    nQn = ((nJ * nK * Qd).sum(1) + Qo[:, 0] * (nJ[:, 0] * nK[:, 1] + nJ[:, 1] * nK[:, 0])
           + Qo[:, 1] * (nJ[:, 0] * nK[:, 2] + nJ[:, 2] * nK[:, 0]) + Qo[:, 2] * (nJ[:, 1] * nK[:, 2] + nJ[:, 2] * nK[:, 1]))
    nj_ok, nk_oj = (nJ * oK).sum(1), (nK * oJ).sum(1)
    E = nQn - (S * nJ).sum(1) * nk_oj - nj_ok * (S * nK).sum(1) + N * nj_ok * nk_oj   # sum (n_j.d_k)(n_k.d_j)
    A = np.empty((n, n, F))
    A[jj, kk] = A[kk, jj] = (nJ * nK).sum(1) * D - E
    return A, b, r


class BatchCholesky:
    """Cholesky factor of the Jacobi-scaled normal matrices C = S A S (S = diag(A)^-1/2) of many
    frames, computed elementwise over frames (A (n, n, F)); a 1e-12 ridge keeps frames that do not
    determine every joint finite. `determined`: all diag(A) > 0 and every pivot of C > _RCOND."""

    def __init__(self, A: np.ndarray):
        n = A.shape[0]
        d = np.einsum("jjf->jf", A)
        self.s = 1.0 / np.sqrt(np.where(d > 0, d, 1.0))
        C = A * self.s[:, None] * self.s[None, :]
        L = np.zeros_like(C)
        piv = np.empty_like(d)
        for j in range(n):
            piv[j] = C[j, j] + 1e-12 - (L[j, :j] ** 2).sum(0)
            L[j, j] = np.sqrt(np.maximum(piv[j], 1e-300))
            for i in range(j + 1, n):
                L[i, j] = (C[i, j] - (L[i, :j] * L[j, :j]).sum(0)) / L[j, j]
        self.L, self.piv = L, piv
        self.determined = (d > 0).all(axis=0) & (piv.min(axis=0) > _RCOND)

    def take(self, idx) -> BatchCholesky:
        """The factors of frames `idx`."""
        f = object.__new__(BatchCholesky)
        f.s, f.L, f.piv, f.determined = self.s[:, idx], self.L[..., idx], self.piv[:, idx], self.determined[idx]
        return f

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x (n, F) with A x = b (n, F)."""
        L, n = self.L, self.L.shape[0]
        z = np.empty_like(b)
        for j in range(n):
            z[j] = (b[j] * self.s[j] - (L[j, :j] * z[:j]).sum(0)) / L[j, j]
        for j in range(n - 1, -1, -1):
            z[j] = (z[j] - (L[j + 1:, j] * z[j + 1:]).sum(0)) / L[j, j]
        return z * self.s

    def inv_diag(self) -> np.ndarray:
        """diag(A^-1), (n, F): squared column norms of L^-1, scaled back."""
        L, n = self.L, self.L.shape[0]
        X = np.zeros_like(L)                                              # X = L^-1, lower triangular
        for j in range(n):
            X[j, j] = 1.0 / L[j, j]
            for i in range(j + 1, n):
                X[i, j] = -(L[i, j:i] * X[j:i, j]).sum(0) / L[i, i]
        return (X * X).sum(0) * self.s**2


def frame_chunks(F: int):
    return (slice(i, min(F, i + _CHUNK)) for i in range(0, F, _CHUNK))


def gauss_newton(model, q, v, w, max_iter, tol):
    """Batched Gauss-Newton from q (n, F) on v (M, 3, F), w (M, F), in cache-sized chunks of frames;
    only unconverged frames are re-evaluated. Steps solve the Jacobi-scaled normal equations and
    are scaled down to at most _MAX_STEP rad. Once a frame's step is below _CHORD rad its normal
    matrix is kept (chord method: the contraction rate stays ~|dq|, and each step then needs only
    the forward kinematics and J^T r).

    Returns q (n, F), iterations (F,), converged (F,) (last step max |dq| < tol rad), the normal
    matrix A (n, n, F) of each frame's last full evaluation (within ~_CHORD^2 rad of q) and the
    squared residuals w |r|^2 (M, F) of its last evaluation (at q for frames not converged).
    """
    q = q.copy()
    n, F = q.shape
    n_it = np.zeros(F, np.int64)
    conv = np.zeros(F, bool)
    A_last = np.empty((n, n, F))
    e2 = np.empty(w.shape)
    for sl in frame_chunks(F):
        act = np.arange(sl.start, sl.stop)                                # frames still iterating
        fac = None                                                        # factors of the chunk's frames
        prev = np.full(act.size, np.inf)                                  # last step of each frame
        for _ in range(max_iter):
            if act.size == 0:
                break
            dq = np.empty((n, act.size))
            full = prev > _CHORD
            for sel in (np.flatnonzero(full), np.flatnonzero(~full)):
                if sel.size == 0:
                    continue
                a = act[sel]
                A, b, r = normal_equations(model, q[:, a], v[..., a], w[:, a], with_A=bool(full[sel[0]]))
                e2[:, a] = (r * r).sum(axis=1) * w[:, a]
                if A is not None:
                    A_last[..., a] = A
                    f = BatchCholesky(A)
                    if fac is None:                                       # first iteration: every frame
                        fac = f
                    else:
                        fac.L[..., a - sl.start], fac.s[:, a - sl.start] = f.L, f.s
                else:
                    f = fac.take(a - sl.start)
                dq[:, sel] = f.solve(b)
            step = np.abs(dq).max(axis=0)
            dq *= np.minimum(1.0, _MAX_STEP / np.maximum(step, 1e-300))
            q[:, act] += dq
            n_it[act] += 1
            done = step < tol
            conv[act[done]] = True
            act, prev = act[~done], step[~done]
    if not conv.all():
        A_last[..., ~conv], e2[:, ~conv] = evaluate_chain(model, q[:, ~conv], v[..., ~conv], w[:, ~conv])
    return q, n_it, conv, A_last, e2


def evaluate_chain(model, q, v, w):
    """Normal matrix A (n, n, F) and weighted squared marker residuals w |v - y|^2 (M, F), chunked."""
    F = q.shape[1]
    A = np.empty((q.shape[0], q.shape[0], F))
    e2 = np.empty(w.shape)
    for sl in frame_chunks(F):
        A[..., sl], _, r = normal_equations(model, q[:, sl], v[..., sl], w[:, sl])
        e2[:, sl] = (r * r).sum(axis=1) * w[:, sl]
    return A, e2
