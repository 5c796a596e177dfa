"""Points seen by several calibrated cameras: normalised coordinates, triangulation, rigid fits and
the L-frame that sets a rig's world (used by :mod:`mocapfj.vision.wand`).

Conventions: docs/conventions.md (world-to-camera extrinsics, pixels 0-based at pixel centres, metres).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import permutations

import numpy as np

from ..errors import InputError
from ..types import Camera, Detections, Wand
from .projection import camera_parameters, normalized_from_pixels, project_batch

__all__ = ["normalized_points", "triangulate", "kabsch", "lframe_pose"]


def normalized_points(cams: Sequence[Camera], camera: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Undistorted normalised coordinates (N, 2) of pixels xy (N, 2), each in its camera[n]."""
    out = np.full(xy.shape, np.nan)
    for c, cam in enumerate(cams):
        sel = camera == c
        if sel.any():
            out[sel] = normalized_from_pixels(cam, xy[sel])
    return out


def triangulate(cameras: Sequence[Camera], camera, point, xy_px, n_points: int, *,
                iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Points seen by several cameras: linear triangulation in normalised coordinates (DLT;
    Hartley and Zisserman 2003, §12.2), then Gauss-Newton on the pixel reprojection error.

    Parameters
    ----------
    cameras : sequence of Camera
    camera, point : (N,) int
        Camera and point index of each observation.
    xy_px : (N, 2) float
    n_points : int

    Returns
    -------
    p_world : (n_points, 3)
        NaN for points seen by fewer than two cameras.
    n_views : (n_points,) int
    """
    camera = np.asarray(camera, dtype=np.intp)
    point = np.asarray(point, dtype=np.intp)
    xy_px = np.asarray(xy_px, dtype=np.float64)
    nrm = normalized_points(cameras, camera, xy_px)
    ok = np.isfinite(nrm).all(axis=1)
    camera, point, xy_px, nrm = camera[ok], point[ok], xy_px[ok], nrm[ok]
    P = np.stack([np.hstack([c.R_cam_world, c.t_cam_world[:, None]]) for c in cameras])[camera]     # (N, 3, 4)
    rows = np.concatenate([nrm[:, :1] * P[:, 2] - P[:, 0], nrm[:, 1:] * P[:, 2] - P[:, 1]], axis=1).reshape(-1, 2, 4)
    A = np.zeros((n_points, 4, 4))
    np.add.at(A, point, np.einsum("nri,nrj->nij", rows, rows))
    n_views = np.bincount(point, minlength=n_points)
    _, V = np.linalg.eigh(A)
    h = V[:, :, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        p = h[:, :3] / h[:, 3:4]
    p[n_views < 2] = np.nan
    params = [camera_parameters(c) for c in cameras]
    rv, tv, intr, extra = (np.stack([q[k] for q in params]) for k in range(4))
    for _ in range(iterations):
        pj = project_batch(rv, tv, intr, extra, camera, p[point])
        r = pj.xy_px - xy_px
        good = np.isfinite(r).all(axis=1)
        H = np.zeros((n_points, 3, 3))
        g = np.zeros((n_points, 3))
        np.add.at(H, point[good], np.einsum("nki,nkj->nij", pj.d_point[good], pj.d_point[good]))
        np.add.at(g, point[good], np.einsum("nki,nk->ni", pj.d_point[good], r[good]))
        solvable = (n_views >= 2) & (np.linalg.det(H) > 0)
        step = np.zeros((n_points, 3))
        step[solvable] = np.linalg.solve(H[solvable], g[solvable][..., None])[..., 0]
        p = p - step
    return p, n_views


def lframe_pose(cams: Sequence[Camera], det: Detections, wand: Wand, where: str = "L-frame detections"):
    """Where the L-frame is in the rig's current frame: (R, t) with p_world = R p_rig + t, the
    triangulated markers (L, 3) in the world, and the fit's RMS (m). Unlabelled blobs are matched
    across cameras by epipolar geometry and labelled by the L-frame's known shape."""
    L = wand.lframe_m
    nL = L.shape[0]
    C = len(cams)
    from .rig import check_detections

    check_detections(det, C, where)
    # per camera: one still position per blob (median over frames)
    blobs = {}
    for c in range(C):
        sel = det.camera == c
        if not sel.any():
            continue
        xy, pid, fr = det.xy_px[sel], det.point_id[sel], det.frame[sel]
        if (pid >= 0).any():
            if (pid < 0).any() or pid.max() >= nL:
                raise InputError(where, "point_id", f"L-frame marker indices 0..{nL - 1} on every row, or -1 on every row",
                                 int(pid.max()))
            pts = np.full((nL, 2), np.nan)
            for k in np.unique(pid):
                pts[k] = np.median(xy[pid == k], axis=0)
            blobs[c] = pts
        else:
            counts = np.bincount(fr - fr.min())
            ref_f = fr.min() + int(np.argmax(counts))
            ref = xy[fr == ref_f]
            if ref.shape[0] != nL:
                continue
            d = np.linalg.norm(xy[:, None, :] - ref[None], axis=2)
            near = d.argmin(axis=1)
            close = d.min(axis=1) < 3.0
            blobs[c] = np.array([np.median(xy[close & (near == k)], axis=0) for k in range(nL)])
    labelled = (det.point_id >= 0).any()
    if not labelled:
        full = [c for c in sorted(blobs) if np.isfinite(blobs[c]).all()]
        if len(full) < 2:
            raise InputError(where, "cameras", f"at least two cameras that see all {nL} L-frame markers",
                             f"{len(full)} camera(s)")
        # the pair with the widest angle between optical axes
        best = max(((a, b) for i, a in enumerate(full) for b in full[i + 1:]),
                   key=lambda ab: np.arccos(np.clip(cams[ab[0]].R_cam_world[2] @ cams[ab[1]].R_cam_world[2], -1, 1)))
        a, b = best
        na = normalized_from_pixels(cams[a], blobs[a])
        nb = normalized_from_pixels(cams[b], blobs[b])
        cand = []
        for perm in permutations(range(nL)):
            pts, _ = triangulate([cams[a], cams[b]], np.r_[np.zeros(nL, int), np.ones(nL, int)],
                                 np.r_[np.arange(nL), np.array(perm)], np.r_[blobs[a], blobs[b]], nL)
            for lab in permutations(range(nL)):
                R, t, rms = kabsch(pts, L[list(lab)])
                cand.append((rms, perm, lab))
        cand.sort(key=lambda x: x[0])
        rms0, perm, lab = cand[0]
        if len(cand) > 1 and cand[1][0] < 1.5 * rms0 + 1e-4 and (cand[1][2] != lab):
            raise InputError(where, "L-frame", "markers whose layout fixes their labels (an asymmetric L-frame), "
                             "or labelled detections (point_id)", "two labellings fit equally well")
        # labels: blob k of camera a is L-frame marker lab[k]; camera b's blob perm[k] too
        pts, _ = triangulate([cams[a], cams[b]], np.r_[np.zeros(nL, int), np.ones(nL, int)],
                             np.r_[np.array(lab), np.array(lab)], np.r_[blobs[a], blobs[b][list(perm)]], nL)
        del na, nb
        # every camera's blobs matched to the projections of these points
        cam_idx, pt_idx, xys = [], [], []
        for c, pts2 in sorted(blobs.items()):
            from .camera import project_points

            proj, _ = project_points(cams[c], pts)
            d = np.linalg.norm(pts2[:, None, :] - proj[None], axis=2)
            for k in range(pts2.shape[0]):
                j = int(np.argmin(d[k]))
                if d[k, j] < 5.0 and np.argmin(d[:, j]) == k:
                    cam_idx.append(c)
                    pt_idx.append(j)
                    xys.append(pts2[k])
    else:
        cam_idx, pt_idx, xys = [], [], []
        for c, pts2 in sorted(blobs.items()):
            for k in range(nL):
                if np.isfinite(pts2[k]).all():
                    cam_idx.append(c)
                    pt_idx.append(k)
                    xys.append(pts2[k])
    p, nv = triangulate(cams, np.array(cam_idx), np.array(pt_idx), np.array(xys).reshape(-1, 2), nL)
    if (nv < 2).any():
        k = int(np.flatnonzero(nv < 2)[0])
        raise InputError(where, f"L-frame marker {k}", "seen by at least two cameras", f"{int(nv[k])} camera(s)")
    R, t, rms = kabsch(p, L)
    return R, t, p @ R.T + t, rms


def kabsch(p: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Rotation and translation (no scale) with q ~ R p + t (Kabsch 1976), and the RMS residual."""
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    U, _, Vt = np.linalg.svd((p - pc).T @ (q - qc))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    t = qc - R @ pc
    return R, t, float(np.sqrt(np.mean(np.sum((p @ R.T + t - q) ** 2, axis=1))))


