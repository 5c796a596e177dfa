"""IDIM-LS of a one-axis drive: inverse dynamic model, least squares (Gautier 1997; the EMPS
benchmark, Janot, Gautier & Brunot 2019, "Data set and reference models of EMPS", Script_IDIM_LS.m).

The model is linear in the parameters, force = W(q', q'') x, with

    "coulomb_viscous_offset":  force = M q'' + Fv q' + Fc sign(q') + offset
    "asymmetric":              force = M q'' + (Fv+ q' + Fc+) [q' > 0] + (Fv- q' - Fc-) [q' < 0]

The benchmark's conditioning, every step overridable:
1. q is low-passed by a zero-phase Butterworth (order 4, 100 Hz; `conditioning.lowpass`);
2. q', q'' by central differences (`conditioning.derivatives`, = the benchmark's diffcent.m);
3. `border` samples are dropped at both ends (filter end effects);
4. parallel decimation of W and the force by `decimate`: the same zero-phase low-pass on every
   column of W and on y, then one sample in `decimate` (Jubien, Abba and Gautier (2014), §3). The default filter is the
   benchmark's own, MATLAB `decimate` = Chebyshev I of order 8, 0.05 dB ripple, cut-off 0.8 x the
   new Nyquist rate, forward-backward (scipy.signal.decimate with zero_phase=True);
   ``decimation_filter="butterworth"`` uses `conditioning.decimate_parallel` instead;
5. ordinary LS with Jubien, Abba and Gautier (2014), eq. 15-17 statistics (`ls.ls_fit`).

Units are SI: q in m (prismatic) or rad, force in N (or N m), t in s. Signs: docs/conventions.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from os import PathLike

import numpy as np
from scipy import signal

from ..errors import InputError
from ..types import LSResult
from .conditioning import decimate_parallel, derivatives, lowpass
from .ls import ls_fit

__all__ = ["IDIM_MODELS", "idim_regressor", "idim_observation", "idim_ls", "idim_cross_validation", "load_emps_mat"]

IDIM_MODELS: dict[str, tuple[str, ...]] = {
    "coulomb_viscous_offset": ("M", "Fv", "Fc", "offset"),
    "asymmetric": ("M", "Fv+", "Fc+", "Fv-", "Fc-"),
}


def idim_regressor(qd: np.ndarray, qdd: np.ndarray, model: str = "coulomb_viscous_offset") -> tuple[np.ndarray, tuple[str, ...]]:
    """Rows of the inverse dynamic model, force = W x (module docstring for the two models).

    qd, qdd : (T,) float, velocity and acceleration (m/s, m/s^2 or rad/s, rad/s^2).
    Returns W (T, p) and the p parameter names, IDIM_MODELS[model].
    """
    if model not in IDIM_MODELS:
        raise InputError(None, "model", f"one of {sorted(IDIM_MODELS)}", model)
    s = np.sign(qd)
    if model == "coulomb_viscous_offset":
        W = np.column_stack([qdd, qd, s, np.ones_like(qd)])
    else:
        pos, neg = (qd > 0).astype(float), (qd < 0).astype(float)
        W = np.column_stack([qdd, qd * pos, pos, qd * neg, -neg])
    return W, IDIM_MODELS[model]


def _rate(t: np.ndarray | None, n: int, fs_hz: float | None) -> float:
    if fs_hz is not None:
        if not (np.isfinite(fs_hz) and fs_hz > 0):
            raise InputError(None, "fs_hz", "a positive sampling rate in Hz", fs_hz)
        return float(fs_hz)
    if t is None:
        raise InputError(None, "t, fs_hz", "the sample times t (T,) or the rate fs_hz", None)
    t = np.asarray(t, dtype=np.float64).ravel()
    if t.shape != (n,) or not np.isfinite(t).all():
        raise InputError(None, "t", f"({n},) finite sample times", t.shape)
    dt = np.diff(t)
    step = float(np.median(dt))
    if step <= 0 or np.abs(dt - step).max() > 0.01 * step:
        raise InputError(None, "t", "uniform sampling (every step within 1 % of the median)",
                         f"steps from {dt.min():g} to {dt.max():g} s", hint="resample (conditioning.resample_to) first")
    return 1.0 / step


def idim_observation(t: np.ndarray | None, q: np.ndarray, force: np.ndarray, model: str = "coulomb_viscous_offset", *,
                     fs_hz: float | None = None, cutoff_hz: float = 100.0, filter_order: int = 4, decimate: int = 10,
                     border: int = 50, decimation_filter: str = "cheby1") -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """The conditioned, decimated observation matrix and force of IDIM-LS (steps 1-4 above).

    Parameters
    ----------
    t : (T,) float, s, or None when fs_hz is given. Must be uniform (1 % tolerance).
    q : (T,) float, measured position (m or rad), without NaN.
    force : (T,) float, actuator force (N or N m), without NaN.
    model : key of IDIM_MODELS.
    fs_hz : sampling rate; inferred from t when None.
    cutoff_hz, filter_order : Butterworth on q (per pass; the forward-backward gain is squared).
    decimate : whole factor >= 1; border : samples dropped at each end before decimating.
    decimation_filter : "cheby1" (the benchmark's, MATLAB decimate) or "butterworth".

    Returns
    -------
    W : (r, p) float, y : (r,) float, names : p str, with r = ceil((T - 2 border) / decimate).
    """
    q = np.asarray(q, dtype=np.float64)
    force = np.asarray(force, dtype=np.float64)
    if q.ndim != 1 or force.shape != q.shape:
        raise InputError(None, "q, force", "two (T,) arrays of the same length", f"{q.shape}, {force.shape}")
    if not np.isfinite(force).all():
        raise InputError(None, "force", "finite samples", f"{int((~np.isfinite(force)).sum())} non-finite samples")
    if int(border) != border or border < 0:
        raise InputError(None, "border", "a whole number of samples >= 0", border)
    if int(decimate) != decimate or decimate < 1:
        raise InputError(None, "decimate", "a positive whole decimation factor", decimate)
    border, decimate = int(border), int(decimate)
    if decimation_filter not in ("cheby1", "butterworth"):
        raise InputError(None, "decimation_filter", "'cheby1' or 'butterworth'", decimation_filter)
    fs = _rate(t, q.shape[0], fs_hz)
    keep = q.shape[0] - 2 * border
    if keep < 30 * decimate:
        raise InputError(None, "q", f"more than 2 x border + 30 x decimate = {2 * border + 30 * decimate} samples",
                         q.shape[0], hint="record longer, or lower border or decimate")
    qd, qdd = derivatives(lowpass(q, fs, cutoff_hz, filter_order), fs)
    W, names = idim_regressor(qd, qdd, model)
    sl = slice(border, q.shape[0] - border)
    W, y = W[sl], force[sl]
    if decimate == 1:
        return W, y, names
    if decimation_filter == "butterworth":
        Wd, yd = decimate_parallel(W, y, decimate, fs_hz=fs)
        return Wd, yd, names
    Xd = signal.decimate(np.column_stack([W, y]), decimate, axis=0, zero_phase=True)  # one filter for all columns
    return Xd[:, :-1], Xd[:, -1], names


def idim_ls(t: np.ndarray | None, q: np.ndarray, force: np.ndarray, model: str = "coulomb_viscous_offset",
            **conditioning) -> LSResult:
    """IDIM-LS estimate of the drive's parameters with Jubien, Abba and Gautier (2014), eq. 15-17 statistics.

    Same arguments as `idim_observation` (keyword-only conditioning options: fs_hz, cutoff_hz,
    filter_order, decimate, border, decimation_filter). On EMPS (DATA_EMPS.mat, force = gtau vir)
    this reproduces the published M = 95.11 kg, Fv = 203.5 N s/m, Fc = 20.39 N, offset = -3.16 N,
    relative error 4.1 %, cond 26.0.
    """
    W, y, names = idim_observation(t, q, force, model, **conditioning)
    return ls_fit(W, y, names)


def idim_cross_validation(result: LSResult, t: np.ndarray | None, q: np.ndarray, force: np.ndarray,
                          **conditioning) -> tuple[float, np.ndarray, np.ndarray]:
    """Direct cross-validation (the benchmark's Script_IDIM_LS_CVT): predict the force of another
    record with the estimated parameters under the same conditioning.

    The model is taken from result.names. Returns (100 ||y - W x|| / ||y|| in %, y_pred (r,), y (r,)).
    """
    model = next((k for k, v in IDIM_MODELS.items() if tuple(result.names) == v), None)
    if model is None:
        raise InputError(None, "result.names", f"the names of one of {sorted(IDIM_MODELS)}", result.names)
    W, y, _ = idim_observation(t, q, force, model, **conditioning)
    y_pred = W @ np.asarray(result.values)
    return float(100.0 * np.linalg.norm(y - y_pred) / np.linalg.norm(y)), y_pred, y


def load_emps_mat(path: str | PathLike[str], fields: Sequence[str] = ("t", "qm", "vir", "gtau")) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read an EMPS benchmark .mat file: (t (T,) s, qm (T,) m, force (T,) N = gtau * vir)."""
    from scipy.io import loadmat

    try:
        d = loadmat(path)
    except (OSError, ValueError) as e:
        raise InputError(path, "file", "a MATLAB .mat file of the EMPS benchmark", str(e)) from None
    missing = [f for f in fields if f not in d]
    if missing:
        raise InputError(path, ",".join(missing), f"variables {list(fields)}", sorted(k for k in d if not k.startswith("__")))
    t, qm, vir = (np.asarray(d[k], dtype=np.float64).ravel() for k in fields[:3])
    gtau = np.asarray(d[fields[3]], dtype=np.float64).ravel()
    if gtau.size != 1 or not (t.shape == qm.shape == vir.shape):
        raise InputError(path, "t, qm, vir, gtau", "three (T,) vectors and a scalar gain",
                         f"{t.shape}, {qm.shape}, {vir.shape}, {gtau.shape}")
    return t, qm, gtau[0] * vir
