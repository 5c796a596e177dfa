"""Fast identification of a joint's oscillation: the algebraic non-asymptotic estimator of
Oueslati, Bearee, Gibaru and Moraru (2012).

The link of an elastic joint whose motor is held by a stiff position loop obeys (their eq. 9-10)

    y'' + lambda1 y' + lambda2 (y - u) = lambda3,   lambda1 = 2 zeta omega0,  lambda2 = omega0^2

y the link angle, u the motor angle (both link side, rad), lambda3 a constant torque / J (gravity,
friction at rest: the equilibrium is u + lambda3 / lambda2). For the free vibration after a stop
(u constant) pass the deflection or the link angle alone (u = None): the equilibrium is then
lambda3 / lambda2. Their damping acts on the link's velocity (``damping="link"``: a viscous
friction, the static lag D u' / K at constant speed); with ``damping="spring"`` it acts on the
deflection rate, y'' + lambda1 (y' - u') + lambda2 (y - u) = lambda3 (no lag at constant speed). A
free vibration cannot tell the two apart; a window where the motor moves can, and ``"auto"`` keeps
the one whose model fits the window better. Pre-compensating with the wrong one adds an error.

**Algebraic estimator** (their eq. 11-16, after Fliess and Sira-Ramirez). In the Laplace domain
the initial conditions are annihilated by d^2/ds^2, and dividing by s^m turns every derivative
into iterated integrals of the samples, P_{m,n} = (-1)^n / (m-1)! int_0^T (T - t)^(m-1) t^n y dt:

    P_{m-2,2}[y] + 4 P_{m-1,1}[y] + 2 P_{m,0}[y]
        = -lambda1 (P_{m-1,2}[y] + 2 P_{m,1}[y]) - lambda2 (P_{m,2}[y] - P_{m,2}[u]) + lambda3 2 T^(m+2) / (m+2)!

one equation per m; m = 3, 4 is their (13)-(14) (their printed sign of the lambda2 term is the
opposite: this sign is the one the derivation and the tests give). No derivative of the
measurement is taken; over one window of length T the parameters are exact up to quadrature.
The integrals are taken over the cubic-spline interpolant of the samples against the exact
polynomial kernels (error O(h^4) in the sampling step h). The covariance is propagated to first
order from white measurement noise on y, its SD taken from the residual of the identified model
refitted to the window (free initial state and equilibrium).

The logarithmic decrement, the paper's second estimate, is :mod:`.decrement`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.interpolate import CubicSpline

from ..errors import InputError
from ..validate import check_array, freeze_arrays

__all__ = ["MIN_FIT_PCT", "SecondOrderEstimate", "SlidingEstimate", "algebraic_estimate", "algebraic_sliding",
           "second_order_response", "quadrature_kernels", "MIN_WINDOW_SAMPLES", "check_segment", "refit_second_order",
           "fit_percentage"]

MIN_WINDOW_SAMPLES = 8
"""Fewest samples a window may hold: the cubic-spline integrals need them, and below a handful per
window the quadrature error exceeds what any noise level would."""


MIN_FIT_PCT = 50.0
"""A segment whose identified model explains less of its variance than this holds no oscillation
above the noise: :func:`algebraic_estimate` refuses it rather than return a number."""


@dataclass(frozen=True)
class SecondOrderEstimate:
    """omega0 and zeta of y'' + 2 zeta omega0 y' + omega0^2 (y - u) = lambda3 from one data segment.

    Attributes
    ----------
    method : "algebraic" or "log_decrement"
    omega0, omega0_std : rad/s
    zeta, zeta_std : 1
    lambda1, lambda2 : 1/s, 1/s^2 (2 zeta omega0, omega0^2)
    cov : (2, 2) covariance of (omega0, zeta)
    equilibrium : rad, the rest value of y - u (NaN when not estimated)
    t_start, t_end : s, the segment used
    noise_sd : rad, the SD of y's noise the SDs were propagated from (model residual RMS)
    fit_pct : 100 (1 - ||y - y_model|| / ||y - mean y||) of the identified model on the segment
    n_samples : int
    damping : "link" (their eq. 9) or "spring" (module docstring)
    link_reversals : int, how often the link's velocity (of the fitted model) changes sign in the
        segment. Each reversal flips any Coulomb friction, which the linear model cannot follow:
        zeta (and omega0, less) are then those of the equivalent linear transient, not the joint's
        viscous damping. A velocity change where the link keeps its direction has none.
    """

    method: str
    omega0: float
    omega0_std: float
    zeta: float
    zeta_std: float
    lambda1: float
    lambda2: float
    cov: np.ndarray
    equilibrium: float
    t_start: float
    t_end: float
    noise_sd: float
    fit_pct: float
    n_samples: int
    damping: str = "link"
    link_reversals: int = 0

    def __post_init__(self) -> None:
        freeze_arrays(self)

    @property
    def f0_hz(self) -> float:
        return self.omega0 / (2 * math.pi)

    @property
    def f0_hz_std(self) -> float:
        return self.omega0_std / (2 * math.pi)

    def stiffness(self, inertia: float) -> tuple[float, float]:
        """K = J omega0^2 and its SD (their eq. 8), for a link inertia J (kg m^2) taken as exact."""
        return inertia * self.omega0 ** 2, 2 * inertia * self.omega0 * self.omega0_std

    def to_dict(self) -> dict:
        return {"method": self.method, "omega0": self.omega0, "omega0_std": self.omega0_std, "f0_hz": self.f0_hz,
                "f0_hz_std": self.f0_hz_std, "zeta": self.zeta, "zeta_std": self.zeta_std,
                "lambda1": self.lambda1, "lambda2": self.lambda2, "equilibrium": self.equilibrium,
                "t_start": self.t_start, "t_end": self.t_end, "window_s": self.t_end - self.t_start,
                "noise_sd": self.noise_sd, "fit_pct": self.fit_pct, "n_samples": self.n_samples,
                "damping": self.damping, "link_reversals": self.link_reversals}


@dataclass(frozen=True)
class SlidingEstimate:
    """The algebraic estimator over sliding windows of one record.

    Attributes
    ----------
    t_end : (W,) s, the end of each window (the estimate is available then)
    omega0, zeta : (W,) the window's estimates (NaN where the window is singular or omega0^2 <= 0)
    omega0_std, zeta_std : (W,) first-order SDs from `noise_sd`
    window_s : float
    noise_sd : float, rad (the identified model's residual RMS over the record's valid windows)
    omega0_median, zeta_median : float, over the valid windows
    omega0_spread, zeta_spread : float, 1.4826 x the median absolute deviation over the valid windows
    n_valid : int
    """

    t_end: np.ndarray
    omega0: np.ndarray
    zeta: np.ndarray
    omega0_std: np.ndarray
    zeta_std: np.ndarray
    window_s: float
    noise_sd: float
    omega0_median: float
    zeta_median: float
    omega0_spread: float
    zeta_spread: float
    n_valid: int

    def __post_init__(self) -> None:
        freeze_arrays(self)

    def to_dict(self) -> dict:
        return {"window_s": self.window_s, "n_windows": int(self.t_end.size), "n_valid": self.n_valid,
                "noise_sd": self.noise_sd, "omega0_median": self.omega0_median, "omega0_spread": self.omega0_spread,
                "f0_hz_median": self.omega0_median / (2 * math.pi), "zeta_median": self.zeta_median,
                "zeta_spread": self.zeta_spread}


def check_segment(t, y, u=None, what: str = "y"):
    """t, y (and u) as float arrays of one length, finite, uniformly sampled, at least
    `MIN_WINDOW_SAMPLES` long; InputError otherwise."""
    dims: dict = {}
    t = check_array(t, "t", ("T",), dims=dims, finite=True)
    y = check_array(y, what, ("T",), dims=dims, finite=True)
    if u is not None:
        u = check_array(u, "u", ("T",), dims=dims, finite=True)
    if t.size < MIN_WINDOW_SAMPLES:
        raise InputError(None, "t", f"at least {MIN_WINDOW_SAMPLES} samples", t.size, hint="record a longer segment")
    dt = np.diff(t)
    if not (dt > 0).all():
        raise InputError(None, "t", "strictly increasing times", f"a step of {dt.min():.3g} s")
    if np.ptp(dt) > 1e-6 * dt.mean() + 1e-12:
        raise InputError(None, "t", "uniform sampling", f"steps from {dt.min():.6g} to {dt.max():.6g} s",
                         hint="resample onto a uniform clock first")
    return t, y, u


def quadrature_kernels(n: int, orders: tuple[int, ...], rule: str = "spline") -> dict[tuple[int, int], np.ndarray]:
    """Weights w (n,) with sum_k w_k y_k = P_{m,n}[y] over a window of unit length sampled at n
    uniform points: the kernel (-1)^n / (m-1)! (1 - s)^(m-1) s^n integrated exactly against the
    not-a-knot cubic spline through the samples (Gauss-Legendre, 6 nodes per interval: exact for
    the degree <= 9 products). Keys (m, n) for every integral the equations of `orders` use.
    ``rule="trapezoid"``: the composite trapezoidal rule on the kernel times the samples
    (Oueslati et al. 2012, section 4.B), for comparison."""
    if rule not in ("spline", "trapezoid"):
        raise InputError(None, "quadrature", '"spline" or "trapezoid"', repr(rule))
    s = np.linspace(0.0, 1.0, n)
    keys = set()
    for m in orders:
        keys |= {(m - 2, 2), (m - 1, 1), (m, 0), (m - 1, 2), (m, 1), (m, 2)}
    if rule == "trapezoid":
        w = np.full(n, 1.0 / (n - 1))
        w[[0, -1]] = 0.5 / (n - 1)
        return {(m, k): w * (-1) ** k / math.factorial(m - 1) * (1 - s) ** (m - 1) * s ** k for m, k in keys}
    basis = CubicSpline(s, np.eye(n), axis=0)
    xg, wg = np.polynomial.legendre.leggauss(6)
    h = s[1] - s[0]
    nodes = (s[:-1, None] + h * (xg[None, :] + 1) / 2).ravel()
    wnodes = np.tile(wg * h / 2, n - 1)
    B = basis(nodes)                                   # (n_nodes, n)
    out = {}
    for m, k in keys:
        kern = (-1) ** k / math.factorial(m - 1) * (1 - nodes) ** (m - 1) * nodes ** k
        out[(m, k)] = (wnodes * kern) @ B
    return out


def _equations(Q: dict, Y: np.ndarray, U: np.ndarray | None, orders, offset: bool, spring: bool = False):
    """A (..., M, p), b (..., M) of the equations for windows Y (..., n), and the per-sample
    weight vectors (M, p, n) / (M, n) of the y-dependent entries (for the noise propagation).
    `spring`: the damping acts on y' - u' (the lambda1 column integrates y - u)."""
    rows_a, rows_b, wa, wb = [], [], [], []
    Y1 = Y - U if (spring and U is not None) else Y
    for m in orders:
        a1 = -(Q[(m - 1, 2)] + 2 * Q[(m, 1)])
        a2 = -Q[(m, 2)]
        bb = Q[(m - 2, 2)] + 4 * Q[(m - 1, 1)] + 2 * Q[(m, 0)]
        cols = [Y1 @ a1, Y @ a2 - (0.0 if U is None else U @ a2)]
        w = [a1, a2]
        if offset:
            c = 2.0 / math.factorial(m + 2)
            cols.append(np.full(Y.shape[:-1], c))
            w.append(np.zeros_like(a1))
        rows_a.append(np.stack(cols, axis=-1))
        rows_b.append(Y @ bb)
        wa.append(np.stack(w))
        wb.append(bb)
    return np.stack(rows_a, axis=-2), np.stack(rows_b, axis=-1), np.stack(wa), np.stack(wb)


def _orders(offset: bool, orders) -> tuple[int, ...]:
    p = 3 if offset else 2
    orders = tuple(int(m) for m in (orders if orders is not None else range(3, 3 + p)))
    if len(orders) < p or min(orders) < 3 or len(set(orders)) != len(orders):
        raise InputError(None, "orders", f"at least {p} distinct integers >= 3", orders)
    return orders


def second_order_response(t, omega0: float, zeta: float, u=None, *, y0: float = 0.0, v0: float = 0.0,
                          lambda3: float = 0.0, damping: str = "link") -> np.ndarray:
    """y (T,) of y'' + 2 zeta omega0 y' + omega0^2 (y - u) = lambda3 (``damping="link"``) or
    y'' + 2 zeta omega0 (y' - u') + omega0^2 (y - u) = lambda3 (``"spring"``) from y(t0) = y0,
    y'(t0) = v0, u (T,) rad (linear between samples; None = 0)."""
    t = np.asarray(t, dtype=np.float64)
    l1, l2 = 2 * zeta * omega0, omega0 ** 2
    uu = np.zeros(t.size) if u is None else np.asarray(u, dtype=np.float64)
    A = np.array([[0.0, 1.0], [-l2, -l1]])
    if damping == "spring":              # state (y, y' - l1 u): transfer (l1 s + l2) / (s^2 + l1 s + l2)
        B = np.array([[l1, 0.0], [l2 - l1 ** 2, 1.0]])
        x0 = [y0, v0 - l1 * uu[0]]
    else:
        B = np.array([[0.0, 0.0], [l2, 1.0]])
        x0 = [y0, v0]
    sys = signal.StateSpace(A, B, np.array([[1.0, 0.0]]), np.zeros((1, 2)))
    _, y, _ = signal.lsim(sys, np.column_stack([uu, np.full(t.size, lambda3)]), t - t[0], X0=x0)
    return np.asarray(y, dtype=np.float64)


def refit_second_order(t, y, u, omega0, zeta, offset: bool = True, damping: str = "link"):
    """Least-squares initial state (and lambda3) of the identified model on the segment: the
    model's response, its residual RMS (with the degrees of freedom of all fitted parameters)
    and the fitted lambda3."""
    cols = [second_order_response(t, omega0, zeta, None, y0=1.0), second_order_response(t, omega0, zeta, None, v0=1.0)]
    if offset:
        cols.append(second_order_response(t, omega0, zeta, None, lambda3=1.0))
    base = np.zeros(t.size) if u is None else second_order_response(t, omega0, zeta, u, damping=damping)
    X = np.column_stack(cols)
    c, *_ = np.linalg.lstsq(X, y - base, rcond=None)
    model = base + X @ c
    dof = max(t.size - X.shape[1] - 2, 1)
    res = y - model
    return model, float(np.sqrt(res @ res / dof)), (float(c[2]) if offset else 0.0)


def fit_percentage(y, model) -> float:
    """100 (1 - ||y - model|| / ||y - mean y||) (docs/conventions.md)."""
    dev = y - y.mean()
    d = float(np.linalg.norm(dev))
    return float(100.0 * (1.0 - np.linalg.norm(y - model) / d)) if d > 0 else float("nan")


def _to_omega_zeta(l1, l2, C_l):
    """(omega0, zeta) and their covariance from (lambda1, lambda2) and the covariance C_l (..., 2, 2)."""
    w = np.sqrt(l2)
    z = l1 / (2 * w)
    Jm = np.zeros(np.shape(l1) + (2, 2))
    Jm[..., 0, 1] = 1 / (2 * w)
    Jm[..., 1, 0] = 1 / (2 * w)
    Jm[..., 1, 1] = -l1 / (4 * w ** 3)
    return w, z, Jm @ C_l @ np.swapaxes(Jm, -1, -2)


def algebraic_estimate(t, y, u=None, *, offset: bool = True, orders=None, noise_sd: float | None = None,
                       damping: str = "auto", quadrature: str = "spline") -> SecondOrderEstimate:
    """omega0 and zeta from one segment by the algebraic estimator (Oueslati et al. 2012, eq. 13-16).

    Parameters
    ----------
    t : (T,) s, uniformly sampled
    y : (T,) rad: the link angle (with u), or the deflection / link angle of a free vibration (u None)
    u : (T,) rad or None: the motor angle (link side) driving the joint
    offset : bool
        Estimate the constant lambda3 (an unknown equilibrium); needed for a free vibration about a
        value other than 0. With u given and no constant torque, False is the paper's estimator.
    orders : the divisors s^m of the equations (default 3, 4 and 5 with the offset: their eq. 13-14
        and one more); more than the unknowns gives a least-squares solution.
    noise_sd : rad, the SD of y's noise; default the identified model's residual RMS on the segment.
    damping : "link" (their eq. 9), "spring", or "auto" (with u: the one whose model fits the
        segment better; without u they coincide and "link" is reported)
    quadrature : "spline" (default) or "trapezoid" (their discretisation; at 25 samples per period
        it is off by percents: docs/identification.md)

    Raises
    ------
    InputError
        Fewer than `MIN_WINDOW_SAMPLES` samples, non-uniform sampling, or a segment that does not
        determine the parameters (omega0^2 <= 0, or a fit below `MIN_FIT_PCT`: no oscillation
        above the noise).
    """
    t, y, u = check_segment(t, y, u)
    if damping not in ("link", "spring", "auto"):
        raise InputError(None, "damping", '"link", "spring" or "auto"', repr(damping))
    if damping == "auto":
        if u is None or np.ptp(u) == 0:
            damping = "link"
        else:
            fits = []
            for form in ("link", "spring"):
                try:
                    fits.append(algebraic_estimate(t, y, u, offset=offset, orders=orders, noise_sd=noise_sd,
                                                   damping=form, quadrature=quadrature))
                except InputError as e:
                    err = e
            if not fits:
                raise err
            return max(fits, key=lambda e: e.fit_pct)
    orders = _orders(offset, orders)
    T = float(t[-1] - t[0])
    ref = float(y[0]) if u is None else float(u[0])
    scale = float(np.std(y - (0.0 if u is None else u))) or 1.0
    ys = (y - ref) / scale
    us = None if u is None else (u - ref) / scale
    Q = quadrature_kernels(t.size, orders, quadrature)
    A, b, wa, wb = _equations(Q, ys, us, orders, offset, spring=damping == "spring")
    if not np.isfinite(A).all() or np.linalg.cond(A) > 1e12:
        raise InputError(None, "y", "a segment that determines omega0 and zeta (an oscillation)",
                         "a singular system", hint="take a longer segment or one after a motion change")
    th, *_ = np.linalg.lstsq(A, b, rcond=None)
    l1, l2 = th[0] / T, th[1] / T ** 2
    if not (l2 > 0 and np.isfinite(l1)):
        raise InputError(None, "y", "a segment with an oscillation (omega0^2 > 0)", f"omega0^2 = {l2:.3g} 1/s^2",
                         hint="take a longer segment or one after a motion change")
    l1, l2 = float(l1), float(l2)
    omega0, zeta = math.sqrt(l2), l1 / (2 * math.sqrt(l2))
    model, rms, lam3 = refit_second_order(t, y, u, omega0, zeta, offset, damping)
    fit = fit_percentage(y, model)
    if not fit >= MIN_FIT_PCT:
        raise InputError(None, "y", f"a segment whose oscillation the model explains (fit >= {MIN_FIT_PCT:g} %)",
                         f"fit {fit:.3g} % (omega0 {omega0:.4g} rad/s, zeta {zeta:.3g})",
                         hint="no oscillation above the noise here: take the segment after a stop or a motion change")
    sd = rms if noise_sd is None else float(noise_sd)
    v = np.gradient(model, t)
    v = v[np.abs(v) > 0.01 * np.abs(v).max()] if np.abs(v).max() > 0 else v[:0]
    reversals = int(np.count_nonzero(np.diff(np.sign(v)) != 0))
    # first-order noise propagation: d(theta) = A^+ (db - dA theta) = A^+ G eps
    G = wb - th[0] * wa[:, 0] - th[1] * wa[:, 1]
    Ap = np.linalg.pinv(A)
    C_th = (sd / scale) ** 2 * Ap @ G @ G.T @ Ap.T
    S = np.diag([1 / T, 1 / T ** 2])
    C_l = S @ C_th[:2, :2] @ S
    _, _, C = _to_omega_zeta(l1, l2, C_l)
    return SecondOrderEstimate(method="algebraic", omega0=omega0, omega0_std=float(np.sqrt(C[0, 0])), zeta=zeta,
                               zeta_std=float(np.sqrt(C[1, 1])), lambda1=float(l1), lambda2=float(l2), cov=C,
                               equilibrium=lam3 / l2 if offset else float("nan"), t_start=float(t[0]),
                               t_end=float(t[-1]), noise_sd=sd, fit_pct=fit, n_samples=int(t.size), damping=damping,
                               link_reversals=reversals)


def algebraic_sliding(t, y, u=None, *, window_s: float, offset: bool = True, orders=None,
                      noise_sd: float | None = None, damping: str = "link") -> SlidingEstimate:
    """The algebraic estimator on every window of `window_s` seconds sliding by one sample (one
    matrix product for all windows). The SDs of each window are propagated from `noise_sd`
    (default: the residual RMS of the median model refitted to the whole record). `damping`:
    "link" or "spring" (see :func:`algebraic_estimate`)."""
    t, y, u = check_segment(t, y, u)
    if damping not in ("link", "spring"):
        raise InputError(None, "damping", '"link" or "spring"', repr(damping))
    if not (np.isfinite(window_s) and window_s > 0):
        raise InputError(None, "window_s", "a positive window length in s", window_s)
    orders = _orders(offset, orders)
    h = float(t[1] - t[0])
    n = int(round(window_s / h)) + 1
    if n < MIN_WINDOW_SAMPLES or n > t.size:
        raise InputError(None, "window_s", f"a window of {MIN_WINDOW_SAMPLES} to {t.size} samples "
                         f"({(MIN_WINDOW_SAMPLES - 1) * h:.3g} to {(t.size - 1) * h:.3g} s)", f"{n} samples")
    T = (n - 1) * h
    scale = float(np.std(y - (0.0 if u is None else u))) or 1.0
    ref = float(y[0]) if u is None else float(u[0])
    Y = np.lib.stride_tricks.sliding_window_view((y - ref) / scale, n)
    U = None if u is None else np.lib.stride_tricks.sliding_window_view((u - ref) / scale, n)
    Q = quadrature_kernels(n, orders)
    A, b, wa, wb = _equations(Q, Y, U, orders, offset, spring=damping == "spring")
    with np.errstate(all="ignore"):
        ok = np.isfinite(A).all(axis=(-1, -2)) & np.isfinite(b).all(axis=-1)
        ok[ok] = np.linalg.cond(A[ok]) < 1e12                       # as algebraic_estimate
        th = np.full((Y.shape[0], A.shape[-1]), np.nan)
        th[ok] = (np.linalg.pinv(A[ok]) @ b[ok][..., None])[..., 0]
        l1, l2 = th[:, 0] / T, th[:, 1] / T ** 2
        valid = ok & (l2 > 0) & np.isfinite(l1)
    if not valid.any():
        raise InputError(None, "y", "a record with an oscillation (omega0^2 > 0 in some window)", "none",
                         hint="check the signal or lengthen the window")
    l2v = np.where(valid, l2, np.nan)
    omega0 = np.sqrt(l2v)
    zeta = np.where(valid, l1, np.nan) / (2 * omega0)
    w_med, z_med = float(np.nanmedian(omega0)), float(np.nanmedian(zeta))
    if noise_sd is None:
        model, rms, _ = refit_second_order(t, y, u, w_med, z_med, offset, damping)
        noise_sd = rms
    Apinv = np.full((Y.shape[0], A.shape[-1], A.shape[-2]), np.nan)
    Apinv[valid] = np.linalg.pinv(A[valid])
    G = wb[None] - th[:, 0, None, None] * wa[None, :, 0] - th[:, 1, None, None] * wa[None, :, 1]   # (W, M, n)
    AG = Apinv[:, :2] @ G                                           # (W, 2, n)
    C_th = (noise_sd / scale) ** 2 * AG @ np.swapaxes(AG, -1, -2)
    S = np.array([1 / T, 1 / T ** 2])
    C_l = C_th * np.outer(S, S)
    with np.errstate(all="ignore"):
        _, _, C = _to_omega_zeta(np.where(valid, l1, np.nan), l2v, C_l)
    mad = lambda x: float(1.4826 * np.nanmedian(np.abs(x - np.nanmedian(x))))   # noqa: E731
    return SlidingEstimate(t_end=t[n - 1:], omega0=omega0, zeta=zeta, omega0_std=np.sqrt(C[:, 0, 0]),
                           zeta_std=np.sqrt(C[:, 1, 1]), window_s=T, noise_sd=float(noise_sd), omega0_median=w_med,
                           zeta_median=z_med, omega0_spread=mad(omega0), zeta_spread=mad(zeta),
                           n_valid=int(valid.sum()))
