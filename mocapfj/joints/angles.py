"""Per-frame link angle of one revolute joint whose geometry is known (docs/conventions.md).

Hinge model: marker p at frame i is ``v_pi = c + R(n, q_i) a_p + noise`` in the parent frame, with
n = ``geometry.axis``, c = ``geometry.point`` and a_p = ``geometry.template[p]``. The angle of each
frame minimises Lightcap and Banks (2007), eq. (13), ``sum_p w_p |v_pi - (c + R(n, q) a_p)|^2``, whose minimiser is
exact and unique (shared/notes/methods.md, "Per-frame angle, exact closed form")::

    b_pi = v_pi - c,   a_p_perp = a_p - (a_p . n) n
    S_i = sum_p w_p n . (a_p x b_pi),   C_i = sum_p w_p a_p_perp . b_pi,   q_i = atan2(S_i, C_i)

Implementation: every marker gets a fixed orthonormal frame (e1_p = a_p_perp / r_p, e2_p = n x e1_p,
n); one matrix product turns all positions into in-plane coordinates x_pi, y_pi and the axial
coordinate z_pi, so that ``C_i = sum_p w_p r_p x_pi``, ``S_i = sum_p w_p r_p y_pi`` and the residual
of marker p is ``(x - r_p cos q)^2 + (y - r_p sin q)^2 + (z - a_p.n)^2``. Frames are processed in
blocks that stay in cache; there is no loop over frames.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erfc, gammainccinv

from ..errors import InputError
from ..types import JointAngles, JointGeometry

__all__ = ["joint_angles", "predict_markers", "outlier_threshold"]

_BLOCK = 1 << 14  # frames per block: the (3P, block) work arrays stay in L2/L3 cache
_GEMM = 1 << 10  # frames per matrix product: small enough that OpenBLAS stays on one thread (its
# threads spin after each call and, on a busy machine, cost more than the product)
_ON_AXIS_M = 1e-6  # a marker closer than this to the axis carries no angle information


def predict_markers(geometry: JointGeometry, q) -> np.ndarray:
    """Marker positions the hinge model predicts, ``c + R(n, q_i) a_p`` (Lightcap and Banks (2007), eq. 13).

    Parameters
    ----------
    geometry : JointGeometry
    q : (T,) float
        Link angles, rad; NaN gives NaN rows.

    Returns
    -------
    v : (T, P, 3) float
        Marker positions in the parent frame, metres, in ``geometry.labels`` order.
    """
    q = np.atleast_1d(np.asarray(q, dtype=np.float64))
    if q.ndim != 1:
        raise InputError(None, "q", "shape (T,)", f"shape {q.shape}")
    n, a = _unit_axis(geometry), geometry.template
    a_n = a @ n
    a_perp = a - a_n[:, None] * n
    n_x_a = np.cross(n, a)
    return (geometry.point + a_n[:, None] * n
            + np.cos(q)[:, None, None] * a_perp + np.sin(q)[:, None, None] * n_x_a)


def outlier_threshold(outlier_sigma: float, dof: int = 3) -> float:
    """Chi-square threshold with the false-alarm rate of a two-sided ``outlier_sigma`` test.

    ``P(chi2_dof > threshold) = P(|N(0, 1)| > outlier_sigma)``; 22.06 for 4 sigma and 3 dof.
    """
    p = erfc(outlier_sigma / np.sqrt(2.0))
    return float(2.0 * gammainccinv(0.5 * dof, p))


def joint_angles(v, geometry: JointGeometry, t=None, *, sigma=None, weights=None, min_markers=2,
                 outlier_sigma=4.0, q_seed=None) -> JointAngles:
    """Link angle of every frame: the exact minimiser of Lightcap and Banks (2007), eq. (13), with its Cramér-Rao SD.

    Parameters
    ----------
    v : (T, P, 3) float
        Marker positions in the parent frame (the world when the parent does not move; see
        `segments.to_parent_frame` otherwise), metres, in ``geometry.labels`` order; NaN where
        a marker is missing.
    geometry : JointGeometry
        Axis n, point c and template a_p (marker positions relative to c at q = 0).
    t : (T,) float, optional
        Sample times, seconds, copied to the result; the frame index when omitted.
    sigma : float, optional
        Marker noise SD per coordinate, metres; ``geometry.sigma_m`` when omitted.
    weights : (P,) or (T, P) float, optional
        Relative inverse variances: marker p has noise SD ``sigma / sqrt(w_p)``. For absolute
        SDs sigma_p pass ``weights = 1 / sigma_p**2`` and ``sigma = 1.0``. Zero drops a marker.
    min_markers : int
        Frames with fewer usable markers (after outlier rejection) get NaN, never a made-up value.
    outlier_sigma : float or None
        Outlier test level; None disables rejection. See Notes.
    q_seed : float or (T,) float, optional
        The angle is unwrapped over the valid frames (np.unwrap) and then shifted by the multiple
        of 2 pi that brings it closest to `q_seed` (e.g. the motor angle): the first valid frame
        for a scalar, the median difference over frames for an array.

    Returns
    -------
    JointAngles
        ``q`` rad (unwrapped); ``sigma_q = sigma / sqrt(sum_p w_p r_p^2)`` over the markers used
        (the Cramér-Rao bound, shared/notes/methods.md: d v_p / d q = n x (v_p - c), of length
        r_p, so I(q) = sum_p w_p r_p^2 / sigma^2); ``marker_rms`` metres (unweighted, markers used);
        ``n_markers``, ``n_rejected`` per frame.

    Notes
    -----
    Outlier rejection is a likelihood-ratio (deletion) test for a mean shift of one marker: for
    marker p, ``D_p = (J_all - J_without_p) / sigma^2``, where J is the weighted cost of eq. (13)
    at its minimum; both minima are closed form (``J = sum_p w_p u_p - 2 sqrt(S^2 + C^2)``), so
    every marker of every frame is tested at once. D_p is chi-square with 3 degrees of freedom for
    a good marker (exactly, in the linearised model); the marker with the largest D_p is dropped
    when D_p exceeds :func:`outlier_threshold` (22.06 for ``outlier_sigma = 4``: a marker alone
    off by more than ~4.7 sigma), the frame re-solved, and the test repeated until no marker
    fails. Removing the worst marker first keeps one gross error from condemning the good markers
    its pull on q displaced. A frame left with fewer than `min_markers` markers is NaN.

    Unwrapping assumes the joint turns less than pi between consecutive valid frames.
    """
    n = _unit_axis(geometry)
    c, a = geometry.point, geometry.template
    P = a.shape[0]
    v = np.asarray(v, dtype=np.float64)
    if v.ndim != 3 or v.shape[1:] != (P, 3):
        raise InputError(None, "v", f"marker positions of shape (T, {P}, 3) in geometry.labels order",
                         f"shape {v.shape}")
    T = v.shape[0]
    t = np.arange(T, dtype=np.float64) if t is None else np.asarray(t, dtype=np.float64)
    if t.shape != (T,):
        raise InputError(None, "t", f"shape ({T},)", f"shape {t.shape}")
    sigma = geometry.sigma_m if sigma is None else sigma
    if not (np.isfinite(sigma) and sigma > 0):
        raise InputError(None, "sigma", "a positive marker noise SD in metres", sigma,
                         "pass sigma= when the geometry carries no noise estimate")
    if not (isinstance(min_markers, (int, np.integer)) and 1 <= min_markers <= P):
        raise InputError(None, "min_markers", f"an integer from 1 to {P}", min_markers)
    w = np.ones(P) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape not in ((P,), (T, P)) or not np.all(np.isfinite(w) & (w >= 0)):
        raise InputError(None, "weights", f"finite non-negative weights of shape ({P},) or ({T}, {P})",
                         f"shape {w.shape}" if w.shape not in ((P,), (T, P)) else "negative or non-finite")
    if outlier_sigma is None or outlier_sigma == np.inf:
        thr = None
    elif outlier_sigma > 0:
        thr = outlier_threshold(outlier_sigma) * sigma**2
    else:
        raise InputError(None, "outlier_sigma", "a positive number of SDs, or None", outlier_sigma)

    a_n = a @ n
    a_perp = a - a_n[:, None] * n
    r = np.linalg.norm(a_perp, axis=1)
    if not np.any(r > _ON_AXIS_M):
        raise InputError(None, "geometry.template", "at least one marker off the joint axis",
                         f"radii {np.round(r * 1e3, 4).tolist()} mm",
                         "markers on the axis do not turn with the joint; place them away from it")
    e1 = np.where((r > _ON_AXIS_M)[:, None], a_perp / np.maximum(r, _ON_AXIS_M)[:, None],
                  _perpendicular(n))
    e2 = np.cross(n, e1)
    # basis (3P, 3P): row block p of v_flat maps to columns p (x), P + p (y), 2P + p (z)
    B = np.zeros((3 * P, 3 * P))
    for p in range(P):
        B[3 * p:3 * p + 3, [p, P + p, 2 * P + p]] = np.stack([e1[p], e2[p], n], axis=1)
    offset = np.concatenate([e1 @ c, e2 @ c, np.full(P, n @ c)])[:, None]
    Bt = np.ascontiguousarray(B.T)

    q = np.empty(T)
    sq_info = np.empty(T)
    rms = np.empty(T)
    n_used = np.empty(T, dtype=np.int64)
    n_rej = np.empty(T, dtype=np.int64)
    any_frame = False  # some frame has min_markers valid markers before outlier rejection
    vf = v.reshape(T, 3 * P)
    for s in range(0, T, _BLOCK):
        e = min(s + _BLOCK, T)
        vb = vf[s:e]
        fin = np.isfinite(vb)
        complete = bool(fin.all())
        if not complete:
            vb = np.where(fin, vb, 0.0)
        X = np.empty((3 * P, e - s))  # x, y, z of every marker in its own frame
        for k in range(0, e - s, _GEMM):
            np.matmul(Bt, vb[k:k + _GEMM].T, out=X[:, k:k + _GEMM])
        X -= offset
        wb = w[:, None] if w.ndim == 1 else w[s:e].T
        if complete:
            W = np.broadcast_to(wb, (P, e - s))
            any_frame = True
        else:
            valid = (fin[:, 0::3] & fin[:, 1::3] & fin[:, 2::3]).T  # (P, frames)
            W = wb * valid
            any_frame = any_frame or bool((valid.sum(axis=0) >= min_markers).any())
        q[s:e], sq_info[s:e], rms[s:e], n_used[s:e], n_rej[s:e] = _solve_block(X, W, r, a_n, thr)

    bad = (n_used < min_markers) | ~(sq_info > 0)
    q[bad] = np.nan
    sigma_q = np.where(bad, np.nan, sigma / np.sqrt(np.where(bad, 1.0, sq_info)))
    rms[bad] = np.nan
    if not any_frame:
        raise InputError(None, "v", f"at least one frame with {min_markers} valid markers",
                         "none (all frames are missing markers)",
                         "check the marker labels, or lower min_markers")
    if bad.all():
        raise InputError(None, "v", "markers that match the joint geometry",
                         f"every frame rejected ({int(n_rej.sum())} markers failed the outlier test)",
                         "are v in the parent frame and in geometry.labels order? is sigma right?")
    ok = ~bad
    q[ok] = np.unwrap(q[ok])
    if q_seed is not None:
        q += 2 * np.pi * _turns_to_seed(q, ok, q_seed, T)
    return JointAngles(t=t, q=q, sigma_q=sigma_q, marker_rms=rms, n_markers=n_used, n_rejected=n_rej)


def _solve_block(X, W, r, a_n, thr):
    """Closed-form angle of a block of frames with outlier rejection; arrays are (markers, frames).

    X (3P, B): in-plane x, y and axial z of every marker; W (P, B) weights, 0 for unused markers.
    Returns wrapped q, sum w r^2, marker RMS, markers used and markers rejected, each (B,).
    """
    P, nb = r.size, X.shape[1]
    x, y, z = X[:P], X[P:2 * P], X[2 * P:]
    rc = r[:, None]
    cp = W * rc
    sp = cp * y
    cp *= x
    C, S = cp.sum(axis=0), sp.sum(axis=0)
    n_rej = np.zeros(nb, dtype=np.int64)
    if thr is not None:
        zr = z - a_n[:, None]
        u = x * x + y * y + zr * zr + rc * rc  # |b_p|^2 + |a_p|^2 - 2 (a_p.n)(b_p.n)
        cols = None  # None: all frames of the block
        W = np.array(W)  # writable: rejected markers get weight 0
        for _ in range(P):
            Wc, uc, cpc, spc, Cc, Sc = ((W, u, cp, sp, C, S) if cols is None else
                                       (W[:, cols], u[:, cols], cp[:, cols], sp[:, cols], C[cols], S[cols]))
            dC, dS = Cc - cpc, Sc - spc
            # D_p sigma^2 = J_all - J_without_p = w_p u_p - 2 rho + 2 rho_without_p
            D = Wc * uc + 2.0 * np.sqrt(dC * dC + dS * dS) - 2.0 * np.sqrt(Cc * Cc + Sc * Sc)
            worst = np.argmax(D, axis=0)
            hit = np.take_along_axis(D, worst[None], axis=0)[0] > thr
            if not hit.any():
                break
            idx = np.flatnonzero(hit) if cols is None else cols[hit]
            pw = worst[hit]
            W[pw, idx] = 0.0
            cp[pw, idx] = 0.0
            sp[pw, idx] = 0.0
            C[idx], S[idx] = cp[:, idx].sum(axis=0), sp[:, idx].sum(axis=0)
            n_rej[idx] += 1
            cols = idx
    used = W > 0
    n_used = used.sum(axis=0)
    info = (W * (rc * rc)).sum(axis=0)
    rho = np.sqrt(C * C + S * S)
    rho[rho == 0] = np.nan
    cq, sq = C / rho, S / rho
    dx, dy, dz = x - rc * cq, y - rc * sq, z - a_n[:, None]
    d2 = dx * dx + dy * dy + dz * dz
    rms = np.sqrt(np.where(used, d2, 0.0).sum(axis=0) / np.maximum(n_used, 1))
    return np.arctan2(S, C), info, rms, n_used, n_rej


def _unit_axis(geometry: JointGeometry) -> np.ndarray:
    n = np.asarray(geometry.axis, dtype=np.float64)
    norm = np.linalg.norm(n)
    if not (np.isfinite(norm) and norm > 0):
        raise InputError(None, "geometry.axis", "a finite non-zero direction", n.tolist())
    return n / norm


def _perpendicular(n: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to unit n."""
    k = np.argmin(np.abs(n))
    e = np.cross(n, np.eye(3)[k])
    return e / np.linalg.norm(e)


def _turns_to_seed(q, ok, q_seed, T) -> float:
    """Whole turns to add to unwrapped q so that it lies closest to q_seed."""
    seed = np.asarray(q_seed, dtype=np.float64)
    if seed.ndim == 0:
        if not np.isfinite(seed):
            raise InputError(None, "q_seed", "a finite angle in rad", float(seed))
        return float(np.round((seed - q[np.flatnonzero(ok)[0]]) / (2 * np.pi)))
    if seed.shape != (T,):
        raise InputError(None, "q_seed", f"a scalar or shape ({T},)", f"shape {seed.shape}")
    diff = seed - q
    diff = diff[np.isfinite(diff)]
    if diff.size == 0:
        raise InputError(None, "q_seed", "finite values in frames with a valid angle", "none")
    return float(np.round(np.median(diff) / (2 * np.pi)))
