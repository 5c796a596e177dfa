"""Frequency response function from periodic (multisine) data, open or closed loop
(Makarov, Grossard, Rodriguez-Ayerbe and Dumur 2012, eq. 23-27; Pintelon and Schoukens 2012).

Data: realisations m = 1..M of a periodic excitation, each P periods of N samples after the
transient periods are dropped. The DFT of period p of realisation m at line k gives U_mp(k),
Y_mp(k) (and R_mp(k) for a reference), eq. (23): Y = G U + V. Their period means Ū_m, Ȳ_m and the
period-to-period sample (co)variances give the noise level at every line with M (P - 1) degrees of
freedom, whatever the loop: periodic excitation, non-periodic noise.

Estimators at the excited lines:

- ``"h1"``: G = sum_{m,p} Y U* / sum_{m,p} |U|^2, the classical H1 over all periods. In closed loop
  the input U carries the fed-back noise, so H1 is biased (towards -1 / C, the inverse controller).
- ``"harmonic"``: per realisation G_m = Ȳ_m / Ū_m (eq. 26: periods averaged first, which removes the
  noise from both), combined by the harmonic mean G = (1/M sum_m G_m^{-1})^{-1} (eq. 25, 27).
- ``"indirect"`` (closed loop, reference r given): G = sum_m Ȳ_m R̄_m* / sum_m Ū_m R̄_m* = S_ry / S_ru,
  unbiased because r is independent of the noise.
- ``"auto"``: indirect with a reference, harmonic without.

Variances by linearisation (first order in the noise): with v_m = E|dȲ_m - G dŪ_m|^2 =
s_Y^2 + |G|^2 s_U^2 - 2 Re(G* s_YU) from the period-to-period (co)variances divided by P,
var G_m = v_m / |Ū_m|^2; the harmonic mean has var G = |G|^4 / M^2 sum_m var G_m / |G_m|^4, the
indirect estimator var G = sum_m |R̄_m|^2 v_m / |sum_m Ū_m R̄_m*|^2. H1 gets the textbook
(1 - gamma^2) / (gamma^2 n_blocks) |G|^2. With M >= 2 realisations the spread of the G_m gives a
second, total variance that also holds the stochastic nonlinear distortions (Schoukens, Pintelon,
Rolain and Dobrowiecki 2001).

Nonlinear distortion: the output at the unexcited lines inside the band (the detection lines of an
odd multisine, :mod:`.multisine`): odd lines show odd distortion, even lines even distortion; each
level is reported beside the noise level at the same lines.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["FRF", "Distortion", "estimate_frf", "transient_count", "FRF_ESTIMATORS"]

FRF_ESTIMATORS = ("auto", "h1", "harmonic", "indirect")


@dataclass(frozen=True, eq=False)
class Distortion:
    """Output at the unexcited lines of the band (nonlinear distortion) and the noise there.

    f_even_hz, f_odd_hz : (De,), (Do,) frequencies of the even and odd detection lines, Hz
    y_even, y_odd : (De,), (Do,) RMS over realisations of the period-mean output amplitude |Ȳ|
    noise_even, noise_odd : (De,), (Do,) SD of the period-mean output from the period-to-period spread
    y_excited : float
        RMS of |Ȳ| over the excited lines (the reference level).
    even_db, odd_db, noise_db : float or None
        20 log10 of the RMS over the lines of y_even, y_odd and of the noise at all detection lines,
        relative to y_excited (None without such lines).
    even_detected, odd_detected : bool
        The detection-line power exceeds 4x the noise power there (a distortion above the noise).
    """

    f_even_hz: np.ndarray
    y_even: np.ndarray
    noise_even: np.ndarray
    f_odd_hz: np.ndarray
    y_odd: np.ndarray
    noise_odd: np.ndarray
    y_excited: float
    even_db: float | None
    odd_db: float | None
    noise_db: float | None
    even_detected: bool
    odd_detected: bool

    def to_dict(self) -> dict:
        return {"even": {"f_hz": self.f_even_hz, "level": self.y_even, "noise": self.noise_even, "db": self.even_db,
                         "detected": self.even_detected},
                "odd": {"f_hz": self.f_odd_hz, "level": self.y_odd, "noise": self.noise_odd, "db": self.odd_db,
                        "detected": self.odd_detected},
                "noise_db": self.noise_db, "output_level": self.y_excited}


@dataclass(frozen=True, eq=False)
class FRF:
    """A frequency response G(j w_k) = Y / U at the excited lines, with its uncertainty.

    Attributes
    ----------
    f_hz : (K,) excited frequencies, Hz
    G : (K,) complex, output unit per input unit (e.g. rad / (N m))
    var : (K,) noise variance E|G_hat - G|^2 from the period-to-period spread
    var_total : (K,) or None
        Variance from the spread over realisations (noise and stochastic nonlinear distortion), M >= 2.
    feedback : dict or None
        Without a reference: whether the noise in the input follows the output's as a feedback loop's
        does (:func:`feedback_evidence`); None with a reference.
    var_nl : (K,) or None
        Variance from the stochastic nonlinear distortion: estimated at the detection lines, and with
        M >= 2 the excess of `var_total` over `var` where the realisations show one (None with neither);
        a fit weighs each line by ``var_fit = var + var_nl``.
    coherence : (K,) ordinary coherence of u and y over all M P periods
    lines : (K,) int, DFT lines of one period
    estimator : "h1", "harmonic" or "indirect"
    n_periods, n_realisations : int, periods used per realisation (after the transient), realisations
    fs_hz : float; n_samples : int, period in samples
    closed_loop : bool, a reference was given
    distortion : Distortion
    """

    f_hz: np.ndarray
    G: np.ndarray
    var: np.ndarray
    var_total: np.ndarray | None
    coherence: np.ndarray
    lines: np.ndarray
    estimator: str
    n_periods: int
    n_realisations: int
    fs_hz: float
    n_samples: int
    closed_loop: bool
    distortion: Distortion
    var_nl: np.ndarray | None = None
    feedback: dict | None = None

    @property
    def magnitude(self) -> np.ndarray:
        return np.abs(self.G)

    @property
    def phase_rad(self) -> np.ndarray:
        """Unwrapped phase, rad."""
        return np.unwrap(np.angle(self.G))

    @property
    def std(self) -> np.ndarray:
        """(K,) SD of G_hat (complex, |.|), from `var`."""
        return np.sqrt(self.var)

    @property
    def var_fit(self) -> np.ndarray:
        """(K,) the variance a model fit weighs line k by: the noise's and the stochastic nonlinear
        distortion's (`var_nl`, when detection lines or realisations measure it)."""
        return self.var if self.var_nl is None else self.var + self.var_nl

    def to_dict(self) -> dict:
        return {"estimator": self.estimator, "closed_loop": self.closed_loop, "n_periods": self.n_periods,
                "n_realisations": self.n_realisations, "fs_hz": self.fs_hz, "period_samples": self.n_samples,
                "frequencies_hz": self.f_hz, "frequencies": self.f_hz, "magnitude": self.magnitude,
                "phase_rad": self.phase_rad, "phase": self.phase_rad,
                "real": self.G.real, "imag": self.G.imag, "coherence": self.coherence, "noise": self.std,
                "noise_total": None if self.var_total is None else np.sqrt(self.var_total),
                "distortion_std": None if self.var_nl is None else np.sqrt(self.var_nl),
                "distortion": self.distortion.to_dict(), "feedback": self.feedback}


SML_MIN_REALISATIONS = 4
"""Realisations from which the spread over them weighs each line by itself (sample maximum likelihood,
Schoukens, Pintelon and Rolain 1999); below, it is pooled over neighbouring lines, and counted only
without detection lines."""

DETECTION_RATIO = 4.0
"""A distortion counts where the power at the detection lines exceeds this many times the noise's there."""

GROWTH_LIMIT = 10.0
"""The largest ratio of two periods' RMS in one realisation of a record estimate_frf accepts."""


def _blocks(name, x, n_samples, skip):
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 1:
        x = x[None]
    if x.ndim != 2:
        raise InputError(None, name, "a signal (T,) or realisations (M, T)", f"shape {x.shape}")
    if not np.all(np.isfinite(x)):
        i = np.argwhere(~np.isfinite(x))[0]
        raise InputError(None, name, "finite samples", f"{x[tuple(i)]} at sample {i[-1]}")
    p = x.shape[1] // n_samples - skip
    if p < 2:
        raise InputError(None, name, f"at least {skip + 2} periods of {n_samples} samples ({skip} dropped as transient, "
                         "2 to measure the noise)", f"{x.shape[1] / n_samples:.3g} periods",
                         hint="record more periods or lower the transient count")
    x = x[:, skip * n_samples:(skip + p) * n_samples].reshape(x.shape[0], p, n_samples)
    # a steady periodic record: each period's RMS (about its mean) within GROWTH_LIMIT of the
    # others'. A record that grows (or dies out) by orders of magnitude is an unstable loop or a
    # transient, and its FRF would be a confident number about nothing
    with np.errstate(over="ignore", invalid="ignore"):
        rms = np.sqrt(np.mean((x - x.mean(axis=-1, keepdims=True)) ** 2, axis=-1))        # (M, P)
    lo, hi = rms.min(axis=1), rms.max(axis=1)
    bad = ~(hi <= GROWTH_LIMIT * np.maximum(lo, 1e-300)) & (hi > 0)
    if bad.any():
        m = int(np.argmax(bad))
        raise InputError(None, name, f"a steady periodic record (each period's RMS within {GROWTH_LIMIT:g}x of the "
                         "others')", f"period RMS from {lo[m]:.3g} to {hi[m]:.3g} in realisation {m + 1} "
                         f"(periods {int(np.argmin(rms[m])) + skip + 1} and {int(np.argmax(rms[m])) + skip + 1})",
                         hint="an unstable loop, or a transient not yet over: check the controller, or drop more "
                              "periods (transient_periods)")
    return np.fft.rfft(x, axis=-1) * (2.0 / n_samples), x.shape


def _excitation(X, rel):
    """(a2, mask): per line the mean power of the period means, and whether it exceeds `rel`^2 x the
    largest and 4x its own period-to-period noise variance (DC and Nyquist never)."""
    P = X.shape[1]
    Xm = X.mean(axis=1)
    a2 = np.mean(np.abs(Xm) ** 2, axis=0)
    noise = np.mean(np.sum(np.abs(X - Xm[:, None]) ** 2, axis=1), axis=0) / ((P - 1) * P)
    a2[0] = a2[-1] = 0.0
    return a2, noise, (a2 > rel ** 2 * a2.max()) & (a2 > 4 * noise) if a2.max() > 0 else np.zeros(a2.size, bool)


def _excited(X, rel):
    """Lines whose period-mean amplitude exceeds `rel` x the largest and 2x its own period-to-period
    noise SD (a periodic excitation there, not noise; DC and Nyquist excluded); none when their
    median power SNR is below 25 (no periodic excitation at all, or a wrong period)."""
    a2, noise, mask = _excitation(X, rel)
    k = np.flatnonzero(mask)
    snr = a2[k] / np.maximum(noise[k], 1e-300)
    return k if k.size and np.median(snr) > 25 else np.empty(0, int)   # noise alone passes 2 % of the lines, at SNR ~ 4-8


def transient_count(u, y, period_samples: int) -> int:
    """Leading periods still in the transient: those whose u or y differ from the mean of the last
    half of the periods by more than 4x the mean-square difference of the late periods themselves
    (the noise); at least 1 (a record's first period is not trusted). u, y (T,) or (M, T)."""
    n = int(period_samples)
    worst = 0
    for x in (u, y):
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        p = x.shape[1] // n
        if p < 3:
            return 1
        X = x[:, : p * n].reshape(x.shape[0], p, n)
        late = X[:, p - (p + 1) // 2:]
        ref = late.mean(axis=1, keepdims=True)
        d = np.mean((X - ref) ** 2, axis=(0, 2))
        noise = np.mean(d[p - (p + 1) // 2:]) * (1 + 1e-12) + 1e-300
        k = 0
        while k < p - 2 and d[k] > 4 * noise:
            k += 1
        worst = max(worst, k)
    return max(worst, 1)


def estimate_frf(u, y, fs_hz: float, period_samples: int, *, r=None, estimator: str = "auto",
                 transient_periods: int = 1, lines=None, min_rel_amplitude: float = 1e-2) -> FRF:
    """FRF of y over u from periodic data (Makarov et al. 2012, eq. 23-27), open or closed loop.

    Parameters
    ----------
    u, y : (T,) or (M, T)
        Input (e.g. motor torque, N m) and output (e.g. motor angle, rad), sampled at fs_hz, one row
        per realisation, starting at a period boundary of the excitation.
    fs_hz : float
        Sampling rate, Hz.
    period_samples : int
        Period N of the excitation, samples; trailing samples short of a whole period are dropped.
    r : (T,) or (M, T) or None
        The reference of a closed loop (e.g. the multisine motor-position reference).
    estimator : "auto", "h1", "harmonic" or "indirect"
    transient_periods : int or "auto"
        Periods dropped at the start of each realisation (the transient); at least 2 must remain.
        "auto": :func:`transient_count`.
    lines : (K,) int or None
        Excited DFT lines; None: those where the period-mean amplitude of r (else u) exceeds
        `min_rel_amplitude` times its largest and twice its period-to-period noise SD.

    Raises InputError for too few periods, a record that is not steady (two periods' RMS more than
    GROWTH_LIMIT apart: an unstable loop or a transient), an unknown estimator, a line without input (an
    unexcited frequency) or an input spectrum that vanishes in a realisation.
    """
    if estimator not in FRF_ESTIMATORS:
        raise InputError(None, "estimator", f"one of {', '.join(FRF_ESTIMATORS)}", estimator)
    if not (np.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(None, "fs_hz", "a positive sampling rate in Hz", fs_hz)
    if int(period_samples) != period_samples or period_samples < 4:
        raise InputError(None, "period_samples", "a period of at least 4 samples", period_samples)
    if transient_periods != "auto" and (not isinstance(transient_periods, (int, np.integer))
                                        or transient_periods < 0):
        raise InputError(None, "transient_periods", "a whole number >= 0 or 'auto'", transient_periods)
    n = int(period_samples)
    if transient_periods == "auto":
        skip = transient_count(u, y, n)
    else:
        skip = int(transient_periods)
    if np.shape(np.atleast_2d(y)) != np.shape(np.atleast_2d(u)):
        raise InputError(None, "y", f"the shape of u {np.shape(u)}", np.shape(y))
    U, shape = _blocks("u", u, n, skip)
    Y, _ = _blocks("y", y, n, skip)
    R = None
    if r is not None:
        if np.shape(np.atleast_2d(r)) != np.shape(np.atleast_2d(u)):
            raise InputError(None, "r", f"the shape of u {np.shape(u)}", np.shape(r))
        R, _ = _blocks("r", r, n, skip)
    if estimator == "auto":
        estimator = "indirect" if R is not None else "harmonic"
    if estimator == "indirect" and R is None:
        raise InputError(None, "r", "the reference signal (the indirect estimator needs it)", "none")
    M, P, _ = shape
    if lines is None:
        k = _excited(R if R is not None else U, min_rel_amplitude)
        if k.size == 0:
            raise InputError(None, "r" if R is not None else "u", "a periodic excitation at some frequency",
                             "no line excited", hint=f"check the period ({n} samples)")
    else:
        k = np.unique(np.asarray(lines, dtype=int))
        if k.size == 0 or k.min() < 1 or k.max() >= n // 2:
            raise InputError(None, "lines", f"DFT lines within 1..{n // 2 - 1}", k)
        _, _, mask = _excitation(R if R is not None else U, 1e-3)
        if not mask[k].all():
            bad = k[~mask[k]][0]
            raise InputError(None, "lines", f"excited frequencies only (the {'reference' if R is not None else 'input'} "
                             "above 1e-3 of its largest line and above its noise)",
                             f"{bad * fs_hz / n:.6g} Hz (line {bad}) not excited",
                             hint="a singular input spectrum there: excite it or leave it out")

    Um, Ym, *cov = _period_stats(U, Y, k)                                    # (M, K)

    def v_of(G):
        return _residual_var(G, *cov)

    au = np.abs(Um)
    weak = au <= 1e-9 * max(au.max(), 1e-300)
    if weak.any():
        mi, ki = np.argwhere(weak)[0]
        raise InputError(None, "u", "a non-zero input spectrum at every excited frequency",
                         f"|U| = {au[mi, ki]:.3g} (largest {au.max():.3g}) at "
                         f"{k[ki] * fs_hz / n:.6g} Hz in realisation {mi + 1}",
                         hint="that frequency is not excited (a singular input spectrum): excite it or leave it out")

    Gm = Ym / Um
    Uall, Yall = U[:, :, k].reshape(M * P, -1), Y[:, :, k].reshape(M * P, -1)
    Syu, Suu, Syy = (Yall * Uall.conj()).sum(0), (np.abs(Uall) ** 2).sum(0), (np.abs(Yall) ** 2).sum(0)
    coh = np.abs(Syu) ** 2 / np.maximum(Suu * Syy, 1e-300)
    if estimator == "h1":
        G = Syu / Suu
        var = (1 - coh) / np.maximum(coh, 1e-12) / (M * P) * np.abs(G) ** 2
    elif estimator == "harmonic":
        G = 1.0 / np.mean(1.0 / Gm, axis=0)
        var_m = v_of(Gm) / au ** 2
        var = np.abs(G) ** 4 / M ** 2 * np.sum(var_m / np.abs(Gm) ** 4, axis=0)
    else:
        Rm = R.mean(axis=1)[:, k]
        den = np.sum(Um * Rm.conj(), axis=0)
        G = np.sum(Ym * Rm.conj(), axis=0) / den
        var = np.sum(np.abs(Rm) ** 2 * v_of(G), axis=0) / np.abs(den) ** 2
    var_total = None
    if M >= 2:
        if estimator == "harmonic":
            inv = 1.0 / Gm
            var_total = np.abs(G) ** 4 * np.sum(np.abs(inv - inv.mean(0)) ** 2, axis=0) / ((M - 1) * M)
        else:
            var_total = np.sum(np.abs(Gm - Gm.mean(0)) ** 2, axis=0) / ((M - 1) * M)

    # distortion at the unexcited lines of the band
    inside = np.arange(k.min(), k.max() + 1)
    det = np.setdiff1d(inside, k)
    var_nl = _distortion_variance(U, Y, k, det, G, Um, R.mean(axis=1)[:, k] if estimator == "indirect" else None,
                                  estimator)
    if var_total is not None and (M >= SML_MIN_REALISATIONS or var_nl is None):
        spread = _spread_excess(var, var_total, Um, per_line=M >= SML_MIN_REALISATIONS)
        var_nl = spread if var_nl is None else np.maximum(var_nl, spread)
    Yd = Y.mean(axis=1)[:, det]
    nd = np.sqrt(np.mean(np.sum(np.abs(Y[:, :, det] - Yd[:, None]) ** 2, axis=1) / ((P - 1) * P), axis=0))
    yd = np.sqrt(np.mean(np.abs(Yd) ** 2, axis=0))
    y_exc = float(np.sqrt(np.mean(np.abs(Ym) ** 2)))
    ev, od = det % 2 == 0, det % 2 == 1

    def db(x):
        return None if x.size == 0 or y_exc == 0 else float(20 * np.log10(max(np.sqrt(np.mean(x ** 2)), 1e-300) / y_exc))

    def detected(sel):
        return bool(sel.any() and np.mean(yd[sel] ** 2) > DETECTION_RATIO * np.mean(nd[sel] ** 2))

    dist = Distortion(f_even_hz=det[ev] * fs_hz / n, y_even=yd[ev], noise_even=nd[ev], f_odd_hz=det[od] * fs_hz / n,
                      y_odd=yd[od], noise_odd=nd[od], y_excited=y_exc, even_db=db(yd[ev]), odd_db=db(yd[od]),
                      noise_db=db(nd), even_detected=detected(ev), odd_detected=detected(od))
    return FRF(f_hz=k * fs_hz / n, G=G, var=var, var_total=var_total, coherence=coh, lines=k, estimator=estimator,
               n_periods=P, n_realisations=M, fs_hz=float(fs_hz), n_samples=n, closed_loop=R is not None,
               distortion=dist, var_nl=var_nl, feedback=None if R is not None else feedback_evidence(U, Y, k, G))


FEEDBACK_P = 1e-3
"""The chance with which the noise of an open loop's input and output would look coherent at a line."""

FEEDBACK_CHANCE = 1e-4
"""The chance below which so many coherent lines are not independent noise's."""


def feedback_evidence(U, Y, k, G) -> dict:
    """Whether the record's noise says it was taken in closed loop, from its period-to-period
    fluctuations at the excited lines k: where those of the input and the output are coherent
    (beyond what independent noise gives with probability FEEDBACK_P at M (P - 1) degrees of
    freedom), their ratio is the system's (G) when the noise enters before the input is measured in
    open loop, and the controller's (-1 / C) in closed loop. ``suspected`` when more lines are
    coherent than independent noise makes with probability FEEDBACK_CHANCE (binomial, FEEDBACK_P per
    line) and the ratio there differs from G by more than half of |G| at the median: then
    without the reference the FRF is biased towards -1 / C. Noise that enters after the controller
    (the measurements' own) says nothing either way."""
    from scipy.stats import binom

    M, P, _ = U.shape
    nu = M * (P - 1)
    s_uu, s_yy, s_yu = (x.sum(axis=0) for x in _period_stats(U, Y, k)[2:])     # over the realisations
    coh = np.abs(s_yu) ** 2 / np.maximum(s_uu * s_yy, 1e-300)
    limit = 1.0 - FEEDBACK_P ** (1.0 / max(nu - 1, 1))
    coherent = coh > limit
    mismatch = np.abs(s_yu / np.maximum(s_uu, 1e-300) - G) / np.maximum(np.abs(G), 1e-300)
    med = float(np.median(mismatch[coherent])) if coherent.any() else None
    return {"coherent_lines": int(coherent.sum()), "lines": int(coherent.size), "median_mismatch": med,
            "suspected": bool(med is not None and med > 0.5
                              and binom.sf(int(coherent.sum()) - 1, coherent.size, FEEDBACK_P) < FEEDBACK_CHANCE)}


def _period_stats(U, Y, lines):
    """Period means Ū, Ȳ of U and Y at `lines` (any shape of DFT line indices) per realisation, and
    the (co)variances s_uu, s_yy, s_yu of those means from the period-to-period spread."""
    P = U.shape[1]
    Um, Ym = U.mean(axis=1)[:, lines], Y.mean(axis=1)[:, lines]
    dU, dY = U[:, :, lines] - Um[:, None], Y[:, :, lines] - Ym[:, None]
    s_uu = np.sum(np.abs(dU) ** 2, axis=1) / ((P - 1) * P)
    s_yy = np.sum(np.abs(dY) ** 2, axis=1) / ((P - 1) * P)
    s_yu = np.sum(dY * dU.conj(), axis=1) / ((P - 1) * P)
    return Um, Ym, s_uu, s_yy, s_yu


def _residual_var(G, s_uu, s_yy, s_yu):
    """The variance of Ȳ - G Ū (first order in the noise)."""
    return np.maximum(s_yy + np.abs(G) ** 2 * s_uu - 2 * np.real(np.conj(G) * s_yu), 0.0)


def _near(n: int, n_near: int) -> np.ndarray:
    """(n, min(n, n_near)) for each of n lines, the indices of the n_near nearest (itself first)."""
    i = np.arange(n)
    return np.argsort(np.abs(i[None, :] - i[:, None]), axis=1, kind="stable")[:, :n_near]


def _spread_excess(var, var_total, Um, n_near: int = 8, per_line: bool = True) -> np.ndarray:
    """The excess of the spread over realisations over the noise, var_total - var, at the excited
    lines where it is a distortion (the noise alone makes the two equal in expectation): where the
    mean of var_total |U|^2 over the `n_near` neighbouring excited lines exceeds DETECTION_RATIO times
    that of var |U|^2 (|U|^2 the input's power, so that what is pooled is the output's, smooth in
    frequency), else 0. Without that test the spread's few degrees of freedom (M - 1 per line) make
    the weights of a linear plant noisy. `per_line`: the excess at each line (M >= 4); else the
    pooled excess over the neighbours divided by the line's |U|^2 (2 or 3 realisations: one line's
    M - 1 degrees of freedom make weights that a few lines dominate, Schoukens, Pintelon and Rolain's
    sample maximum likelihood needs M >= 4; a full multisine with Coulomb friction, 2 realisations, in
    an independent simulation: the resonance 6.7 of its SDs off per line, 1.2 pooled)."""
    u2 = np.mean(np.abs(Um) ** 2, axis=0)
    near = _near(var.size, n_near)
    pooled_total, pooled_noise = (np.mean((x * u2)[near], axis=1) for x in (var_total, var))
    excess = np.maximum(var_total - var, 0.0) if per_line else (pooled_total - pooled_noise) / u2
    return np.where(pooled_total > DETECTION_RATIO * pooled_noise, excess, 0.0)


def _distortion_variance(U, Y, k, det, G, Um, Rm, estimator, n_near: int = 8) -> np.ndarray | None:
    """Variance of G at the excited lines k from the stochastic nonlinear distortion, estimated at the
    detection lines `det` (Pintelon and Schoukens 2012, §4.3: a random-phase multisine's stochastic
    distortions at an excited line have the level of those at the neighbouring unexcited lines of the
    same parity, an odd nonlinearity reaching odd lines only).

    At a detection line j the period means hold distortion and noise only; the distortion's share of
    G's error there is d_j = |Ȳ_j - G Ū_j|^2 less the noise's period-to-period part (in closed loop the
    distortion circulates through u as well, hence G Ū_j). d at line k is the mean over the `n_near`
    detection lines of k's parity nearest to it, counted only where that mean exceeds DETECTION_RATIO
    times the noise's (otherwise the estimate is noise: weighing by it raised the largest k error of
    benchmarks/bench_frf.py's linear grid by 20-28 %), and goes through the estimator's own formula
    in place of the noise. None without detection lines (a full multisine): nothing to estimate it from.
    """
    if det.size == 0:
        return None
    M = U.shape[0]
    same = (det[None, :] % 2) == (k[:, None] % 2)
    if not same.any(axis=1).all():
        same = np.ones_like(same)
    dist = np.where(same, np.abs(det[None, :] - k[:, None]).astype(float), np.inf)          # (K, D)
    near = np.argsort(dist, axis=1)[:, :n_near]
    ok = np.take_along_axis(np.isfinite(dist), near, axis=1)                                # (K, n)
    Ud, Yd, *cov = _period_stats(U, Y, det[near])                                          # (M, K, n)
    e2 = np.abs(Yd - G[:, None] * Ud) ** 2
    s2 = _residual_var(G[:, None], *cov)
    e2, s2 = (np.sum(np.where(ok, x, 0.0), axis=2) / np.maximum(ok.sum(axis=1), 1) for x in (e2, s2))
    d = np.where(e2 > DETECTION_RATIO * s2, e2 - s2, 0.0)             # (M, K): only a distortion above the noise
    if estimator == "indirect":
        return np.sum(np.abs(Rm) ** 2 * d, axis=0) / np.abs(np.sum(Um * Rm.conj(), axis=0)) ** 2
    if estimator == "harmonic":
        Gm = G[None, :]
        return np.abs(G) ** 4 / M ** 2 * np.sum(d / np.abs(Um) ** 2 / np.abs(Gm) ** 4, axis=0)
    return np.sum(d, axis=0) / M ** 2 / np.mean(np.abs(Um) ** 2, axis=0)
