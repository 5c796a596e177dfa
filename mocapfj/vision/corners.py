"""Chessboard corners without OpenCV's board finders: saddle points, their sub-pixel position
by point symmetry, and a lattice grown from a seed square with local homographies.

OpenCV's classic detector (``findChessboardCorners``) segments the squares into quadrilaterals and
fails when strong distortion curves them, blur merges them or the white quiet zone is cut;
its sector-based detector (``findChessboardCornersSB``, Duda and Frese 2018) fails on strongly
curved boards too and costs about a second per megapixel. Here:

1. **Saddle points** (Chen and Zhang 2005): at an X-junction of a chessboard the Gaussian-smoothed
   grey level I has a saddle, ``det(Hessian) < 0``. Local maxima of ``Ixy^2 - Ixx Iyy`` are
   candidates, placed to sub-pixel by the local quadratic (``-H^-1 grad I``) and kept when the grey
   levels on small circles around them look like an X-junction: four sign changes about their
   mean, the second harmonic dominant and the pattern point-symmetric (an X-junction of straight
   edges is symmetric under a half turn whatever the angle between its lines; an L-corner, an edge
   or the board's outer border is not).
2. **Growth** (after Geiger et al. 2012, who grow boards from seed corners): a seed square of
   four candidates (a corner, its nearest neighbours along its two lines, and the opposite
   corner) fixes a lattice; each unfilled lattice node next to the grown part is predicted by the
   homography of the filled nodes within two steps of it and takes the candidate within 0.3 of
   the local spacing. Local homographies follow strong distortion that a global one cannot.
3. **Sub-pixel position by point symmetry**: the corner c minimises
   ``sum_d w(d) (I(c + d) - I(c - d))^2`` over a disc of offsets d (Gauss-Newton on bilinear
   samples of a lightly smoothed image). Unlike the gradient-orthogonality of ``cornerSubPix``
   it needs no straight edges over the window, only the half-turn symmetry of the junction.

Pixel coordinates follow docs/conventions.md (origin at the centre of the top-left pixel).
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

__all__ = ["saddle_points", "xjunction_test", "refine_saddles", "grow_lattice", "lattice_spacing", "lattice_size", "predict_nodes",
           "refine_square_corners"]

_N_CIRCLE = 32
_THETA = np.arange(_N_CIRCLE) * (2.0 * np.pi / _N_CIRCLE)


def _float_image(grey: np.ndarray, sigma: float) -> np.ndarray:
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
    g = _float_image(grey, sigma)
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
    light = _float_image(grey, 0.7)
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
    img = _float_image(grey[y0:y1, x0:x1], smooth_sigma)
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


def _angdiff(a, b):
    d = np.abs((a - b) % np.pi)
    return np.minimum(d, np.pi - d)


def _edge_contrast(light: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """How much the segment a-b looks like an edge between a dark and a bright square all along:
    the grey levels a fifth of its length to either side, at 20, 35, 50, 65 and 80 % along it,
    differ with one sign; the weakest difference as a share of the strongest (about 1 for an
    edge, about 0 for a square's diagonal, which crosses the middle of a square, or a step that
    leaves the board)."""
    d = b - a
    n = np.array([-d[1], d[0]]) * 0.2
    t = np.array([0.2, 0.35, 0.5, 0.65, 0.8])[:, None]
    pts = np.vstack([a + t * d + n, a + t * d - n]).astype(np.float32)
    v = cv2.remap(light, pts[:, 0:1], pts[:, 1:2], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel()
    diff = v[:5] - v[5:]
    top = np.abs(diff).max()
    if top < 6.0:
        return 0.0
    return float((diff * np.sign(diff.sum())).min() / top)


def _step(p: np.ndarray, tree: cKDTree, light: np.ndarray, k: int, direction: np.ndarray,
          tol_deg: float = 20.0, lengths: tuple[float, float] | None = None) -> int | None:
    """The lattice neighbour of candidate k in `direction` (image vector): the nearest candidate
    within `tol_deg` of it whose segment from k is a square's edge (`_edge_contrast` above 0.7),
    and, with `lengths` (lo, hi), between lo and hi times the length of `direction` away."""
    _, nn = tree.query(p[k], k=min(40, len(p)))
    step = np.linalg.norm(direction)
    for c in nn[1:]:
        v = p[c] - p[k]
        if lengths is not None and not lengths[0] * step <= np.linalg.norm(v) <= lengths[1] * step:
            continue
        cosang = v @ direction / max(np.linalg.norm(v) * np.linalg.norm(direction), 1e-12)
        if cosang > np.cos(np.radians(tol_deg)) and _edge_contrast(light, p[k], p[c]) > 0.7:
            return int(c)
    return None


def _seed(p: np.ndarray, angles: np.ndarray, tree: cKDTree, s: int, light: np.ndarray) -> dict | None:
    """A seed square {(i, j): point index} at candidate s, or None.

    Its arms are the nearest candidates along each of the junction's two lines whose segments are
    edges between a dark and a bright square (a diagonal neighbour, which strong foreshortening
    can bring near a line's direction, crosses the middle of a square); the fourth corner is the
    neighbour of the arms' ends along the other arm, the same from both."""
    arms = []
    for line in (0, 1):
        a = angles[s, line]
        ends = [_step(p, tree, light, s, sign * np.array([np.cos(a), np.sin(a)]), 15.0) for sign in (1.0, -1.0)]
        ends = [e for e in ends if e is not None]
        if not ends:
            return None
        arms.append(min(ends, key=lambda e: np.linalg.norm(p[e] - p[s])))
    u, w = p[arms[0]] - p[s], p[arms[1]] - p[s]
    via_u = _step(p, tree, light, arms[0], w)
    via_w = _step(p, tree, light, arms[1], u)
    k = via_u if via_u is not None else via_w
    if k is None or (via_w is not None and via_w != k) or k in (s, *arms):
        return None
    return {(0, 0): s, (1, 0): arms[0], (0, 1): arms[1], (1, 1): k}


def _line_predictions(node: tuple, grid: dict, p: np.ndarray) -> list:
    """Quadratic extrapolations of `node` along the lattice's rows and columns: p0 = 3 p1 - 3 p2 + p3
    from three known nodes in a line behind it (they follow the bending of strong distortion)."""
    out = []
    for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        back = [(node[0] - m * di, node[1] - m * dj) for m in (1, 2, 3)]
        if all(b in grid for b in back):
            a, b, c = (p[grid[q]] for q in back)
            out.append(3.0 * a - 3.0 * b + c)
    return out


def predict_nodes(nodes, known_ij, known_xy, reach: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Lattice nodes predicted by the local homographies of known nodes around them.

    For each node, the homography (normalised DLT with h33 = 1) of the known nodes within
    `reach` lattice steps (Chebyshev distance; the node itself left out) gives its image position
    and those of the nodes one step along each lattice axis. All nodes are solved at once.

    Parameters
    ----------
    nodes : (F, 2) float
        Lattice coordinates (i, j) to predict.
    known_ij : (K, 2) float
        Lattice coordinates of the known nodes.
    known_xy : (K, 2) float
        Their image positions, pixels.
    reach : int

    Returns
    -------
    q : (F, 3, 2) float
        Predicted pixels of node, node + (1, 0) and node + (0, 1).
    ok : (F,) bool
        At least 4 known nodes around it that determine a homography (not three of four, or
        all, on one lattice line).
    """
    nodes = np.asarray(nodes, dtype=np.float64).reshape(-1, 2)
    kij = np.asarray(known_ij, dtype=np.float64).reshape(-1, 2)
    kxy = np.asarray(known_xy, dtype=np.float64).reshape(-1, 2)
    f = len(nodes)
    q = np.full((f, 3, 2), np.nan)
    if f == 0 or len(kij) == 0:
        return q, np.zeros(f, bool)
    d = kij[None] - nodes[:, None]                                           # (F, K, 2) node-centred
    m = (np.abs(d).max(axis=2) <= reach) & (np.abs(d).max(axis=2) > 0)
    w = m.astype(np.float64)
    n = w.sum(axis=1)
    ok = n >= 4
    nn = np.maximum(n, 1.0)
    mx = (w[..., None] * kxy[None]).sum(axis=1) / nn[:, None]
    dist = np.linalg.norm(kxy[None] - mx[:, None], axis=2)
    sc = np.sqrt(2.0) / np.maximum((w * dist).sum(axis=1) / nn, 1e-12)
    x = (kxy[None] - mx[:, None]) * sc[:, None, None]                         # (F, K, 2) normalised
    u, v = d[..., 0], d[..., 1]
    one, zero = np.ones_like(u), np.zeros_like(u)
    r1 = np.stack([u, v, one, zero, zero, zero, -u * x[..., 0], -v * x[..., 0]], axis=-1)
    r2 = np.stack([zero, zero, zero, u, v, one, -u * x[..., 1], -v * x[..., 1]], axis=-1)
    ata = np.einsum("fk,fki,fkj->fij", w, r1, r1) + np.einsum("fk,fki,fkj->fij", w, r2, r2)
    atb = np.einsum("fk,fki->fi", w * x[..., 0], r1) + np.einsum("fk,fki->fi", w * x[..., 1], r2)
    # general position: no lattice row, column or diagonal holds all but one of the points
    for line in (d[..., 0], d[..., 1], d[..., 0] - d[..., 1], d[..., 0] + d[..., 1]):
        key = np.rint(line).astype(np.int64) + 2 * reach
        onehot = key[..., None] == np.arange(4 * reach + 1)
        ok &= (w[..., None] * onehot).sum(axis=1).max(axis=1) <= n - 2
    ata[~ok] = np.eye(8)
    h = np.linalg.solve(ata, atb[..., None])[..., 0]                          # (F, 8)
    for col, (a, b) in enumerate(((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))):
        den = h[:, 6] * a + h[:, 7] * b + 1.0
        q[:, col, 0] = (h[:, 0] * a + h[:, 1] * b + h[:, 2]) / den / sc + mx[:, 0]
        q[:, col, 1] = (h[:, 3] * a + h[:, 4] * b + h[:, 5]) / den / sc + mx[:, 1]
    ok &= np.isfinite(q).all(axis=(1, 2))
    return q, ok


def _grow(p: np.ndarray, angles: np.ndarray, tree: cKDTree, grid: dict, max_nodes: int,
          light: np.ndarray) -> dict:
    """Grow `grid` {(i, j): candidate} round by round (module docstring, step 2)."""
    used = set(grid.values())
    tried: dict = {}                      # node -> nearby known nodes when it last failed
    steps = np.array([(1, 0), (-1, 0), (0, 1), (0, -1)])
    while len(grid) < max_nodes:
        keys = np.array(list(grid.keys()), dtype=np.float64)
        xy = p[list(grid.values())]
        front = {tuple(k) for k in (keys[:, None] + steps[None]).reshape(-1, 2).astype(int).tolist()} - grid.keys()
        front = np.array(sorted(front), dtype=np.float64)
        near = (np.abs(keys[None] - front[:, None]).max(axis=2) <= 2).sum(axis=1)
        fresh = np.array([tried.get(tuple(int(c) for c in n)) != k for n, k in zip(front, near)])
        front, near = front[fresh], near[fresh]
        if not len(front):
            break
        q, ok = predict_nodes(front, keys, xy)
        spacing = np.minimum(np.linalg.norm(q[:, 1] - q[:, 0], axis=1), np.linalg.norm(q[:, 2] - q[:, 0], axis=1))
        dd, kk = tree.query(np.where(ok[:, None], q[:, 0], 0.0), k=2)
        d1, d2, k = dd[:, 0], dd[:, 1], kk[:, 0]
        # where extrapolating along a row or column lands nearer a candidate, take that prediction
        for f in np.nonzero(ok)[0]:
            for e in _line_predictions(tuple(int(c) for c in front[f]), grid, p):
                (e1, e2), (ek, _) = tree.query(e, k=2)
                if e1 < d1[f]:
                    d1[f], d2[f], k[f] = e1, e2, ek
        good = ok & np.isfinite(spacing) & (d1 <= 0.45 * spacing) & (d1 <= 0.5 * d2)
        good &= ~np.isin(k, list(used))
        # far from the prediction (strong distortion): the junction's lines must follow the lattice
        dirs = np.sort(np.arctan2(q[:, 1:, 1] - q[:, :1, 1], q[:, 1:, 0] - q[:, :1, 0]) % np.pi, axis=1)
        cand = np.sort(angles[k], axis=1)
        lines_ok = (_angdiff(cand, dirs).max(axis=1) < np.radians(20))
        good &= (d1 <= 0.25 * spacing) | lines_ok
        added = 0
        for f in np.argsort(d1 / np.where(spacing > 0, spacing, np.inf)):
            node = tuple(int(c) for c in front[f])
            if not good[f]:                          # no prediction close enough: follow the edges
                walk = _walk(node, grid, p, tree, light)
                if walk is not None and walk not in used:
                    good[f], k[f] = True, walk
            if good[f] and np.isfinite(spacing[f]):
                # a junction of the board is symmetric out to a third of a square; the corners of the
                # outer squares against a thin white border and a dark background beyond are not
                good[f] = bool(xjunction_test(light, p[int(k[f])][None], max(3.0, 0.3 * spacing[f]))[0][0])
            if good[f] and int(k[f]) not in used:
                grid[node] = int(k[f])
                used.add(int(k[f]))
                added += 1
            elif not good[f]:
                tried[node] = near[f]
        if not added:
            break
    return grid


def _walk(node: tuple, grid: dict, p: np.ndarray, tree: cKDTree, light: np.ndarray) -> int | None:
    """The candidate at `node` reached by stepping along lattice edges from its known neighbours
    (`_step` in the direction of the row or column behind each); None unless they agree."""
    found = set()
    for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        m1, m2 = (node[0] - di, node[1] - dj), (node[0] - 2 * di, node[1] - 2 * dj)
        if m1 in grid and m2 in grid:
            c = _step(p, tree, light, grid[m1], p[grid[m1]] - p[grid[m2]], 25.0, lengths=(0.4, 1.8))
            if c is not None:
                found.add(c)
    return found.pop() if len(found) == 1 else None


def _fill(win: np.ndarray, grey: np.ndarray, light: np.ndarray, p: np.ndarray, tree: cKDTree) -> np.ndarray | None:
    """Fill the missing nodes of a (rows, cols, 2) window: the candidate nearest to the local
    homography's prediction (within 0.45 of the spacing), else the prediction itself, kept where
    the symmetric refinement converges on an X-junction; None when a node has none."""
    for y, x in np.argwhere(np.isnan(win[..., 0])):
        have = np.argwhere(~np.isnan(win[..., 0]))
        q, ok = predict_nodes([(x, y)], have[:, ::-1], win[have[:, 0], have[:, 1]])
        if not ok[0]:
            return None
        q = q[0]
        spacing = min(np.linalg.norm(q[1] - q[0]), np.linalg.norm(q[2] - q[0]))
        preds = [q[0]]
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):         # quadratic along rows and columns
            back = [(y - m * dy, x - m * dx) for m in (1, 2, 3)]
            if all(0 <= b[0] < win.shape[0] and 0 <= b[1] < win.shape[1] and not np.isnan(win[b][0]) for b in back):
                preds.append(3.0 * win[back[0]] - 3.0 * win[back[1]] + win[back[2]])
        dists, idx = tree.query(np.array(preds))
        best = int(np.argmin(dists))
        d, k = dists[best], idx[best]
        start = p[k:k + 1] if d < 0.45 * spacing else preds[best][None]
        r, ok = refine_saddles(grey, start, 4.0)
        if not ok[0] or not (xjunction_test(light, r, 3.0)[0][0] or xjunction_test(light, r, 5.0)[0][0]):
            return None
        if np.linalg.norm(win[have[:, 0], have[:, 1]] - r[0], axis=1).min() < 0.3 * spacing:
            return None                                                   # that junction is taken
        win[y, x] = r[0]
    return win


def grow_lattice(grey: np.ndarray, cols: int, rows: int, *, max_seeds: int = 12, sigma: float = 1.5,
                 points: tuple | None = None, stats: dict | None = None) -> np.ndarray | None:
    """A chessboard's inner corners as a lattice grown from saddle points (module docstring).

    Parameters
    ----------
    grey : (H, W) uint8
    cols, rows : int
        Inner corners along the board's x and y.
    max_seeds : int
        Seed squares tried (strongest saddles first).
    sigma : float
        Scale of the saddle response, pixels.
    points : tuple, optional
        `saddle_points` (grey, sigma) when already computed.
    stats : dict, optional
        Filled with ``best`` (the most nodes of a grown lattice inside one cols x rows window),
        ``best_xy`` (their pixels) and ``larger`` (a lattice held more than one full window: the
        print is larger).

    Returns
    -------
    (rows, cols, 2) float or None
        Pixel positions, in lattice order (not yet oriented: the caller fixes which corner is
        the board's first), or None when no seed grows into exactly one cols x rows block.
    """
    stats = {} if stats is None else stats
    stats.update(best=0, larger=False, best_xy=np.zeros((0, 2)))
    p, score, angles = saddle_points(grey, sigma) if points is None else points
    if len(p) < 0.8 * cols * rows:
        stats["best"] = len(p)
        return None
    tree = cKDTree(p)
    light = _float_image(grey, 0.7)
    seeds = 0
    covered: set = set()
    for s in np.argsort(-score):
        if seeds >= max_seeds:
            break
        if s in covered:
            continue
        grid = _seed(p, angles, tree, int(s), light)
        if grid is None:
            continue
        seeds += 1
        grid = _grow(p, angles, tree, grid, max_nodes=4 * cols * rows, light=light)
        covered |= set(grid.values())
        keys = np.array(list(grid.keys()))
        lo = keys.min(axis=0)
        arr = np.full(tuple(keys.max(axis=0) - lo + 1)[::-1] + (2,), np.nan)
        for (i, j), k in grid.items():
            arr[j - lo[1], i - lo[0]] = p[k]
        for a in (arr, arr.transpose(1, 0, 2)):
            full = ~np.isnan(a[..., 0])
            ny, nx = full.shape
            if ny < rows or nx < cols:
                if full.sum() > stats["best"]:
                    stats["best"], stats["best_xy"] = int(full.sum()), a[full]
                continue
            csum = np.pad(full.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
            cnt = csum[rows:, cols:] - csum[:-rows, cols:] - csum[rows:, :-cols] + csum[:-rows, :-cols]
            best = cnt.max()
            if best > stats["best"]:
                y, x = np.argwhere(cnt == best)[0]
                w = a[y:y + rows, x:x + cols]
                stats["best"], stats["best_xy"] = int(best), w[~np.isnan(w[..., 0])]
            if best == rows * cols and (cnt == best).sum() > 1:
                stats["larger"] = True
            if best < rows * cols - 3 or (cnt == best).sum() != 1:
                continue
            y, x = np.argwhere(cnt == best)[0]
            win = a[y:y + rows, x:x + cols].copy()
            if best < rows * cols:
                win = _fill(win, grey, light, p, tree)
            if win is not None:
                return win
    return None


def lattice_size(grey: np.ndarray, *, max_seeds: int = 3, sigma: float = 1.5,
                 points: tuple | None = None) -> tuple[int, int] | None:
    """Inner corners (along, across) of the largest chessboard-like lattice in `grey`, the longer
    side first, or None: what a board file should say when it finds nothing (the largest window
    of a grown lattice at least 97 % filled, 3 x 2 or larger)."""
    p, score, angles = saddle_points(grey, sigma) if points is None else points
    if len(p) < 6:
        return None
    tree = cKDTree(p)
    light = _float_image(grey, 0.7)
    best = None
    seeds = 0
    for s in np.argsort(-score):
        if seeds >= max_seeds:
            break
        grid = _seed(p, angles, tree, int(s), light)
        if grid is None:
            continue
        seeds += 1
        grid = _grow(p, angles, tree, grid, max_nodes=5000, light=light)
        keys = np.array(list(grid.keys()))
        lo = keys.min(axis=0)
        full = np.zeros(tuple(keys.max(axis=0) - lo + 1), bool)
        full[keys[:, 0] - lo[0], keys[:, 1] - lo[1]] = True
        csum = np.pad(full.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
        # the largest window at least 97 % filled (stray junctions beside the board left out)
        for a in range(full.shape[0], 1, -1):
            for b in range(full.shape[1], 1, -1):
                if best is not None and a * b <= best[0] * best[1]:
                    continue
                cnt = csum[a:, b:] - csum[:-a, b:] - csum[a:, :-b] + csum[:-a, :-b]
                if cnt.max() >= 0.97 * a * b:
                    best = tuple(sorted((a, b), reverse=True))
    return best if best is not None and best[0] >= 3 and best[1] >= 2 else None


def lattice_spacing(grid: np.ndarray) -> np.ndarray:
    """Distance from each node of a (rows, cols, 2) lattice to its nearest 4-neighbour, (rows, cols) px."""
    d = np.full(grid.shape[:2], np.inf)
    dx = np.linalg.norm(np.diff(grid, axis=1), axis=2)
    dy = np.linalg.norm(np.diff(grid, axis=0), axis=2)
    d[:, :-1] = np.minimum(d[:, :-1], dx)
    d[:, 1:] = np.minimum(d[:, 1:], dx)
    d[:-1] = np.minimum(d[:-1], dy)
    d[1:] = np.minimum(d[1:], dy)
    return d


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
    light = _float_image(grey, 0.7)
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
