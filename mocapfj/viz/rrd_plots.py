"""x-y plots in the rerun recording: the deflection-torque loops and the FRF.

rerun's time-series views plot against a timeline only, and its 2D views draw y downward
(rerun-io/rerun#1387). So each plot is an entity whose Transform3D maps its data coordinates
onto a PLOT_W x PLOT_H display box with y up (a negative y scale); the children hold the data
in their own units (stored values are the measured ones), with axis lines and labelled ticks.

- ``/loops/<j>`` (x: deflection, mrad; y: spring torque, N m): ``/measured`` every mocap sample
  of the motor-side spring torque against the deflection (Lightcap and Banks 2007, Fig. 6),
  ``/model`` the identified spring along the same path, ``/located`` the samples inside the
  windows discovery located, ``/now`` the sample at the time cursor.
- ``/frf/magnitude`` (x: log10 of the frequency in Hz; y: 20 log10 |G| in dB of the output unit
  per input unit) and ``/frf/phase`` (y: degrees): ``/measured`` the excited lines, ``/model``
  the fitted model at the same lines.
"""

from __future__ import annotations

import numpy as np

from .rrd_signals import TIMELINE, joint_params, spring_torques, windows_of

__all__ = ["log_loops", "log_frf", "plot_transform", "nice_ticks", "PLOT_W", "PLOT_H"]

PLOT_W, PLOT_H = 400.0, 250.0


def _rr():
    import rerun as rr

    return rr


def nice_ticks(lo: float, hi: float, n: int = 5) -> np.ndarray:
    """About n round tick values (1, 2 or 5 times a power of ten apart) inside [lo, hi]."""
    span = hi - lo
    if not (np.isfinite(span) and span > 0):
        return np.array([lo])
    raw = span / max(n - 1, 1)
    p = 10.0 ** np.floor(np.log10(raw))
    step = p * min((m for m in (1, 2, 5, 10) if m * p >= raw), default=10)
    return np.arange(np.ceil(lo / step) * step, hi + 1e-9 * span, step)


def plot_transform(xlim, ylim) -> tuple[np.ndarray, np.ndarray]:
    """(translation (3,), scale (3,)) mapping data (x, y) to the display box: x0 -> 0, x1 -> PLOT_W,
    y0 -> PLOT_H, y1 -> 0 (up on screen)."""
    (x0, x1), (y0, y1) = xlim, ylim
    sx, sy = PLOT_W / (x1 - x0), PLOT_H / (y1 - y0)
    return np.array([-x0 * sx, PLOT_H + y0 * sy, 0.0]), np.array([sx, -sy, 1.0])


def _limits(x, pad=0.05):
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    lo, hi = (float(x.min()), float(x.max())) if x.size else (0.0, 1.0)
    if hi <= lo:
        lo, hi = lo - 1.0, hi + 1.0
    d = (hi - lo) * pad
    return lo - d, hi + d


def _frame(rec, path: str, xlim, ylim, xlabel: str, ylabel: str, xtick_text=None) -> None:
    """The plot entity's transform, its box and labelled ticks (static)."""
    rr = _rr()
    tr, sc = plot_transform(xlim, ylim)
    rec.log(path, rr.Transform3D(translation=tr, scale=sc), static=True)
    (x0, x1), (y0, y1) = xlim, ylim
    box = [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]
    rec.log(f"{path}/axes", rr.LineStrips2D([box], colors=[(120, 120, 120)], radii=0.5), static=True)
    xt, yt = nice_ticks(x0, x1), nice_ticks(y0, y1)
    xlab = [xtick_text(v) if xtick_text else f"{v:g}" for v in xt]
    pts = [[v, y0] for v in xt] + [[x0, v] for v in yt] + [[0.5 * (x0 + x1), y0], [x0, y1]]
    labels = xlab + [f"{v:g}" for v in yt] + [xlabel, ylabel]
    rec.log(f"{path}/ticks", rr.Points2D(pts, labels=labels, radii=1.0, colors=[(120, 120, 120)], show_labels=True),
            static=True)
    grid = [[[v, y0], [v, y1]] for v in xt] + [[[x0, v], [x1, v]] for v in yt]
    rec.log(f"{path}/grid", rr.LineStrips2D(grid, colors=[(220, 220, 220)], radii=0.3), static=True)


def log_loops(rec, contents) -> list[str]:
    """The deflection-torque loop of each joint with a torque log; returns the joints drawn."""
    rr = _rr()
    drawn = []
    for j in contents.joints:
        ident = joint_params(contents, j.name)
        s = spring_torques(j, ident)
        if s is None:
            continue
        ok = np.isfinite(s["delta"]) & np.isfinite(s["tau_s"])
        if ok.sum() < 2:
            continue
        x, y, t = 1e3 * s["delta"][ok], s["tau_s"][ok], s["t"][ok]
        path = f"loops/{j.name}"
        ylabel = "spring torque u - J q_m'' - b q_m' (N m)" if ident is not None else "logged torque (N m)"
        _frame(rec, path, _limits(x), _limits(y), "deflection q_m - q (mrad)", ylabel)
        rec.log(f"{path}/measured", rr.Points2D(np.column_stack([x, y]), radii=0.6, colors=[(60, 130, 230)]),
                static=True)
        if s["model"] is not None:
            mk = np.isfinite(s["model"][ok])
            rec.log(f"{path}/model", rr.Points2D(np.column_stack([x[mk], s["model"][ok][mk]]), radii=0.4,
                                                 colors=[(230, 160, 30)]), static=True)
        inside = np.zeros(t.size, bool)
        for _, t0, t1 in windows_of(contents.discovery, j.name):
            inside |= (t >= t0) & (t <= t1)
        if inside.any():
            rec.log(f"{path}/located", rr.Points2D(np.column_stack([x[inside], y[inside]]), radii=0.9,
                                                   colors=[(250, 200, 0)]), static=True)
        rec.log(f"{path}/now", rr.Points2D.from_fields(radii=3.0, colors=[(230, 80, 60)]), static=True)
        rec.send_columns(f"{path}/now", indexes=[rr.TimeColumn(TIMELINE, duration=t)],
                         columns=rr.Points2D.columns(positions=np.column_stack([x, y])))
        drawn.append(j.name)
    return drawn


def _frf_lines(contents):
    """(f_hz, G measured, G model or None) from frf.csv, else from frf.json; None without an FRF."""
    c, d = contents.frf_lines, contents.frf
    if c is not None and "f_hz" in c:
        f = c["f_hz"]
        G = c["G_real"] + 1j * c["G_imag"] if "G_real" in c else c["magnitude"] * np.exp(1j * c["phase_rad"])
        M = c["model_real"] + 1j * c["model_imag"] if "model_real" in c else None
        return f, G, M
    fr = (d or {}).get("frf") or {}
    if "frequencies_hz" in fr:
        f = np.asarray(fr["frequencies_hz"], dtype=np.float64)
        return f, np.asarray(fr["real"], dtype=np.float64) + 1j * np.asarray(fr["imag"], dtype=np.float64), None
    return None


def log_frf(rec, contents) -> bool:
    """The FRF's magnitude (dB) and phase (deg) against log10 frequency, measured and model."""
    rr = _rr()
    lines = _frf_lines(contents)
    if lines is None:
        return False
    f, G, M = lines
    ok = np.isfinite(f) & (f > 0) & np.isfinite(G)
    f, G = f[ok], G[ok]
    M = M[ok] if M is not None else None
    if f.size < 2:
        return False
    lf = np.log10(f)
    mag = 20 * np.log10(np.abs(G))
    ph = np.degrees(np.unwrap(np.angle(G)))
    series = {"magnitude": (mag, "|G| (dB)"), "phase": (ph, "phase (deg)")}
    model = None
    if M is not None and np.isfinite(M).any():
        model = {"magnitude": 20 * np.log10(np.abs(M)), "phase": np.degrees(np.unwrap(np.angle(M)))}
        # the model's unwrapping may start a turn away from the data's
        model["phase"] += 360.0 * np.round((np.nanmedian(ph - model["phase"])) / 360.0)
    unit = ""
    if contents.frf:
        inp, outp = contents.frf.get("input"), contents.frf.get("output")
        unit = f" of {outp} per {inp}" if inp and outp else ""
    for name, (y, ylabel) in series.items():
        path = f"frf/{name}"
        ys = [y] + ([model[name]] if model is not None else [])
        _frame(rec, path, _limits(lf, 0.02), _limits(np.concatenate(ys)), "frequency (Hz)", ylabel + unit,
               xtick_text=lambda v: f"{10 ** v:.3g}")
        pts = np.column_stack([lf, y])
        rec.log(f"{path}/measured", rr.LineStrips2D([pts], colors=[(60, 130, 230)], radii=0.8), static=True)
        rec.log(f"{path}/measured_points", rr.Points2D(pts, colors=[(60, 130, 230)], radii=1.5), static=True)
        if model is not None:
            mk = np.isfinite(model[name])
            rec.log(f"{path}/model", rr.LineStrips2D([np.column_stack([lf[mk], model[name][mk]])],
                                                     colors=[(230, 80, 60)], radii=0.8), static=True)
    return True
