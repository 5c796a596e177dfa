"""Retro-reflective markers in camera images: bright blobs to sub-pixel centroids.

For a stack of frames (T, H, W) at once, without a Python loop over pixels or blobs:

1. **Background and noise** per frame: the median grey level and 1.4826 x the median absolute
   deviation of a 1-in-16 subsample (blobs cover a small share of a mocap image).
2. **Threshold** (default background + max(6 noise SDs, 4 grey levels)) and 8-connected components
   of the pixels above it in all frames at once (a graph of the sparse pixels and their forward
   neighbours, ``scipy.sparse.csgraph.connected_components``: a mocap image is mostly dark, so
   only the few bright pixels are visited after the threshold). Components whose thresholded area is outside [min_area_px,
   max_area_px] or that touch the image border are left out.
3. **Support**: each component grown by `ring_px` pixels, so that the faint anti-aliased edge
   pixels below the threshold count too (pixels two blobs both reach are left out).
4. **Intensity-weighted centroid** over the support with weights I - background (not clipped, so
   the noise of the ring does not bias it), by ``np.bincount`` moments: the centroid, the second
   moments and the sums for its uncertainty.
5. **Shape and quality**: circularity = sqrt(lambda_min / lambda_max) of the weighted second
   moments (1 for a disc; two touching discs of radius r at distance d give r / sqrt(r^2 + d^2));
   blobs below `min_circularity` (merged or smeared markers) are left out and counted. The
   centroid's SD per coordinate from the pixel noise, sigma_c = noise sqrt(sum (x_i - x_c)^2) / sum w
   (first-order propagation through the centroid), is the quantitative quality; ``quality`` in
   [0, 1] ranks blobs (circularity^2 x snr / (snr + 10), snr the peak contrast over the noise).

Pixels follow docs/conventions.md: the centre of the top-left pixel is (0, 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from ..types import Detections

__all__ = ["Blobs", "detect_blobs"]

_MAX_PIXELS = 1 << 25          # pixels per chunk of frames (about 25 frames of 1.3 MP)


@dataclass(frozen=True, eq=False)
class Blobs:
    """Blobs found in a stack of frames.

    Attributes
    ----------
    frame : (n,) int
        Frame of each blob (index into the stack).
    xy_px : (n, 2) float
        Intensity-weighted centroids, pixels.
    sigma_px : (n,) float
        SD of each centroid coordinate from the image noise, pixels.
    area_px : (n,) int
        Pixels above the threshold.
    circularity : (n,) float
        sqrt(lambda_min / lambda_max) of the weighted second moments (1 = round).
    radius_px : (n,) float
        2 sqrt(sqrt(det M)) of the weighted second moments M (the radius of a uniform disc).
    peak : (n,) float
        Highest grey level above the background.
    saturated : (n,) bool
        Some pixel at the image type's largest value.
    quality : (n,) float
        circularity^2 snr / (snr + 10) in [0, 1].
    background, noise : (T,) float
        Per-frame background grey level and noise SD.
    rejected : dict
        Components left out, by reason: "area", "border", "circularity".
    """

    frame: np.ndarray
    xy_px: np.ndarray
    sigma_px: np.ndarray
    area_px: np.ndarray
    circularity: np.ndarray
    radius_px: np.ndarray
    peak: np.ndarray
    saturated: np.ndarray
    quality: np.ndarray
    background: np.ndarray
    noise: np.ndarray
    rejected: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.frame.size)

    def detections(self, camera: int, frame_offset: int = 0) -> Detections:
        """These blobs as unlabelled detections of `camera` (point_id -1)."""
        n = self.frame.size
        return Detections(frame=self.frame + int(frame_offset), camera=np.full(n, int(camera)), xy_px=self.xy_px,
                          point_id=np.full(n, -1))

    def to_dict(self) -> dict:
        return {"n_blobs": len(self), "n_frames": int(self.background.size),
                "blobs_per_frame": len(self) / max(1, self.background.size),
                "sigma_px_median": float(np.median(self.sigma_px)) if len(self) else math.nan,
                "circularity_median": float(np.median(self.circularity)) if len(self) else math.nan,
                "rejected": dict(self.rejected)}


def _stack(images) -> np.ndarray:
    a = np.asarray(images)
    if a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[1] < 3 or a.shape[2] < 3:
        raise InputError(None, "images", "a grey image (H, W) or a stack of them (T, H, W)", f"shape {a.shape}")
    if a.dtype.kind not in "uif":
        raise InputError(None, "images", "grey levels (integers or floats)", f"dtype {a.dtype}")
    return a


def detect_blobs(images, *, threshold: float | None = None, min_area_px: int = 3, max_area_px: int = 5000,
                 min_circularity: float = 0.7, ring_px: int = 1, threshold_sigmas: float = 6.0) -> Blobs:
    """Bright blobs in grey images: sub-pixel centroids with shape filters and uncertainty.

    Parameters
    ----------
    images : (H, W) or (T, H, W) array
        Grey images (uint8, uint16 or float); bright markers on a darker background.
    threshold : float, optional
        Absolute grey level a blob's core must exceed; default per frame: background +
        max(`threshold_sigmas` x noise, 4 grey levels).
    min_area_px, max_area_px : int
        Bounds of a blob's thresholded area, pixels.
    min_circularity : float
        Least sqrt(lambda_min / lambda_max) of a blob's weighted second moments.
    ring_px : int
        How far each blob's support reaches beyond its thresholded core, pixels.

    Returns
    -------
    Blobs
        Sorted by frame, then by y and x.
    """
    stack = _stack(images)
    T, H, W = stack.shape
    top = float(np.iinfo(stack.dtype).max) if stack.dtype.kind in "ui" else math.inf
    sub = stack[:, 1::4, 1::4].reshape(T, -1).astype(np.float32)
    bg = np.median(sub, axis=1)
    noise = 1.4826 * np.median(np.abs(sub - bg[:, None]), axis=1)
    noise = np.maximum(noise, 0.5 if stack.dtype.kind in "ui" else 1e-6)
    thr = bg + np.maximum(threshold_sigmas * noise, 4.0 if stack.dtype.kind in "ui" else 0.0)
    if threshold is not None:
        thr = np.full(T, float(threshold))
    per = max(1, _MAX_PIXELS // (H * W))
    parts = []
    rejected = {"area": 0, "border": 0, "circularity": 0}
    for f0 in range(0, T, per):
        parts.append(_chunk(stack[f0:f0 + per], f0, bg[f0:f0 + per], noise[f0:f0 + per], thr[f0:f0 + per],
                            top, min_area_px, max_area_px, min_circularity, ring_px, rejected))
    cols = [np.concatenate([p[k] for p in parts]) for k in range(9)]
    return Blobs(*cols, background=bg.astype(np.float64), noise=noise.astype(np.float64), rejected=rejected)


def _chunk(frames, f0, bg, noise, thr, top, min_area, max_area, min_circ, ring, rejected):
    """Blobs of frames[f0:f0 + T]: the columns of :class:`Blobs` (arrays), in their order."""
    T, H, W = frames.shape
    if frames.dtype.kind in "ui":          # compare in the image's own type: no float copy of the frames
        level = np.clip(np.floor(thr), 0, top).astype(frames.dtype)
        mask = frames > level[:, None, None]
    else:
        mask = frames > thr[:, None, None]
    core = np.flatnonzero(mask)                                            # sorted flat indices (t, y, x)
    n_pix = core.size
    empty = (np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int64), np.zeros(0),
             np.zeros(0), np.zeros(0), np.zeros(0, bool), np.zeros(0))
    if not n_pix:
        return empty
    fx = core % W
    fy = (core // W) % H
    ft = core // (W * H)
    # 8-connected components of the sparse core pixels (scipy csgraph on the forward neighbours)
    src, dst = [], []
    for off, okx, oky in ((1, fx + 1 < W, True), (W - 1, fx > 0, fy + 1 < H), (W, True, fy + 1 < H),
                          (W + 1, fx + 1 < W, fy + 1 < H)):
        cand = core + off
        pos = np.minimum(np.searchsorted(core, cand), n_pix - 1)
        hit = (core[pos] == cand) & okx & oky
        src.append(np.flatnonzero(hit))
        dst.append(pos[hit])
    src, dst = np.concatenate(src), np.concatenate(dst)
    graph = coo_matrix((np.ones(src.size, np.int8), (src, dst)), shape=(n_pix, n_pix)).tocsr()
    m_all, lab = connected_components(graph, directed=False)
    area = np.bincount(lab, minlength=m_all)
    x0 = np.full(m_all, W)
    y0 = np.full(m_all, H)
    x1 = np.full(m_all, -1)
    y1 = np.full(m_all, -1)
    np.minimum.at(x0, lab, fx)
    np.minimum.at(y0, lab, fy)
    np.maximum.at(x1, lab, fx)
    np.maximum.at(y1, lab, fy)
    keep = (area >= min_area) & (area <= max_area)
    border = (x0 < ring + 1) | (y0 < ring + 1) | (x1 > W - ring - 2) | (y1 > H - ring - 2)
    rejected["area"] += int((~keep).sum())
    rejected["border"] += int((keep & border).sum())
    keep &= ~border
    if not keep.any():
        return empty
    sel = keep[lab]
    ft, fy, fx, lab = ft[sel], fy[sel], fx[sel], lab[sel]
    if ring > 0:                          # the support: each core grown by `ring` pixels
        d = np.arange(-ring, ring + 1)
        dy, dx = (a.ravel() for a in np.meshgrid(d, d, indexing="ij"))
        nt = np.repeat(ft, dy.size)
        ny = (fy[:, None] + dy[None]).ravel()
        nx = (fx[:, None] + dx[None]).ravel()
        nl = np.repeat(lab, dy.size)
        key = (nt * H + ny) * W + nx                                       # in range: border blobs dropped
        pos = np.minimum(np.searchsorted(core, key), n_pix - 1)
        outside = core[pos] != key
        key, nt, ny, nx, nl = key[outside], nt[outside], ny[outside], nx[outside], nl[outside]
        u, first, inv = np.unique(key, return_index=True, return_inverse=True)
        lo = np.full(u.size, np.iinfo(np.int64).max)
        hi = np.full(u.size, -1)
        np.minimum.at(lo, inv, nl)
        np.maximum.at(hi, inv, nl)
        pick = first[lo == hi]                                              # pixels only one blob reaches
        ft = np.concatenate([ft, nt[pick]])
        fy = np.concatenate([fy, ny[pick]])
        fx = np.concatenate([fx, nx[pick]])
        lab = np.concatenate([lab, nl[pick]])
    ids = np.flatnonzero(keep)
    comp = np.searchsorted(ids, lab)
    m = ids.size
    val = frames[ft, fy, fx].astype(np.float64)
    w = val - bg[ft]
    s0 = np.bincount(comp, w, m)
    with np.errstate(divide="ignore", invalid="ignore"):
        cx = np.bincount(comp, w * fx, m) / s0
        cy = np.bincount(comp, w * fy, m) / s0
        ddx = fx - cx[comp]
        ddy = fy - cy[comp]
        mxx = np.bincount(comp, w * ddx * ddx, m) / s0
        myy = np.bincount(comp, w * ddy * ddy, m) / s0
        mxy = np.bincount(comp, w * ddx * ddy, m) / s0
        tr = mxx + myy
        disc = np.sqrt(np.maximum((mxx - myy) ** 2 + 4 * mxy * mxy, 0.0))
        lmax, lmin = (tr + disc) / 2, (tr - disc) / 2
        circ = np.sqrt(np.clip(lmin / lmax, 0.0, 1.0))
        radius = 2.0 * np.sqrt(np.sqrt(np.maximum(lmax * lmin, 0.0)))
        frame_of = np.zeros(m, np.int64)
        frame_of[comp] = ft
        nz = noise[frame_of]
        sig = nz * np.sqrt(0.5 * np.bincount(comp, ddx * ddx + ddy * ddy, m)) / s0
    peak = np.full(m, -np.inf)
    np.maximum.at(peak, comp, w)
    sat = np.zeros(m, bool)
    if math.isfinite(top):
        np.logical_or.at(sat, comp, val >= top)
    good = np.isfinite(cx) & (s0 > 0) & (circ >= min_circ)
    rejected["circularity"] += int((~good).sum())
    snr = peak / nz
    quality = circ**2 * snr / (snr + 10.0)
    order = np.lexsort((cx[good], cy[good], frame_of[good]))
    g = np.flatnonzero(good)[order]
    return (frame_of[g] + f0, np.stack([cx[g], cy[g]], axis=1), sig[g], area[ids[g]].astype(np.int64), circ[g],
            radius[g], peak[g], sat[g], quality[g])
