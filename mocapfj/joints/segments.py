"""Joints between two moving marker clusters: cluster poses, rigid templates, SCoRE and SARA.

For a joint whose parent link moves (a human elbow or knee, a robot joint above the base), each
segment carries a rigid marker cluster. :func:`cluster_template` builds each cluster's template,
:func:`kabsch` gives its pose in every frame, and then either

- :func:`to_parent_frame` expresses the child's markers in the parent cluster's frame, where the
  single-joint fits (axis, angles) apply unchanged, or
- :func:`fit_score` (centre of rotation, Ehrig et al. 2006) and :func:`fit_sara` (hinge axis,
  Ehrig et al. 2007) use the poses of both segments directly.

Poses follow docs/conventions.md: ``R`` (T, 3, 3) and ``t`` (T, 3) map cluster coordinates into
the world, ``p_world = R @ p_cluster + t`` (R_world_cluster, t_world_cluster). Metres, radians.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["kabsch", "cluster_template", "to_parent_frame", "fit_score", "fit_sara"]

_RANK_TOL = 1e-10  # second/first singular value below which a cluster is collinear


def kabsch(template, v, weights=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pose of a rigid marker cluster in every frame: weighted Kabsch / Umeyama (no scaling).

    Minimises ``sum_p w_p |v_ip - (R_i template_p + t_i)|^2`` per frame over proper rotations
    (det R = +1, Umeyama 1991 eq. 39-40) with one batched SVD; each frame uses the markers it has.

    Parameters
    ----------
    template : (P, 3) float
        Marker positions in the cluster frame, metres.
    v : (T, P, 3) float
        Measured positions, world frame, metres; NaN where missing.
    weights : (P,) or (T, P) float, optional
        Non-negative weights (inverse variances); zero drops a marker.

    Returns
    -------
    R : (T, 3, 3) float
        R_world_cluster; NaN in frames with fewer than 3 usable markers or collinear ones.
    t : (T, 3) float
        t_world_cluster, metres; NaN in the same frames.
    rms : (T,) float
        RMS distance of the used markers from the fitted template, metres.
    """
    x = np.asarray(template, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3 or x.shape[0] < 3 or not np.all(np.isfinite(x)):
        raise InputError(None, "template", "finite marker positions of shape (P, 3) with P >= 3",
                         f"shape {x.shape}", "a rigid pose needs at least 3 markers")
    T, P = v.shape[0] if v.ndim == 3 else -1, x.shape[0]
    if v.shape != (T, P, 3):
        raise InputError(None, "v", f"shape (T, {P}, 3)", f"shape {v.shape}")
    valid = np.isfinite(v).all(axis=2)
    w = np.ones(P) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape not in ((P,), (T, P)) or not np.all(np.isfinite(w) & (w >= 0)):
        raise InputError(None, "weights", f"finite non-negative weights of shape ({P},) or ({T}, {P})",
                         f"shape {w.shape}")
    M = valid * w  # (T, P)
    y = np.where(valid[..., None], v, 0.0)
    sw = M.sum(axis=1)
    ok = ((M > 0).sum(axis=1) >= 3) & (sw > 0)
    sw = np.where(ok, sw, 1.0)
    x_mean = (M @ x) / sw[:, None]  # (T, 3) cluster frame
    y_mean = np.einsum("tp,tpk->tk", M, y) / sw[:, None]  # (T, 3) world
    xc = x[None] - x_mean[:, None]
    yc = y - y_mean[:, None]
    H = np.swapaxes(M[..., None] * xc, 1, 2) @ yc  # (T, 3, 3) = sum_p w x_c y_c^T
    U, s, Vt = np.linalg.svd(H)
    ok &= s[:, 1] > _RANK_TOL * s[:, 0]
    d = np.sign(np.linalg.det(np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)))
    Vt[:, 2, :] *= d[:, None]
    R = np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)  # V D U^T
    t = y_mean - np.einsum("tij,tj->ti", R, x_mean)
    e = y - (np.einsum("tij,pj->tpi", R, x) + t[:, None])
    n = np.maximum(valid.sum(axis=1), 1)
    rms = np.sqrt(np.where(valid, (e * e).sum(axis=2), 0.0).sum(axis=1) / n)
    R[~ok], t[~ok], rms[~ok] = np.nan, np.nan, np.nan
    return R, t, rms


def cluster_template(v, *, max_iter: int = 100, tol: float = 1e-10) -> np.ndarray:
    """A rigid template of a marker cluster from many frames (generalised Procrustes).

    Starts from the first frame with every marker present, then repeats: Kabsch-align each frame
    to the template, average the aligned markers (each over the frames that have it), centre at
    the centroid; stops when no marker moves more than `tol` metres.

    Parameters
    ----------
    v : (T, P, 3) float
        Marker positions, world frame, metres; NaN where missing. P >= 3, not collinear.

    Returns
    -------
    template : (P, 3) float
        Marker positions in the cluster frame (origin at their centroid, axes those of the
        starting frame's world axes, up to the alignment), metres.
    """
    v = np.asarray(v, dtype=np.float64)
    if v.ndim != 3 or v.shape[2] != 3 or v.shape[1] < 3:
        raise InputError(None, "v", "marker positions of shape (T, P, 3) with P >= 3", f"shape {v.shape}",
                         "a rigid cluster needs at least 3 markers")
    valid = np.isfinite(v).all(axis=2)
    full = np.flatnonzero(valid.all(axis=1))
    if full.size == 0:
        raise InputError(None, "v", "at least one frame with every cluster marker visible",
                         f"none of {v.shape[0]} frames", "check the labels or the occlusions")
    template = v[full[0]] - v[full[0]].mean(axis=0)
    s = np.linalg.svd(template, compute_uv=False)
    if s[1] <= _RANK_TOL * s[0]:
        raise InputError(None, "v", "cluster markers that are not on one line",
                         "collinear markers", "the rotation about their line is undetermined; add a marker")
    for _ in range(max_iter):
        R, t, _ = kabsch(template, v)
        aligned = np.einsum("tji,tpj->tpi", R, v - t[:, None])  # R^T (v - t): cluster frame
        new = np.nanmean(aligned, axis=0)
        new -= new.mean(axis=0)
        step = np.max(np.abs(new - template))
        template = new
        if step < tol:
            break
    return template


def to_parent_frame(v_child, R, t) -> np.ndarray:
    """Child markers in the parent cluster's frame: ``p_parent = R^T (p_world - t)``.

    Parameters
    ----------
    v_child : (T, P, 3) float
        Child-segment markers, world frame, metres (NaN where missing).
    R, t : (T, 3, 3), (T, 3) float
        Parent pose R_world_parent, t_world_parent, e.g. from :func:`kabsch`.

    Returns
    -------
    (T, P, 3) float
        The markers in the parent frame; NaN in frames without a parent pose.
    """
    v = np.asarray(v_child, dtype=np.float64)
    R, t = np.asarray(R, dtype=np.float64), np.asarray(t, dtype=np.float64)
    T = v.shape[0] if v.ndim == 3 else -1
    if v.shape[1:] != v.shape[1:2] + (3,) or R.shape != (T, 3, 3) or t.shape != (T, 3):
        raise InputError(None, "v_child, R, t", "shapes (T, P, 3), (T, 3, 3), (T, 3)",
                         f"{v.shape}, {R.shape}, {t.shape}")
    return np.einsum("tji,tpj->tpi", R, v - t[:, None])


def fit_score(R_i, t_i, R_j, t_j, *, min_range_deg: float = 5.0):
    """Centre of rotation between two moving segments, SCoRE (Ehrig et al. 2006).

    The joint centre is fixed in both segments: ``R_i c_i + t_i = R_j c_j + t_j`` in every frame,
    i.e. ``[R_i, -R_j] [c_i; c_j] = t_j - t_i`` stacked over frames, solved by least squares
    through the 6 x 6 normal matrix ``sum A^T A = [[N I, -sum R_i^T R_j], [., N I]]``.

    Parameters
    ----------
    R_i, t_i, R_j, t_j : (T, 3, 3), (T, 3) float
        Poses R_world_i, t_world_i of segment i and of segment j (e.g. :func:`kabsch`); frames
        with NaN are skipped.
    min_range_deg : float
        Least range of relative rotation about every axis (uniform-equivalent, from the smallest
        eigenvalue of the normal matrix). A hinge excites only two axes of the centre: use
        :func:`fit_sara`.

    Returns
    -------
    c_i, c_j : (3,) float
        The centre in segment i's and segment j's frame, metres.
    rms : float
        RMS over frames of ``|R_i c_i + t_i - R_j c_j - t_j|``, metres.
    """
    A, b, nrm, g = _normal_equations(R_i, t_i, R_j, t_j)
    lam, V = np.linalg.eigh(nrm)
    got = _range_deg(lam[0])
    if got < min_range_deg:
        raise InputError(None, "poses", f"a relative rotation of at least {min_range_deg:g} deg about "
                         "every axis", f"{got:.3g} deg about the least-moved axis",
                         "move the joint about more axes; for a hinge use fit_sara")
    c = V @ ((V.T @ g) / lam)
    return c[:3], c[3:], _rms(A, b, c)


def fit_sara(R_i, t_i, R_j, t_j, *, min_range_deg: float = 5.0):
    """Hinge axis between two moving segments, SARA (Ehrig et al. 2007).

    With the stacked system ``[R_i, -R_j] [c_i; c_j] = t_j - t_i`` (see :func:`fit_score`), every
    point of a hinge axis solves it, so the 6-column matrix has a null direction: the right
    singular vector with the smallest singular value, ``[a_i; a_j]`` with ``R_i a_i = R_j a_j``,
    is the axis in both segment frames. A point on the axis comes from the pseudo-inverse with
    that direction dropped (a full pseudo-inverse would make its position along the axis noise,
    shared/notes/methods.md); this places it half-way between the feet of the perpendiculars
    from the two segment origins (``c_i . a_i + c_j . a_j = 0``). The axis is a direction and is
    never translated.

    Parameters
    ----------
    R_i, t_i, R_j, t_j : (T, 3, 3), (T, 3) float
        Poses of the two segments (R_world_i, t_world_i, ...); frames with NaN are skipped.
    min_range_deg : float
        Least range of motion about the hinge (uniform-equivalent, from the second-smallest
        eigenvalue of the normal matrix).

    Returns
    -------
    axis_i, axis_j : (3,) float
        Unit axis in segment i's and j's frame; sign chosen so that the largest-magnitude
        component of ``axis_i`` is positive.
    c_i, c_j : (3,) float
        The same point of the axis in segment i's and j's frame, metres.
    """
    _, _, nrm, g = _normal_equations(R_i, t_i, R_j, t_j)
    lam, V = np.linalg.eigh(nrm)
    got = _range_deg(lam[1])
    if got < min_range_deg:
        raise InputError(None, "poses", f"a range of motion of at least {min_range_deg:g} deg about the "
                         "hinge", f"{got:.3g} deg", "move the joint further during calibration")
    u = V[:, 0]
    axis_i, axis_j = u[:3] / np.linalg.norm(u[:3]), u[3:] / np.linalg.norm(u[3:])
    if axis_i[np.argmax(np.abs(axis_i))] < 0:
        axis_i, axis_j = -axis_i, -axis_j
    c = V[:, 1:] @ ((V[:, 1:].T @ g) / lam[1:])
    return axis_i, axis_j, c[:3], c[3:]


def _normal_equations(R_i, t_i, R_j, t_j):
    """Stacked SCoRE system over the finite frames: A (N, 3, 6), b (N, 3), A^T A / N, A^T b / N."""
    arrs = [np.asarray(a, dtype=np.float64) for a in (R_i, t_i, R_j, t_j)]
    T = arrs[0].shape[0] if arrs[0].ndim == 3 else -1
    shapes = [(T, 3, 3), (T, 3), (T, 3, 3), (T, 3)]
    if [a.shape for a in arrs] != shapes:
        raise InputError(None, "R_i, t_i, R_j, t_j", "shapes (T, 3, 3), (T, 3), (T, 3, 3), (T, 3)",
                         ", ".join(str(a.shape) for a in arrs))
    ok = np.ones(T, dtype=bool)
    for a in arrs:
        ok &= np.isfinite(a.reshape(T, -1)).all(axis=1)
    if ok.sum() < 2:
        raise InputError(None, "poses", "at least 2 frames where both segments have a pose",
                         f"{int(ok.sum())} of {T}", "check the cluster markers' visibility")
    Ri, ti, Rj, tj = (a[ok] for a in arrs)
    A = np.concatenate([Ri, -Rj], axis=2)  # (N, 3, 6)
    b = tj - ti
    N = A.shape[0]
    nrm = np.einsum("nki,nkj->ij", A, A) / N
    g = np.einsum("nki,nk->i", A, b) / N
    return A, b, 0.5 * (nrm + nrm.T), g


def _rms(A, b, c) -> float:
    e = A @ c - b
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


_X = np.linspace(0.0, np.pi, 4001)  # half-range
_SINC = np.sinc(_X / np.pi)  # mean of cos over a uniform range of width 2x: sin(x) / x, decreasing


def _range_deg(lam: float) -> float:
    """Uniform-equivalent range of rotation from an eigenvalue 1 - rho of the normalised normal matrix.

    For angles spread uniformly over a range W about one axis, the mean relative rotation has
    singular value rho = sin(W/2) / (W/2) in the plane of rotation, and the normal matrix the
    eigenvalue 1 - rho. Capped at 360 deg.
    """
    rho = 1.0 - max(float(lam), 0.0)
    return float(np.degrees(2.0 * np.interp(rho, _SINC[::-1], _X[::-1])))
