"""Least squares with the statistics identification reports (seed 003 eq. 14-17).

For y = W x + rho: x_hat = argmin ||y - W x||^2 (or with weights), sigma_rho^2 = ||y - W x_hat||^2
/ (r - p) (eq. 15), C = sigma_rho^2 (W^T W)^-1 (eq. 16), %sigma_i = 100 sigma_i / |x_i| (eq. 17).
A rank-deficient W is not solved silently: the parameters it cannot separate are named.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.linalg import qr

from ..errors import InputError
from ..types import LSResult

__all__ = ["ls_fit", "unidentifiable_columns", "cv_pct"]


def unidentifiable_columns(W: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """Indices of columns of W that QR with column pivoting finds dependent on the others."""
    scale = np.linalg.norm(W, axis=0)
    zero = scale == 0
    Ws = W / np.where(zero, 1.0, scale)
    _, R, P = qr(Ws, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int((d > rtol * max(W.shape) * (d[0] if d.size else 0.0)).sum())
    return np.sort(np.union1d(P[rank:], np.flatnonzero(zero)))


def ls_fit(W: np.ndarray, y: np.ndarray, names: Sequence[str], weights: np.ndarray | None = None) -> LSResult:
    """Ordinary (or weighted) least squares of y (r,) on W (r, p) with seed 003's statistics.

    Parameters
    ----------
    W : (r, p) float
        Observation matrix; rows with a NaN in W or y are left out (and counted out of r).
    y : (r,) float
    names : p str
    weights : (r,) float, optional
        1 / sigma_k^2 per row (weighted LS); the statistics are those of the weighted problem.

    Raises
    ------
    InputError
        Shapes disagree, fewer rows than parameters, or a parameter is not excited (its column
        is zero or dependent on others: the message names them).
    """
    W = np.asarray(W, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64).ravel()
    names = tuple(names)
    if W.ndim != 2 or W.shape[0] != y.shape[0] or W.shape[1] != len(names):
        raise InputError(None, "W, y, names", "W (r, p), y (r,) and p names", f"{W.shape}, {y.shape}, {len(names)} names")
    ok = np.isfinite(y) & np.isfinite(W).all(axis=1)
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64).ravel()
        ok &= np.isfinite(weights) & (weights > 0)
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
    x, *_ = np.linalg.lstsq(W, y, rcond=None)
    res = y - W @ x
    rss = float(res @ res)
    sigma2 = rss / (r - p)
    cov = sigma2 * np.linalg.inv(W.T @ W)
    std = np.sqrt(np.diag(cov))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(x != 0, 100.0 * std / np.abs(x), np.nan)
    yy = float(y @ y)
    dev = y - y.mean()
    return LSResult(names=names, values=x, std=std, rel_std_pct=rel, cov=cov, cond=float(np.linalg.cond(W)),
                    residual_rms=float(np.sqrt(rss / r)), rel_error_pct=100.0 * np.sqrt(rss / yy) if yy > 0 else np.nan,
                    r2=1.0 - rss / float(dev @ dev) if dev.any() else np.nan, n_samples=r)


def cv_pct(results: Sequence[LSResult]) -> np.ndarray:
    """Coefficient of variation across repeated trials, 100 SD / |mean| per parameter (seed 000 Table I)."""
    v = np.array([r.values for r in results])
    if v.shape[0] < 2:
        raise InputError(None, "results", "at least 2 repeated trials", v.shape[0])
    mean = v.mean(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(mean != 0, 100.0 * v.std(axis=0, ddof=1) / np.abs(mean), np.nan)
