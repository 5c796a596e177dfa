"""The report's figures, drawn with matplotlib (Agg, no display) from plain arrays and the
results' JSON dictionaries. Every function returns PNG bytes; every axis carries its unit.

Figures are made with :class:`matplotlib.figure.Figure` and its Agg canvas directly (no
``pyplot``: no global state, no backend to select, safe in worker threads).
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence

import numpy as np

__all__ = ["signals_figure", "cameras_figure", "parameter_sd_figure", "spring_figure", "frf_figure",
           "residuals_figure", "smooth_derivatives", "lowpass"]

_STYLE = {
    "font.size": 10.5, "axes.titlesize": 11.5, "axes.labelsize": 10.5, "legend.fontsize": 9.5,
    "xtick.labelsize": 9.5, "ytick.labelsize": 9.5, "axes.grid": True, "grid.alpha": 0.3,
    "axes.spines.top": False, "axes.spines.right": False, "savefig.facecolor": "white",
}
_DPI = 110
_BLUE, _ORANGE, _GREEN, _RED, _GREY = "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#7f7f7f"


def _figure(w_in: float, h_in: float, nrows: int = 1, ncols: int = 1, **kw):
    import matplotlib
    from matplotlib.figure import Figure

    with matplotlib.rc_context(_STYLE):
        fig = Figure(figsize=(w_in, h_in), dpi=_DPI, layout="constrained")
        axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    return fig, axes


def _png(fig) -> bytes:
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    with matplotlib.rc_context(_STYLE):
        FigureCanvasAgg(fig)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=_DPI)
    return buf.getvalue()


def _styled(draw):
    """Run `draw` (which builds and returns a Figure) under the report's style; return PNG bytes."""
    import matplotlib

    with matplotlib.rc_context(_STYLE):
        return _png(draw())


def smooth_derivatives(x: np.ndarray, dt: float, window_s: float = 0.044) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives of a sampled signal by a cubic Savitzky-Golay filter
    (Savitzky and Golay 1964) over about `window_s` seconds; NaN samples stay NaN.

    x : (T,) samples on a uniform clock of step `dt` (s). Returns (x', x''), each (T,), in the
    unit of x per s and per s^2.
    """
    from scipy.signal import savgol_filter

    x = np.asarray(x, dtype=np.float64)
    n = max(5, int(round(window_s / dt)) | 1)
    ok = np.isfinite(x)
    if ok.sum() <= n:
        return np.full_like(x, np.nan), np.full_like(x, np.nan)
    idx = np.arange(x.size)
    xf = np.interp(idx, idx[ok], x[ok])
    d1 = savgol_filter(xf, n, 3, deriv=1, delta=dt)
    d2 = savgol_filter(xf, n, 3, deriv=2, delta=dt)
    d1[~ok], d2[~ok] = np.nan, np.nan
    return d1, d2


def lowpass(x: np.ndarray, fs_hz: float, f_hz: float) -> np.ndarray:
    """Zero-phase 4th-order Butterworth low-pass of a (T,) signal at `f_hz`; NaN stay NaN."""
    from scipy.signal import butter, filtfilt

    x = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(x)
    if ok.sum() < 30 or not 0 < f_hz < 0.5 * fs_hz:
        return x.copy()
    idx = np.arange(x.size)
    xf = np.interp(idx, idx[ok], x[ok])
    b, a = butter(4, f_hz / (0.5 * fs_hz))
    y = filtfilt(b, a, xf)
    y[~ok] = np.nan
    return y


def signals_figure(t: np.ndarray, q: np.ndarray, q_m: np.ndarray | None, delta: np.ndarray | None,
                   sigma_delta: np.ndarray | None, tau: np.ndarray | None, joint: str) -> bytes:
    """A joint's measured signals against time: link angle q (and motor angle q_m, link side),
    deflection delta = q_m - q (raw, with its per-sample SD in the legend, and low-passed at 5 Hz),
    and the logged torque.

    t (s), q, q_m, delta, sigma_delta (rad), tau (N m): (T,) each; None for a stream the
    recording does not have (markers only: q alone).
    """
    panels = 1 + (delta is not None) + (tau is not None)

    def draw():
        fig, ax = _figure(10, 2.0 + 1.9 * panels, panels, 1, sharex=True)
        ax = ax[:, 0]
        top = dict(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=3, frameon=False, borderaxespad=0.2)
        ax[0].plot(t, np.degrees(q), color=_BLUE, lw=1.0, label="link angle q (markers)")
        if q_m is not None:
            ax[0].plot(t, np.degrees(q_m), color=_ORANGE, lw=1.0, ls="--", label="motor angle q_m (link side)")
        ax[0].set_ylabel("angle (deg)")
        ax[0].legend(**top)
        fig.suptitle(f"joint {joint}: measured signals", fontsize=_STYLE["axes.titlesize"])
        i = 1
        if delta is not None:
            d = 1e3 * delta
            sd = float(np.nanmedian(sigma_delta)) * 1e3 if sigma_delta is not None and np.isfinite(sigma_delta).any() \
                else None
            ax[i].plot(t, d, color=_GREEN, lw=0.5, alpha=0.45,
                       label="deflection q_m − q" + (f" (per-sample SD {sd:.2g} mrad)" if sd else ""))
            fs = 1.0 / float(np.nanmedian(np.diff(t))) if t.size > 1 else 1.0
            if fs > 20:
                ax[i].plot(t, lowpass(d, fs, 5.0), color="#145a14", lw=1.0, label="low-passed at 5 Hz")
            ax[i].set_ylabel("deflection (mrad)")
            ax[i].legend(**top)
            i += 1
        if tau is not None:
            ax[i].plot(t, tau, color=_RED, lw=0.6, label="logged torque (link side)")
            ax[i].set_ylabel("torque (N m)")
            ax[i].legend(**top)
        ax[-1].set_xlabel("time (s)")
        return fig

    return _styled(draw)


def _view_dirs(rotvecs: np.ndarray) -> np.ndarray:
    """Viewing directions (world frame) of cameras whose `rotation` is the rotation vector of
    R_cam_world (anipose): the third row of R_cam_world. (N, 3) -> (N, 3)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.asarray(rotvecs, dtype=np.float64).reshape(-1, 3)).as_matrix()[:, 2, :]


def cameras_figure(cameras: Sequence[Mapping]) -> bytes:
    """A rig seen from above and each camera's reprojection RMS.

    cameras: calibrate_rig.json's `cameras` (name, position_m, position_std_m, rotation (the
    rotation vector of R_cam_world), rms_px, n_observations, n_outliers).
    """
    names = [str(c.get("name", i)) for i, c in enumerate(cameras)]
    pos = np.array([c.get("position_m") or [np.nan] * 3 for c in cameras], dtype=np.float64)
    rms = np.array([np.nan if c.get("rms_px") is None else c["rms_px"] for c in cameras], dtype=np.float64)
    rot = [c.get("rotation") for c in cameras]
    dirs = _view_dirs(rot) if all(r is not None for r in rot) else None

    def draw():
        fig, ax = _figure(10, 4.4, 1, 2, width_ratios=[1.1, 1])
        a = ax[0, 0]
        a.scatter(pos[:, 0], pos[:, 1], color=_BLUE, s=40, zorder=3)
        span = np.nanmax(np.ptp(pos[:, :2], axis=0)) if len(pos) > 1 else 1.0
        span = span if np.isfinite(span) and span > 0 else 1.0
        if dirs is not None:
            a.quiver(pos[:, 0], pos[:, 1], dirs[:, 0], dirs[:, 1], angles="xy", scale_units="xy",
                     scale=1 / (0.18 * span), color=_BLUE, width=0.004)
        for n, p in zip(names, pos):
            a.annotate(n, (p[0], p[1]), textcoords="offset points", xytext=(6, 6), fontsize=9.5)
        a.scatter([0], [0], marker="+", color="k", s=80, zorder=3)
        a.annotate("world origin", (0, 0), textcoords="offset points", xytext=(6, -12), fontsize=9)
        a.set_aspect("equal", adjustable="datalim")
        a.set_xlabel("x (m)")
        a.set_ylabel("y (m)")
        a.set_title("camera centres from above (arrows: viewing direction)")
        b = ax[0, 1]
        b.bar(np.arange(len(names)), rms, color=_BLUE)
        b.set_xticks(np.arange(len(names)), names, rotation=30 if len(names) > 6 else 0)
        b.set_ylabel("reprojection RMS (px)")
        b.set_title("reprojection error per camera")
        for i, c in enumerate(cameras):
            if c.get("n_observations") is not None:
                b.annotate(f"{c['n_observations']} pts", (i, rms[i]), textcoords="offset points", xytext=(0, 3),
                           ha="center", fontsize=8.5)
        return fig

    return _styled(draw)


def parameter_sd_figure(names: Sequence[str], rel_sd_pct: Sequence[float | None], determined: Sequence[bool],
                        joint: str) -> bytes:
    """Relative SD of each identified parameter (log scale), determined in blue, not in red."""
    rel = np.array([np.nan if r is None else abs(r) for r in rel_sd_pct], dtype=np.float64)
    det = np.asarray(determined, dtype=bool)

    def draw():
        fig, ax = _figure(10, 0.9 + 0.36 * len(names))
        a = ax[0, 0]
        y = np.arange(len(names))[::-1]
        a.barh(y, np.where(np.isfinite(rel), rel, 0), color=np.where(det, _BLUE, _RED))
        a.set_yticks(y, names)
        a.set_xscale("log")
        from matplotlib.ticker import FuncFormatter

        a.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        a.set_xlabel("relative SD (% of the value, log scale)")
        a.set_title(f"joint {joint}: how well each parameter is determined (red: not determined)")
        for yi, r in zip(y, rel):
            if np.isfinite(r):
                a.annotate(f"{r:.2g} %", (r, yi), textcoords="offset points", xytext=(4, -3), fontsize=9)
        lo, hi = np.nanmin(rel) if np.isfinite(rel).any() else 0.01, np.nanmax(rel) if np.isfinite(rel).any() else 10
        a.set_xlim(max(lo / 3, 1e-4), hi * 4)
        return fig

    return _styled(draw)


def spring_figure(delta: np.ndarray, tau_s: np.ndarray, k: float, tau0: float, joint: str,
                  direction: np.ndarray | None = None, r2: float | None = None) -> bytes:
    """Spring torque against deflection with the fitted spring tau0 + k delta (left), and what the
    line leaves averaged in bins of spring torque, separately while the spring torque rises and
    falls (right: a hysteresis loop shows as two curves apart).

    The bins are of the spring torque, not of the deflection: the deflection's noise (times k) is
    the larger, and binning by a noisy variable bends the means at the ends (regression dilution).

    delta (rad) and tau_s (N m): (T,) samples; direction: (T,) +1 / -1 for the sign of the spring
    torque's rate, NaN at rest (left out), or None for the left panel alone.
    """
    ok = np.isfinite(delta) & np.isfinite(tau_s)
    d, ts = delta[ok], tau_s[ok]
    res = ts - (tau0 + k * d)
    two = direction is not None

    def draw():
        fig, ax = _figure(10, 4.4, 1, 2 if two else 1)
        a = ax[0, 0]
        step = max(1, d.size // 6000)
        a.scatter(1e3 * d[::step], ts[::step], s=3, color=_GREY, alpha=0.35, lw=0, rasterized=True,
                  label=f"samples (one in {step})" if step > 1 else "samples")
        xs = np.linspace(d.min(), d.max(), 2) if d.size else np.zeros(2)
        k_s = f"{k:.0f}" if abs(k) >= 100 else f"{k:.4g}"
        lab = f"fit: {tau0:.3g} N m + {k_s} N m/rad × deflection" + (f"\n(R² {r2:.4f})" if r2 is not None else "")
        a.plot(1e3 * xs, tau0 + k * xs, color=_RED, lw=2, label=lab)
        a.set_xlabel("deflection q_m − q (mrad)")
        a.set_ylabel("spring torque (N m)")
        a.set_title(f"joint {joint}: spring torque against deflection")
        a.legend(loc="lower right")
        if two:
            b = ax[0, 1]
            dr = direction[ok]
            edges = np.quantile(ts, np.linspace(0.01, 0.99, 21)) if ts.size else np.zeros(2)
            mid = 0.5 * (edges[1:] + edges[:-1])
            for sgn, col, lab in ((1, _BLUE, "spring torque rising"), (-1, _ORANGE, "spring torque falling")):
                sel = dr == sgn
                i = np.digitize(ts[sel], edges) - 1
                good = (i >= 0) & (i < mid.size)
                n = np.bincount(i[good], minlength=mid.size)
                s1 = np.bincount(i[good], res[sel][good], minlength=mid.size)
                s2 = np.bincount(i[good], res[sel][good] ** 2, minlength=mid.size)
                with np.errstate(invalid="ignore", divide="ignore"):
                    m = s1 / n
                    se = np.sqrt(np.maximum(s2 / n - m ** 2, 0) / np.maximum(n - 1, 1))
                m[n < 10] = np.nan
                b.errorbar(mid, m, yerr=se, color=col, marker="o", ms=3, lw=1.2, capsize=2, label=lab)
            b.axhline(0, color="k", lw=0.8)
            b.set_xlabel("spring torque (N m)")
            b.set_ylabel("spring torque − fit (N m)")
            b.set_title("what the line leaves, by direction (bin means ± SE)")
            b.legend(loc="best")
        return fig

    return _styled(draw)


def frf_figure(f_hz: np.ndarray, mag: np.ndarray, phase_rad: np.ndarray, coherence: np.ndarray | None,
               noise: np.ndarray | None, model: np.ndarray | None, modes: Sequence[Mapping],
               output_unit: str = "rad/(N m)", model_f_hz: np.ndarray | None = None) -> bytes:
    """Measured FRF (magnitude with its ±2 SD noise band, phase, coherence) with the fitted model
    and vertical lines at the modes.

    f_hz, mag, phase_rad, coherence, noise: (F,) per excited line; model: complex, the model at
    `model_f_hz` (a dense grid, so the curve shows the model between the lines) or, when that is
    None, at `f_hz`; None for no model.
    """
    mf = f_hz if model_f_hz is None else np.asarray(model_f_hz, dtype=np.float64)
    rows = 3 if coherence is not None else 2

    def draw():
        fig, ax = _figure(10, 2.2 + 2.0 * rows, rows, 1, sharex=True, height_ratios=[2, 1.3, 0.9][:rows])
        ax = ax[:, 0]
        a = ax[0]
        if noise is not None and np.isfinite(noise).any():
            a.fill_between(f_hz, np.maximum(mag - 2 * noise, mag * 1e-3), mag + 2 * noise, color=_BLUE, alpha=0.2,
                           lw=0, label="±2 SD (period-to-period noise)")
        a.loglog(f_hz, mag, "o", color=_BLUE, ms=4, label="measured (excited lines)")
        if model is not None:
            a.loglog(mf, np.abs(model), color=_RED, lw=1.8, label="fitted model")
        a.set_ylabel(f"magnitude ({output_unit})")
        a.set_title("frequency response")
        ph = ax[1]
        ph.semilogx(f_hz, np.degrees(phase_rad), "o", color=_BLUE, ms=4)
        if model is not None:
            mp = np.unwrap(np.angle(model))
            if mp.size and f_hz.size:
                mp += 2 * np.pi * np.round((phase_rad[0] - np.interp(f_hz[0], mf, mp)) / (2 * np.pi))
            ph.semilogx(mf, np.degrees(mp), color=_RED, lw=1.8)
        ph.set_ylabel("phase (deg)")
        if coherence is not None:
            ax[2].semilogx(f_hz, coherence, "o-", color=_GREEN, ms=3, lw=1)
            ax[2].set_ylabel("coherence (1)")
            ax[2].set_ylim(min(0.8, float(np.nanmin(coherence)) - 0.02) if np.isfinite(coherence).any() else 0, 1.01)
        for i, m in enumerate(x for x in modes if x.get("f_hz") is not None):
            res = m.get("kind") == "resonance"
            for x in ax:
                x.axvline(m["f_hz"], color=_GREY, ls="-" if res else ":", lw=1)
            a.annotate(f"{m.get('kind', 'mode')} {m['f_hz']:.4g} Hz", (m["f_hz"], 1), xycoords=("data", "axes fraction"),
                       textcoords="offset points", xytext=(3, -12 - 14 * (i % 2)), fontsize=9, color="k",
                       bbox=dict(boxstyle="square,pad=0.1", fc="white", ec="none", alpha=0.8))
        a.legend(loc="lower left")
        from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

        lo, hi = (float(np.min(mf)), float(np.max(mf))) if np.size(mf) else (0.1, 100.0)
        ticks = [m * 10.0 ** e for e in range(-3, 5) for m in (1, 2, 5) if lo / 1.2 <= m * 10.0 ** e <= hi * 1.2]
        for x in ax:
            x.xaxis.set_major_locator(FixedLocator(ticks))
            x.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            x.xaxis.set_minor_formatter(NullFormatter())
        ax[-1].set_xlabel("frequency (Hz)")
        return fig

    return _styled(draw)


def _robust_ylim(ax, *ys) -> None:
    """Y limits from the 0.2-99.8 percentiles of the data: a single spike (a filter's edge, a
    glitch) does not flatten the rest."""
    v = np.concatenate([np.asarray(y, dtype=np.float64).ravel() for y in ys])
    v = v[np.isfinite(v)]
    if v.size:
        lo, hi = np.percentile(v, [0.2, 99.8])
        pad = 0.12 * (hi - lo) if hi > lo else 1.0
        ax.set_ylim(lo - pad, hi + pad)


def residuals_figure(t: np.ndarray, channels: Sequence[tuple[str, str, float, np.ndarray, np.ndarray]],
                     windows: Sequence[tuple[float, float]], title: str, band_hz: float | None = None) -> bytes:
    """Residuals before and after the effects were added, against time, each with what the
    effects changed (before - after) beneath it; the located windows shaded.

    t: (T,) s. channels: (label, unit, scale, before, after) per channel; the plotted values are
    scale x residual (e.g. 1e3 for rad -> mrad), low-passed at `band_hz` when given (the band the
    fit is judged in). windows: (start, end) s. Y limits are robust (0.2-99.8 percentiles).
    """
    fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 1.0

    def draw():
        n = len(channels)
        fig, ax = _figure(10, 1.0 + 3.1 * n, 2 * n, 1, sharex=True, height_ratios=[2, 1] * n)
        ax = ax[:, 0]
        for k, (label, unit, scale, before, after) in enumerate(channels):
            a, dax = ax[2 * k], ax[2 * k + 1]
            b, f = scale * before, scale * after
            if band_hz:
                b, f = lowpass(b, fs, band_hz), lowpass(f, fs, band_hz)
            for x in (a, dax):
                for i, (t0, t1) in enumerate(windows):
                    x.axvspan(t0, t1, color=_ORANGE, alpha=0.18, lw=0, label="located windows" if i == 0 else None)
            a.plot(t, b, color=_GREY, lw=1.0, label="before (identified model)")
            a.plot(t, f, color=_BLUE, lw=0.8, label="after (with the effects)")
            _robust_ylim(a, b, f)
            a.set_ylabel(f"{label}\n({unit})")
            dax.plot(t, b - f, color=_GREEN, lw=0.8, label="change: before − after")
            dax.axhline(0, color="k", lw=0.6)
            _robust_ylim(dax, b - f)
            dax.set_ylabel(f"change\n({unit})")
        h1, l1 = ax[0].get_legend_handles_labels()
        h2, l2 = ax[1].get_legend_handles_labels()
        fig.legend(h1 + h2[1:], l1 + l2[1:], loc="outside lower center", ncols=4, frameon=False)
        ax[0].set_title(title + (f" (low-passed at {band_hz:.3g} Hz, the fit's band)" if band_hz else ""))
        ax[-1].set_xlabel("time (s)")
        return fig

    return _styled(draw)
