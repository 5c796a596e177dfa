"""FRF of a single record (one period, or no periodicity at all) and a rational model fitted to it.

:mod:`.frf` measures the noise from one period to the next and needs at least two periods. A single
record (one period of a sweep, a random excitation, a recording that was never repeated) has no
such spread; here the noise comes from the record's own spectrum instead.

Local polynomial method (LPM; Pintelon, Schoukens, Vandersteen and Barbé 2010; Pintelon and
Schoukens 2012): the DFT of a finite record of a linear system is Y(k) = G(k) U(k) + T(k) +
V(k), with T the transient (leakage) term, smooth in k. Around each line k, over the 2 n + 1 lines
k + r, r = -n..n, G and T are replaced by polynomials of degree R in r; the complex linear least
squares of the 2 (R + 1) coefficients gives G(k) (the constant term), and its residuals the output
noise variance s^2(k) with q = 2 n + 1 - 2 (R + 1) complex degrees of freedom; var G(k) = s^2(k)
[(K^H K)^-1]_00. The transient (and leakage of a non-periodic input) is removed, not averaged.
The coherence reported is the signal-to-total ratio of the output at the line,
|G U|^2 / (|G U|^2 + s^2), what the ordinary coherence measures when the noise is on the output.
Bias: the polynomial fails across a resonance narrower than a few lines (its half-power width
2 zeta f_r, in lines, below about 2 n); then the noise variance there is overstated, which the fit
below weights down.

The classical alternative, :func:`estimate_frf_welch`: H1 averaged over overlapped windowed
segments with the ordinary coherence and the Bendat-Piersol variance; coarser (fs / segment), no
transient removal, biased where |G| changes within a segment's resolution.

Rational model (Pintelon and Schoukens 2012): G(s) = B(s) / A(s), s = j w / w_n (w_n the top
of the band, for conditioning), A monic of degree n_a, B of degree n_b, optionally times
exp(-s tau) (a delay). Weighted nonlinear least squares on the complex FRF, sum |G_k - G(s_k)|^2 /
var_k, started by the iterations of Sanathanan and Koerner (1963) (linearised, reweighted by
1 / |A|^2).
Covariance (A^T A)^-1 x max(1, chi2 / dof) x (1 + 3 / q^2) (the allowance for noisy weights of
:mod:`.frf_fit`). Resonances are the complex pole pairs, anti-resonances the complex zero pairs,
f = |p| / 2 pi, zeta = -Re p / |p|; their SDs by the delta method through the root sensitivities
dp / dc_i = -p^i / P'(p) of a polynomial P with coefficients c.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..errors import InputError
from .frf import FRF, Distortion
from .frf_fit import Mode
from .result import Parameter

__all__ = ["estimate_frf_lpm", "estimate_frf_welch", "SingleRecordFRF", "RationalFit", "fit_rational", "rational_frf"]


def _signal(name, x):
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise InputError(None, name, "a signal (T,)", f"shape {x.shape}")
    if not np.all(np.isfinite(x)):
        i = int(np.argmax(~np.isfinite(x)))
        raise InputError(None, name, "finite samples", f"{x[i]} at sample {i}")
    return x


@dataclass(frozen=True, eq=False)
class SingleRecordFRF:
    """An LPM FRF and the full covariance of its errors.

    frf : FRF (estimator "lpm"; `var` the diagonal of `cov`)
    cov : (K, K) complex E[dG dG^H]: lines closer than 2 n + 1 share DFT lines and correlate
    dof : q = 2 n + 1 - 2 (R + 1), complex degrees of freedom of each noise variance
    order, half_width : R and n
    """

    frf: FRF
    cov: np.ndarray
    dof: int
    order: int
    half_width: int
    periodic: bool = False

    def to_dict(self) -> dict:
        return {**self.frf.to_dict(), "lpm": {"order": self.order, "half_width": self.half_width, "dof": self.dof,
                                              "periodic": self.periodic}}


def estimate_frf_lpm(u, y, fs_hz: float, *, order: int = 2, half_width: int | None = None, lines=None,
                     min_rel_amplitude: float = 1e-2, periodic: bool = False) -> SingleRecordFRF:
    """FRF of y over u from one record by the local polynomial method (see the module docstring).

    Parameters
    ----------
    u, y : (T,) input and output, sampled at fs_hz (one record; periodic or not)
    order : degree R of the local polynomials of G and of the transient
    half_width : n, lines on each side (default R + 2: q = 3 degrees of freedom per line)
    lines : DFT lines of the record to estimate at; None: those where |U| exceeds `min_rel_amplitude`
        of its largest, and its power averaged over the window `min_rel_amplitude`^2 of the largest
        such average (a random input's dips inside the band count, an unexcited band does not); lines
        whose window holds no input are left out
    periodic : the record is one whole period of a periodic excitation in steady state: there is no
        leakage, G(k) = Y(k) / U(k) exactly up to the noise, and the local polynomials serve only
        to measure the noise, var G(k) = s^2(k) / |U(k)|^2 with the lines independent. Use it when
        modes are narrower than a few lines: the polynomial's G then smears the peak (on a
        simulated mode 0.25 line wide, zeta came out 2-6x the truth), the ratio does not

    Returns a :class:`SingleRecordFRF`: its `frf` has estimator "lpm", n_periods = n_realisations = 1,
    `var` the LPM variance of G and `n_samples` the record length; its `cov` the errors' covariance
    over the lines. Raises InputError for a record too
    short for the window, an input without excitation, or a line with a singular local input.
    """
    u, y = _signal("u", u), _signal("y", y)
    if y.shape != u.shape:
        raise InputError(None, "y", f"the shape of u {u.shape}", y.shape)
    if not (np.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(None, "fs_hz", "a positive sampling rate in Hz", fs_hz)
    if int(order) != order or order < 0:
        raise InputError(None, "order", "a whole number >= 0", order)
    R = int(order)
    n = R + 2 if half_width is None else half_width
    if int(n) != n or 2 * n + 1 <= 2 * (R + 1):
        raise InputError(None, "half_width", f"a whole number with 2 n + 1 > {2 * (R + 1)} (order {R})", half_width)
    n = int(n)
    N = u.size
    if N // 2 - 1 < 2 * n + 2:
        raise InputError(None, "u", f"a record of more than {4 * n + 6} samples", N)
    U, Y = np.fft.rfft(u) * (2.0 / N), np.fft.rfft(y) * (2.0 / N)
    au = np.abs(U)
    au[0] = au[-1] = 0.0
    if lines is None:
        if au.max() == 0:
            raise InputError(None, "u", "an input with some excitation", "all zero")
        smooth = np.convolve(au ** 2, np.ones(2 * n + 1) / (2 * n + 1), mode="same")
        k = np.flatnonzero((smooth > min_rel_amplitude ** 2 * smooth.max()) & (au > min_rel_amplitude * au.max()))
        k = k[(k >= 1) & (k <= N // 2 - 1)]
        if k.size == 0:
            raise InputError(None, "u", "an input with some excitation", "no line excited")
    else:
        k = np.unique(np.asarray(lines, dtype=int))
        if k.size == 0 or k.min() < 1 or k.max() >= N // 2:
            raise InputError(None, "lines", f"DFT lines within 1..{N // 2 - 1}", k)
    # windows: centred where possible, shifted inwards at the ends of the spectrum (lines 1..N/2-1)
    lo = np.clip(k - n, 1, N // 2 - 1 - 2 * n)
    idx = lo[:, None] + np.arange(2 * n + 1)                             # (K, W)
    r = (idx - k[:, None]).astype(np.float64)                            # offsets
    powers = r[..., None] ** np.arange(R + 1)                            # (K, W, R+1)
    Kmat = np.concatenate([powers * U[idx][..., None], powers.astype(complex)], axis=2)   # (K, W, 2R+2)
    Yw = Y[idx]
    scale = np.linalg.norm(Kmat, axis=1, keepdims=True)
    scale = np.where(scale > 0, scale, 1.0)
    Kn = Kmat / scale
    Q, Rr = np.linalg.qr(Kn)
    dg = np.abs(np.diagonal(Rr, axis1=1, axis2=2))
    local = np.sqrt(np.mean(np.abs(U[idx]) ** 2, axis=1))
    bad = (dg.min(axis=1) <= 1e-10 * dg.max(axis=1)) | (local <= 1e-6 * au.max())
    if bad.any() and lines is None and not bad.all():       # automatic lines: those with input in their window
        keep = ~bad
        k, idx, r, Kmat, Yw, scale, Q, Rr = (a[keep] for a in (k, idx, r, Kmat, Yw, scale, Q, Rr))
        bad = bad[keep]
    if bad.any():
        kb = k[np.argmax(bad)]
        raise InputError(None, "u", "an input spectrum that varies around every line asked for",
                         f"a singular local input around {kb * fs_hz / N:.6g} Hz (line {kb})",
                         hint="that band is not excited: leave it out or excite it")
    theta = np.linalg.solve(Rr, np.einsum("kwp,kw->kp", Q.conj(), Yw)[..., None])[..., 0] / scale[:, 0, :]
    res = Yw - np.einsum("kwp,kp->kw", Kmat, theta)
    q = 2 * n + 1 - 2 * (R + 1)
    s2 = np.sum(np.abs(res) ** 2, axis=1) / q                           # output noise variance at line k
    Rinv = np.linalg.inv(Rr)
    c00 = np.sum(np.abs(Rinv[:, 0, :]) ** 2, axis=1) / scale[:, 0, 0] ** 2     # [(K^H K)^-1]_00
    G = theta[:, 0]
    var = s2 * c00
    # G_k = sum_w L_kw Y(idx_kw): the estimates of nearby lines share lines, so their errors correlate
    L = np.einsum("kp,kwp->kw", Rinv[:, 0, :], Q.conj()) / scale[:, 0, :1]
    s2_line = s2[np.clip(np.searchsorted(k, np.arange(N // 2 + 1)), 0, k.size - 1)]   # noise at every line
    Lf = np.zeros((k.size, N // 2 + 1), complex)
    np.put_along_axis(Lf, idx, L, axis=1)
    cov = (Lf * s2_line) @ Lf.conj().T
    if periodic:
        G = Y[k] / U[k]
        cov = np.diag(s2 / np.maximum(np.abs(U[k]) ** 2, 1e-300)).astype(complex)
    sig = np.abs(G * U[k]) ** 2
    coh = sig / np.maximum(sig + s2, 1e-300)
    empty = np.empty(0)
    dist = Distortion(empty, empty, empty, empty, empty, empty, float(np.sqrt(np.mean(np.abs(Y[k]) ** 2))),
                      None, None, None, False, False)
    frf = FRF(f_hz=k * fs_hz / N, G=G, var=np.real(np.diagonal(cov)).copy(), var_total=None, coherence=coh,
              lines=k, estimator="lpm", n_periods=1, n_realisations=1, fs_hz=float(fs_hz), n_samples=N,
              closed_loop=False, distortion=dist)
    return SingleRecordFRF(frf=frf, cov=cov, dof=q, order=R, half_width=n, periodic=bool(periodic))


def estimate_frf_welch(u, y, fs_hz: float, *, segment: int = 256, overlap: float = 0.5, window: str = "hann",
                       min_rel_amplitude: float = 1e-2) -> FRF:
    """The classical segment-averaged H1 = S_uy / S_uu with the ordinary coherence (Welch 1967;
    Bendat and Piersol 2010): no transient removal, a resolution of fs / segment, and a bias
    where |G| changes within that; what a sceptic checks the LPM against.

    var: E|dH|^2 = (1 - gamma^2) / (n_d gamma^2) |H|^2 (Bendat and Piersol 2010, the random errors
    of frequency-response estimates: the relative SD of |H| and the SD of the phase, rad, are each sqrt((1 - gamma^2) / (2 n_d gamma^2))),
    with n_d the equivalent number of independent segments of the overlapped window (Welch 1967):
    K / (1 + 2 sum_j (1 - j / K) c_j^2), c_j the window's overlap correlation at shift j.
    Returns an FRF with estimator "welch", n_periods = K segments, n_samples = segment.
    """
    from scipy import signal as sps

    u, y = _signal("u", u), _signal("y", y)
    if y.shape != u.shape:
        raise InputError(None, "y", f"the shape of u {u.shape}", y.shape)
    if int(segment) != segment or segment < 16 or segment > u.size:
        raise InputError(None, "segment", f"a whole number of samples within 16..{u.size}", segment)
    if not 0 <= overlap < 1:
        raise InputError(None, "overlap", "a fraction in [0, 1)", overlap)
    seg = int(segment)
    nov = int(round(overlap * seg))
    step = seg - nov
    K = (u.size - nov) // step
    if K < 2:
        raise InputError(None, "u", f"at least 2 segments of {seg} samples", f"{u.size} samples")
    kw = dict(fs=fs_hz, window=window, nperseg=seg, noverlap=nov, detrend=False)
    f, Suu = sps.welch(u, **kw)
    _, Syy = sps.welch(y, **kw)
    _, Suy = sps.csd(u, y, **kw)                                  # conj(U) Y
    k = np.flatnonzero(Suu > min_rel_amplitude ** 2 * Suu.max()) if Suu.max() > 0 else np.empty(0, int)
    k = k[(k >= 1) & (k <= seg // 2 - 1)]
    if k.size == 0:
        raise InputError(None, "u", "an input with some excitation", "no line excited")
    H = Suy[k] / Suu[k]
    coh = np.abs(Suy[k]) ** 2 / np.maximum(Suu[k] * Syy[k], 1e-300)
    w = sps.get_window(window, seg)
    cj = np.array([np.sum(w[: seg - j * step] * w[j * step:]) ** 2 for j in range(1, K) if j * step < seg])
    cj = cj / np.sum(w * w) ** 2
    n_d = K / (1 + 2 * np.sum((1 - np.arange(1, cj.size + 1) / K) * cj))
    var = (1 - coh) / np.maximum(coh, 1e-12) / n_d * np.abs(H) ** 2
    empty = np.empty(0)
    dist = Distortion(empty, empty, empty, empty, empty, empty, float(np.sqrt(np.mean(Syy[k]))), None, None, None,
                      False, False)
    return FRF(f_hz=f[k], G=H, var=var, var_total=None, coherence=coh, lines=k, estimator="welch", n_periods=K,
               n_realisations=1, fs_hz=float(fs_hz), n_samples=seg, closed_loop=False, distortion=dist)


def rational_frf(f_hz, b, a, *, w_norm: float, tau: float = 0.0) -> np.ndarray:
    """B(s) / A(s) exp(-j w tau) at s = j 2 pi f / w_norm; b, a highest power first."""
    w = 2 * np.pi * np.asarray(f_hz, dtype=np.float64)
    s = 1j * w / w_norm
    return np.polyval(b, s) / np.polyval(a, s) * np.exp(-1j * w * tau)


@dataclass(frozen=True, eq=False)
class RationalFit:
    """G(s) = B(s) / A(s) exp(-s tau) fitted to an FRF (s scaled by w_norm, rad/s).

    b, a : coefficients in the scaled s = j w / w_norm, highest power first (a monic)
    cov : covariance of (b, a[1:], [tau w_norm])
    params : dict name -> Parameter (b_i, a_i of s^i in the scaled s; tau in s)
    modes : tuple of Mode, resonances and anti-resonances up to the top of the fitted band, by frequency
    beyond_band : tuple of Mode, complex roots above the band (the model's shape there, not modes of the data)
    chi2, dof, G_fit as in :class:`~mocapfj.ident.frf_fit.FRFFit`
    """

    b: np.ndarray
    a: np.ndarray
    tau: float
    w_norm: float
    cov: np.ndarray
    params: dict
    modes: tuple
    chi2: float
    dof: int
    G_fit: np.ndarray
    beyond_band: tuple = ()
    model: str = "rational"

    @property
    def chi2_red(self) -> float:
        return self.chi2 / max(self.dof, 1)

    def to_dict(self) -> dict:
        return {"name": self.model, "order": [len(self.b) - 1, len(self.a) - 1], "w_norm": self.w_norm,
                "params": {n: {"value": p.value, "std": p.std} for n, p in self.params.items()},
                "chi2": self.chi2, "dof": self.dof, "chi2_red": self.chi2_red,
                "modes": [m.to_dict() for m in self.modes], "beyond_band": [m.to_dict() for m in self.beyond_band]}


def _root_modes(c, cov_c, kind, w_norm):
    """Modes of the complex roots (upper half) of the polynomial c (highest first) and their SDs."""
    deg = len(c) - 1
    out = []
    if deg < 1:
        return out
    dc = np.polyder(c)
    for p in np.roots(c):
        if p.imag <= 1e-9 * abs(p):
            continue
        # dp/dc_i = -p^(deg - i) / P'(p) for c_i the coefficient of s^(deg - i)
        g = -(p ** np.arange(deg, -1, -1)) / np.polyval(dc, p)
        m = abs(p)
        # f = |p| w_norm / 2 pi ; zeta = -Re p / |p| ; derivatives through p = x + j y
        x, yv = p.real, p.imag
        df = np.array([x / m, yv / m]) * w_norm / (2 * np.pi)
        dz = np.array([-1 / m + x * x / m ** 3, x * yv / m ** 3])
        Dp = np.vstack([g.real, g.imag])                                # d(x, y) / dc
        Jf, Jz = df @ Dp, dz @ Dp
        vf, vz = Jf @ cov_c @ Jf, Jz @ cov_c @ Jz                       # negative: not determined, NaN
        out.append(Mode(kind, float(m * w_norm / (2 * np.pi)), float(-x / m),
                        float(np.sqrt(vf)) if vf >= 0 else np.nan, float(np.sqrt(vz)) if vz >= 0 else np.nan))
    return sorted(out, key=lambda md: md.f_hz)


def fit_rational(frf: FRF, n_b: int, n_a: int, *, delay: bool = False, f_band_hz=None, dof: int | None = None,
                 sk_iterations: int = 20) -> RationalFit:
    """Fit G(s) = B(s) / A(s) [exp(-s tau)] of degrees n_b, n_a to `frf` by weighted nonlinear least squares.

    `frf`: an FRF, or a :class:`SingleRecordFRF` whose full covariance then enters a sandwich
    covariance (A^T A)^-1 A^T C A (A^T A)^-1 of the estimate (C of the weighted residuals): the
    LPM's correlated lines. `dof`: complex degrees of freedom of the FRF's variances (default: M (P - 1)
    of a periodic FRF, q of an LPM one), for the allowance on noisy weights.
    """
    full_cov = None
    if isinstance(frf, SingleRecordFRF):
        full_cov, dof, frf = frf.cov, frf.dof if dof is None else dof, frf.frf
    if not isinstance(frf, FRF):
        raise InputError(None, "frf", "an FRF (mocapfj.ident.frf)", type(frf).__name__)
    if int(n_a) != n_a or int(n_b) != n_b or n_a < 1 or n_b < 0:
        raise InputError(None, "order", "whole numbers n_b >= 0, n_a >= 1", (n_b, n_a))
    sel = np.ones(frf.f_hz.size, bool)
    if f_band_hz is not None:
        sel = (frf.f_hz >= f_band_hz[0]) & (frf.f_hz <= f_band_hz[1])
    nb1, na = int(n_b) + 1, int(n_a)
    npar = nb1 + na + int(bool(delay))
    if 2 * sel.sum() <= npar:
        raise InputError(None, "frf", f"more than {npar / 2:.0f} lines to fit {npar} coefficients", int(sel.sum()))
    f, G = frf.f_hz[sel], frf.G[sel]
    sd = np.sqrt(np.maximum(frf.var[sel], (1e-10 * np.abs(G)) ** 2 + 1e-300) / 2.0)
    w_norm = 2 * np.pi * float(f.max())
    s = 1j * 2 * np.pi * f / w_norm
    Sb = s[:, None] ** np.arange(n_b, -1, -1)                   # (K, nb1)
    Sa = s[:, None] ** np.arange(na - 1, -1, -1)                 # (K, na) lower coefficients of A
    # Sanathanan-Koerner: B - G A_low = G s^na, weighted by 1 / (sd |A_prev|)
    wA = np.ones(f.size)
    x_ba = None
    for _ in range(max(int(sk_iterations), 1)):
        wt = 1.0 / (sd * wA)
        M = np.hstack([Sb, -G[:, None] * Sa]) * wt[:, None]
        rhs = G * s ** na * wt
        sol = np.linalg.lstsq(np.vstack([M.real, M.imag]), np.concatenate([rhs.real, rhs.imag]), rcond=None)[0]
        x_ba = sol
        A = np.polyval(np.r_[1.0, sol[nb1:]], s)
        wA = np.maximum(np.abs(A), 1e-12)

    def model(x):
        b, a = x[:nb1], np.r_[1.0, x[nb1:nb1 + na]]
        tau = x[-1] if delay else 0.0
        return np.polyval(b, s) / np.polyval(a, s) * np.exp(-s * tau)   # tau in units of 1 / w_norm

    def resid(x):
        with np.errstate(all="ignore"):
            e = (G - model(x)) / sd
        r = np.concatenate([e.real, e.imag])
        return np.where(np.isfinite(r), r, 1e150)

    x0 = np.r_[x_ba, 0.0] if delay else x_ba
    sol = least_squares(resid, x0, method="lm", xtol=1e-14, ftol=1e-14, max_nfev=20000)
    if not np.all(np.isfinite(sol.x)):
        raise InputError(None, "frf", "an FRF the rational model can be fitted to", "no convergence")
    Ajac = sol.jac
    dof_fit = 2 * f.size - npar
    chi2 = float(2 * sol.cost)
    q = int(dof) if dof is not None else frf.n_realisations * max(frf.n_periods - 1, 1)
    cs = np.linalg.norm(Ajac, axis=0)
    cs = np.where(cs > 0, cs, 1.0)
    _, sv, Vt = np.linalg.svd(Ajac / cs, full_matrices=False)
    if sv.min() <= 1e-9 * sv.max():
        raise InputError(None, "order", "a model whose coefficients the FRF determines",
                         f"(n_b, n_a) = ({n_b}, {n_a}){' with a delay' if delay else ''}: the fit's Jacobian has "
                         f"condition {sv.max() / max(sv.min(), 1e-300):.2g}", hint="lower the order or drop the delay")
    try:
        H = (Vt.T / sv ** 2) @ Vt / np.outer(cs, cs)                       # (A^T A)^-1, by the SVD
        if full_cov is not None:     # sandwich: the weighted residuals' covariance with the lines' correlation
            C = full_cov[np.ix_(sel, sel)] / np.outer(sd, sd)
            Cri = 0.5 * np.block([[C.real, -C.imag], [C.imag, C.real]])
            H = H @ (Ajac.T @ Cri @ Ajac) @ H
        cov = H * max(1.0, chi2 / max(dof_fit, 1)) * (1.0 + 3.0 / max(q, 1) ** 2)
    except np.linalg.LinAlgError:
        cov = np.full((npar, npar), np.nan)
    ev = np.linalg.eigvalsh(cov / np.sqrt(np.outer(np.abs(np.diag(cov)), np.abs(np.diag(cov))) + 1e-300))
    if not np.all(np.isfinite(ev)) or ev.min() < -1e-8:                  # the correlation matrix: PSD up to rounding
        raise InputError(None, "order", "a model whose coefficients the FRF determines",
                         f"(n_b, n_a) = ({n_b}, {n_a}){' with a delay' if delay else ''}: the covariance of its "
                         "coefficients is not positive semi-definite (numerically singular)",
                         hint="lower the order or drop the delay")
    x = sol.x
    b, a = x[:nb1], np.r_[1.0, x[nb1:nb1 + na]]
    cov_b = cov[:nb1, :nb1]
    cov_a = np.zeros((na + 1, na + 1))
    cov_a[1:, 1:] = cov[nb1:nb1 + na, nb1:nb1 + na]
    modes = [*_root_modes(a, cov_a, "resonance", w_norm), *_root_modes(b, cov_b, "antiresonance", w_norm)]
    modes.sort(key=lambda md: md.f_hz)
    beyond = tuple(m for m in modes if m.f_hz > f.max())          # the model's shape beyond the data, not modes
    modes = [m for m in modes if m.f_hz <= f.max()]
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    names = ([f"b{i}" for i in range(n_b, -1, -1)] + [f"a{i}" for i in range(na - 1, -1, -1)]
             + (["tau"] if delay else []))
    scale = np.ones(npar)
    if delay:
        scale[-1] = 1.0 / w_norm                                       # tau in s
    params = {nm: Parameter(nm, float(x[i] * scale[i]), float(std[i] * scale[i])) for i, nm in enumerate(names)}
    tau = float(x[-1] / w_norm) if delay else 0.0
    return RationalFit(b=b, a=a, tau=tau, w_norm=w_norm, cov=cov, params=params, modes=tuple(modes), chi2=chi2,
                       dof=dof_fit, beyond_band=beyond, G_fit=rational_frf(frf.f_hz, b, a, w_norm=w_norm, tau=tau))
