"""A chessboard's inner corners as a lattice grown from X-junctions (:mod:`mocapfj.vision.corners`).

OpenCV's classic detector (``findChessboardCorners``) segments the squares into quadrilaterals and
fails when strong distortion curves them, blur merges them or the white quiet zone is cut; its
sector-based detector (``findChessboardCornersSB``, Duda and Frese 2018) fails on strongly curved
boards too and costs about a second per megapixel. Here, after Geiger et al. 2012, who grow
boards from seed corners:

- **Seed**: a square of four X-junctions: a junction, its nearest neighbours along its two lines
  that are joined to it by an edge between a dark and a bright square (a diagonal neighbour, which
  strong foreshortening can bring near a line's direction, crosses the middle of a square), and
  the neighbour of both arms' ends.
- **Growth**, round by round: each unfilled node next to the grown part is predicted by the
  homography of the filled nodes within two steps (all of a round's nodes solved at once), or by
  a quadratic along its row or column, which bends with the lens; it takes the candidate nearest
  to a prediction (within 0.45 of the local spacing, and unambiguous), or the one reached by
  following the squares' edges from its neighbours; the candidate must be an X-junction out to a
  third of a square (the outer squares' corners against a thin white border are not).
- **The board**: the grown lattice must hold exactly one window of the board's size, filled but
  for at most 3 nodes, which are then predicted and placed by the symmetric refinement.

Pixel coordinates follow docs/conventions.md.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

from .corners import refine_saddles, saddle_points, smoothed, xjunction_test

__all__ = ["grow_lattice", "lattice_size", "lattice_spacing", "predict_nodes"]


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
    light = smoothed(grey, 0.7)
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
    light = smoothed(grey, 0.7)
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
