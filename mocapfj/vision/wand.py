"""Wand calibration of a camera rig, as commercial motion capture (Vicon, OptiTrack, Qualisys) does it.

A wand with K >= 2 collinear markers at known distances is waved through the volume while every
camera records the markers' blob centroids; an L-frame of 3-4 markers then sets the world's
origin and axes. The cameras' intrinsics are known (a prior intrinsic calibration); their poses
come from the wand:

1. **Labels.** Unlabelled blobs are labelled per camera and frame: the K blobs must lie on a line
   (in undistorted coordinates); their order along it and the ratios of the gaps between them,
   compared with the wand's own (which must not be symmetric), tell which end is which. Frames
   where a camera sees another number of blobs, or an ambiguous ratio, are left out for it.
2. **Pairs.** Each pair of cameras with enough common frames gives an essential matrix
   (``cv2.findEssentialMat`` in normalised coordinates; Nister 2004, inside OpenCV's RANSAC,
   whose random generator is seeded: the same input gives the same answer) and a relative pose;
   the wand's length gives the scale of its translation (Borghese and Cerveri 2000).
3. **Pose graph**: robust rotation averaging, then translations (:mod:`mocapfj.vision.posegraph`).
4. **Bundle adjustment** (:mod:`mocapfj.vision.bundle`, kind ``"wand"``): every camera's pose
   (camera 0 holds the gauge), optionally its intrinsics, and per frame the wand's position and
   direction, with the markers at their known distances along it: the wand-length constraint is
   exact. Robust loss, outliers dropped, covariance from the Schur complement.
5. **Check.** Each marker is triangulated again without the constraint, frame by frame; the
   spread of the first-to-last distance (wand length mean and SD, mm) is the calibration's
   accuracy check that commercial systems report.
6. **L-frame** (:mod:`mocapfj.vision.multiview`). Its markers (labelled, or matched across
   cameras and by their known shape) are triangulated, and the rigid transform onto their nominal
   positions (Kabsch 1976) moves the rig into the L-frame's world.

Standard deviations are those of the bundle adjustment, in the gauge of camera 0 (positions
along the world's axes); the L-frame's own uncertainty is not in them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from ..rotations import matrix_from_rotvec
from ..types import Camera, Detections, Rig, Wand
from .bundle import bundle_adjust, wand_basis
from .multiview import lframe_pose, normalized_points, triangulate
from .posegraph import average_rotations, average_translations, components
from .projection import camera_parameters, project_batch
from .rig import CameraSummary, intrinsic_mask, rig_metadata, summarize_cameras

__all__ = ["WandCalibration", "calibrate_wand", "label_wand_blobs"]


@dataclass(frozen=True, eq=False)
class WandCalibration:
    """Result of :func:`calibrate_wand`.

    Attributes
    ----------
    rig : Rig
        Calibrated cameras in the L-frame's world (or camera 0's without an L-frame).
    cameras : tuple of CameraSummary
        Per camera: RMS (px), residual in mm at the markers' depth (``extra["rms_mm"]``), SDs.
    sigma_px, rms_px, initial_rms_px : float
    wand_length_mm : float
        The wand's nominal length (first to last marker).
    wand_length_mean_mm, wand_length_sd_mm : float
        Mean and SD of the length of the wand triangulated frame by frame, without the constraint.
    n_wand_lengths : int
        Frames that gave a length.
    n_frames, n_frames_used : int
        Frames with detections, and frames in the bundle adjustment.
    labelled : bool
        Whether the input named the markers (else :func:`label_wand_blobs` did).
    n_views_unlabelled : int
        Camera-frames left out because their blobs could not be labelled.
    world : str
        "lframe" or "camera 0".
    lframe_rms_mm : float or None
        RMS distance of the triangulated L-frame markers from their nominal positions.
    refined_intrinsics : tuple of str
    covariance, parameter_names : camera parameters' covariance (gauge: camera 0), their names
    nfev : int
    """

    rig: Rig
    cameras: tuple
    sigma_px: float
    rms_px: float
    initial_rms_px: float
    wand_length_mm: float
    wand_length_mean_mm: float
    wand_length_sd_mm: float
    n_wand_lengths: int
    n_frames: int
    n_frames_used: int
    labelled: bool
    n_views_unlabelled: int
    world: str
    lframe_rms_mm: float | None
    refined_intrinsics: tuple
    covariance: np.ndarray
    parameter_names: tuple
    nfev: int

    def to_dict(self) -> dict:
        """Machine-readable summary (the CLI's --json)."""
        from .rig import camera_dict

        cams = []
        for cam, s in zip(self.rig.cameras, self.cameras):
            d = s.to_dict()
            d.update(camera_dict(cam))
            cams.append(d)
        return {"method": "wand", "world": self.world, "sigma_px": self.sigma_px, "rms_px": self.rms_px,
                "initial_rms_px": self.initial_rms_px, "wand_length_mm": self.wand_length_mm,
                "wand_length_mean_mm": self.wand_length_mean_mm, "wand_length_sd_mm": self.wand_length_sd_mm,
                "n_wand_lengths": self.n_wand_lengths, "n_frames": self.n_frames,
                "n_frames_used": self.n_frames_used, "labelled": self.labelled,
                "n_views_unlabelled": self.n_views_unlabelled, "lframe_rms_mm": self.lframe_rms_mm,
                "refined_intrinsics": list(self.refined_intrinsics), "nfev": self.nfev, "cameras": cams}


def label_wand_blobs(det: Detections, wand: Wand, cameras: Sequence[Camera], *,
                     line_tol_px: float = 2.5) -> tuple[Detections, int]:
    """Give unlabelled wand blobs their marker index (module docstring, step 1).

    Returns the labelled detections (camera-frames that cannot be labelled left out) and how many
    camera-frames were left out.
    """
    K = wand.markers_m.size
    s = np.diff(wand.markers_m) / wand.length_m
    s_rev = s[::-1]
    if K < 3 or np.abs(s - s_rev).max() < 0.05:
        raise InputError(None, "wand markers_m", "labelled detections (point_id), or a wand of 3 or more markers "
                         "with unequal spacing (so that its ends can be told apart)", wand.markers_m.tolist())
    order = np.lexsort((det.xy_px[:, 0], det.frame, det.camera))
    cam, frame, xy = det.camera[order], det.frame[order], det.xy_px[order]
    key = cam.astype(np.int64) * (int(frame.max(initial=0)) + 1) + frame
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    count = np.diff(np.r_[start, key.size])
    n_groups = start.size
    ok_g = count == K
    rows = (start[ok_g][:, None] + np.arange(K)).ravel()
    G = int(ok_g.sum())
    n = normalized_points(cameras, cam[rows], xy[rows]).reshape(G, K, 2)
    f = np.array([cameras[int(c)].K[0, 0] for c in cam[rows][::K]]) if G else np.zeros(0)
    mean = n.mean(axis=1, keepdims=True)
    d = n - mean
    cov = np.einsum("gki,gkj->gij", d, d)
    w, V = np.linalg.eigh(cov) if G else (np.zeros((0, 2)), np.zeros((0, 2, 2)))
    axis = V[:, :, 1]                                                # principal direction
    along = np.einsum("gki,gi->gk", d, axis)
    perp = np.abs(np.einsum("gki,gi->gk", d, np.stack([-axis[:, 1], axis[:, 0]], 1))) * f[:, None]
    srt = np.argsort(along, axis=1)
    pos = np.take_along_axis(along, srt, axis=1)
    gaps = np.diff(pos, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = gaps / gaps.sum(axis=1, keepdims=True)
        fwd = np.abs(g - s).sum(axis=1)
        bwd = np.abs(g - s_rev).sum(axis=1)
    sep = np.abs(s - s_rev).sum()
    good = (perp.max(axis=1) < line_tol_px) & (np.abs(fwd - bwd) > 0.4 * sep) & np.isfinite(fwd)
    label = np.where((fwd <= bwd)[:, None], np.argsort(srt, axis=1), K - 1 - np.argsort(srt, axis=1))
    keep_rows = rows.reshape(G, K)[good].ravel()
    labels = label[good].ravel()
    src = order[keep_rows]
    out = Detections(det.frame[src], det.camera[src], det.xy_px[src], labels)
    return out, int(n_groups - good.sum())


def _pair_poses(cams, lab: Detections, K: int, wand: Wand, min_points: int):
    """Relative pose samples (i, j, R_ij, t_ij, weight) from the essential matrix of each camera pair."""
    nrm = normalized_points(cams, lab.camera, lab.xy_px)
    key = lab.frame.astype(np.int64) * K + lab.point_id
    out = []
    C = len(cams)
    for a in range(C):
        for b in range(a + 1, C):
            ia = np.flatnonzero(lab.camera == a)
            ib = np.flatnonzero(lab.camera == b)
            common, xa, xb = np.intersect1d(key[ia], key[ib], assume_unique=True, return_indices=True)
            if common.size < min_points:
                continue
            pa, pb = nrm[ia[xa]], nrm[ib[xb]]
            f = 0.5 * (cams[a].K[0, 0] + cams[b].K[0, 0])
            E, mask = cv2.findEssentialMat(pa, pb, np.eye(3), method=cv2.RANSAC, prob=0.999, threshold=2.0 / f)
            if E is None or E.shape != (3, 3):
                continue
            n_in, R, t, mask = cv2.recoverPose(E, pa, pb, np.eye(3), mask=mask)
            inl = mask.ravel() > 0
            if n_in < min_points:
                continue
            X = cv2.triangulatePoints(np.hstack([np.eye(3), np.zeros((3, 1))]), np.hstack([R, t]),
                                      pa[inl].T, pb[inl].T)
            X = (X[:3] / X[3]).T
            fr, mk = common[inl] // K, common[inl] % K
            # distances between markers of the same frame, against their true spacing
            ratios = []
            for i in range(K):
                for j in range(i + 1, K):
                    ci = np.flatnonzero(mk == i)
                    cj = np.flatnonzero(mk == j)
                    both, ii, jj = np.intersect1d(fr[ci], fr[cj], return_indices=True)
                    if both.size:
                        dist = np.linalg.norm(X[ci[ii]] - X[cj[jj]], axis=1)
                        ratios.append((wand.markers_m[j] - wand.markers_m[i]) / dist)
            if not ratios:
                continue
            scale = float(np.median(np.concatenate(ratios)))
            out.append((b, a, R, t.ravel() * scale, float(n_in)))
    return out


def _check(det: Detections, n_cameras: int, where: str) -> None:
    from .rig import check_detections

    check_detections(det, n_cameras, where)


def calibrate_wand(detections: Detections, wand: Wand, intrinsics: Rig | Sequence[Camera], *,
                   lframe: Detections | None = None, refine_intrinsics="fixed", loss: str = "soft_l1",
                   f_scale_px: float = 1.0, min_pair_points: int = 30, source: str | None = None,
                   lframe_source: str | None = None, max_lframe_rms_m: float = 0.01) -> WandCalibration:
    """Calibrate a rig's extrinsics from a wand wave (module docstring).

    Parameters
    ----------
    detections : Detections
        Blob centroids per camera and frame; point_id the marker index (0 = the first marker of
        `wand`), or -1 everywhere for unlabelled blobs.
    wand : Wand
        Marker distances along the wand and, to set the world, the L-frame.
    intrinsics : Rig or sequence of Camera
        Each camera's intrinsics (poses ignored), in camera-number order.
    lframe : Detections, optional
        The still L-frame's blobs (labelled or not); without it the world is camera 0.
    refine_intrinsics : "fixed", "default", "all" or names
        Intrinsics refined with the poses (default: held, as a prior intrinsic calibration gave them).
    min_pair_points : int
        Common marker observations a camera pair needs for an essential matrix.
    source, lframe_source : str, optional
        File names for error messages.
    max_lframe_rms_m : float
        A larger misfit of the L-frame markers to their nominal layout is refused.
    """
    where = source or "detections"
    cams = tuple(intrinsics.cameras if isinstance(intrinsics, Rig) else intrinsics)
    C = len(cams)
    _check(detections, C, where)
    K = wand.markers_m.size
    names = [c.name for c in cams]
    pid = detections.point_id
    labelled = bool((pid >= 0).any())
    if labelled:
        if (pid < 0).any() or pid.max() >= K:
            bad = int(np.flatnonzero((pid < 0) | (pid >= K))[0])
            raise InputError(where, f"row {bad} point_id", f"a marker index 0..{K - 1} on every row (or -1 on every "
                             "row for unlabelled blobs)", int(pid[bad]))
        lab = detections
        n_unlab = 0
    else:
        lab, n_unlab = label_wand_blobs(detections, wand, cams)
    if lab.frame.size == 0:
        raise InputError(where, "detections", f"frames where a camera sees the wand's {K} markers", "none")
    mask, refined = intrinsic_mask(refine_intrinsics, C, "refine_intrinsics")
    for c in range(C):
        if not (lab.camera == c).any():
            raise InputError(where, f"camera {c} ({names[c]})", "wand observations", "none")
    samples = _pair_poses(cams, lab, K, wand, min_pair_points)
    si = np.array([s[0] for s in samples], np.intp)
    sj = np.array([s[1] for s in samples], np.intp)
    lab_c = components(C, si, sj)
    for c in range(C):
        if lab_c[c] != lab_c[0]:
            raise InputError(where, f"camera {c} ({names[c]})",
                             f"at least {min_pair_points} wand markers seen together with camera 0 or a camera "
                             "linked to it", "too few", hint="wave the wand where this camera and another see it")
    w = np.array([s[4] for s in samples])
    R_abs, _ = average_rotations(C, si, sj, np.array([s[2] for s in samples]), weights=w)
    t_abs, _ = average_translations(C, si, sj, R_abs, np.array([s[3] for s in samples]), weights=w, min_scale=1e-3)
    start = [Camera(c.name, c.size, c.K, c.dist, R, t) for c, R, t in zip(cams, R_abs, t_abs)]
    # the wand in each frame from the starting rig
    frames = np.unique(lab.frame)
    f_index = np.searchsorted(frames, lab.frame)
    point = f_index * K + lab.point_id
    p, nv = triangulate(start, lab.camera, point, lab.xy_px, frames.size * K)
    p = p.reshape(-1, K, 3)
    have = np.isfinite(p).all(axis=2)
    ok_f = have.sum(axis=1) >= 2
    s = wand.markers_m
    c0 = np.zeros((frames.size, 3))
    u0 = np.tile([1.0, 0.0, 0.0], (frames.size, 1))
    for f in np.flatnonzero(ok_f):
        k = np.flatnonzero(have[f])
        A = np.column_stack([np.ones(k.size), s[k]])
        sol = np.linalg.lstsq(A, p[f, k], rcond=None)[0]
        u = sol[1] / np.linalg.norm(sol[1])
        u0[f] = u
        c0[f] = np.mean(p[f, k] - s[k, None] * u, axis=0)
    keep = ok_f[f_index]
    if ok_f.sum() < 10:
        raise InputError(where, "detections", "at least 10 frames where two cameras see two wand markers",
                         f"{int(ok_f.sum())} frame(s)")
    used_frames = np.flatnonzero(ok_f)
    g_of_f = np.full(frames.size, -1)
    g_of_f[used_frames] = np.arange(used_frames.size)
    cam_i, grp = lab.camera[keep], g_of_f[f_index[keep]]
    local = np.zeros((cam_i.size, 3))
    local[:, 0] = s[lab.point_id[keep]]
    params = [camera_parameters(c) for c in start]
    rv0, tv0, intr0, extra0 = (np.stack([q[k] for q in params]) for k in range(4))
    groups = np.c_[c0[used_frames], np.zeros((used_frames.size, 2))]
    pose_free = np.ones(C, bool)
    pose_free[0] = False
    ba = bundle_adjust("wand", cam_i, grp, local, lab.xy_px[keep], rv0, tv0, intr0, extra0, groups,
                       pose_free=pose_free, intr_free=mask, basis=wand_basis(u0[used_frames]), loss=loss,
                       f_scale_px=f_scale_px)
    if not (np.isfinite(ba.rvecs).all() and np.isfinite(ba.tvecs).all() and np.isfinite(ba.intrinsics).all()):
        raise InputError(where, "bundle adjustment", "a finite solution", "non-finite parameters")
    out = []
    for c in range(C):
        i = ba.intrinsics[c]
        d = np.r_[i[4:9], extra0[c]][: max(cams[c].dist.size, 5)]
        K_ = np.array([[i[0], 0.0, i[2]], [0.0, i[1], i[3]], [0.0, 0.0, 1.0]])
        out.append(Camera(names[c], cams[c].size, K_, d, matrix_from_rotvec(ba.rvecs[c]), ba.tvecs[c]))
    # unconstrained wand lengths from the inlier observations
    inl = ba.inlier
    pt, nvw = triangulate(out, cam_i[inl], (grp * K + lab.point_id[keep])[inl], lab.xy_px[keep][inl],
                          used_frames.size * K)
    pt = pt.reshape(-1, K, 3)
    lengths = np.linalg.norm(pt[:, -1] - pt[:, 0], axis=1)
    lengths = lengths[np.isfinite(lengths)]
    # L-frame
    R_wg, t_wg, lrms, world = np.eye(3), np.zeros(3), None, "camera 0"
    if lframe is not None:
        if wand.lframe_m is None:
            raise InputError(lframe_source or "L-frame detections", "wand file", "an [lframe] table with markers_m "
                             "for the L-frame detections", "none")
        R_wg, t_wg, _, lrms = lframe_pose(out, lframe, wand, lframe_source or "L-frame detections")
        if not lrms <= max_lframe_rms_m:
            raise InputError(lframe_source or "L-frame detections", "L-frame markers",
                             f"positions matching the wand file's L-frame within {max_lframe_rms_m * 1000:.0f} mm RMS",
                             f"{lrms * 1000:.1f} mm RMS", hint="check the L-frame's marker positions in the wand file")
        world = "lframe"
        out = [Camera(c.name, c.size, c.K, c.dist, c.R_cam_world @ R_wg.T, c.t_cam_world - c.R_cam_world @ R_wg.T @ t_wg)
               for c in out]
    n_obs = np.bincount(cam_i, minlength=C)
    summaries = summarize_cameras(ba, names, cam_i, n_obs, R_wg, t_wg)
    # residual in mm at the marker's depth: px * z / f
    pj = project_batch(ba.rvecs, ba.tvecs, ba.intrinsics, extra0, cam_i, ba.points_world, jacobians=False)
    mm = np.linalg.norm(ba.residual_px, axis=1) * pj.z_cam / ba.intrinsics[cam_i, 0] * 1000.0
    for c in range(C):
        sel = inl & (cam_i == c)
        extra = {"rms_mm": float(np.sqrt(np.mean(mm[sel] ** 2))) if sel.any() else float("nan"),
                 "n_frames": int(np.unique(grp[cam_i == c]).size)}
        summaries[c] = CameraSummary(**{**summaries[c].__dict__, "extra": extra})
    meta = rig_metadata("wand", summaries, ba.sigma_px, refined,
                        "camera 0 fixed in the bundle adjustment; " + ("world from the L-frame" if lframe is not None
                                                                       else "camera 0 is the world"))
    meta.update({"wand": wand.name, "wand_length_mm": wand.length_m * 1000.0,
                 "wand_length_mean_mm": float(np.mean(lengths) * 1000.0) if lengths.size else 0.0,
                 "wand_length_sd_mm": float(np.std(lengths, ddof=1) * 1000.0) if lengths.size > 1 else 0.0})
    if lrms is not None:
        meta["lframe_rms_mm"] = lrms * 1000.0
    return WandCalibration(
        rig=Rig(tuple(out), meta), cameras=tuple(summaries), sigma_px=ba.sigma_px, rms_px=ba.rms_px,
        initial_rms_px=ba.initial_rms_px, wand_length_mm=wand.length_m * 1000.0,
        wand_length_mean_mm=float(np.mean(lengths) * 1000.0) if lengths.size else float("nan"),
        wand_length_sd_mm=float(np.std(lengths, ddof=1) * 1000.0) if lengths.size > 1 else float("nan"),
        n_wand_lengths=int(lengths.size), n_frames=int(frames.size), n_frames_used=int(used_frames.size),
        labelled=labelled, n_views_unlabelled=n_unlab, world=world,
        lframe_rms_mm=None if lrms is None else lrms * 1000.0, refined_intrinsics=refined, covariance=ba.covariance,
        parameter_names=ba.names, nfev=ba.nfev)

