"""Friction from constant-velocity sweeps: plateaus, Stribeck fits per side, pre-sliding.

The experiment (Oueslati et al. (2012) sec. III-B, Bompos et al. (2007) sec. 3): the joint is driven in velocity mode
through a staircase of constant velocities on both signs (Bompos et al. (2007): 0.001 rad/s to 60 % of the
maximum; Oueslati et al. (2012): +-0.004 ... +-0.2 rad/s). On a plateau q'' = 0, so the link equation
``I q'' + G(q) + F(q, q') = tau`` (docs/conventions.md) leaves ``F(q') = tau - G(q)``: each
plateau gives one point (mean velocity, mean friction torque) of the friction characteristic.

- :func:`sweep_points`: find the plateaus of a recording and average them (SI, link side:
  rad, rad/s, N m).
- :func:`fit_stribeck`: Oueslati et al. (2012), eq. (7), one set of coefficients per side of q' = 0
  (:class:`~mocapfj.dynamics.AsymmetricStribeck`) or one for both (:class:`~mocapfj.dynamics.Stribeck`).
- :func:`fit_extended_stribeck`: Bompos et al. (2007), eq. (18) per side (:class:`~mocapfj.dynamics.ExtendedStribeck`).
- :func:`fit_presliding`: torque against displacement at the start of a very slow motion (seed
  001 sec. III-B-2, 5.931e-5 rad/s), the Dahl curve ``tau = Fs (1 - exp(-sigma0 x / Fs))``.

Nonlinear fits use ``scipy.optimize.least_squares`` from deterministic starts: the models are
linear in their levels for fixed velocity scales, so the scales are first chosen on a grid by
linear least squares (variable projection) and then all parameters are refined together. The
reported standard deviations are Jubien, Abba and Gautier (2014), eq. (16) with the Jacobian at the solution:
``C = sigma^2 (J^T J)^-1``, ``sigma^2 = rss / (r - p)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.ndimage import maximum_filter1d, minimum_filter1d, uniform_filter1d
from scipy.optimize import least_squares

from ..dynamics.friction import AsymmetricStribeck, ExtendedStribeck, Stribeck
from ..dynamics.hysteresis import Dahl
from ..errors import InputError

__all__ = ["SweepPoints", "FrictionFit", "PreslidingFit", "sweep_points", "fit_stribeck",
           "fit_extended_stribeck", "fit_presliding"]


# --------------------------------------------------------------------------- plateaus


@dataclass(frozen=True, eq=False)
class SweepPoints:
    """Constant-velocity plateaus of a sweep, in time order (one entry per plateau).

    Attributes
    ----------
    v : (P,) float
        Mean link velocity on the plateau, rad/s.
    tau : (P,) float
        Mean friction torque ``tau - G(q)`` on the plateau, N m.
    se : (P,) float
        Standard error of `tau`, N m: sample SD / sqrt(n) (white torque noise assumed; correlated
        noise makes it optimistic).
    n_samples : (P,) int
        Samples averaged.
    t_start, t_end : (P,) float
        First and last averaged sample, s.
    """

    v: np.ndarray
    tau: np.ndarray
    se: np.ndarray
    n_samples: np.ndarray
    t_start: np.ndarray
    t_end: np.ndarray

    def __len__(self) -> int:
        return int(self.v.size)


def _vec(name: str, x, n: int | None = None) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 1 or (n is not None and a.size != n):
        want = f"a 1-D array of {n} samples" if n is not None else "a 1-D array"
        raise InputError(None, name, want, f"shape {a.shape}", hint="all inputs must have the same length")
    if not np.isfinite(a).all():
        raise InputError(None, name, "finite samples", f"{int((~np.isfinite(a)).sum())} NaN/inf",
                         hint="cut or interpolate the missing samples first")
    return a


def _ro(*arrays):
    for a in arrays:
        a.setflags(write=False)
    return arrays


def sweep_points(t, q, qd, tau, *, gravity: Callable | np.ndarray | None = None, min_duration_s: float = 0.5,
                 rel_tol: float = 0.02, abs_tol: float = 1e-5, window_s: float | None = None,
                 settle_s: float = 0.0) -> SweepPoints:
    """Find the constant-velocity plateaus of a sweep recording and average each one.

    A sample is steady when, over a centred window of `window_s`, the velocity stays within
    ``+-(rel_tol |v| + abs_tol)`` of its window mean v and ``|v| > abs_tol`` (standstill is not a
    plateau: the friction at rest is undetermined). A run of steady samples, less its first
    `settle_s` and less the samples off its median velocity by more than the tolerance, is a
    plateau when it lasts at least `min_duration_s`.

    Parameters
    ----------
    t : (T,) float
        Strictly increasing times, s.
    q, qd : (T,) float
        Link angle, rad, and link velocity, rad/s (filter a differentiated velocity first, e.g.
        :func:`mocapfj.ident.lowpass`: the tolerance must cover its noise).
    tau : (T,) float
        Joint torque on the link side, N m.
    gravity : callable or (T,) float, optional
        G(q) in N m (a callable is evaluated on `q`); it is subtracted: on a plateau q'' = 0, so
        the friction torque is ``tau - G(q)``. None: gravity-free configuration (G = 0).
    min_duration_s : float
        Shortest plateau kept, s.
    rel_tol : float
        Relative velocity tolerance (0.02 = 2 %).
    abs_tol : float
        Absolute velocity tolerance, rad/s; also the slowest |v| counted as motion.
    window_s : float, optional
        Window of the steadiness test, s; default min_duration_s / 5. Each plateau loses about
        half a window at either end (the windows that straddle a transient are not steady), so
        hold each level for at least min_duration_s + window_s.
    settle_s : float
        Time dropped at the start of each plateau (controller settling), s.

    Returns
    -------
    SweepPoints

    Raises
    ------
    InputError
        Lengths differ, NaN/inf, times not increasing, a bad option, or no plateau found.
    """
    tt = _vec("t", t)
    n = tt.size
    if n < 3 or not (np.diff(tt) > 0).all():
        raise InputError(None, "t", "at least 3 strictly increasing times, s", f"{n} samples")
    qq, vv, yy = _vec("q", q, n), _vec("qd", qd, n), _vec("tau", tau, n)
    for name, val in (("min_duration_s", min_duration_s), ("rel_tol", rel_tol)):
        if not (np.isfinite(val) and val > 0):
            raise InputError(None, name, "a positive number", val)
    if not (np.isfinite(abs_tol) and abs_tol >= 0) or not (np.isfinite(settle_s) and settle_s >= 0):
        raise InputError(None, "abs_tol, settle_s", "non-negative numbers", f"{abs_tol}, {settle_s}")
    if window_s is not None and not (np.isfinite(window_s) and window_s > 0):
        raise InputError(None, "window_s", "a positive number of seconds or None", window_s)
    if gravity is not None:
        g = np.asarray(gravity(qq) if callable(gravity) else gravity, dtype=np.float64)
        yy = yy - _vec("gravity", np.broadcast_to(g, (n,)) if g.ndim == 0 else g, n)
    dt = float(np.median(np.diff(tt)))
    w = max(3, int(round((min_duration_s / 5 if window_s is None else window_s) / dt)))
    mean = uniform_filter1d(vv, w, mode="nearest")
    spread = maximum_filter1d(vv, w, mode="nearest") - minimum_filter1d(vv, w, mode="nearest")
    steady = (spread <= 2 * (rel_tol * np.abs(mean) + abs_tol)) & (np.abs(mean) > abs_tol)
    edges = np.diff(np.concatenate([[0], steady.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    out = []
    for a, b in zip(starts, stops):
        idx = np.arange(a, b)
        idx = idx[tt[idx] >= tt[a] + settle_s]
        if idx.size < 2:
            continue
        vm = float(np.median(vv[idx]))
        idx = idx[np.abs(vv[idx] - vm) <= rel_tol * abs(vm) + abs_tol]
        if idx.size < 2 or tt[idx[-1]] - tt[idx[0]] < min_duration_s - 0.5 * dt or abs(vm) <= abs_tol:
            continue
        y = yy[idx]
        out.append((vv[idx].mean(), y.mean(), y.std(ddof=1) / np.sqrt(idx.size), idx.size, tt[idx[0]], tt[idx[-1]]))
    if not out:
        raise InputError(None, "qd", f"constant-velocity plateaus of at least {min_duration_s} s within "
                         f"{100 * rel_tol:g} % + {abs_tol:g} rad/s", "none",
                         hint="lengthen the plateaus, filter the velocity or widen rel_tol/abs_tol")
    cols = list(zip(*out))
    arrs = [np.array(c, dtype=np.float64) for c in cols]
    arrs[3] = arrs[3].astype(np.int64)
    return SweepPoints(*_ro(*arrs))


# --------------------------------------------------------------------------- fits


@dataclass(frozen=True, eq=False)
class FrictionFit:
    """A friction characteristic fitted to plateau points.

    Attributes
    ----------
    model : Stribeck, AsymmetricStribeck or ExtendedStribeck
        The :mod:`mocapfj.dynamics.friction` model with the fitted coefficients.
    params : dict of str to float
        Fitted coefficients, named as in ``model.params`` (fixed ones, e.g. the exponent, left out).
    std : dict of str to float
        Their standard deviations, Jubien, Abba and Gautier (2014), eq. (16): sqrt(diag(sigma^2 (J^T J)^-1)) per side.
    rms : float
        RMS of tau - model(v) over all points, N m (unweighted).
    r2 : float
        1 - rss / sum((tau - mean)^2) over all points.
    n_points : int
        Points fitted.
    """

    model: object
    params: dict
    std: dict
    rms: float
    r2: float
    n_points: int

    def predict(self, v) -> np.ndarray:
        """Friction torque, N m, at velocities `v`, rad/s."""
        return self.model.torque(v)  # type: ignore[attr-defined]


def _points(v, tau, weights):
    if isinstance(v, SweepPoints):
        if tau is None:
            v, tau = v.v, v.tau
        else:
            v = v.v
    vv = _vec("v", v)
    yy = _vec("tau", tau, vv.size)
    if (vv == 0).any():
        raise InputError(None, "v", "non-zero plateau velocities, rad/s", f"{int((vv == 0).sum())} zeros",
                         hint="the friction at rest is undetermined; drop standstill points")
    if weights is None:
        w = np.ones_like(vv)
    else:
        w = _vec("weights", weights, vv.size)
        if (w <= 0).any():
            raise InputError(None, "weights", "positive weights (1 / se^2)", f"min {w.min():g}")
    return vv, yy, w


def _sides(v, asymmetric, p, what):
    """Index arrays of the sides fitted: {"pos": ..., "neg": ...} or {"": all}."""
    pos, neg = np.flatnonzero(v > 0), np.flatnonzero(v < 0)
    if asymmetric:
        if pos.size <= p or neg.size <= p:
            raise InputError(None, "v", f"more than {p} plateaus with v > 0 and more than {p} with v < 0 "
                             f"for an asymmetric {what} fit ({p} parameters per side)",
                             f"{pos.size} positive, {neg.size} negative",
                             hint="sweep both directions, or fit asymmetric=False")
        return {"pos": pos, "neg": neg}
    if v.size <= p:
        raise InputError(None, "v", f"more than {p} plateaus for a {what} fit ({p} parameters)", v.size)
    return {"": np.arange(v.size)}


def _refine(resid, jac, x0, lb, ub, names, field, expected, hint):
    """least_squares from x0, then (x, std) with std from sigma^2 (J^T J)^-1 (Jubien, Abba and Gautier (2014), eq. 16).

    Raises InputError(field, expected) when J at the solution has a zero column or columns that
    are dependent (condition number of the column-normalised J above 1e10).
    """
    x0 = np.clip(x0, lb, ub)
    r = least_squares(resid, x0, jac=jac, bounds=(lb, ub), x_scale="jac", method="trf",
                      xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=400)
    res = resid(r.x)
    J = jac(r.x)
    dof = res.size - x0.size
    sigma2 = float(res @ res) / dof
    try:
        cov = sigma2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((x0.size, x0.size), np.nan)
    std = np.sqrt(np.abs(np.diag(cov)))
    norm = np.linalg.norm(J, axis=0)
    if not np.isfinite(std).all() or not norm.all() or np.linalg.cond(J / norm) > 1e10:
        raise InputError(None, field, expected, f"no independent excitation of {list(names)} at the solution",
                         hint=hint)
    return r.x, std


def _grid_lstsq(M, y, sw):
    """Weighted linear LS coefficients (grid, p) for a stack of design matrices M (grid, P, p)."""
    return (np.linalg.pinv(M * sw[None, :, None]) @ (y * sw))


_EXCITE = "add plateaus below and above the Stribeck velocity"


def _stribeck_side(a, y, sw, exponent):
    """(fc, fs, vs, fv) and std for y = fc + (fs - fc) exp(-(a/vs)^e) + fv a, a = |v| > 0."""

    def basis(vs):
        E = np.exp(-(a / vs) ** exponent)
        return np.column_stack([1 - E, E, a]), E

    vss = np.geomspace(a.min() / 3, a.max(), 60)
    E = np.exp(-(a[None, :] / vss[:, None]) ** exponent)
    M = np.stack([1 - E, E, np.broadcast_to(a, E.shape)], axis=-1)  # (grid, P, 3)
    c = _grid_lstsq(M, y, sw)
    k = int(np.argmin(np.sum(((M @ c[..., None])[..., 0] - y) ** 2 * sw ** 2, axis=1)))
    x0 = np.array([c[k, 0], c[k, 1], vss[k], c[k, 2]])

    def resid(x):
        B, _ = basis(x[2])
        return (B @ x[[0, 1, 3]] - y) * sw

    def jac(x):
        fc, fs, vs, fv = x
        B, E = basis(vs)
        dvs = (fs - fc) * E * exponent * (a / vs) ** exponent / vs
        return np.column_stack([B[:, 0], B[:, 1], dvs, B[:, 2]]) * sw[:, None]

    lb = np.array([-np.inf, -np.inf, 1e-6 * a.min(), -np.inf])
    ub = np.array([np.inf, np.inf, 1e3 * a.max(), np.inf])
    return _refine(resid, jac, x0, lb, ub, ("fc", "fs", "vs", "fv"), "v",
                   "plateau velocities that excite every Stribeck coefficient", _EXCITE)


def _finish(model, params, std, v, y):
    r = y - model.torque(v)
    rss = float(r @ r)
    dev = y - y.mean()
    return FrictionFit(model=model, params=params, std=std, rms=float(np.sqrt(rss / y.size)),
                       r2=1.0 - rss / float(dev @ dev) if dev.any() else float("nan"), n_points=int(y.size))


def fit_stribeck(v, tau=None, *, asymmetric: bool = True, weights=None, exponent: float = 2.0) -> FrictionFit:
    """Fit the Stribeck model of Oueslati et al. (2012), eq. (7) to plateau points, each side on its own.

        F = (fc + (fs - fc) exp(-|q'/vs|^exponent)) sign(q') + fv q'

    Parameters
    ----------
    v : (P,) float or SweepPoints
        Plateau velocities, rad/s, none zero (a SweepPoints supplies `v` and, if `tau` is None, `tau`).
    tau : (P,) float
        Friction torques, N m.
    asymmetric : bool
        True: coefficients fc_pos, fs_pos, vs_pos, fv_pos from v > 0 and fc_neg ... from v < 0
        (magnitudes positive on both sides, Oueslati et al. (2012), Table I) -> AsymmetricStribeck. False: one
        set from all points -> Stribeck.
    weights : (P,) float, optional
        1 / se^2 per point (e.g. ``1 / points.se**2``); None: equal weights.
    exponent : float
        Fixed Stribeck exponent (2 in Oueslati et al. (2012)).

    Returns
    -------
    FrictionFit

    Raises
    ------
    InputError
        Mismatched lengths, NaN, a zero velocity, at most 4 points on a fitted side (or none on one
        side of an asymmetric fit), or velocities that cannot separate the coefficients.
    """
    vv, yy, w = _points(v, tau, weights)
    if not (np.isfinite(exponent) and exponent > 0):
        raise InputError(None, "exponent", "a positive number", exponent)
    params, std = {}, {}
    for side, idx in _sides(vv, asymmetric, 4, "Stribeck").items():
        s = np.sign(vv[idx])
        x, sd = _stribeck_side(np.abs(vv[idx]), s * yy[idx], np.sqrt(w[idx]), exponent)
        suffix = f"_{side}" if side else ""
        for name, val, e in zip(("fc", "fs", "vs", "fv"), x, sd):
            params[name + suffix], std[name + suffix] = float(val), float(e)
    cls = AsymmetricStribeck if asymmetric else Stribeck
    return _finish(cls(**params, exponent=exponent), params, std, vv, yy)


def _extended_side(a, y, sw):
    """(f1..f6) and std for y = f1 a + f2 - f3 exp(-a/f4) - f5 exp(-1/(f6 a)), a = |v| > 0."""

    def parts(f4, f6):
        A = np.exp(-a / f4)
        Bx = np.exp(-1.0 / (f6 * a)) if f6 > 0 else np.zeros_like(a)
        return A, Bx

    f4s = np.geomspace(a.min() / 2, a.max(), 30)
    f6s = np.geomspace(0.1 / a.max(), 10 / a.min(), 30)
    g4, g6 = (g.ravel() for g in np.meshgrid(f4s, f6s, indexing="ij"))
    A = np.exp(-a[None, :] / g4[:, None])
    Bx = np.exp(-1.0 / (g6[:, None] * a[None, :]))
    M = np.stack([np.broadcast_to(a, A.shape), np.ones_like(A), -A, -Bx], axis=-1)  # (grid, P, 4)
    c = _grid_lstsq(M, y, sw)
    k = int(np.argmin(np.sum(((M @ c[..., None])[..., 0] - y) ** 2 * sw ** 2, axis=1)))
    x0 = np.array([c[k, 0], c[k, 1], c[k, 2], g4[k], c[k, 3], g6[k]])

    def resid(x):
        A, Bx = parts(x[3], x[5])
        return (x[0] * a + x[1] - x[2] * A - x[4] * Bx - y) * sw

    def jac(x):
        f1, f2, f3, f4, f5, f6 = x
        A, Bx = parts(f4, f6)
        d6 = -f5 * Bx / (f6 ** 2 * a) if f6 > 0 else np.zeros_like(a)
        return np.column_stack([a, np.ones_like(a), -A, -f3 * A * a / f4 ** 2, -Bx, d6]) * sw[:, None]

    lb = np.array([-np.inf, -np.inf, -np.inf, 1e-6 * a.min(), -np.inf, 1e-6 / a.max()])
    ub = np.array([np.inf, np.inf, np.inf, 1e3 * a.max(), np.inf, 1e3 / a.min()])
    return _refine(resid, jac, x0, lb, ub, tuple(f"f{i}" for i in range(1, 7)), "v",
                   "plateau velocities that excite every eq. (18) coefficient", _EXCITE)


def fit_extended_stribeck(v, tau=None, *, asymmetric: bool = True, weights=None) -> FrictionFit:
    """Fit the six-coefficient model of Bompos et al. (2007), eq. (18) to plateau points, per side of q' = 0.

        F = f1 q' + f2 sign(q') - f3 sign(q') exp(-|q'| / f4) - f5 sign(q') exp(-1 / (f6 |q'|))

    Parameters
    ----------
    v : (P,) float or SweepPoints
        Plateau velocities, rad/s, none zero.
    tau : (P,) float
        Friction torques, N m.
    asymmetric : bool
        True: f1..f6 from v > 0 and f1_neg..f6_neg from v < 0 (Bompos et al. (2007), Table II); False: one set.
    weights : (P,) float, optional
        1 / se^2 per point; None: equal weights.

    Returns
    -------
    FrictionFit
        ``model`` is an ExtendedStribeck (f1 N m s/rad, f2, f3, f5 N m, f4 rad/s, f6 s/rad).

    Raises
    ------
    InputError
        As :func:`fit_stribeck`, with more than 6 points needed per fitted side. The two
        exponential terms need plateaus spanning both f4 and 1/f6: Bompos et al. (2007) swept from 0.001 rad/s
        to 60 % of the maximum velocity.
    """
    vv, yy, w = _points(v, tau, weights)
    params, std, sets = {}, {}, {}
    for side, idx in _sides(vv, asymmetric, 6, "eq. (18)").items():
        s = np.sign(vv[idx])
        x, sd = _extended_side(np.abs(vv[idx]), s * yy[idx], np.sqrt(w[idx]))
        sets[side] = tuple(float(c) for c in x)
        suffix = "_neg" if side == "neg" else ""
        for i, (val, e) in enumerate(zip(x, sd), 1):
            params[f"f{i}{suffix}"], std[f"f{i}{suffix}"] = float(val), float(e)
    model = ExtendedStribeck(f=sets["pos"], f_neg=sets["neg"]) if asymmetric else ExtendedStribeck(f=sets[""])
    return _finish(model, params, std, vv, yy)


# --------------------------------------------------------------------------- pre-sliding


@dataclass(frozen=True, eq=False)
class PreslidingFit:
    """Dahl pre-sliding curve fitted to torque against displacement from the start of motion.

    Attributes
    ----------
    fs : float
        Level the torque saturates at (static / breakaway friction), N m, positive.
    sigma0 : float
        Pre-sliding (rest) stiffness, N m / rad: the initial slope of torque against displacement.
    std : dict of str to float
        Standard deviations of "fs" and "sigma0" (Jubien, Abba and Gautier (2014), eq. 16).
    direction : int
        +1 or -1, the sign of the motion; the curve is ``direction * fs (1 - exp(-sigma0 |x| / fs))``.
    rms, r2 : float
        Residual RMS, N m, and coefficient of determination.
    model : Dahl
        ``Dahl(sigma=sigma0, fc=fs)``, whose ``run`` reproduces the curve for monotone motion.
    """

    fs: float
    sigma0: float
    std: dict
    direction: int
    rms: float
    r2: float
    model: Dahl

    def predict(self, x) -> np.ndarray:
        """Torque, N m, at displacements `x`, rad, from the start of motion (same sign as the fit)."""
        x = np.asarray(x, dtype=np.float64)
        return self.direction * self.fs * (1 - np.exp(-self.sigma0 * np.abs(x) / self.fs))


def fit_presliding(x, tau) -> PreslidingFit:
    """Fit ``tau = Fs (1 - exp(-sigma0 x / Fs))`` to a start-of-motion experiment.

    This is the Dahl element (exponent 1, :class:`mocapfj.dynamics.Dahl`) solved for monotone
    motion from rest: ``dF/dx = sigma0 (1 - F / Fs)`` with F(0) = 0. The experiment of Oueslati et al. (2012)
    sec. III-B-2 drives the joint at a very low constant velocity (5.931e-5 rad/s) so the torque
    is friction only; there Fs came out about 150 N m (148.54 N m from the Stribeck fit).

    Parameters
    ----------
    x : (T,) float
        Link displacement from the start of motion, rad (monotone; either sign).
    tau : (T,) float
        Friction torque, N m, with the torque at rest (and gravity) already subtracted.

    Returns
    -------
    PreslidingFit

    Raises
    ------
    InputError
        Lengths differ, NaN, fewer than 4 samples, no motion, or a torque not of the motion's sign.
    """
    xx = _vec("x", x)
    yy = _vec("tau", tau, xx.size)
    if xx.size < 4:
        raise InputError(None, "x", "at least 4 samples", xx.size)
    end = float(np.median(xx[-max(1, xx.size // 10):]))
    if end == 0:
        raise InputError(None, "x", "a displacement away from 0 (rad)", "no motion")
    d = 1 if end > 0 else -1
    a, y = d * xx, d * yy
    if np.mean(y[-max(1, y.size // 10):]) <= 0:
        raise InputError(None, "tau", "a friction torque of the sign of the motion", "the opposite sign",
                         hint="pass F of the link equation: positive for motion towards positive x")
    amax = float(np.max(a))
    best = None
    for x0 in np.geomspace(amax / 1e4, amax, 80):
        b = 1 - np.exp(-a / x0)
        fs = float(b @ y / (b @ b))
        rss = float(np.sum((fs * b - y) ** 2))
        if best is None or rss < best[0]:
            best = (rss, np.array([fs, fs / x0]))

    def resid(p):
        return p[0] * (1 - np.exp(-p[1] * a / p[0])) - y

    def jac(p):
        fs, s0 = p
        e = np.exp(-s0 * a / fs)
        return np.column_stack([1 - e - s0 * a / fs * e, a * e])

    (fs, s0), sd = _refine(resid, jac, best[1], np.array([1e-12, 1e-12]), np.array([np.inf, np.inf]),
                           ("fs", "sigma0"), "x", "displacements from the start of motion through saturation",
                           "record from rest until the torque levels off, at several displacements")
    r = resid(np.array([fs, s0]))
    dev = y - y.mean()
    rss = float(r @ r)
    return PreslidingFit(fs=float(fs), sigma0=float(s0), std={"fs": float(sd[0]), "sigma0": float(sd[1])},
                         direction=d, rms=float(np.sqrt(rss / y.size)), r2=1.0 - rss / float(dev @ dev),
                         model=Dahl(sigma=float(s0), fc=float(fs)))
