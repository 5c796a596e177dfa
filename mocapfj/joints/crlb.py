"""Cramér-Rao bounds for a revolute joint seen through a marker cluster (docs/conventions.md).

Hinge model (Lightcap and Banks (2007), §III, eq. 13): marker p in frame i is at

    v_pi = c + R(n, q_i) a_p + e_pi,      e_pi ~ N(0, sigma_p^2 I),   sigma_p = sigma / sqrt(w_p)

with unit axis n, a point c on the axis, template a_p (marker relative to c at q = 0) and per-frame
angles q_i. The structural parameters are the axis tilt (2, rad, in the basis `tangent_basis(n)`)
and the in-plane centre (2, m, same basis). The template (3 P) and the angles (N) are nuisance
parameters: they are eliminated by Schur complements, the angles frame by frame (their block of
the Fisher information is diagonal), then the template. One direction is a gauge (rotating the
template about n while shifting every angle back leaves the data unchanged); it touches neither
the axis nor the centre and is removed exactly (methods.md, "Axis and centre").

The same normal-equation blocks drive the Gauss-Newton steps of `axis.fit_hinge_ml`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..rotations import matrix_from_axis_angle, skew

__all__ = ["Crlb", "hinge_crlb", "angle_crlb", "angle_crlb_cov", "tangent_basis"]


@dataclass(frozen=True, eq=False)
class Crlb:
    """Cramér-Rao covariance of a hinge's axis and centre.

    Attributes
    ----------
    basis : (3, 2) float
        Orthonormal columns e1, e2 spanning the plane normal to the axis (`tangent_basis`).
    cov : (4, 4) float
        Covariance of (tilt e1, tilt e2 [rad]; centre e1, centre e2 [m]): axis = n + tilt_k e_k,
        centre = c + centre_k e_k, at the height of `point`.
    cov_axis : (3, 3) float
        The tilt block in 3D, rank 2, rad^2.
    cov_point : (3, 3) float
        The centre block in 3D, rank 2 (in the plane normal to the axis), m^2.
    """

    basis: np.ndarray
    cov: np.ndarray
    cov_axis: np.ndarray
    cov_point: np.ndarray

    @property
    def sd_axis_max(self) -> float:
        """Largest principal SD of the axis direction, rad."""
        return float(np.sqrt(np.linalg.eigvalsh(self.cov[:2, :2])[-1]))

    @property
    def sd_point_max(self) -> float:
        """Largest principal SD of the in-plane centre, m."""
        return float(np.sqrt(np.linalg.eigvalsh(self.cov[2:, 2:])[-1]))


def tangent_basis(n: np.ndarray) -> np.ndarray:
    """Deterministic orthonormal basis (3, 2) of the plane normal to the unit vector `n` (3,)."""
    n = np.asarray(n, dtype=np.float64)
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    K = skew(n)
    e1 = K @ helper
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, K @ e1], axis=1)


def normal_blocks(n, template, q, wm, resid=None):
    """Gauss-Newton normal equations of the hinge model with the angles eliminated.

    Parameters
    ----------
    n : (3,) unit axis.
    template : (P, 3) a_p, metres.
    q : (N,) angles, rad (any value where a frame has no marker).
    wm : (N, P) weight of each observation (w_p, 0 where the marker is missing).
    resid : (N, P, 3) or None
        Residuals v - model (0 where missing); when given, the reduced right-hand side is returned.

    Returns
    -------
    S : (G, G) reduced information, G = 4 + 3 P, parameter order (tilt 2, centre 2, template 3 P).
    rhs : (G,) or None, reduced J^T W r.
    u : (G,) gauge direction (S u = 0): (0, n x a_p).
    E : (3, 2) tangent basis of the tilt and centre parameters.
    """
    P = template.shape[0]
    E = tangent_basis(n)
    R = matrix_from_axis_angle(n, q)                                # (N, 3, 3)
    s, c1 = np.sin(q)[:, None, None, None], (1.0 - np.cos(q))[:, None, None, None]
    nxa = template @ skew(n).T                                    # (P, 3) n x a_p
    t = np.matmul(R, nxa.T).transpose(0, 2, 1)                    # n x (R a_p) = R (n x a_p)
    # d(R a)/dn . e = sin q (e x a) + (1 - cos q) ((e.a) n + (n.a) e), for e = e1, e2
    exa = np.stack([template @ skew(e).T for e in E.T], axis=1)   # (P, 2, 3)
    ea, na = template @ E, template @ n                           # (P, 2), (P,)
    tilt = s * exa + c1 * (ea[:, :, None] * n + na[:, None, None] * E.T)        # (N, P, 2, 3)
    Jg = np.concatenate([tilt, np.broadcast_to(E.T, tilt.shape)], axis=2)     # (N, P, 4, 3)
    Jw = Jg * wm[:, :, None, None]
    G = 4 + 3 * P
    H = np.zeros((G, G))
    H[:4, :4] = np.tensordot(Jw, Jg, axes=([0, 1, 3], [0, 1, 3]))
    Hga = np.matmul(Jw, R[:, None]).sum(axis=0).transpose(1, 0, 2).reshape(4, 3 * P)
    H[:4, 4:], H[4:, :4] = Hga, Hga.T
    H[4:, 4:] = np.diag(np.repeat(wm.sum(axis=0), 3))
    hq = np.concatenate([np.matmul(Jw, t[..., None])[..., 0].sum(axis=1),
                         (wm[:, :, None] * nxa[None]).reshape(-1, 3 * P)], axis=1)  # (N, G)
    D = wm @ (nxa**2).sum(axis=1)                                 # (N,) sum_p w r_p^2
    inv_D = np.divide(1.0, D, out=np.zeros_like(D), where=D > 0)
    S = H - (hq * inv_D[:, None]).T @ hq
    rhs = None
    if resid is not None:
        rw = resid * wm[:, :, None]
        g = np.concatenate([np.tensordot(Jg, rw, axes=([0, 1, 3], [0, 1, 2])),
                            np.matmul(rw, R).sum(axis=0).ravel()])
        gq = (t * rw).sum(axis=(1, 2))
        rhs = g - hq.T @ (gq * inv_D)
    u = np.concatenate([np.zeros(4), nxa.ravel()])
    return S, rhs, u, E


def marginal_information(n, template, q, wm) -> tuple[np.ndarray, np.ndarray]:
    """Fisher information (4, 4) of (tilt 2, centre 2) per unit noise variance, and the basis (3, 2).

    The template and angles are marginalised by Schur complements; the gauge direction is
    removed by adding s u u^T to the template block (exact: S u = 0, so the added term only
    replaces the pseudo-inverse).
    """
    S, _, u, E = normal_blocks(n, template, q, wm)
    Saa, Sga = S[4:, 4:], S[:4, 4:]
    ua = u[4:] / np.linalg.norm(u[4:])
    scale = np.trace(Saa) / Saa.shape[0]
    info = S[:4, :4] - Sga @ np.linalg.solve(Saa + scale * np.outer(ua, ua), Sga.T)
    return 0.5 * (info + info.T), E


def _check_vec(x, shape, name) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise InputError(None, name, f"finite array of shape {shape}", f"shape {a.shape}")
    return a


def hinge_crlb(axis, point, template, q, sigma, weights=None, mask=None) -> Crlb:
    """Cramér-Rao covariance of the axis tilt and in-plane centre of a hinge, for one design.

    Parameters
    ----------
    axis : (3,) float
        Unit axis direction (normalised here).
    point : (3,) float
        The point on the axis whose in-plane position is bounded, metres; the bound is for the
        centre at this height (`axis.fit_*` report the foot of the markers' centroid).
    template : (P, 3) float
        Markers relative to `point` at q = 0, metres.
    q : (N,) float
        Angle of every frame, rad.
    sigma : float
        Marker noise SD per coordinate, metres (for weight 1).
    weights : (P,) float, optional
        Relative weights: marker p has SD sigma / sqrt(weights[p]). Default all 1.
    mask : (N, P) bool, optional
        Which markers are seen in which frame. Default all.

    Returns
    -------
    Crlb
        Full-circle check (methods.md): in-plane centre sigma sqrt(2 / (N P)) per coordinate,
        axis tilt sigma sqrt(2 / (N sum r_p^2)) rad per direction when the markers share one
        plane normal to the axis (else sum r_p^2 + sum (h_p - mean h)^2).
    """
    n = _check_vec(axis, (3,), "axis")
    n = n / np.linalg.norm(n)
    _check_vec(point, (3,), "point")
    a = np.asarray(template, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or not np.all(np.isfinite(a)):
        raise InputError(None, "template", "finite array of shape (P, 3)", f"shape {a.shape}")
    qq = np.asarray(q, dtype=np.float64)
    if qq.ndim != 1 or not np.all(np.isfinite(qq)):
        raise InputError(None, "q", "finite array of shape (N,)", f"shape {qq.shape}")
    P, N = a.shape[0], qq.shape[0]
    w = np.ones(P) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (P,) or not np.all(w > 0):
        raise InputError(None, "weights", f"{P} positive weights", w)
    m = np.ones((N, P), bool) if mask is None else np.asarray(mask, bool)
    if m.shape != (N, P):
        raise InputError(None, "mask", f"shape ({N}, {P})", f"shape {m.shape}")
    if not (np.isfinite(sigma) and sigma > 0):
        raise InputError(None, "sigma", "a positive noise SD in metres", sigma)
    info, E = marginal_information(n, a, qq, m * w[None, :])
    cov = float(sigma) ** 2 * np.linalg.inv(info)
    cov = 0.5 * (cov + cov.T)
    return Crlb(basis=E, cov=cov, cov_axis=E @ cov[:2, :2] @ E.T, cov_point=E @ cov[2:, 2:] @ E.T)


def angle_crlb(radii, sigma) -> float:
    """Cramér-Rao SD of one frame's angle, rad: sigma / sqrt(sum_p r_p^2) (methods.md).

    radii : (P,) distances of the markers from the axis, metres (NaN = marker missing);
    sigma : isotropic marker noise SD per coordinate, metres.
    """
    r = np.asarray(radii, dtype=np.float64)
    return float(sigma / np.sqrt(np.nansum(r**2)))


def angle_crlb_cov(axis, point, positions, cov) -> np.ndarray:
    """Cramér-Rao SD of the angle with per-marker noise covariances, rad.

    I(q) = sum_p t_p^T Sigma_p^-1 t_p with t_p = n x (y_p - c) (methods.md).

    Parameters
    ----------
    axis, point : (3,) unit axis and a point on it, metres.
    positions : (..., P, 3) marker positions y_p, metres; NaN rows are missing markers.
    cov : (P, 3, 3) or (..., P, 3, 3) noise covariance of each marker, m^2.

    Returns
    -------
    (...) float, the SD (inf where no marker carries information).
    """
    n = np.asarray(axis, dtype=np.float64)
    n = n / np.linalg.norm(n)
    y = np.asarray(positions, dtype=np.float64) - np.asarray(point, dtype=np.float64)
    t = np.cross(n, y)
    ok = np.all(np.isfinite(t), axis=-1)
    t = np.where(ok[..., None], t, 0.0)
    Sinv_t = np.linalg.solve(np.broadcast_to(cov, t.shape + (3,)), t[..., None])[..., 0]
    info = np.einsum("...pk,...pk->...", t, Sinv_t)
    with np.errstate(divide="ignore"):
        return 1.0 / np.sqrt(info)
