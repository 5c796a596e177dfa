"""Figures of a camera calibration: where in the image the board's features were seen, and what
the model leaves of them.

Drawn with OpenCV (a dependency of the calibration itself), so a calibration always gets its
figure without the plotting stack.
"""

from __future__ import annotations

import os

import cv2
import numpy as np

__all__ = ["coverage_figure", "coverage_figure_png", "write_coverage_figure"]

_PANEL_W = 640
_TITLE_H = 34
_FOOT_H = 26
_WHITE = (255, 255, 255)
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def _text(img, s, x, y, scale=0.5, colour=(20, 20, 20)):
    cv2.putText(img, s, (int(x), int(y)), _FONT, scale, colour, 1, cv2.LINE_AA)


def coverage_figure(intrinsics) -> np.ndarray:
    """The coverage figure of an :class:`mocapfj.vision.intrinsics.Intrinsics` as a BGR image.

    Left: features used per cell of the coverage grid (colour, 0 is black) with the features as
    white dots. Right: each feature's reprojection residual (measured - model) drawn from it,
    magnified so that the RMS residual spans 4 % of the width. Both panels show the whole image
    (pixel coordinates as in docs/conventions.md).

    Returns
    -------
    (H, W, 3) uint8
    """
    w, h = intrinsics.camera.size
    s = _PANEL_W / w
    ph = int(round(h * s))
    pts = np.asarray(intrinsics.points_px, dtype=np.float64)
    res = np.asarray(intrinsics.residuals_px, dtype=np.float64)
    grid = np.asarray(intrinsics.coverage, dtype=np.float64)
    q = ((pts + 0.5) * s).round().astype(np.int32)

    top = grid.max() if grid.size and grid.max() > 0 else 1.0
    heat = cv2.applyColorMap((255 * grid / top).astype(np.uint8), cv2.COLORMAP_VIRIDIS)
    heat[grid == 0] = (0, 0, 0)
    left = cv2.resize(heat, (_PANEL_W, ph), interpolation=cv2.INTER_NEAREST)
    for x in np.linspace(0, _PANEL_W, grid.shape[1] + 1).round().astype(int):
        cv2.line(left, (min(x, _PANEL_W - 1), 0), (min(x, _PANEL_W - 1), ph - 1), (70, 70, 70), 1)
    for y in np.linspace(0, ph, grid.shape[0] + 1).round().astype(int):
        cv2.line(left, (0, min(y, ph - 1)), (_PANEL_W - 1, min(y, ph - 1)), (70, 70, 70), 1)
    inside = (q[:, 0] >= 0) & (q[:, 0] < _PANEL_W) & (q[:, 1] >= 0) & (q[:, 1] < ph)
    left[q[inside, 1], q[inside, 0]] = _WHITE

    right = np.full((ph, _PANEL_W, 3), 235, np.uint8)
    cv2.rectangle(right, (0, 0), (_PANEL_W - 1, ph - 1), (120, 120, 120), 1)
    rms = float(intrinsics.rms_px)
    gain = 0.04 * _PANEL_W / max(rms, 1e-9)                   # screen px per residual px
    tip = (q + res * gain).round().astype(np.int32)
    cv2.polylines(right, [np.stack([a, b]) for a, b in zip(q, tip)], False, (40, 40, 200), 1, cv2.LINE_AA)
    right[q[inside, 1], q[inside, 0]] = (0, 0, 0)

    fig = np.full((_TITLE_H + ph + _FOOT_H, 2 * _PANEL_W + 10, 3), 255, np.uint8)
    fig[_TITLE_H:_TITLE_H + ph, :_PANEL_W] = left
    fig[_TITLE_H:_TITLE_H + ph, _PANEL_W + 10:] = right
    K = intrinsics.camera.K
    _text(fig, f"{intrinsics.camera.name} ({w} x {h} px): fx {K[0, 0]:.2f}, fy {K[1, 1]:.2f}, cx {K[0, 2]:.2f}, "
               f"cy {K[1, 2]:.2f} px, {intrinsics.model} distortion, RMS {rms:.3f} px", 8, 22, 0.55)
    _text(fig, f"coverage: {intrinsics.n_points} features in {intrinsics.n_views_used} views, "
               f"{intrinsics.coverage_pct:.0f} % of cells (max {int(top)} per cell)", 8, _TITLE_H + ph + 18)
    _text(fig, f"residuals x {gain / s:.3g} (measured - model)", _PANEL_W + 18, _TITLE_H + ph + 18)
    return fig


def coverage_figure_png(intrinsics) -> bytes:
    """`coverage_figure` encoded as PNG."""
    ok, buf = cv2.imencode(".png", coverage_figure(intrinsics))
    if not ok:  # pragma: no cover
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()


def write_coverage_figure(path: str | os.PathLike[str], intrinsics) -> None:
    """Write `coverage_figure_png` to `path`, atomically."""
    from ..io.atomic import write_bytes_atomic

    write_bytes_atomic(path, coverage_figure_png(intrinsics))
