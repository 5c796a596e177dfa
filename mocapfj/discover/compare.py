"""The comparison of a simulated joint with its recording, measured against the recording's own
noise floor (docs/conventions.md, "Fit and noise floor").

A recording carries noise a perfect model cannot predict: the markers' (in the deflection), the
torque sensor's or current loop's, and the encoder's, which reaches the prediction because the
simulated link is driven by the recorded motor angle and the torque model differentiates it
twice. Compared at full rate, that noise decides the score (a torque fit of 20 % for the true
model of a recording with 0.5 N m torque noise and 6e-5 rad encoder noise). So the comparison is
made

- in the band the model claims: a lumped flexible joint is a model of the motion up to a fraction
  of its link's resonance (:data:`BAND_FRACTION` of sqrt(k / I) / 2 pi, at least
  :data:`MIN_BAND_HZ`, at most 60 Hz and 0.4 x the sampling rate), both signals through the same
  zero-phase low-pass;
- against the noise floor: the fit a perfect model would reach on this recording, from the part
  of the residual that does not repeat. An identification excitation is periodic (a Fourier series
  or a multisine: Swevers, Ganseman, Tukel, de Schutter and Van Brussel 1997; Pintelon and
  Schoukens 2012, ch. 2), and so is everything a deterministic model predicts for it once the
  start has died out; what changes from period to period is noise. The noise variance is that
  of the residual's samples about their mean at the same phase of every period (scaled by
  c / (c - 1) for c periods), over every sample the fit squares (a period all of whose
  differences from its neighbours are above 4 x the median left out: a disturbed period such as
  a start ramp does not decide it), estimated per channel on the
  in-band residual itself, so it holds for coloured noise and for the encoder noise the
  prediction carries. Without a period (|autocorrelation| of the motor angle below
  :data:`MIN_PERIOD_CORR` at every lag between 0.5 s and half the recording) the floor is the
  recorded signal's white floor (the median of its spectrum over :data:`WHITE_BAND`) carried into the band, which leaves
  coloured noise out: reported as ``floor_method = "white"``. For the logged torque the white
  floor also bounds the period estimate from below (a drive's quantised current repeats with the
  motion, so the period differences miss it).

The fit of a channel y with prediction y_hat is 100 (1 - ||y - y_hat|| / ||y - mean(y)||) (in
band, inside the trims); its floor 100 (1 - sigma / SD(y)), sigma the in-band noise SD. The joint's
fit and floor combine the deflection's and the torque's normalised errors e as
100 (1 - sqrt((e_delta^2 + e_u^2) / 2)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..ident.conditioning import lowpass, noise_floor_sd, noise_gain
from .memo import by_content

__all__ = ["SMOOTHED_WHITE", "BAND_FRACTION", "MIN_BAND_HZ", "MIN_PERIOD_CORR", "comparison_band_hz",
           "excitation_period_s", "Channel", "compare_channel", "in_band", "combined_fit", "combined_floor_sd", "WHITE_BAND", "fit_change_sd"]

BAND_FRACTION = 0.6
"""The comparison band's upper edge as a fraction of the link's resonance sqrt(k / I) / 2 pi: the
identification's band (:data:`mocapfj.ident.output_error.LINK_BAND_FRACTION`)."""
MIN_BAND_HZ = 1.0
"""The band's edge is at least this (a link resonating below 1.7 Hz is still compared up to 1 Hz)."""
WHITE_BAND = (0.2, 0.35)
"""The share of the sampling rate the white floor is read in (:func:`mocapfj.ident.conditioning.noise_floor_sd`):
where a joint's motion has little power and a resampler's anti-alias filter (at 0.4 x fs) has not
yet cut."""
MIN_PERIOD_CORR = 0.95
"""The motor angle is periodic when its normalised autocorrelation reaches this at some lag."""


SMOOTHED_WHITE = (0.5, 0.9)
"""Where a recording whose markers were smoothed before export has its deflection's white floor
read: this share of the smoothing's corner (above it the noise is gone; a light cobot's trial
smoothed at 6 Hz read its floor at 1.3 % of the in-band noise over WHITE_BAND, and a clock offset
of 0.03 ms was named on its control)."""


@by_content()
def _white_sd(x: np.ndarray, fs_hz: float, above: float = WHITE_BAND[0], below: float = WHITE_BAND[1]) -> float:
    """The recorded signal's white floor over WHITE_BAND, or over (above, below) x fs (the
    recording's alone: kept, :mod:`.memo`)."""
    return noise_floor_sd(x, fs_hz, above, below)


@by_content(64)
def _gain(fs_hz: float, band_hz: float) -> float:
    return noise_gain(fs_hz, band_hz)


def comparison_band_hz(k: float, I: float, fs_hz: float) -> float:
    """The band the model claims, Hz (module docstring)."""
    f_link = math.sqrt(max(k, 0.0) / I) / (2 * math.pi) if I > 0 else math.inf
    return float(min(max(BAND_FRACTION * f_link, MIN_BAND_HZ), 60.0, 0.4 * fs_hz))


def excitation_period_s(x: np.ndarray, fs_hz: float, min_s: float = 0.5) -> float | None:
    """The period of a periodic excitation x (T,) (the motor angle), s, or None when x does not
    repeat (module docstring). The lag of the highest normalised autocorrelation between `min_s`
    and half the record (the shortest within 0.005 of it: the fundamental, not a multiple), refined
    to a fraction of a sample by the least variance of the difference between x and x shifted by
    it (scanned over +-2 % of the lag, then refined; one window for every shift, after the first
    period when three or more remain)."""
    from scipy.interpolate import CubicSpline
    from scipy.optimize import minimize_scalar

    x = np.asarray(x, dtype=np.float64)
    n = x.size
    if n < 8 or not np.isfinite(x).all():
        return None
    x = x - np.polyval(np.polyfit(np.arange(n), x, 1), np.arange(n))
    F = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(np.abs(F) ** 2)[:n]
    e = np.cumsum(x ** 2)
    lags = np.arange(n)
    head = e[n - 1 - lags]                              # sum of x[:n - L]^2
    tail = e[-1] - np.concatenate([[0.0], e[:-1]])      # sum of x[L:]^2
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = ac / np.sqrt(head * tail)
    lo, hi = int(math.ceil(min_s * fs_hz)), n // 2
    if hi <= lo + 2:
        return None
    seg = np.nan_to_num(rho[lo:hi], nan=-1.0)
    peak = float(seg.max())
    if peak < MIN_PERIOD_CORR:
        return None
    inner = (seg[1:-1] >= seg[:-2]) & (seg[1:-1] >= seg[2:]) & (seg[1:-1] >= peak - 0.005)
    cand = np.flatnonzero(inner) + 1
    L = lo + int(cand[0] if cand.size else np.argmax(seg))
    t = np.arange(n) / fs_hz
    spline = CubicSpline(t, x)
    # the autocorrelation's peak is broad for a slow motion: the lag is scanned over +-2 % first;
    # one window for every trial shift, after the first period when three or more remain (the
    # start ramp and the loop's settling repeat nothing)
    reach = max(3, int(math.ceil(0.02 * L)))
    skip = min(L, max(0, n - 2 * (L + reach))) / fs_hz
    m = (t >= skip) & (t <= t[-1] - (L + reach) / fs_hz)

    def mismatch(T):                                    # the variance: a drift's offset left out
        return float(np.var(spline(t[m] + T) - x[m]))

    scan = (L + np.linspace(-reach, reach, 41)) / fs_hz
    i = int(np.argmin([mismatch(T) for T in scan]))
    step = scan[1] - scan[0]
    res = minimize_scalar(mismatch, bounds=(scan[i] - step, scan[i] + step), method="bounded",
                          options={"xatol": 1e-6})
    return float(res.x)


@dataclass(frozen=True)
class Channel:
    """One channel's comparison in the band: fit %, floor % (the fit a perfect model would reach),
    the in-band noise SD (the channel's unit), how it was estimated ("periods" or "white"), the
    pairs of consecutive periods the estimate is worth (rounded), and the floor's own SD in points
    (periods: from the variance estimate's degrees of freedom, 2 band x period per pair of periods;
    white: the scatter of the noise realised in the band, 2 band x T degrees of freedom, about the
    level read above it, which is an upper bound of the floor when the noise is coloured); sd_y:
    the recorded signal's SD in the band (what the fit is normalised by)."""

    fit: float
    floor: float
    noise_sd: float
    method: str
    n_pairs: int
    floor_sd: float = math.nan
    sd_y: float = math.nan

    @property
    def e(self) -> float:
        return 1.0 - self.fit / 100.0

    @property
    def e_floor(self) -> float:
        return 1.0 - self.floor / 100.0


def _period_noise_var(r: np.ndarray, fs_hz: float, period_s: float) -> tuple[float, float]:
    """(variance, pairs of periods it is worth) of the part of r (n,) (uniform, no NaN) that
    differs between periods, over every sample of r: resampled at M phases per period, the c
    samples of one phase (one per period, the last period a part) have sum of noise variances
    c / (c - 1) sum (r_a - mean)^2, whatever each sample's own variance; summed over the phases
    and divided by the samples, it is the mean noise variance of exactly the samples the fit
    squares. A period whose differences from its neighbours are all above 4 x the median of the
    consecutive periods' (three pairs or more) is left out (a start ramp the model does not
    repeat). Worth: sum over the phases of (c - 1) / M, consecutive pairs' equivalent."""
    from scipy.interpolate import CubicSpline

    n = r.size
    span = (n - 1) / fs_hz
    P = int(span // period_s)
    if P < 2:
        return math.nan, 0.0
    M = int(round(period_s * fs_hz))
    tau = np.arange(P + 1)[:, None] * period_s + np.arange(M)[None, :] * (period_s / M)
    valid = tau <= span
    R = CubicSpline(np.arange(n) / fs_hz, r)(np.minimum(tau, span))
    both = valid[:-1] & valid[1:]
    pair = np.array([0.5 * np.mean(np.diff(R[i:i + 2, b], axis=0) ** 2) if b.sum() >= M // 4 else np.nan
                     for i, b in enumerate(both)])
    full = pair[np.isfinite(pair)]
    if full.size >= 3:
        bad = np.nan_to_num(pair, nan=0.0) > 4.0 * np.median(full)
        # a period is disturbed when every difference it takes part in is (those it has)
        has = np.isfinite(pair)
        for i in range(P + 1):
            mine = [k for k in (i - 1, i) if 0 <= k < pair.size and has[k]]
            if mine and all(bad[k] for k in mine):
                valid[i] = False
    c = valid.sum(axis=0)
    use = c >= 2
    if not use.any():
        return math.nan, 0.0
    V, Rv, cu = valid[:, use], R[:, use], c[use]
    mean = (Rv * V).sum(axis=0) / cu
    s2 = (((Rv - mean) ** 2) * V).sum(axis=0) * cu / (cu - 1)
    return float(s2.sum() / V.sum()), float((cu - 1).sum() / M)


def in_band(x: np.ndarray, fs_hz: float, band_hz: float) -> np.ndarray:
    """x (n,) through the comparison's low-pass, the filter's own start and end cut off."""
    edge = min(int(math.ceil(2.0 * fs_hz / band_hz)), x.size // 4)
    return lowpass(x, fs_hz, band_hz)[edge:x.size - edge]


def compare_channel(y: np.ndarray, y_hat: np.ndarray, raw: np.ndarray | None, fs_hz: float, band_hz: float,
                    keep: np.ndarray, period_s: float | None, center: bool = False,
                    bounded: bool = False, white_hz: tuple[float, float] | None = None) -> Channel:
    """A channel's in-band fit and noise floor (module docstring).

    y, y_hat : (T,) recorded and predicted (NaN allowed outside `keep`); raw : (T,) the recorded
    signal whose white floor (over :data:`WHITE_BAND`) serves when there is no period, and bounds
    the floor from below when there is one (None: only when there is no period); keep : (T,) bool,
    the samples compared (a contiguous run); center : compare y - y_hat less its mean (a constant
    the recording cannot fix); bounded : the white floor bounds the period estimate from below
    (a logged torque: a drive's quantised current repeats with the motion); white_hz : (lo, hi) Hz
    to read the white floor in instead of WHITE_BAND (a recording smoothed before export:
    SMOOTHED_WHITE of its corner).
    """
    idx = np.flatnonzero(keep)
    sl = slice(int(idx[0]), int(idx[-1]) + 1)
    yy, yh = y[sl], y_hat[sl]
    ok = np.isfinite(yy) & np.isfinite(yh)
    ar = np.arange(yy.size)
    yy = np.interp(ar, ar[ok], yy[ok])
    yh = np.interp(ar, ar[ok], yh[ok])
    yb, rb = in_band(yy, fs_hz, band_hz), in_band(yy - yh, fs_hz, band_hz)
    if center:
        rb = rb - rb.mean()
    sd_y = float(np.std(yb))
    fit = float(100.0 * (1.0 - math.sqrt(float(np.mean(rb ** 2))) / sd_y)) if sd_y > 0 else math.nan
    white, pairs, method = 0.0, 0, "white"
    v_per = math.nan
    if period_s is not None:
        v_per, pairs = _period_noise_var(rb, fs_hz, period_s)
    if raw is not None and (bounded or not np.isfinite(v_per)):
        x = np.asarray(raw, dtype=np.float64)
        x = x[np.isfinite(x)]
        where = WHITE_BAND if white_hz is None else (white_hz[0] / fs_hz, white_hz[1] / fs_hz)
        white = _white_sd(x, fs_hz, *where) ** 2 * _gain(fs_hz, band_hz) if x.size > 64 else 0.0
    var = white
    if np.isfinite(v_per) and v_per >= white:
        var, method = v_per, "periods"
    sd = math.sqrt(max(var, 0.0))
    floor = float(100.0 * (1.0 - sd / sd_y)) if sd_y > 0 else math.nan
    # the floor's SD: the periods' estimate has about 2 band x period degrees of freedom per pair
    # of periods; a white floor is a level read from the spectrum above the band, which the noise
    # realised in the band, 2 band x T degrees of freedom, scatters about
    if method == "periods":
        dof = max(1.0, pairs * 2.0 * band_hz * period_s)
    else:
        dof = max(1.0, 2.0 * band_hz * rb.size / fs_hz)
    floor_sd = float(100.0 * sd / sd_y * math.sqrt(1.0 / (2.0 * dof))) if sd_y > 0 else math.nan
    return Channel(fit=fit, floor=floor, noise_sd=sd, method=method, n_pairs=int(round(pairs)) if method == "periods" else 0,
                   floor_sd=floor_sd, sd_y=sd_y)


def combined_fit(e_delta: float, e_u: float) -> float:
    """The joint's fit % from the two channels' normalised errors."""
    return float(100.0 * (1.0 - math.sqrt((e_delta ** 2 + e_u ** 2) / 2.0)))


def combined_floor_sd(d: Channel, u: Channel) -> float:
    """The SD (points) of the joint's floor from its channels' (first order)."""
    e = math.sqrt((d.e_floor ** 2 + u.e_floor ** 2) / 2.0)
    if not e > 0 or (math.isnan(d.floor_sd) and math.isnan(u.floor_sd)):
        return math.nan
    return float(math.hypot(d.e_floor * np.nan_to_num(d.floor_sd), u.e_floor * np.nan_to_num(u.floor_sd)) / (2.0 * e))


def fit_change_sd(t: np.ndarray, keep: np.ndarray, band_hz: float, fit: float, channels,
                  with_size: bool = False) -> float | tuple[float, float]:
    """The SD (points) of the change in a joint's fit between two models compared on one recording
    in one band that the recording's noise alone gives (docs/conventions.md, "Fit and noise floor").

    With r the in-band residual of the first model and m the change in its prediction, the second's
    squared error is |r - m|^2 = |r|^2 - 2 <r, m> + |m|^2: only <n, m> with the noise n is random,
    of variance sigma^2 |m|^2 / g for noise of in-band SD sigma that is white over the band the
    prediction changes in (g: the low-pass's variance gain, so sigma^2 / g is the noise per
    sample before it). Carried through fit = 100 (1 - sqrt((e_delta^2 + e_u^2) / 2)) at first order.

    A channel compared less its mean (the deflection: the mocap angle's zero is not known) takes
    the change less its mean too: a model that moves the mean deflection (a stiffening spring
    under gravity) does not change that channel's fit by it, and counting it made the SD 2.5x too
    large (hinge grid seed 22000: a cubic spring's validation gain 14.9 points at an SD of 3.3,
    where 200 noise draws give 1.3).

    With `with_size`, also the change's size G (points): |m|^2 through the same first order, the
    gain the second model would bring if it were the truth and the first left m out (and minus the
    loss if the first were). The gain is then G (2 a - 1) when the recording holds a x m, so
    (gain + G) / SD is the recording's own estimate of a in SDs: the z of the change's shape in
    the residual, which does not depend on the change's fitted size (:mod:`.tournament`).

    t, keep : (T,) the samples compared; fit : the first model's joint fit %; channels : for each
    channel (recorded SD in band, noise SD in band, the change of the prediction (T,), and
    optionally whether the channel is compared less its mean)."""
    fs = 1.0 / float(np.median(np.diff(t)))
    g = _gain(fs, band_hz)
    idx = np.flatnonzero(keep)
    sl = slice(int(idx[0]), int(idx[-1]) + 1)
    E = (1.0 - fit / 100.0) ** 2
    var, size = 0.0, 0.0
    for sd_y, sigma, dm, *center in channels:
        if not (sd_y > 0 and np.isfinite(sigma)):
            continue
        m = in_band(np.nan_to_num(np.asarray(dm, dtype=np.float64)[sl]), fs, band_hz)
        if center and center[0]:
            m = m - m.mean()
        # d(e^2) of this channel: 2 <n, m> / (N sd_y^2); its size |m|^2 / (N sd_y^2)
        mm = float(m @ m)
        var += (2.0 * sigma * math.sqrt(mm) / math.sqrt(g) / (m.size * sd_y ** 2)) ** 2
        size += mm / (m.size * sd_y ** 2)
    if not E > 0:
        return (math.nan, math.nan) if with_size else math.nan
    k = 100.0 / (2.0 * math.sqrt(E)) * 0.5
    sd = float(k * math.sqrt(var))
    return (sd, float(k * size)) if with_size else sd
