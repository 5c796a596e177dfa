"""Axis and centre of one revolute joint from a marker cluster: three levels (methods.md).

Hinge model (Lightcap and Banks (2007), §III): marker p in frame i is at v_pi = c + R(n, q_i) a_p + noise, with unit
axis n, a point c on the axis, template a_p and per-frame angle q_i, in the parent (world) frame.

- `fit_gamage_lasenby`: algebraic (Gamage & Lasenby 2002; Lightcap and Banks (2007), eq. 11). Consistent axis,
  biased centre at small ranges of motion.
- `fit_halvorsen`: bias-compensated centre (Halvorsen 2003; Lightcap and Banks (2007), eq. 12).
- `fit_hinge_ml`: maximum likelihood over axis, centre, template and every angle (Lightcap and Banks (2007)
  eq. 13 jointly), by Gauss-Newton with the angles eliminated frame by frame (variable projection
  with the closed-form angle of methods.md); covariances from the marginalised information.

All functions take v (N, P, 3) metres, frames x markers x xyz, NaN where a marker is missing, and
return `mocapfj.types.JointGeometry` (docs/conventions.md). Markers seen in fewer than
`MIN_FRAMES` frames are left out of the result (its `labels` say which were used).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..types import JointGeometry
from ..rotations import rotate, skew
from .crlb import marginal_information, normal_blocks, tangent_basis

__all__ = ["fit_gamage_lasenby", "fit_halvorsen", "fit_hinge_ml", "MIN_FRAMES", "MIN_RANGE_DEG"]

MIN_FRAMES = 3
"""Frames a marker needs to take part in a fit."""
MIN_RANGE_DEG = 5.0
"""Default smallest range of motion accepted for a fit, degrees."""
_ON_AXIS = 3.0         # a marker closer to the axis than this many residual SDs carries no angle (the SD
                       # includes model misfit on real limbs, so this is a guard against markers on the axis)
_CHUNK = 2_000_000     # bootstrap samples generated at once


# ---------------------------------------------------------------- input and batched estimators
def _prepare(v, labels, weights=None):
    """Validate; return centred v (N, P', 3), mask (N, P'), centroid (3,), labels, weights."""
    v = np.asarray(v, dtype=np.float64)
    if v.ndim != 3 or v.shape[2] != 3 or v.shape[0] < 1 or v.shape[1] < 1:
        raise InputError(None, "v", "marker positions of shape (N frames, P markers, 3)", f"shape {v.shape}")
    N, P, _ = v.shape
    labels = tuple(f"m{p}" for p in range(P)) if labels is None else tuple(str(s) for s in labels)
    if len(labels) != P or len(set(labels)) != P:
        raise InputError(None, "labels", f"{P} unique marker labels", labels)
    w = np.ones(P) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (P,) or not np.all(np.isfinite(w) & (w > 0)):
        raise InputError(None, "weights", f"{P} positive finite weights (1 / sigma_p^2)", weights)
    mask = np.all(np.isfinite(v), axis=2)
    if not mask.any():
        raise InputError(None, "v", "some finite marker positions", "all NaN",
                         hint="check the marker labels of the cluster")
    cnt = mask.sum(axis=0)
    keep = cnt >= MIN_FRAMES
    if keep.sum() < 2:
        got = ", ".join(f"{s}: {c}" for s, c in zip(labels, cnt))
        raise InputError(None, "v", f"at least 2 markers seen in {MIN_FRAMES} or more frames",
                         f"frames per marker {got}",
                         hint="a single marker defines the axis only through a plane fit of its "
                              "circle; put at least 2 (better 3-4) markers on the link")
    v, mask, w = v[:, keep], mask[:, keep], w[keep]
    centroid = np.nanmean(v, axis=0).mean(axis=0)
    vc = np.where(mask[..., None], v - centroid, np.nan)
    return vc, mask, centroid, tuple(s for s, k in zip(labels, keep) if k), w / w.mean()


def _gl_core(v):
    """Gamage-Lasenby moments and fit, batched over leading axes (Lightcap and Banks (2007), eq. 11).

    v (..., N, P, 3), NaN where missing. Returns axis (..., 3), in-plane centre m (..., 3) (the
    foot of the origin on the axis: truncated pseudo-inverse), and the per-marker moments about
    each marker's mean that `_halvorsen_core` needs.
    """
    mask = np.all(np.isfinite(v), axis=-1)
    vz = np.where(mask[..., None], v, 0.0)
    cnt = mask.sum(axis=-2)                                            # (..., P)
    mean_p = vz.sum(axis=-3) / cnt[..., None]
    d = np.moveaxis(np.where(mask[..., None], vz - mean_p[..., None, :, :], 0.0), -3, -2)
    dT = np.swapaxes(d, -1, -2)                                        # (..., P, 3, N)
    C = dT @ d / cnt[..., None, None]                                  # (..., P, 3, 3)
    A = 2.0 * C.sum(axis=-3)
    s = np.moveaxis((vz**2).sum(axis=-1), -1, -2)                      # (..., P, N) |v|^2
    b = ((dT @ s[..., None])[..., 0] / cnt[..., None]).sum(axis=-2)    # sum_p mean(|v|^2 d)
    e = np.where(np.moveaxis(mask, -1, -2), (d**2).sum(-1), 0.0)
    d2 = e.sum(axis=-1) / cnt
    e = np.where(np.moveaxis(mask, -1, -2), e - d2[..., None], 0.0)    # |d|^2 - mean |d|^2
    lam, U = np.linalg.eigh(A)
    m = np.einsum("...kj,...j->...k", U[..., :, 1:],
                  np.einsum("...kj,...k->...j", U[..., :, 1:], b) / lam[..., 1:])
    return {"axis": U[..., :, 0], "m": m, "lam": lam, "U": U, "b": b, "mean_p": mean_p,
            "cnt": cnt, "C": C, "d2": d2, "e2": (e**2).sum(-1), "ed": (dT @ e[..., None])[..., 0]}


def _halvorsen_core(v, core, sigma=None, max_iter=50, tol=1e-12):
    """Bias-compensated centre (Halvorsen 2003; Lightcap and Banks (2007), eq. 12), batched like `_gl_core`.

    Solves A m = b - Δb, Δb = 2 sigma^2 sum_p f_p (mean_i v_pi - m), f_p = 1 - 1/N_p (the exact
    finite-N noise terms of A and b), in the plane normal to the axis (truncated pseudo-inverse),
    with sigma^2 = mean_p var_i(|v_pi - m|^2) / (4 mean_i |v_pi - m|^2) (methods.md; N_p - 1 in
    the variance) re-estimated until m moves < tol; the spread of |v - m|^2 comes from moments
    about each marker's mean (|u|^2 = |d|^2 + 2 d.g + |g|^2, g = mean_p - m).
    Returns m (..., 3), sigma^2 (...), and the ratio of the noise term to the smallest in-plane
    eigenvalue of A (near 1: range of motion too small for the noise).
    """
    U, lam, cnt = core["U"][..., :, 1:], core["lam"][..., 1:], core["cnt"]
    f = np.where(cnt > 1, 1.0 - 1.0 / cnt, 0.0)
    F = f.sum(axis=-1)
    ybar = np.einsum("...p,...pk->...k", f, core["mean_p"])
    m = core["m"]
    for _ in range(max_iter if sigma is None else 1):
        if sigma is None:
            g = core["mean_p"] - m[..., None, :]                           # (..., P, 3)
            var = (core["e2"] + 4.0 * (g * core["ed"]).sum(-1)
                   + 4.0 * cnt * np.einsum("...pk,...pkl,...pl->...p", g, core["C"], g))
            mu = core["d2"] + (g**2).sum(-1)
            s2 = np.maximum((var / (4.0 * mu * np.maximum(cnt - 1, 1))).mean(axis=-1), 0.0)
        else:
            s2 = np.full(F.shape, float(sigma) ** 2)
        rhs = np.einsum("...kj,...k->...j", U, core["b"] - 2.0 * s2[..., None] * ybar)
        m_new = np.einsum("...kj,...j->...k", U, rhs / (lam - 2.0 * (s2 * F)[..., None]))
        done = np.max(np.abs(m_new - m)) < tol
        m = m_new
        if done:
            break
    return m, s2, 2.0 * s2 * F / lam[..., 0]


def _cluster_range(vc, mask, n):
    """Range of motion, rad: rotation of the cluster about n by 2D Procrustes against the frame
    with most markers (independent of the centre); 1st-99th percentile of the unwrapped angle."""
    x = vc @ tangent_basis(n)                                          # (N, P, 2)
    i0 = int(np.argmax(mask.sum(axis=1)))
    com = mask & mask[i0]
    k = com.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        dx = x - np.where(com[..., None], x, 0.0).sum(axis=1, keepdims=True) / k[:, None, None]
        dr = x[i0] - np.where(com[..., None], x[i0], 0.0).sum(axis=1, keepdims=True) / k[:, None, None]
    dx, dr = np.where(com[..., None], dx, 0.0), np.where(com[..., None], dr, 0.0)
    ang = np.arctan2((dr[..., 0] * dx[..., 1] - dr[..., 1] * dx[..., 0]).sum(1), (dr * dx).sum((1, 2)))
    ang = np.unwrap(ang[k >= 2])
    return float(np.percentile(ang, 99) - np.percentile(ang, 1)) if ang.size > 1 else 0.0


# ---------------------------------------------------------------- angles and template
def _angles(vc, mask, w, n, c, a):
    """Closed-form per-frame angles (methods.md; the minimiser of Lightcap and Banks (2007), eq. 13), (N,) rad
    in (-pi, pi]; NaN where no marker carries angle information."""
    bz = np.where(mask[..., None], vc - c, 0.0)
    wm = mask * w
    a_perp = a - np.outer(a @ n, n)
    S = np.einsum("ip,ipk,pk->i", wm, bz, a @ skew(n).T)          # n.(a x b) = (n x a).b
    C = np.einsum("ip,ipk,pk->i", wm, bz, a_perp)
    ok = (wm @ (a_perp**2).sum(1)) > 0
    return np.where(ok & (np.abs(S) + np.abs(C) > 0), np.arctan2(S, C), np.nan)


def _template(vc, mask, n, c, q):
    """a_p = mean over frames of R(n, -q_i)(v_pi - c), (P, 3)."""
    b = np.where(mask[..., None], vc - c, 0.0)
    back = rotate(n, -np.nan_to_num(q)[:, None], b)
    ok = mask & np.isfinite(q)[:, None]
    return np.where(ok[..., None], back, 0.0).sum(0) / np.maximum(ok.sum(0), 1)[:, None]


def _template_angles(vc, mask, w, n, c, labels, rounds=3):
    """Template (P, 3) and angles (N,) for a fixed axis and centre: the per-marker in-plane angles
    chained through shared frames, then alternating template means and closed-form angles."""
    N, P = mask.shape
    x = np.where(mask[..., None], vc - c, 0.0) @ tangent_basis(n)
    phi = np.arctan2(x[..., 1], x[..., 0])
    q = np.full(N, np.nan)
    reach = np.where(mask, np.hypot(x[..., 0], x[..., 1]), 0.0).sum(0)   # frames x radius
    todo = list(np.argsort(-reach, kind="stable"))
    q[mask[:, todo[0]]] = phi[mask[:, todo[0]], todo[0]]
    todo.pop(0)
    while todo:
        linked = [p for p in todo if np.any(mask[:, p] & np.isfinite(q))]
        if not linked:
            raise InputError(None, "v", "every marker seen in some frame together with the others",
                             f"{[labels[p] for p in todo]} never are",
                             hint="the cluster's template cannot be tied together otherwise")
        for p in linked:
            both = mask[:, p] & np.isfinite(q)
            off = np.angle(np.exp(1j * (phi[both, p] - q[both])).mean())
            fill = mask[:, p] & ~np.isfinite(q)
            q[fill] = phi[fill, p] - off
            todo.remove(p)
    for _ in range(rounds):
        a = _template(vc, mask, n, c, q)
        q = _angles(vc, mask, w, n, c, a)
    return _template(vc, mask, n, c, q), q


def _unwrap(q):
    out = q.copy()
    ok = np.isfinite(q)
    out[ok] = np.unwrap(q[ok])
    return out


def _resolve(vc, mask, w, n, c, a, q, labels):
    """Point = foot of the centroid (the origin of vc), template relative to it with q = 0 at the
    first frame with an angle, radii and residual statistics; sigma = sqrt(weighted RSS / dof),
    dof = 3 x observations - (3 + 3 P + frames). Refuses markers on the axis, dof < 1."""
    t = c @ n
    point = c - t * n
    a = a + t * n
    q = _unwrap(q)
    first = np.flatnonzero(np.isfinite(q))[0]
    a, q = rotate(n, q[first], a), q - q[first]
    model = point + rotate(n, np.nan_to_num(q)[:, None], a[None])
    ok = mask & np.isfinite(q)[:, None]
    r2 = np.where(ok, ((vc - model) ** 2).sum(-1), 0.0)
    radii = np.linalg.norm(a - np.outer(a @ n, n), axis=1)
    rel = np.where(mask[..., None], vc - point, 0.0)
    dist = np.linalg.norm(rel - (rel @ n)[..., None] * n, axis=-1)
    rad_rms = np.sqrt(np.where(mask, (dist - radii) ** 2, 0.0).sum(0) / mask.sum(0))
    dof = 3 * ok.sum() - (3 + 3 * len(labels) + np.isfinite(q).sum())
    if dof < 1:
        raise InputError(None, "v", "more observations than hinge parameters",
                         f"{dof} degrees of freedom", hint="record more frames")
    sigma_m = np.sqrt((r2 * w).sum() / dof)
    if (radii >= max(_ON_AXIS * sigma_m, 1e-6)).sum() < 2:
        raise InputError(None, "v", f"at least 2 markers more than {_ON_AXIS:g} noise SDs "
                         f"({1e3 * _ON_AXIS * sigma_m:.2g} mm) from the joint axis",
                         "radii " + ", ".join(f"{s}: {1e3 * r:.3g} mm" for s, r in zip(labels, radii)),
                         hint="markers on the axis do not move with the joint: place them away from it")
    return {"point": point, "template": a, "q": q, "radii": radii, "radius_rms": rad_rms,
            "marker_rms": float(np.sqrt(r2.sum() / ok.sum())), "sigma": sigma_m}


def _check_range(vc, mask, n, min_range_deg, method):
    rom = np.degrees(_cluster_range(vc, mask, n))
    if rom < min_range_deg:
        raise InputError(None, "v", f"a range of motion of at least {min_range_deg:g} deg for the "
                         f"{method} fit", f"{rom:.3g} deg",
                         hint="move the joint further during calibration")


# ---------------------------------------------------------------- uncertainty by bootstrap
def _bootstrap(method, n, res, mask, sigma, sigma_given, n_boot, seed=0):
    """Parametric bootstrap of the algebraic fits: simulate the fitted hinge with the fitted
    noise, refit, and return the mean-square deviation about the fit (3, 3), (3, 3): axis
    (rad^2) and point (m^2), both in the plane normal to n (the estimator's bias is included)."""
    if n_boot < 2 or sigma <= 0:
        return np.full((3, 3), np.nan), np.full((3, 3), np.nan)
    rng = np.random.default_rng(seed)
    N, P = mask.shape
    y = res["point"] + rotate(n, np.nan_to_num(res["q"])[:, None], res["template"][None])
    y = np.where((mask & np.isfinite(res["q"])[:, None])[..., None], y, np.nan)
    Pn = np.eye(3) - np.outer(n, n)
    dn, dp = [], []
    chunk = max(1, min(n_boot, _CHUNK // (3 * N * P)))
    for start in range(0, n_boot, chunk):
        vb = y + sigma * rng.standard_normal((min(chunk, n_boot - start), N, P, 3))
        core = _gl_core(vb)
        m = core["m"] if method == "gamage_lasenby" else _halvorsen_core(
            vb, core, sigma if sigma_given else None)[0]
        nb = core["axis"] * np.sign(core["axis"] @ n)[:, None]
        cen = core["mean_p"].mean(axis=1)
        foot = m + ((cen - m) * nb).sum(-1, keepdims=True) * nb
        dn.append(nb @ Pn)
        dp.append((foot - res["point"]) @ Pn)
    dn, dp = np.concatenate(dn), np.concatenate(dp)
    return dn.T @ dn / len(dn), dp.T @ dp / len(dp)


def _geometry(res, n, centroid, labels, cov_axis, cov_point, sigma_m, method):
    return JointGeometry(axis=n, point=centroid + res["point"], template=res["template"],
                         labels=labels, radii=res["radii"], radius_rms=res["radius_rms"],
                         marker_rms=res["marker_rms"], cov_axis=cov_axis, cov_point=cov_point,
                         sigma_m=float(sigma_m), method=method, n_frames=int(np.isfinite(res["q"]).sum()))


def _algebraic(v, labels, method, sigma, max_iter, tol, n_boot, min_range_deg):
    vc, mask, centroid, labels, w = _prepare(v, labels)
    core = _gl_core(vc)
    n = core["axis"]
    _check_range(vc, mask, n, min_range_deg, method)
    if method == "gamage_lasenby":
        m = core["m"]
    else:
        if sigma is not None and not (np.isfinite(sigma) and sigma >= 0):
            raise InputError(None, "sigma", "a non-negative marker noise SD in metres", sigma)
        m, s2, ratio = _halvorsen_core(vc, core, sigma, max_iter, tol)
        if not ratio < 0.5:
            raise InputError(None, "v", "a range of motion that makes the circle's curvature stand "
                             "out of the noise (bias correction below half the signal)",
                             f"correction/signal {ratio:.2f} at noise {1e3 * np.sqrt(s2):.2g} mm",
                             hint="move the joint further during calibration")
    res = _resolve(vc, mask, w, n, m, *_template_angles(vc, mask, w, n, m, labels), labels)
    sigma_m = res["sigma"] if method == "gamage_lasenby" else (np.sqrt(s2) if sigma is None else sigma)
    cov_axis, cov_point = _bootstrap(method, n, res, mask, sigma_m, sigma is not None, n_boot)
    return _geometry(res, n, centroid, labels, cov_axis, cov_point, sigma_m, method)


# ---------------------------------------------------------------- public fits
def fit_gamage_lasenby(v, labels=None, *, n_boot=200, min_range_deg=MIN_RANGE_DEG) -> JointGeometry:
    """Algebraic axis and centre (Gamage & Lasenby 2002; Lightcap and Banks (2007), eq. 11; methods.md).

    A = 2 sum_p Cov_i(v_p), b = sum_p [mean(|v|^2 v) - mean(|v|^2) mean(v)] (per-marker
    statistics over the frames where the marker is seen); axis = eigenvector of A with the
    smallest eigenvalue; centre = A^+ b with the axis direction truncated, reported as the foot of
    the perpendicular from the markers' centroid. The centre is biased towards the markers at
    small ranges of motion (use `fit_halvorsen` or `fit_hinge_ml`).

    Parameters
    ----------
    v : (N, P, 3) float
        Marker positions, metres, parent (world) frame; NaN where missing.
    labels : sequence of P str, optional
        Marker labels (default "m0", "m1", ...).
    n_boot : int
        Parametric bootstrap replicates for `cov_axis` and `cov_point` (mean-square error about
        the fit, bias included; seeded, so the result is deterministic). 0 leaves them NaN.
    min_range_deg : float
        Smallest accepted range of motion, degrees.

    Returns
    -------
    JointGeometry
        `sigma_m` from the residuals of the fitted hinge (degrees of freedom: 3 x observations
        minus 3 + 3 P + frames).

    Raises
    ------
    InputError
        Bad shapes, all NaN, fewer than 2 usable markers, fewer than 2 markers off the axis,
        range of motion below `min_range_deg`.
    """
    return _algebraic(v, labels, "gamage_lasenby", None, 1, 0.0, n_boot, min_range_deg)


def fit_halvorsen(v, labels=None, sigma=None, max_iter=50, tol=1e-12, *, n_boot=200,
                  min_range_deg=MIN_RANGE_DEG) -> JointGeometry:
    """Bias-compensated axis and centre (Halvorsen 2003; Lightcap and Banks (2007), eq. 12; methods.md).

    Iterates m <- A^+ (b - Δb), Δb = 2 sigma^2 sum_p (1 - 1/N_p)(mean_i v_pi - m), in the plane
    normal to the Gamage-Lasenby axis (the truncated pseudo-inverse keeps the hinge's free
    direction out), re-estimating sigma^2 = mean_p var_i(|v_pi - m|^2) / (4 mean_i |v_pi - m|^2)
    when `sigma` is None. Assumes isotropic, equal noise on all markers.

    Parameters
    ----------
    v, labels, n_boot, min_range_deg : as `fit_gamage_lasenby`.
    sigma : float, optional
        Known marker noise SD per coordinate, metres.
    max_iter, tol : iterations and the step (metres) below which they stop.

    Raises
    ------
    InputError
        As `fit_gamage_lasenby`, and when the noise correction exceeds half of the smallest
        in-plane eigenvalue of A (range of motion too small for the noise).
    """
    return _algebraic(v, labels, "halvorsen", sigma, max_iter, tol, n_boot, min_range_deg)


def fit_hinge_ml(v, labels=None, init=None, weights=None, *, max_iter=50,
                 min_range_deg=MIN_RANGE_DEG) -> tuple[JointGeometry, np.ndarray]:
    """Maximum-likelihood hinge: axis, centre, template and every angle (methods.md; Lightcap and Banks (2007), eq. 13).

    Minimises sum_pi w_p |v_pi - (c + R(n, q_i) a_p)|^2 over the axis (tangent-plane update, 2),
    the centre (2, in the plane normal to the axis), the template (3 P; gauge: mean a_p.n = 0)
    and the angles (N, nuisance), by Levenberg-Marquardt on the normal equations with the
    angles eliminated frame by frame and then set to their closed-form optimum (variable
    projection). Seeded by the Halvorsen centre (the Gamage-Lasenby one when the bias correction
    is unreliable) on the Gamage-Lasenby axis, or by `init`.

    Parameters
    ----------
    v, labels, min_range_deg : as `fit_gamage_lasenby`.
    init : JointGeometry, optional
        Seed axis and point instead of the Halvorsen fit.
    weights : (P,) float, optional
        Relative weights 1 / sigma_p^2 (only ratios matter); default equal.
    max_iter : int

    Returns
    -------
    geometry : JointGeometry
        `cov_axis`, `cov_point`: sigma_m^2 (J^T W J)^-1 with the template and angles
        marginalised (`crlb.marginal_information`), rank 2. `sigma_m`: sqrt(weighted RSS / dof),
        dof = 3 x observations - (3 + 3 P + frames), the SD of a marker of mean weight.
    q : (N,) float
        Angle of every frame, rad, unwrapped, 0 at the first frame with markers; NaN where none.
    """
    vc, mask, centroid, labels, w = _prepare(v, labels, weights)
    if init is None:
        core = _gl_core(vc)
        n = core["axis"]
        _check_range(vc, mask, n, min_range_deg, "ml")
        c, _, ratio = _halvorsen_core(vc, core)
        if not ratio < 0.5:
            c = core["m"]
    else:
        n = np.asarray(init.axis, dtype=np.float64) / np.linalg.norm(init.axis)
        _check_range(vc, mask, n, min_range_deg, "ml")
        c = np.asarray(init.point, dtype=np.float64) - centroid
    a, q = _template_angles(vc, mask, w, n, c, labels)
    _resolve(vc, mask, w, n, c, a, q, labels)              # refuse degenerate seeds early
    n, c, a, q = _ml_solve(vc, mask, w, n, c, a, max_iter)
    res = _resolve(vc, mask, w, n, c, a, q, labels)
    sigma_m = res["sigma"]
    ok = np.isfinite(res["q"])
    info, E = marginal_information(n, res["template"], np.where(ok, res["q"], 0.0),
                                   (mask & ok[:, None]) * w)
    cov = sigma_m**2 * np.linalg.pinv(info)
    geo = _geometry(res, n, centroid, labels, E @ cov[:2, :2] @ E.T, E @ cov[2:, 2:] @ E.T,
                    sigma_m, "ml")
    return geo, res["q"]


def _ml_solve(vc, mask, w, n, c, a, max_iter):
    """Levenberg-Marquardt / variable projection for the hinge; returns n, c, a, q."""
    wm = mask * w
    scale = float(np.sqrt(np.mean((a - np.outer(a @ n, n)) ** 2)) + 1e-12)

    def evaluate(n, c, a):
        q = _angles(vc, mask, w, n, c, a)
        ok = mask & np.isfinite(q)[:, None]
        r = np.where(ok[..., None], vc - c - rotate(n, np.nan_to_num(q)[:, None], a[None]), 0.0)
        return q, r, float((wm * (r**2).sum(-1)).sum())

    def gauge(n, c, a):
        t = (a @ n).mean()
        return n, c + t * n, a - t * n

    n, c, a = gauge(n, c, a)
    q, r, cost = evaluate(n, c, a)
    mu = 0.0
    for _ in range(max_iter):
        ok = np.isfinite(q)
        S, rhs, u, E = normal_blocks(n, a, np.where(ok, q, 0.0), wm * ok[:, None], r)
        d = np.diag(S).copy()
        S = S + np.mean(d[4:]) * np.outer(u, u) / (u @ u)
        for _ in range(12):
            try:
                step = np.linalg.solve(S + mu * np.diag(d), rhs)
            except np.linalg.LinAlgError:
                step = np.linalg.lstsq(S + mu * np.diag(d), rhs, rcond=None)[0]
            n1 = n + E @ step[:2]
            n1, c1, a1 = gauge(n1 / np.linalg.norm(n1), c + E @ step[2:4],
                               a + step[4:].reshape(-1, 3))
            q1, r1, cost1 = evaluate(n1, c1, a1)
            if cost1 <= cost:
                break
            mu = max(10.0 * mu, 1e-6)
        else:
            break
        small = max(np.abs(step[:2]).max(), np.abs(step[2:]).max() / scale) < 1e-12
        rel = (cost - cost1) <= 1e-15 * cost
        n, c, a, q, r, cost = n1, c1, a1, q1, r1, cost1
        mu = mu / 10.0 if mu > 1e-9 else 0.0
        if small or rel:
            break
    return n, c, a, q
