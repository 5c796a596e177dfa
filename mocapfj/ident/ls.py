"""Least squares with the statistics identification reports (Jubien, Abba and Gautier 2014,
eq. 14-17), and a covariance that holds when the residuals are correlated.

For y = W x + rho: x_hat = argmin ||y - W x||^2 (or with weights), sigma_rho^2 = ||y - W x_hat||^2
/ (r - p) (eq. 15), C = sigma_rho^2 (W^T W)^-1 (eq. 16), %sigma_i = 100 sigma_i / |x_i| (eq. 17).
Eq. 16 assumes independent residuals. After low-pass filtering and decimation they are not, and
it understates the SD by the square root of the residual's correlation time in samples; with
``cov="hac"`` the covariance is the heteroscedasticity- and autocorrelation-consistent sandwich
of Newey and West (1987), (W^T W)^-1 S (W^T W)^-1 with S the Bartlett-weighted sum of the
score's autocovariances up to a lag chosen from the residual's own autocorrelation.

A rank-deficient W is not solved silently: the parameters it cannot separate are named, and so
are columns that are zero to rounding (a column of norm 1e-16 next to columns of norm 1 is no
excitation, whatever its direction). A condition number beyond what float64 resolves (of the
column-scaled matrix, `MAX_SCALED_COND`) is refused.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.linalg import qr

from ..errors import InputError
from ..types import LSResult

__all__ = ["ls_fit", "unidentifiable_columns", "cv_pct", "hac_lags", "sandwich_cov", "ZERO_COLUMN_RTOL",
           "MAX_SCALED_COND"]

ZERO_COLUMN_RTOL = 1e-10
"""A column whose norm is below this fraction of the largest column norm is zero (rounding: a URDF
joint origin rotated by rpy = pi/2 leaves entries of 6e-17 where the exact regressor has 0)."""

MAX_SCALED_COND = 1e10
"""Condition number (after scaling every column to unit norm) beyond which a fit is refused: the
solution would keep fewer than 6 of float64's 16 significant digits, and its SD would be noise."""


def unidentifiable_columns(W: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """Indices of columns of W that are zero to rounding (`ZERO_COLUMN_RTOL` of the largest) or that
    QR with column pivoting finds dependent on the others (|R_ii| below rtol x max(r, p) x |R_00|
    after scaling the columns to unit norm)."""
    scale = np.linalg.norm(W, axis=0)
    zero = scale <= ZERO_COLUMN_RTOL * (scale.max() if scale.size else 0.0)
    Ws = W[:, ~zero] / scale[~zero]
    dep = np.empty(0, dtype=int)
    if Ws.shape[1]:
        _, R, P = qr(Ws, mode="economic", pivoting=True)
        d = np.abs(np.diag(R))
        rank = int((d > rtol * max(W.shape) * (d[0] if d.size else 0.0)).sum())
        dep = np.flatnonzero(~zero)[P[rank:]]
    return np.sort(np.union1d(dep, np.flatnonzero(zero))).astype(int)


def hac_lags(r: np.ndarray, max_share: float = 0.25) -> int:
    """Bandwidth (in samples) of the Newey-West sum for a residual r (n,): twice the lag at which its
    autocorrelation first drops below 0.1, at least the textbook 4 (n/100)^(2/9), at most
    `max_share` x n."""
    r = np.asarray(r, dtype=np.float64)
    n = r.size
    x = r - r.mean()
    f = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[:n]
    if ac[0] <= 0:
        return 0
    ac = ac / ac[0]
    below = np.flatnonzero(ac < 0.1)
    first = int(below[0]) if below.size else n
    rule = int(np.ceil(4 * (n / 100.0) ** (2.0 / 9.0)))
    return int(min(max(2 * first, rule), max_share * n))


def _hac_meat(G: np.ndarray, lags: int) -> np.ndarray:
    """S = sum over |l| <= lags of (1 - |l| / (lags + 1)) sum_t g_t g_{t-l}^T, for scores G (n, p)."""
    S = G.T @ G
    for lag in range(1, lags + 1):
        w = 1.0 - lag / (lags + 1.0)
        C = G[lag:].T @ G[:-lag]
        S += w * (C + C.T)
    return S


def sandwich_cov(J: np.ndarray, r: np.ndarray, time_index: np.ndarray | None = None,
                 lags: int | None = None) -> np.ndarray:
    """Newey-West covariance (J^T J)^-1 S (J^T J)^-1 of a least-squares solution.

    J (r, p): the Jacobian of the residuals r (r,) at the solution (for linear LS, the
    observation matrix); rows may stack several equations per time sample, `time_index` (r,)
    giving each row's sample (scores are summed per sample before their autocovariances are
    taken). `lags`: the Bartlett bandwidth in samples, default from the summed residual
    (:func:`hac_lags`). With r - p degrees of freedom (the small-sample factor r / (r - p)).
    """
    J = np.asarray(J, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    n, p = J.shape
    G = J * r[:, None]
    if time_index is not None:
        _, inverse = np.unique(np.asarray(time_index), return_inverse=True)
        Gt = np.zeros((inverse.max() + 1, p))
        np.add.at(Gt, inverse, G)
        rt = np.bincount(inverse, weights=r)
        G = Gt
    else:
        rt = r
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    Js = J / scale
    inv_s = np.linalg.inv(Js.T @ Js)
    S = _hac_meat(G / scale, hac_lags(rt) if lags is None else int(lags)) * n / max(n - p, 1)
    return (inv_s @ S @ inv_s) / np.outer(scale, scale)


def ls_fit(W: np.ndarray, y: np.ndarray, names: Sequence[str], weights: np.ndarray | None = None, *,
           cov: str = "classic", time_index: np.ndarray | None = None) -> LSResult:
    """Ordinary (or weighted) least squares of y (r,) on W (r, p) with its statistics.

    Parameters
    ----------
    W : (r, p) float
        Observation matrix; rows with a NaN in W or y are left out (and counted out of r).
    y : (r,) float
    names : p str
    weights : (r,) float, optional
        1 / sigma_k^2 per row (weighted LS); the statistics are those of the weighted problem.
    cov : "classic" or "hac"
        Eq. 16 (independent residuals), or the Newey-West covariance (module docstring).
    time_index : (r,) int, optional
        For "hac" on stacked equations (several rows per time sample, e.g. one per joint): the
        sample each row belongs to, in time order; the score is summed over the rows of a sample
        before the autocovariances are taken. Default: one row per sample, rows in time order.

    Raises
    ------
    InputError
        Shapes disagree, fewer rows than parameters, a parameter is not excited (its column is
        zero, or zero to rounding, or dependent on others: the message names them), or the
        column-scaled condition number exceeds `MAX_SCALED_COND`.
    """
    W = np.asarray(W, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64).ravel()
    names = tuple(names)
    if W.ndim != 2 or W.shape[0] != y.shape[0] or W.shape[1] != len(names):
        raise InputError(None, "W, y, names", "W (r, p), y (r,) and p names", f"{W.shape}, {y.shape}, {len(names)} names")
    if cov not in ("classic", "hac"):
        raise InputError(None, "cov", '"classic" or "hac"', repr(cov))
    ok = np.isfinite(y) & np.isfinite(W).all(axis=1)
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64).ravel()
        ok &= np.isfinite(weights) & (weights > 0)
    if time_index is not None:
        time_index = np.asarray(time_index).ravel()
        if time_index.shape != y.shape:
            raise InputError(None, "time_index", f"one sample index per row ({y.size})", time_index.shape)
        time_index = time_index[ok]
    W, y = W[ok], y[ok]
    r, p = W.shape
    if r <= p:
        raise InputError(None, "W", f"more rows ({r}) than parameters ({p})", r,
                         hint="record longer or decimate less")
    if weights is not None:
        s = np.sqrt(weights[ok])
        W, y = W * s[:, None], y * s
    bad = unidentifiable_columns(W)
    if bad.size:
        raise InputError(None, "excitation", "a trajectory that excites every parameter",
                         f"no independent excitation of {[names[i] for i in bad]}",
                         hint="change the trajectory or remove/merge these parameters")
    scale = np.linalg.norm(W, axis=0)
    Ws = W / scale
    cond_scaled = float(np.linalg.cond(Ws))
    if not cond_scaled < MAX_SCALED_COND:
        raise InputError(None, "excitation", f"a condition number below {MAX_SCALED_COND:.0e} (columns scaled)",
                         f"{cond_scaled:.3g}", hint="the parameters are nearly dependent: change the trajectory "
                         "or merge parameters")
    xs, *_ = np.linalg.lstsq(Ws, y, rcond=None)
    x = xs / scale
    res = y - W @ x
    rss = float(res @ res)
    sigma2 = rss / (r - p)
    if cov == "classic":
        C = sigma2 * np.linalg.inv(Ws.T @ Ws) / np.outer(scale, scale)
    else:
        C = sandwich_cov(W, res, time_index)
    std = np.sqrt(np.diag(C))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(x != 0, 100.0 * std / np.abs(x), np.nan)
    yy = float(y @ y)
    dev = y - y.mean()
    return LSResult(names=names, values=x, std=std, rel_std_pct=rel, cov=C, cond=float(np.linalg.cond(W)),
                    residual_rms=float(np.sqrt(rss / r)), rel_error_pct=100.0 * np.sqrt(rss / yy) if yy > 0 else np.nan,
                    r2=1.0 - rss / float(dev @ dev) if dev.any() else np.nan, n_samples=r)


def cv_pct(results: Sequence[LSResult]) -> np.ndarray:
    """Coefficient of variation across repeated trials, 100 SD / |mean| per parameter (Lightcap and
    Banks 2007, Table I)."""
    v = np.array([r.values for r in results])
    if v.shape[0] < 2:
        raise InputError(None, "results", "at least 2 repeated trials", v.shape[0])
    mean = v.mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(mean != 0, 100.0 * v.std(axis=0, ddof=1) / np.abs(mean), np.nan)
