"""A pose graph over cameras: robust rotation averaging, then translations.

Nodes are cameras; each measurement (an edge sample) is a relative pose between two cameras from
one co-observation (both cameras saw the same board at the same frame, or a pair's essential
matrix), with the convention

    x_i = R_ij x_j + t_ij,  so that R_i = R_ij R_j and t_i = R_ij t_j + t_ij

for world-to-camera poses (R_i, t_i). Camera `root` is the world (R = I, t = 0): the gauge.

Rotations (:func:`average_rotations`): each pair's samples are averaged by the geodesic L1 mean
(Weiszfeld's algorithm, Hartley, Aftab and Trumpf 2011), a maximum spanning tree of the pairs
(weighted by their number of samples) chains the pair means from the root, and iteratively
reweighted least squares over every sample refines all rotations at once, in the Lie algebra,
with Cauchy weights (Chatterjee and Govindu 2013, 2018: L1 start, then IRLS). Translations
(:func:`average_translations`): weighted linear least squares on t_i - R_ij t_j = t_ij with the
averaged rotations, reweighted the same way. No random sampling anywhere: the same
measurements give the same poses, bit for bit.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["chordal_mean", "geodesic_median", "average_rotations", "average_translations", "components",
           "log_rotation", "exp_rotation"]


def exp_rotation(w: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) to matrices (..., 3, 3) (Rodrigues)."""
    from .projection import rotation_jacobian

    w = np.asarray(w, dtype=np.float64)
    return rotation_jacobian(w.reshape(-1, 3))[0].reshape(w.shape[:-1] + (3, 3))


def log_rotation(R: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) to rotation vectors (..., 3), rad."""
    from scipy.spatial.transform import Rotation

    R = np.asarray(R, dtype=np.float64)
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(R.shape[:-2] + (3,))


def _project_so3(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    D = np.ones(M.shape[:-2] + (3,))
    D[..., 2] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def chordal_mean(R: np.ndarray, weights=None) -> np.ndarray:
    """The rotation nearest (Frobenius) to the weighted mean of rotations R (N, 3, 3)."""
    w = np.ones(len(R)) if weights is None else np.asarray(weights, dtype=np.float64)
    return _project_so3(np.einsum("n,nij->ij", w, R) / w.sum())


def geodesic_median(R: np.ndarray, iterations: int = 50, tol: float = 1e-12) -> np.ndarray:
    """The geodesic L1 mean of rotations R (N, 3, 3), by Weiszfeld's algorithm on SO(3)
    (Hartley, Aftab and Trumpf 2011), started at the chordal mean."""
    m = chordal_mean(R)
    for _ in range(iterations):
        v = log_rotation(np.einsum("nij,kj->nik", R, m))    # R_n m^T
        d = np.linalg.norm(v, axis=1)
        w = 1.0 / np.maximum(d, 1e-9)
        step = (w[:, None] * v).sum(axis=0) / w.sum()
        m = exp_rotation(step) @ m
        if np.linalg.norm(step) < tol:
            break
    return m


def components(n: int, i, j) -> np.ndarray:
    """Connected component label (the smallest node number in it) of each of n nodes under edges (i, j)."""
    label = np.arange(n)
    changed = True
    i = np.asarray(i, dtype=np.intp)
    j = np.asarray(j, dtype=np.intp)
    while changed:
        lo = np.minimum(label[i], label[j])
        new = label.copy()
        np.minimum.at(new, i, lo)
        np.minimum.at(new, j, lo)
        new = new[new]
        changed = bool((new != label).any())
        label = new
    return label


def _spanning_tree_rotations(n: int, pairs: dict, root: int) -> np.ndarray:
    """Chain pair means along a maximum spanning tree (Prim, ties by node number) from `root`."""
    R = np.full((n, 3, 3), np.nan)
    R[root] = np.eye(3)
    done = {root}
    while len(done) < n:
        best = None
        for (a, b), (Rab, count) in sorted(pairs.items()):
            if (a in done) == (b in done):
                continue
            if best is None or count > best[0]:
                best = (count, a, b, Rab)
        if best is None:
            break
        _, a, b, Rab = best
        if a in done:                                   # R_b = R_ab^T R_a
            R[b] = Rab.T @ R[a]
            done.add(b)
        else:                                           # R_a = R_ab R_b
            R[a] = Rab @ R[b]
            done.add(a)
    return R


def _cauchy(e: np.ndarray, scale: float) -> np.ndarray:
    return 1.0 / (1.0 + (e / scale) ** 2)


def average_rotations(n: int, i, j, R_ij, *, root: int = 0, weights=None, min_scale_rad: float = np.radians(0.2),
                      iterations: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """Absolute rotations of n cameras from relative rotation samples.

    Parameters
    ----------
    n : int
        Number of cameras.
    i, j : (E,) int
        The two cameras of each sample.
    R_ij : (E, 3, 3) float
        Samples of R_i R_j^T.
    root : int
        The camera that is the world (R = I).
    weights : (E,) float, optional
        Prior weight of each sample (default 1).
    min_scale_rad : float
        Floor of the Cauchy scale; the scale is otherwise 3 x the robust SD of the residuals.

    Returns
    -------
    R : (n, 3, 3)
        World-to-camera rotations, R[root] = I.
    residual_rad : (E,)
        Angle of R_ij R_j R_i^T per sample at the solution.
    """
    i = np.asarray(i, dtype=np.intp)
    j = np.asarray(j, dtype=np.intp)
    R_ij = np.asarray(R_ij, dtype=np.float64)
    w0 = np.ones(len(i)) if weights is None else np.asarray(weights, dtype=np.float64)
    lab = components(n, i, j)
    if (lab != lab[root]).any():
        bad = int(np.flatnonzero(lab != lab[root])[0])
        raise InputError(None, f"camera {bad}", f"co-observations linking it to camera {root}", "none")
    # per pair (a < b) geodesic median of the samples, as R_ab
    pairs = {}
    key = np.where(i < j, i * n + j, j * n + i)
    for k in np.unique(key):
        sel = key == k
        a, b = divmod(int(k), n)
        S = np.where((i[sel] == a)[:, None, None], R_ij[sel], np.swapaxes(R_ij[sel], 1, 2))
        pairs[(a, b)] = (geodesic_median(S), int(sel.sum()))
    R = _spanning_tree_rotations(n, pairs, root)
    free = np.array([c for c in range(n) if c != root])
    pos = np.full(n, -1)
    pos[free] = np.arange(free.size)
    for _ in range(iterations):
        E = np.einsum("eab,ebc,edc->ead", R_ij, R[j], R[i])       # R_ij R_j R_i^T
        e = log_rotation(E)
        en = np.linalg.norm(e, axis=1)
        scale = max(3.0 * 1.4826 * float(np.median(en)), min_scale_rad)
        w = w0 * _cauchy(en, scale)
        # w_e | omega_i - R_ij omega_j - e |^2 ; omega_root = 0
        H = np.zeros((n, n, 3, 3))
        g = np.zeros((n, 3))
        I3 = np.broadcast_to(np.eye(3), (len(i), 3, 3))
        np.add.at(H, (i, i), w[:, None, None] * I3)
        np.add.at(H, (j, j), w[:, None, None] * I3)
        np.add.at(H, (i, j), -w[:, None, None] * R_ij)
        np.add.at(H, (j, i), -w[:, None, None] * np.swapaxes(R_ij, 1, 2))
        np.add.at(g, i, w[:, None] * e)
        np.add.at(g, j, -w[:, None] * np.einsum("eba,eb->ea", R_ij, e))
        Hf = H[np.ix_(free, free)].transpose(0, 2, 1, 3).reshape(3 * free.size, 3 * free.size)
        step = np.linalg.lstsq(Hf, g[free].ravel(), rcond=None)[0].reshape(-1, 3)
        R[free] = exp_rotation(step) @ R[free]
        if np.abs(step).max() < 1e-12:
            break
    E = np.einsum("eab,ebc,edc->ead", R_ij, R[j], R[i])
    return R, np.linalg.norm(log_rotation(E), axis=1)


def average_translations(n: int, i, j, R: np.ndarray, t_ij, *, root: int = 0, weights=None,
                         min_scale: float = 1e-4, iterations: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Camera translations from relative translation samples, with the rotations known.

    Solves t_i - R_i R_j^T t_j = t_ij (t_root = 0) by least squares reweighted with Cauchy weights
    (scale 3 x the robust SD of the residual lengths, at least `min_scale`, in the unit of t_ij).

    Parameters
    ----------
    n : int
    i, j : (E,) int
    R : (n, 3, 3)
        World-to-camera rotations (:func:`average_rotations`).
    t_ij : (E, 3)
        Samples of t_i - R_i R_j^T t_j, in the unit of the result (m).

    Returns
    -------
    t : (n, 3)
        World-to-camera translations, t[root] = 0.
    residual : (E,)
        |t_i - R_ij t_j - t_ij| per sample.
    """
    i = np.asarray(i, dtype=np.intp)
    j = np.asarray(j, dtype=np.intp)
    t_ij = np.asarray(t_ij, dtype=np.float64)
    w0 = np.ones(len(i)) if weights is None else np.asarray(weights, dtype=np.float64)
    Rij = np.einsum("eab,ecb->eac", R[i], R[j])
    free = np.array([c for c in range(n) if c != root])
    t = np.zeros((n, 3))
    w = w0.copy()
    for it in range(iterations):
        H = np.zeros((n, n, 3, 3))
        g = np.zeros((n, 3))
        I3 = np.broadcast_to(np.eye(3), (len(i), 3, 3))
        np.add.at(H, (i, i), w[:, None, None] * I3)
        np.add.at(H, (j, j), w[:, None, None] * I3)
        np.add.at(H, (i, j), -w[:, None, None] * Rij)
        np.add.at(H, (j, i), -w[:, None, None] * np.swapaxes(Rij, 1, 2))
        np.add.at(g, i, w[:, None] * t_ij)
        np.add.at(g, j, -w[:, None] * np.einsum("eba,eb->ea", Rij, t_ij))
        Hf = H[np.ix_(free, free)].transpose(0, 2, 1, 3).reshape(3 * free.size, 3 * free.size)
        new = np.zeros((n, 3))
        new[free] = np.linalg.lstsq(Hf, g[free].ravel(), rcond=None)[0].reshape(-1, 3)
        done = it > 0 and np.abs(new - t).max() < 1e-12
        t = new
        r = np.linalg.norm(t[i] - np.einsum("eab,eb->ea", Rij, t[j]) - t_ij, axis=1)
        scale = max(3.0 * 1.4826 * float(np.median(r)), min_scale)
        w = w0 * _cauchy(r, scale)
        if done:
            break
    return t, np.linalg.norm(t[i] - np.einsum("eab,eb->ea", Rij, t[j]) - t_ij, axis=1)
