"""Markers smoothed before export: the recording's own evidence, and the band it still carries.

Mocap software can low-pass the marker trajectories before they are exported (a Woltring spline, a
Butterworth filter; often at 6-20 Hz). The link angle then carries neither its noise nor its motion
above that corner, and a model compared with it beyond the corner is off by the filter, not by its
physics: on a light cobot of the hinge grid with free play, markers smoothed at 6 Hz (zero-phase,
4th order) had free play read as a stiffening spring, a clock offset and a transmission error
(fresh seed 43000, case 003); on its control the true model stayed 1.4 points below its floor.

The tell is the markers' own residual about the rigid cluster fitted each frame
(`JointAngles.marker_rms`): it holds no motion, and a camera system's marker noise is white from
frame to frame, so its per-frame square is uncorrelated at one frame's lag (0.01-0.07 on the grid's
recordings). Smoothed, the residuals of neighbouring frames are nearly equal (0.96-0.98 at 6 Hz and
200-250 frames/s). The lag l_half at which that correlation, rho(l)^2 for Gaussian residuals, falls
to one half gives the filter's corner, fc = K fs / l_half: K = 0.23 for white noise through
zero-phase Butterworth filters of order 2 and 4, over 2-40 Hz at 200 frames/s (K = 0.2 is taken).
A cluster's residual also carries its template's error, which turns with the link and makes the
residual look smoother: on the hinge grid's recordings the corner comes out at 0.63-0.75 of the
filter's (6, 12 and 20 Hz), never above it (tests/joints/test_smoothing.py). Only the frames with
the usual count of markers are used: a dropout changes the residual's level for its whole burst.

Not covered: a causal filter (a real-time stream's) distorts the rigid cluster with the motion,
and its estimate scattered from 0.04 to 1.0 of its corner; a cluster that is not rigid (markers on
skin: the elbow and knee recordings of ../shared/realdata read 5.9 and 2.0 Hz) shows the same
correlation without any smoothing. On the hinge grid's 540 recordings without smoothing (seeds
41000-44000) none was taken for smoothed.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

from ..types import JointAngles

__all__ = ["SMOOTHED_CORR", "CORNER_K", "smoothing_corner_hz"]

SMOOTHED_CORR = 0.5
"""The per-frame squared residual's correlation at one frame's lag above which the markers were
smoothed (white marker noise: 0.01-0.07)."""
CORNER_K = 0.2
"""fc = CORNER_K fs / l_half (module docstring)."""
MIN_FRAMES = 200


def smoothing_corner_hz(angles: JointAngles) -> float | None:
    """The corner (Hz) of a low-pass the markers went through before export, or None when their
    residuals are white from frame to frame (or too few frames tell)."""
    rms, n = np.asarray(angles.marker_rms, float), np.asarray(angles.n_markers)
    t = np.asarray(angles.t, float)
    if rms.size < MIN_FRAMES or not np.isfinite(rms).any():
        return None
    usual = int(np.bincount(n[np.isfinite(rms)]).argmax())
    ok = np.isfinite(rms) & (n == usual)
    if ok.sum() < MIN_FRAMES:
        return None
    fs = 1.0 / float(np.median(np.diff(t)))
    z = rms ** 2
    zi = np.interp(np.arange(z.size), np.flatnonzero(ok), z[ok])
    # the slow part (the template's error as the link turns) out, over 4 s
    z = np.where(ok, z - uniform_filter1d(zi, max(3, int(4 * fs)), mode="nearest"), 0.0)
    L = min(int(fs), z.size // 4)
    m = 2 * z.size
    ac = np.fft.irfft(np.abs(np.fft.rfft(z, m)) ** 2, m)[:L + 1]
    o = ok.astype(float)
    cnt = np.fft.irfft(np.abs(np.fft.rfft(o, m)) ** 2, m)[:L + 1]
    c = ac / np.maximum(cnt, 1.0)
    if not c[0] > 0:
        return None
    c = c / c[0]
    if not c[1] > SMOOTHED_CORR:
        return None
    below = np.flatnonzero(c < 0.5)
    if below.size == 0:
        return float(CORNER_K * fs / L)        # correlated beyond a second: below this at most
    i = int(below[0])
    l_half = i - 1 + (c[i - 1] - 0.5) / (c[i - 1] - c[i])
    return float(CORNER_K * fs / l_half)
