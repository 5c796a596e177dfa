"""Sub-pixel corner features: chessboard X-junctions (saddle points, placed by point symmetry)
and the corners of dark squares on a bright ground (AprilTags, placed where their edges meet).

1. **Saddle points** (Chen and Zhang 2005): at an X-junction of a chessboard the Gaussian-smoothed
   grey level I has a saddle, ``det(Hessian) < 0``. Local maxima of ``Ixy^2 - Ixx Iyy`` are
   candidates, moved to the junction (step 2) and kept when the grey levels on small circles
   around them look like an X-junction: four sign changes about their mean, the second harmonic
   dominant and the pattern point-symmetric (an X-junction of straight edges is symmetric under a
   half turn whatever the angle between its lines; an L-corner, an edge or the board's outer
   border is not).
2. **Sub-pixel position by point symmetry**: the corner c minimises
   ``sum_d w(d) (I(c + d) - I(c - d))^2`` over a disc of offsets d (Gauss-Newton on bilinear
   samples of a lightly smoothed image). Unlike the gradient-orthogonality of ``cornerSubPix``
   it needs no straight edges over the window, only the half-turn symmetry of the junction.
3. **Square corners** (`refine_square_corners`): each side located along its normal and fitted by
   a quadratic, the corner where the sides' tangents meet; blur moves an edge nowhere.

How the X-junctions are assembled into a board: :mod:`mocapfj.vision.lattice`. Pixel
coordinates follow docs/conventions.md (origin at the centre of the top-left pixel).
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

__all__ = ["smoothed", "saddle_points", "xjunction_test", "refine_saddles", "refine_square_corners"]

_N_CIRCLE = 32
_THETA = np.arange(_N_CIRCLE) * (2.0 * np.pi / _N_CIRCLE)


def smoothed(grey: np.ndarray, sigma: float) -> np.ndarray:
    """`grey` as float32, Gaussian-smoothed by `sigma` pixels (not at all for sigma 0)."""
    g = grey.astype(np.float32)
    return cv2.GaussianBlur(g, (0, 0), sigma) if sigma > 0 else g


def xjunction_test(smooth: np.ndarray, p: np.ndarray, radius: float, min_contrast: float = 6.0,
                   max_odd: float = 0.15, max_first: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Which points look like chessboard X-junctions on a circle of `radius` px around them.

    Parameters
    ----------
    smooth : (H, W) float32
        Lightly smoothed grey image.
    p : (n, 2) float
        Points, pixels.
    radius : float
        Circle radius, pixels.
    min_contrast : float
        Least amplitude of the second harmonic, grey levels.
    max_odd : float
        Largest RMS of the part of the circle's grey levels that a half turn does not preserve,
        relative to their RMS.
    max_first : float
        Largest amplitude of the first harmonic relative to the second.

    Returns
    -------
    good : (n,) bool
    line_angles : (n, 2) float
        For good points, the directions (rad, in [0, pi)) of the junction's two lines; NaN else.
    """
    n = len(p)
    if n == 0:
        return np.zeros(0, bool), np.zeros((0, 2))
    mx = (p[:, 0:1] + radius * np.cos(_THETA)[None]).astype(np.float32)
    my = (p[:, 1:2] + radius * np.sin(_THETA)[None]).astype(np.float32)
    v = cv2.remap(smooth, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
    v -= v.mean(axis=1, keepdims=True)
    f = np.fft.rfft(v, axis=1) * (2.0 / _N_CIRCLE)
    a1, a2 = np.abs(f[:, 1]), np.abs(f[:, 2])
    rms = np.sqrt((v * v).mean(axis=1)) + 1e-12
    odd = 0.5 * (v - np.roll(v, _N_CIRCLE // 2, axis=1))
    odd_ratio = np.sqrt((odd * odd).mean(axis=1)) / rms
    nxt = np.roll(v, -1, axis=1)
    cross = (v > 0) != (nxt > 0)
    good = (a2 > min_contrast) & (a1 < max_first * a2) & (cross.sum(axis=1) == 4) & (odd_ratio < max_odd)
    angles = np.full((n, 2), np.nan)
    idx = np.nonzero(good)[0]
    if len(idx):
        k = np.nonzero(cross[idx])[1].reshape(-1, 4)                         # the 4 crossings, ascending
        vk = v[idx[:, None], k]
        frac = vk / (vk - nxt[idx[:, None], k])
        a = (k + frac) * (2.0 * np.pi / _N_CIRCLE)
        # crossings 0 and 2 lie on one line, 1 and 3 on the other: average each pair's direction mod pi
        for line, (i0, i1) in enumerate(((0, 2), (1, 3))):
            z = np.exp(2j * a[:, i0]) + np.exp(2j * a[:, i1])
            angles[idx, line] = (np.angle(z) / 2.0) % np.pi
    return good, angles


def saddle_points(grey: np.ndarray, sigma: float = 1.5, radii=(3.0, 5.0),
                  max_points: int = 20000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chessboard X-junction candidates (Chen and Zhang 2005; module docstring).

    Parameters
    ----------
    grey : (H, W) uint8
    sigma : float
        Gaussian scale of the saddle response, pixels.
    radii : sequence of float
        Circle radii of the X-junction test (a point passes on any of them).
    max_points : int
        At most this many local maxima are tested (the strongest).

    Returns
    -------
    p : (n, 2) float
        Candidate positions, pixels (sub-pixel from the local quadratic).
    score : (n,) float
        Saddle strength ``Ixy^2 - Ixx Iyy`` of the smoothed image.
    line_angles : (n, 2) float
        Directions of each junction's two lines, rad in [0, pi).
    """
    g = smoothed(grey, sigma)
    ixx = cv2.Sobel(g, cv2.CV_32F, 2, 0, ksize=3) * 0.25
    iyy = cv2.Sobel(g, cv2.CV_32F, 0, 2, ksize=3) * 0.25
    ixy = cv2.Sobel(g, cv2.CV_32F, 1, 1, ksize=3) * 0.25
    s = ixy * ixy - ixx * iyy
    k = 2 * int(np.ceil(1.5 * sigma)) + 1
    peak = (s == cv2.dilate(s, np.ones((k, k), np.uint8))) & (s > 0)
    ys, xs = np.nonzero(peak)
    if len(xs) == 0:
        return np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2))
    sv = s[ys, xs]
    top = np.sort(sv)[-20:]
    keep = sv > 0.02 * np.median(top)
    ys, xs, sv = ys[keep], xs[keep], sv[keep]
    if len(xs) > max_points:
        order = np.argsort(sv)[-max_points:]
        ys, xs, sv = ys[order], xs[order], sv[order]
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)[ys, xs] * 0.125
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)[ys, xs] * 0.125
    a, b, c = ixx[ys, xs], ixy[ys, xs], iyy[ys, xs]
    det = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        dx = -(c * gx - b * gy) / det
        dy = -(a * gy - b * gx) / det
    step_ok = (np.abs(dx) < 1.0) & (np.abs(dy) < 1.0)
    p = np.stack([xs + np.where(step_ok, dx, 0.0), ys + np.where(step_ok, dy, 0.0)], axis=1).astype(np.float64)
    light = smoothed(grey, 0.7)
    # a loose test first (the strict one needs the junction's centre within a fraction of a pixel),
    # then the symmetric refinement, then the strict test on every radius
    # (a saddle response's peak can sit 2-3 px from the junction of a blurred, compressed print)
    loose = np.zeros(len(p), bool)
    for r in (max(radii), max(radii) + 2.0):
        loose |= xjunction_test(light, p, r, max_odd=np.inf, max_first=1.0)[0]
    p, sv = p[loose], sv[loose]
    p, ok = refine_saddles(grey, p, min(radii) + 1.0, max_move=1.0)
    p, sv = p[ok], sv[ok]
    good = np.zeros(len(p), bool)
    angles = np.full((len(p), 2), np.nan)
    for r in radii:
        ok, ang = xjunction_test(light, p, r)
        new = ok & ~good
        angles[new] = ang[new]
        good |= ok
    p, sv, angles = p[good], sv[good], angles[good]
    # peaks of one junction that converged together: keep the strongest
    order = np.argsort(-sv)
    p, sv, angles = p[order], sv[order], angles[order]
    keep = np.ones(len(p), bool)
    if len(p) > 1:
        for i, j in sorted(cKDTree(p).query_pairs(1.0)):
            if keep[i] and keep[j]:
                keep[j] = False
    return p[keep], sv[keep].astype(np.float64), angles[keep]


def refine_saddles(grey: np.ndarray, p, radius_px, iterations: int = 12, smooth_sigma: float = 0.7,
                   max_move: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel X-junction positions by point symmetry (module docstring, step 3).

    Parameters
    ----------
    grey : (H, W) uint8
    p : (n, 2) float
        Starting positions, pixels (within about a third of `radius_px` of the junction).
    radius_px : float or (n,) float
        Radius of the disc of offsets, pixels: smaller than the distance to any other feature.
    iterations : int
        Gauss-Newton steps at most.
    smooth_sigma : float
        Gaussian smoothing of the image before sampling, pixels.
    max_move : float
        Largest move accepted, as a share of the radius.

    Returns
    -------
    p_refined : (n, 2) float
    ok : (n,) bool
        Converged, moved less than `max_move` x `radius_px` and stayed inside the image.
    """
    p0 = np.asarray(p, dtype=np.float64).reshape(-1, 2)
    n = len(p0)
    if n == 0:
        return p0.copy(), np.zeros(0, bool)
    radius = np.broadcast_to(np.asarray(radius_px, dtype=np.float64), (n,)).copy()
    h, wd = grey.shape[:2]
    # work on the region the offsets can reach (plus the smoothing's support)
    pad = 1.5 * radius.max() + 4.0 * smooth_sigma + 4.0
    x0 = int(max(0, np.floor(np.nanmin(p0[:, 0]) - pad)))
    y0 = int(max(0, np.floor(np.nanmin(p0[:, 1]) - pad)))
    x1 = int(min(wd, np.ceil(np.nanmax(p0[:, 0]) + pad) + 1))
    y1 = int(min(h, np.ceil(np.nanmax(p0[:, 1]) + pad) + 1))
    if x1 - x0 < 3 or y1 - y0 < 3:
        return p0.copy(), np.zeros(n, bool)
    origin = np.array([x0, y0], dtype=np.float64)
    p_img = p0
    p0 = p0 - origin
    img = smoothed(grey[y0:y1, x0:x1], smooth_sigma)
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3) * 0.125
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3) * 0.125
    # unit offsets over a half disc (each pair d, -d once), Gaussian weights
    u = np.linspace(-1.0, 1.0, 11)
    ux, uy = np.meshgrid(u, u)
    half = ((uy > 0) | ((uy == 0) & (ux > 0))) & (ux * ux + uy * uy <= 1.0)
    ux, uy = ux[half], uy[half]
    w = np.exp(-(ux * ux + uy * uy) / (2 * 0.5**2))
    c = p0.copy()
    active = np.ones(n, bool)
    for _ in range(iterations):
        if not active.any():
            break
        ia = np.nonzero(active)[0]
        dx = radius[ia, None] * ux[None]
        dy = radius[ia, None] * uy[None]
        xp, yp = (c[ia, 0:1] + dx).astype(np.float32), (c[ia, 1:2] + dy).astype(np.float32)
        xm, ym = (c[ia, 0:1] - dx).astype(np.float32), (c[ia, 1:2] - dy).astype(np.float32)
        samp = [cv2.remap(im, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
                for im in (img, gx, gy) for mx, my in ((xp, yp), (xm, ym))]
        r = samp[0] - samp[1]
        jx = samp[2] - samp[3]
        jy = samp[4] - samp[5]
        a11 = (w * jx * jx).sum(1)
        a12 = (w * jx * jy).sum(1)
        a22 = (w * jy * jy).sum(1)
        b1 = -(w * jx * r).sum(1)
        b2 = -(w * jy * r).sum(1)
        det = a11 * a22 - a12 * a12
        with np.errstate(divide="ignore", invalid="ignore"):
            sx = (a22 * b1 - a12 * b2) / det
            sy = (a11 * b2 - a12 * b1) / det
        bad = ~np.isfinite(sx) | ~np.isfinite(sy)
        sx[bad], sy[bad] = 0.0, 0.0
        step = np.hypot(sx, sy)
        lim = 0.25 * radius[ia]
        scale = np.minimum(1.0, lim / np.maximum(step, 1e-12))
        c[ia, 0] += sx * scale
        c[ia, 1] += sy * scale
        done = (step < 1e-3) | bad
        active[ia[done]] = False
    moved = np.linalg.norm(c - p0, axis=1)
    c = c + origin
    ok = (np.isfinite(c).all(axis=1) & (moved < max_move * radius) & (c[:, 0] >= 0) & (c[:, 1] >= 0)
          & (c[:, 0] <= wd - 1) & (c[:, 1] <= h - 1))
    c[~np.isfinite(c).all(axis=1)] = p_img[~np.isfinite(c).all(axis=1)]
    return c, ok


def refine_square_corners(grey: np.ndarray, corners, inner_px, outer_px, *, positions: int = 21,
                          samples: int = 33, iterations: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Corners of dark squares on a bright ground (AprilTags) as intersections of their edges.

    Each side of a square is located along its normal at `positions` places between 15 % and
    85 % of its length (the maximum of the grey-level gradient on a profile reaching `inner_px`
    into the square and `outer_px` out of it, placed to sub-pixel by a parabola), the side's
    offsets are fitted by a quadratic in the position along it (lens distortion bends it), and
    each corner is where the tangents of its two sides' curves meet. A symmetric blur moves an
    edge nowhere, so unlike a gradient-orthogonality refinement (``cornerSubPix``) on an
    L-shaped corner the result is not pulled into the square by the blur.

    Parameters
    ----------
    grey : (H, W) uint8
    corners : (T, 4, 2) float
        Rough corners of T squares, clockwise in the image (ArUco order), pixels.
    inner_px, outer_px : float or (T,) float
        How far the profiles reach inside (within the dark border) and outside, pixels.
    positions, samples : int
        Profiles per side and samples per profile.
    iterations : int
        Rounds (each re-fits the sides from the corners of the last).

    Returns
    -------
    corners : (T, 4, 2) float
    ok : (T, 4) bool
        Both sides fitted and the corner moved less than a tenth of the square's side (>= 2 px).
    """
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2).copy()
    t_n = len(c)
    if t_n == 0:
        return c, np.zeros((0, 4), bool)
    c0 = c.copy()
    inner = np.broadcast_to(np.asarray(inner_px, dtype=np.float64), (t_n,))
    outer = np.broadcast_to(np.asarray(outer_px, dtype=np.float64), (t_n,))
    light = smoothed(grey, 0.7)
    s = np.linspace(0.15, 0.85, positions)
    u = np.linspace(0.0, 1.0, samples)
    ok = np.ones((t_n, 4), bool)
    for _ in range(iterations):
        a, b = c, np.roll(c, -1, axis=1)                                          # side k: a[k] -> b[k]
        e = b - a
        length = np.linalg.norm(e, axis=2, keepdims=True)
        e = e / length
        n = np.stack([e[..., 1], -e[..., 0]], axis=-1)                            # outward normal
        t = -inner[:, None, None] + (inner + outer)[:, None, None] * u[None, None, :]   # (T, 1, P)
        base = a[:, :, None, :] + s[None, None, :, None] * (b - a)[:, :, None, :]       # (T, 4, M, 2)
        pts = base[..., None, :] + t[:, :, None, :, None] * n[:, :, None, None, :]     # (T, 4, M, P, 2)
        flat = pts.reshape(-1, samples, 2).astype(np.float32)
        prof = cv2.remap(light, flat[..., 0], flat[..., 1], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
        g = np.gradient(prof, axis=1)                                               # dark -> bright: > 0
        k = np.argmax(g, axis=1)
        r = np.arange(len(g))
        g0 = g[r, k]
        # centroid of the gradient over the run of samples around the peak above a fifth of it
        idx = np.arange(samples)[None]
        low = g < 0.2 * g0[:, None]
        left = np.where(low & (idx < k[:, None]), idx, -1).max(axis=1) + 1
        right = np.where(low & (idx > k[:, None]), idx, samples).min(axis=1) - 1
        run = (idx >= left[:, None]) & (idx <= right[:, None])
        gw = np.where(run, g - 0.2 * g0[:, None], 0.0)
        frac = (gw * (idx - k[:, None])).sum(axis=1) / np.maximum(gw.sum(axis=1), 1e-12)
        step = (inner + outer) / (samples - 1)                                      # (T,) px per sample
        pos = (k + frac).reshape(t_n, 4, positions)
        off = -inner[:, None, None] + pos * step[:, None, None]                       # edge offset along n, px
        contrast = (g0 > 3.0).reshape(t_n, 4, positions)
        # quadratic fit of the offsets in s (least squares; positions without an edge left out)
        vand = np.stack([np.ones_like(s), s, s * s], axis=1)                        # (M, 3)
        w = contrast.astype(np.float64)
        ata = np.einsum("tkm,mi,mj->tkij", w, vand, vand)
        atb = np.einsum("tkm,mi,tkm->tki", w, vand, off)
        enough = w.sum(axis=2) >= 5
        ata[~enough] = np.eye(3)
        coef = np.linalg.solve(ata, atb[..., None])[..., 0]                           # (T, 4, 3)
        ok &= enough & np.roll(enough, 1, axis=1)         # corner k joins side k and side k - 1
        # side k at s = 0 (start: corner k) and side k - 1 at s = 1 (end: corner k)
        def point_dir(kk, s_at):
            cf = coef[:, kk]
            off_s = cf[:, 0] + cf[:, 1] * s_at + cf[:, 2] * s_at**2
            d_off = cf[:, 1] + 2 * cf[:, 2] * s_at
            seg = (b - a)[:, kk]
            return a[:, kk] + s_at * seg + off_s[:, None] * n[:, kk], seg + d_off[:, None] * n[:, kk]
        new = np.empty_like(c)
        for kk in range(4):
            pa, da = point_dir(kk, 0.0)
            pb, db = point_dir((kk - 1) % 4, 1.0)
            m = np.stack([da, -db], axis=2)                                           # (T, 2, 2)
            det = np.linalg.det(m)
            good = np.abs(det) > 1e-9
            m[~good] = np.eye(2)
            alpha = np.linalg.solve(m, (pb - pa)[..., None])[:, 0, 0]
            new[:, kk] = np.where(good[:, None], pa + alpha[:, None] * da, c[:, kk])
            ok[:, kk] &= good
        c = np.where(ok[..., None], new, c)
    side = np.linalg.norm(c0 - np.roll(c0, -1, axis=1), axis=2).mean(axis=1)
    ok &= np.isfinite(c).all(axis=2) & (np.linalg.norm(c - c0, axis=2) < np.maximum(2.0, 0.1 * side)[:, None])
    return c, ok
