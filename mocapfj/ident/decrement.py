"""The logarithmic decrement of a free vibration (Oueslati, Bearee, Gibaru and Moraru 2012, eq. 8),
the second estimate beside the algebraic estimator (:mod:`.algebraic`).

**Logarithmic decrement** (their eq. 8): the half-cycle swings D_i = |e_i - e_(i+1)| between
successive extrema decay as exp(-delta / 2) per half period (independent of the equilibrium);
delta and the damped period come from straight lines through log D_i and the extremum times,
zeta = delta / sqrt(4 pi^2 + delta^2) and omega0 = 2 pi / (T_d sqrt(1 - zeta^2)). Oueslati et al.
(2012) used zeta = delta / (2 pi) (0.1626 from their D1 = 99.55 %, D2 = 35.84 %; the exact form
gives 0.1605).
Extrema are searched on a Savitzky-Golay smoothing (Savitzky and Golay 1964) over a sixth of the
period found in the spectrum, and refined by a quadratic fitted to the raw samples around each.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from .algebraic import SecondOrderEstimate, check_segment, fit_percentage, refit_second_order

__all__ = ["log_decrement", "zeta_from_decrement"]


def zeta_from_decrement(delta: float, *, exact: bool = True) -> float:
    """Damping ratio from the logarithmic decrement delta = ln(x_i / x_(i+1)) over one period:
    delta / sqrt(4 pi^2 + delta^2), or delta / (2 pi) with ``exact=False`` (Oueslati et al. 2012, eq. 8)."""
    return delta / math.sqrt(4 * math.pi ** 2 + delta ** 2) if exact else delta / (2 * math.pi)


def _candidates(t, y):
    """Extremum candidates of a decaying oscillation: (indices, half-width of the local fits, noise
    SD). The period from the spectrum's peak; a Savitzky-Golay smoothing over a sixth of it; the
    sign changes of its slope, merged until maxima and minima alternate at least a quarter period
    apart (noise wiggles near an extremum are not extrema)."""
    from scipy.signal import savgol_filter

    h = float(t[1] - t[0])
    n = y.size
    spec = np.abs(np.fft.rfft((y - y.mean()) * np.hanning(n), 8 * n))
    f = np.fft.rfftfreq(8 * n, h)
    f_peak = f[1 + int(np.argmax(spec[1:]))]
    period = 1.0 / f_peak
    half = int(np.clip(round(period / h / 12), 1, 50))
    sm = savgol_filter(y, 2 * half + 1, 2) if 2 * half + 1 <= n else y
    if 2 * half + 1 <= n:
        h0 = savgol_filter(np.eye(2 * half + 1)[half], 2 * half + 1, 2, mode="interp")[half]
        sd = float(np.std(y - sm) / math.sqrt(max(1 - h0, 1e-3)))
    else:
        sd = float(np.std(np.diff(y, 2)) / math.sqrt(6))
    idx = np.flatnonzero((sm[1:-1] - sm[:-2]) * (sm[2:] - sm[1:-1]) < 0) + 1
    kept: list[int] = []
    for i in idx:
        is_max = sm[i] > sm[i - 1]
        if kept:
            j = kept[-1]
            same = (sm[j] > sm[j - 1]) == is_max
            close = (t[i] - t[j]) < 0.25 * period
            if same or close:
                if same and ((sm[i] > sm[j]) == is_max):
                    kept[-1] = i            # the more extreme of two of a kind
                elif close and not same:
                    kept.pop()              # a wiggle: drop both
                continue
        kept.append(int(i))
    return np.array(kept, dtype=int), half, sd


def _extrema(t, y, idx, half: int):
    """Times, values, and the SD factors of the values and times (times the noise SD), of the
    extrema at candidate indices idx: a quadratic fitted to the 2 half + 1 samples around each."""
    n = y.size
    idx = np.asarray(idx, dtype=int)
    idx = idx[(idx >= half) & (idx < n - half)]
    if idx.size == 0:
        return np.empty(0), np.empty(0), np.empty(0), np.empty(0)
    k = np.arange(-half, half + 1)
    h = t[1] - t[0]
    X = np.column_stack([np.ones_like(k), k, k ** 2]).astype(float)
    Xp = np.linalg.pinv(X)                                  # (3, 2 half + 1)
    seg = y[idx[:, None] + k[None, :]]
    c = seg @ Xp.T                                          # (E, 3)
    with np.errstate(all="ignore"):
        kv = np.clip(-c[:, 1] / (2 * c[:, 2]), -half, half)
    val = c[:, 0] + c[:, 1] * kv + c[:, 2] * kv ** 2
    # SD factor of the fitted value at kv (times the noise SD)
    xv = np.column_stack([np.ones_like(kv), kv, kv ** 2])
    Cc = Xp @ Xp.T
    fac = np.sqrt(np.einsum("ei,ij,ej->e", xv, Cc, xv))
    with np.errstate(all="ignore"):
        g = np.column_stack([np.zeros_like(kv), -1 / (2 * c[:, 2]), c[:, 1] / (2 * c[:, 2] ** 2)])
    tfac = h * np.sqrt(np.einsum("ei,ij,ej->e", g, Cc, g))
    return t[idx] + kv * h, val, fac, tfac


def log_decrement(t, y, *, noise_sd: float | None = None, min_swing: float | None = None) -> SecondOrderEstimate:
    """omega0 and zeta of a free vibration from its extrema (Oueslati et al. 2012, eq. 8).

    Parameters
    ----------
    t : (T,) s, uniformly sampled; y : (T,) rad, a decaying oscillation about a constant
    noise_sd : rad, default the residual RMS of the identified model refitted to the segment
    min_swing : rad, swings between successive extrema smaller than this are left out (default 8
        noise SDs, the noise from the residual of a smoothing over a sixth of the period; at least
        1 % of the largest swing)

    Needs at least 3 extrema (2 swings). SDs: straight-line fits through ln D_i and the extremum
    times, weighted by the propagated noise, inflated by the square root of the reduced chi-square
    when it exceeds 1 (model error: an oscillation that is not a damped sinusoid).
    """
    t, y, _ = check_segment(t, y, None)
    idx, half, sd_sm = _candidates(t, y)
    tx, vx, fac, tfac = _extrema(t, y, idx, half)
    if tx.size < 3:
        raise InputError(None, "y", "a decaying oscillation with at least 3 extrema (about 1.5 periods)",
                         f"{tx.size} extrema", hint="take a longer segment after the stop")
    sd0 = sd_sm if noise_sd is None else float(noise_sd)
    D = np.abs(np.diff(vx))
    floor = max(8 * sd0, 0.01 * D.max()) if min_swing is None else float(min_swing)
    keep = np.flatnonzero(D > floor)
    # keep the first run of consecutive swings above the floor
    if keep.size:
        run = np.split(keep, np.flatnonzero(np.diff(keep) != 1) + 1)[0]
    else:
        run = keep
    if run.size < 2:
        raise InputError(None, "y", "at least 2 successive swings above the noise", f"{run.size}",
                         hint="take a segment starting at the stop")
    i = np.arange(run.size, dtype=float)
    lnD = np.log(D[run])
    te = tx[run[0]:run[-1] + 2]

    def line(x, yv, w):
        X = np.column_stack([np.ones_like(x), x])
        Wt = X * w[:, None]
        C = np.linalg.inv(X.T @ Wt)
        c = C @ (Wt.T @ yv)
        r = yv - X @ c
        dof = x.size - 2
        chi2 = float(r @ (r * w)) / dof if dof > 0 else 1.0
        return c, C * max(chi2, 1.0)

    def fit(sd):
        var_v = (sd * fac) ** 2
        var_ln = (var_v[run] + var_v[run + 1]) / D[run] ** 2
        c_ln, C_ln = line(i, lnD, 1 / var_ln)
        # extremum times: equally spaced by T_d / 2
        j = np.arange(te.size, dtype=float)
        c_t, C_t = line(j, te, 1 / (sd * tfac[run[0]:run[-1] + 2]) ** 2)
        delta = -2 * c_ln[1]
        var_delta = 4 * C_ln[1, 1]
        Td = 2 * c_t[1]
        var_Td = 4 * C_t[1, 1]
        return delta, var_delta, Td, var_Td

    delta, var_delta, Td, var_Td = fit(sd0)
    if not (delta > 0 and Td > 0):
        raise InputError(None, "y", "a decaying oscillation", f"log decrement {delta:.3g}")
    delta, Td = float(delta), float(Td)
    zeta = zeta_from_decrement(delta)
    omega0 = 2 * math.pi / (Td * math.sqrt(1 - zeta ** 2))
    model, rms, lam3 = refit_second_order(t, y, None, omega0, zeta, True)
    if noise_sd is None:
        delta, var_delta, Td, var_Td = fit(rms)
        sd = rms
    else:
        sd = float(noise_sd)
    dz = (4 * math.pi ** 2) / (4 * math.pi ** 2 + delta ** 2) ** 1.5          # d zeta / d delta
    var_z = dz ** 2 * var_delta
    # omega0 = 2 pi / (Td sqrt(1 - zeta^2))
    dw_dT = -omega0 / Td
    dw_dz = omega0 * zeta / (1 - zeta ** 2)
    var_w = dw_dT ** 2 * var_Td + dw_dz ** 2 * var_z
    cov_wz = dw_dz * var_z
    C = np.array([[var_w, cov_wz], [cov_wz, var_z]])
    return SecondOrderEstimate(method="log_decrement", omega0=omega0, omega0_std=math.sqrt(var_w), zeta=zeta,
                               zeta_std=math.sqrt(var_z), lambda1=2 * zeta * omega0, lambda2=omega0 ** 2, cov=C,
                               equilibrium=lam3 / omega0 ** 2, t_start=float(t[0]), t_end=float(t[-1]), noise_sd=sd,
                               fit_pct=fit_percentage(y, model), n_samples=int(t.size))
