"""Signal conditioning for identification (Jubien, Abba and Gautier (2014), §3; Gautier 1997): zero-phase low-pass
filtering, derivatives by central differences, parallel decimation of the observation matrix and
the torque together, resampling onto another clock. Every default is overridable.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import signal

from ..errors import InputError
from ..types import ControllerLog, Deflection, JointSignals

__all__ = ["lowpass", "derivatives", "decimate_parallel", "resample_to", "complementary", "white_noise_sd", "noise_floor_sd", "longest_gap", "gap_error", "MAX_GAP_S", "MAX_GAP_OUTPUT_ERROR_S",
           "noise_gain", "controller_on", "controller_span", "check_signals", "joint_signals"]


def _check_rate(fs_hz: float, cutoff_hz: float, what: str) -> None:
    if not (np.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(None, "fs_hz", "a positive sampling rate in Hz", fs_hz)
    if not 0 < cutoff_hz < fs_hz / 2:
        raise InputError(None, what, f"a cut-off between 0 and the Nyquist rate {fs_hz / 2:g} Hz", cutoff_hz)


@functools.lru_cache(maxsize=256)
def _butter_sos(order: int, cutoff_hz: float, fs_hz: float) -> np.ndarray:
    """The low-pass's second-order sections, designed once per (order, cut-off, rate): output
    error filters thousands of signals with the same few designs (shared: not to be modified)."""
    sos = signal.butter(order, cutoff_hz, fs=fs_hz, output="sos")
    return sos


@functools.lru_cache(maxsize=256)
def _butter_zi(order: int, cutoff_hz: float, fs_hz: float) -> np.ndarray:
    """The sections' steady-state initial conditions (scipy.signal.sosfilt_zi), once per design."""
    return signal.sosfilt_zi(_butter_sos(order, cutoff_hz, fs_hz))


def lowpass(x: np.ndarray, fs_hz: float, cutoff_hz: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 (forward-backward, so the order doubles).

    x : (T, ...) float, uniformly sampled at fs_hz, without NaN (fill or cut gaps first).
    """
    _check_rate(fs_hz, cutoff_hz, "cutoff_hz")
    x = np.asarray(x, dtype=np.float64)
    if np.isnan(x).any():
        raise InputError(None, "x", "a signal without NaN (fill or cut the gaps before filtering)",
                         f"{int(np.isnan(x).sum())} NaN samples")
    sos = _butter_sos(int(order), float(cutoff_hz), float(fs_hz))
    padlen = min(3 * (2 * len(sos) + 1), x.shape[0] - 1)
    if x.shape[0] < 3 * (2 * len(sos) + 1) + 1:
        raise InputError(None, "x", f"at least {3 * (2 * len(sos) + 1) + 1} samples for an order-{order} filter",
                         x.shape[0], hint="record longer")
    # scipy.signal.sosfiltfilt's steps (odd extension, forward and backward passes started at the
    # steady state of the end samples), the same numbers to the bit, with the initial conditions
    # designed once: output error filters thousands of signals per identification
    ext = np.concatenate((2 * x[:1] - x[padlen:0:-1], x, 2 * x[-1:] - x[-2:-padlen - 2:-1]), axis=0)
    zi = _butter_zi(int(order), float(cutoff_hz), float(fs_hz)).reshape((len(sos), 2) + (1,) * (x.ndim - 1))
    y, _ = signal.sosfilt(sos, ext, axis=0, zi=zi * ext[:1])
    y, _ = signal.sosfilt(sos, y[::-1], axis=0, zi=zi * y[-1:])
    return y[::-1][padlen:y.shape[0] - padlen]


def derivatives(x: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives by central differences (second order inside, one-sided at
    the ends) along axis 0, for a uniformly sampled signal: (x', x'')."""
    if not (np.isfinite(fs_hz) and fs_hz > 0):
        raise InputError(None, "fs_hz", "a positive sampling rate in Hz", fs_hz)
    x = np.asarray(x, dtype=np.float64)
    if x.ndim == 0 or x.shape[0] < 3:
        raise InputError(None, "x", "at least 3 samples for a second derivative", x.shape[:1])
    dt = 1.0 / fs_hz
    d1 = np.gradient(x, dt, axis=0)
    return d1, np.gradient(d1, dt, axis=0)


def decimate_parallel(W: np.ndarray, y: np.ndarray, factor: int, fs_hz: float | None = None,
                      cutoff_hz: float | None = None, order: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Parallel decimation (Jubien, Abba and Gautier (2014), §3): the same low-pass on y and on every column of W, then
    one sample in `factor`. The default cut-off is 0.8 x the new Nyquist rate (as
    scipy.signal.decimate's Chebyshev filter); pass fs_hz and cutoff_hz to choose it.
    """
    if int(factor) != factor or factor < 1:
        raise InputError(None, "factor", "a positive whole decimation factor", factor)
    factor = int(factor)
    if np.shape(W)[0] != np.shape(y)[0]:
        raise InputError(None, "W, y", "as many rows in W as samples in y", f"{np.shape(W)}, {np.shape(y)}")
    if factor == 1:
        return np.asarray(W, float), np.asarray(y, float)
    fs = 1.0 if fs_hz is None else fs_hz
    fc = 0.8 * fs / (2 * factor) if cutoff_hz is None else cutoff_hz
    Wf = lowpass(W, fs, fc, order // 2)
    yf = lowpass(y, fs, fc, order // 2)
    return Wf[::factor], yf[::factor]


def resample_to(t_from: np.ndarray, x: np.ndarray, t_to: np.ndarray) -> np.ndarray:
    """Linear interpolation of x (T, ...) sampled at t_from onto t_to; NaN outside its span."""
    x = np.asarray(x, dtype=np.float64)
    flat = x.reshape(x.shape[0], -1)
    out = np.column_stack([np.interp(t_to, t_from, flat[:, k], left=np.nan, right=np.nan) for k in range(flat.shape[1])])
    return out.reshape((len(t_to),) + x.shape[1:])


def complementary(low: np.ndarray, high: np.ndarray, fs_hz: float, split_hz: float) -> np.ndarray:
    """A complementary split: `low` below `split_hz` and `high` above it, L(low) + high - L(high)
    with L the zero-phase low-pass (e.g. a deflection from mocap below and from the spring above)."""
    return lowpass(low, fs_hz, split_hz) + high - lowpass(high, fs_hz, split_hz)


def white_noise_sd(x: np.ndarray, fs_hz: float) -> float:
    """SD of the white measurement noise on x (T,), from the mean periodogram above fs/4 (where
    a joint's motion has no power at mocap rates): E|X_f|^2 / T = sigma^2 for white noise."""
    x = np.asarray(x, dtype=np.float64)
    f = np.fft.rfftfreq(x.size, 1.0 / fs_hz)
    P = np.abs(np.fft.rfft(x - x.mean())) ** 2 / x.size
    band = (f > fs_hz / 4) & (f < 0.98 * fs_hz / 2)
    return float(np.sqrt(P[band].mean())) if band.any() else 0.0


def noise_floor_sd(x: np.ndarray, fs_hz: float, above: float = 0.25, below: float = 0.5) -> float:
    """SD of the white noise on x (T,), from the median of its Welch spectrum (Hann windows of 2 s,
    so the leakage of a large slow motion stays far below a quantisation-level floor) between
    `above` and `below` x fs: a robust floor where the motion has no power (`below` under 0.4 for
    a signal resampled through an anti-alias filter at 0.4 x fs). 0 when there is no such band."""
    from scipy.signal import welch

    x = np.asarray(x, dtype=np.float64)
    nper = int(min(x.size, max(64, 2 * fs_hz)))
    f, P = welch(x, fs=fs_hz, nperseg=nper)
    band = (f > above * fs_hz) & ((f < below * fs_hz) if below < 0.5 else True)
    return float(np.sqrt(np.median(P[band]) * fs_hz / 2)) if band.any() else 0.0


def noise_gain(fs_hz: float, *cutoffs_hz: float) -> float:
    """Variance gain of white noise through zero-phase low-passes in cascade (sum of the squared
    impulse response): the noise variance after them is sigma^2 times this."""
    n = int(40 * fs_hz / min(cutoffs_hz)) | 1
    h = np.zeros(n)
    h[n // 2] = 1.0
    for fc in cutoffs_hz:
        h = lowpass(h, fs_hz, fc)
    return float(h @ h)


def controller_on(t_to: np.ndarray, t_ctrl: np.ndarray, x: np.ndarray, fs_ctrl_hz: float,
                  cutoff_hz: float | None = None) -> np.ndarray:
    """A controller signal x (T_c,) at t_ctrl (s) on another time base t_to (T,) (s, same clock).

    Anti-aliased first: zero-phase low-pass at `cutoff_hz` (default: 0.4 x the target rate) at the
    controller rate, then linear interpolation; NaN outside the log's span.
    """
    t_to = np.asarray(t_to, dtype=np.float64)
    t_ctrl = np.asarray(t_ctrl, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    fs_to = 1.0 / float(np.median(np.diff(t_to)))
    t_ctrl, (x,), _ = _on_median_step(t_ctrl, x)          # the filter assumes uniform samples
    fc = 0.4 * min(fs_to, fs_ctrl_hz) if cutoff_hz is None else cutoff_hz
    xf = lowpass(x, fs_ctrl_hz, fc) if fc < 0.5 * fs_ctrl_hz else x
    return resample_to(t_ctrl, xf, t_to)


def check_signals(t, q, q_m, u, fs_hz: float):
    """(t, q, q_m, u) as float64 (T,) arrays, finite, on one uniform time base at fs_hz; raises
    InputError naming the first that is not."""
    arrs = [np.asarray(a, dtype=np.float64) for a in (t, q, q_m, u)]
    t, q, q_m, u = arrs
    if t.ndim != 1 or any(a.shape != t.shape for a in arrs):
        raise InputError(None, "t, q, q_m, u", "four (T,) arrays", [a.shape for a in arrs])
    for name, a in zip(("t", "q", "q_m", "u"), arrs):
        if not np.isfinite(a).all():
            raise InputError(None, name, "finite samples on one uniform time base", f"{int((~np.isfinite(a)).sum())} NaN",
                             hint="fill short gaps (np.interp) or cut the trial before identifying")
    dt = np.diff(t)
    if not (np.isfinite(fs_hz) and fs_hz > 0) or np.abs(dt * fs_hz - 1.0).max() > 1e-3:
        raise InputError(None, "t, fs_hz", f"uniform samples at fs_hz = {fs_hz} Hz",
                         f"steps {dt.min():.6g} .. {dt.max():.6g} s", hint="resample onto one clock (controller_on)")
    return t, q, q_m, u


MAX_GAP_S = 0.1
"""The longest gap in the link angle the equation-error methods accept (filled by interpolation,
whose straight line they would differentiate), s."""
MAX_GAP_OUTPUT_ERROR_S = 2.0
"""The longest gap output error accepts: it simulates the link through the gap and leaves the
gap's samples out, so a gap costs only its samples; beyond this the link's start after the gap
is no longer tied to the data before it, s."""


def longest_gap(t: np.ndarray, measured: np.ndarray) -> tuple[float, float]:
    """(length s, start time s) of the longest run of unmeasured samples (0, nan without one)."""
    bad = ~np.asarray(measured, bool)
    if not bad.any():
        return 0.0, float("nan")
    edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    dt = float(np.median(np.diff(t)))
    i = int(np.argmax(stops - starts))
    return float((stops[i] - starts[i] + 1) * dt), float(t[starts[i]])


def gap_error(source, joint: str, gap: float, t0: float, max_gap_s: float, why: str = "") -> InputError:
    """The refusal of a gap longer than max_gap_s, naming where it is."""
    return InputError(source, f"joints[{joint}] link angle", f"gaps in the link angle of at most {max_gap_s:g} s{why}",
                      f"{gap:.3f} s without an angle from t = {t0:.3f} s",
                      hint="cut the trial around the gap, or check the markers' visibility there")


def joint_signals(d: Deflection, controller: ControllerLog, joint: str, *, min_valid: float = 0.95,
                  max_gap_s: float = MAX_GAP_OUTPUT_ERROR_S, source=None) -> JointSignals:
    """A joint's link angle and its controller signals on one clock, for identification.

    `d` is the joint's deflection from the joints stage (mocap samples on the controller clock,
    link angle zero aligned to the motor's). Gaps in the link angle of up to `max_gap_s` are filled
    by linear interpolation of the deflection q_m - q, the link following the logged motor angle
    through them (of the link angle itself where the log does not reach: a 0.15 s gap at 1 rad/s
    filled linearly missed a heavy joint's link by 10.7 mrad, 20x its deflection noise; hinge grid
    seed 23000) (`n_filled`: a counted repair, and `measured` False there; the
    equation-error methods refuse gaps over :data:`MAX_GAP_S`, output error leaves them out); the logged motor angle and torque are
    low-passed (zero phase, 100 Hz or 0.45 x their rate) and interpolated at the mocap samples;
    samples outside the controller log are dropped. A longer gap, less than `min_valid` of the
    frames with an angle, or a NaN in the controller log is refused with the time it happens:
    interpolation across it would invent the motion the identification fits. `source` names the
    recording in messages.
    """
    t, q = d.t, d.q
    ok = np.isfinite(q)
    if ok.mean() < min_valid:
        raise InputError(source, f"joints[{joint}] link angle",
                         f"a link angle in at least {100 * min_valid:.0f} % of the frames", f"{100 * ok.mean():.1f} %",
                         hint="check the markers' visibility")
    gap, t_gap = longest_gap(t, ok)
    if gap > max_gap_s:
        raise gap_error(source, joint, gap, t_gap, max_gap_s)
    j = controller.joint_names.index(joint)
    for name, x in (("q_m", controller.q_m[:, j]), ("tau", controller.tau[:, j])):
        bad = ~np.isfinite(x)
        if bad.any():
            raise InputError(source, f"controller log {name} (joint {joint})", "finite samples",
                             f"{int(bad.sum())} NaN, the first at t = {controller.t[np.argmax(bad)]:.4f} s",
                             hint="cut the trial where the log is complete")
        if x.size and np.ptp(x) == 0:
            what = "a motor torque that varies while the joint moves" if name == "tau" else "a motor angle that moves"
            raise InputError(source, f"controller log {name} (joint {joint})", what,
                             f"the constant {float(x[0]):g} in all {x.size} samples",
                             hint="check the column recording.toml names for this joint")
    cutoff = min(100.0, 0.45 * controller.rate_hz)
    q_m = controller_on(t, controller.t, controller.q_m[:, j], controller.rate_hz, cutoff)
    u = controller_on(t, controller.t, controller.tau[:, j], controller.rate_hz, cutoff)
    q = np.interp(t, t[ok], q[ok])
    both = ok & np.isfinite(q_m)
    if not ok.all() and both.sum() >= 2:
        guided = q_m - np.interp(t, t[both], (q_m - q)[both])
        q = np.where(ok | ~np.isfinite(guided), q, guided)
    g = np.isfinite(q_m) & np.isfinite(u)
    fs = 1.0 / float(np.median(np.diff(t)))
    ctrl = controller_span(controller, j, t[g][0], t[g][-1])
    # a jittered log's uniform grid can end a fraction of a step inside the mocap span: only the
    # mocap samples the grid covers are kept
    g &= (t >= ctrl["t_c"][0] - 1e-9) & (t <= ctrl["t_c"][-1] + 1e-9)
    return JointSignals(t=t[g], q=q[g], q_m=q_m[g], u=u[g], fs_hz=fs, n_filled=int((~ok[g]).sum()), name=joint,
                        filled=~ok[g], **ctrl)


def controller_span(controller: ControllerLog, j: int, t0: float, t1: float) -> dict:
    """The controller's own samples of joint index `j` covering [t0, t1] (one sample beyond each
    end where the log has it), on a uniform time base: {t_c, q_m_c, u_c, fs_c_hz}. Time stamps
    within 1e-3 of a step of the uniform grid are taken as they are; a jittered log is
    interpolated onto its median step."""
    t = controller.t
    i0 = max(int(np.searchsorted(t, t0, side="right")) - 1, 0)
    i1 = min(int(np.searchsorted(t, t1, side="left")) + 1, t.size)
    grid, (qm, u), dt = _on_median_step(t[i0:i1], controller.q_m[i0:i1, j], controller.tau[i0:i1, j])
    return {"t_c": grid, "q_m_c": qm, "u_c": u, "fs_c_hz": 1.0 / dt}


def _on_median_step(t: np.ndarray, *xs: np.ndarray) -> tuple[np.ndarray, tuple, float]:
    """Samples xs at times t on a uniform grid of t's median step from t[0], ending at or before
    t[-1]: (grid, xs on it, step). Stamps within 1e-3 of a step of the grid keep their values;
    a jittered log is interpolated."""
    t = np.asarray(t, dtype=np.float64)
    step = float(np.median(np.diff(t)))
    grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step + 1e-6)) + 1)
    if grid.size != t.size or np.max(np.abs(grid - t)) > 1e-3 * step:
        xs = tuple(np.interp(grid, t, np.asarray(x, dtype=np.float64)) for x in xs)
    return grid, xs, step
