"""Multi-camera rig calibration from a board seen by several cameras at once.

1. Each view (one camera, one frame) gives the board's pose in that camera by PnP (IPPE for a
   planar target, Collins and Bartoli 2014, refined by Levenberg-Marquardt; ``cv2.solvePnP``).
2. Cameras that saw the board at the same frame give samples of their relative pose; the pose
   graph over these co-observations is solved by robust rotation averaging and then translations
   (:mod:`mocapfj.vision.posegraph`: deterministic, no random sampling).
3. Bundle adjustment (:mod:`mocapfj.vision.bundle`) refines every camera's pose, the board's pose
   at every frame and, optionally, every camera's intrinsics, with a robust loss, then reports the
   reprojection RMS per camera and the covariance of the camera parameters.

The gauge: camera 0 is the world (R = I, t = 0); the board fixes the scale. Standard deviations
are those of the parameters in this gauge (a camera's SDs are relative to camera 0).
Conventions: docs/conventions.md (world-to-camera extrinsics, pixels 0-based at pixel centres).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..errors import InputError
from ..rotations import matrix_from_rotvec, rotvec_from_matrix
from ..types import Board, Camera, Detections, Rig
from .bundle import POSE_NAMES, BundleResult, bundle_adjust
from .posegraph import average_rotations, average_translations, chordal_mean, components, log_rotation
from .projection import INTRINSIC_NAMES, camera_parameters, rotation_jacobian

__all__ = ["RigCalibration", "CameraSummary", "calibrate_rig", "intrinsic_mask", "board_corner_table", "symmetry_maps",
           "summarize_cameras", "camera_position_std", "camera_dict", "check_detections", "rig_metadata"]

DEFAULT_INTRINSICS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")
"""Intrinsics refined by default (k3 is held: with k2 it trades off unless views fill the image corners)."""


def intrinsic_mask(intrinsics, n_cameras: int, where: str = "intrinsics") -> tuple[np.ndarray, tuple[str, ...]]:
    """(C, 9) bool mask of refined intrinsics from "fixed", "default", "all" or a sequence of names."""
    if isinstance(intrinsics, str):
        names = {"fixed": (), "none": (), "default": DEFAULT_INTRINSICS, "all": INTRINSIC_NAMES}.get(intrinsics)
        if names is None:
            raise InputError(None, where, "fixed, default, all or a list of names from "
                             + ", ".join(INTRINSIC_NAMES), repr(intrinsics))
    else:
        names = tuple(intrinsics)
        bad = [n for n in names if n not in INTRINSIC_NAMES]
        if bad:
            raise InputError(None, where, "names from " + ", ".join(INTRINSIC_NAMES), bad)
    m = np.array([n in names for n in INTRINSIC_NAMES])
    return np.tile(m, (n_cameras, 1)), tuple(n for n in INTRINSIC_NAMES if n in names)


@dataclass(frozen=True, eq=False)
class CameraSummary:
    """One camera's calibration quality.

    Attributes
    ----------
    name : str
    rms_px : float
        Reprojection RMS over its inlier observations (both coordinates), px.
    n_observations, n_outliers : int
        Points used, and dropped as outliers.
    std : dict
        SD of each estimated parameter: rx, ry, rz (rad), tx, ty, tz (m), fx, fy, cx, cy (px),
        k1, k2, p1, p2, k3; held parameters are left out.
    position_m : (3,)
        Optical centre in the world, m.
    position_std_m : (3,)
        Its SD per axis, m.
    rotation_std_rad : (3,)
        SD of its orientation about its own x, y, z axes (the error psi of R_est = exp([psi]) R,
        free of the rotation vector's chart), rad.
    extra : dict
        Stage-specific numbers (views, residual in mm, ...).
    """

    name: str
    rms_px: float
    n_observations: int
    n_outliers: int
    std: dict
    position_m: np.ndarray
    position_std_m: np.ndarray
    rotation_std_rad: np.ndarray
    extra: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = {"name": self.name, "rms_px": self.rms_px, "n_observations": self.n_observations,
             "n_outliers": self.n_outliers, "std": dict(self.std), "position_m": self.position_m.tolist(),
             "position_std_m": self.position_std_m.tolist(),
             "rotation_std_deg": np.degrees(self.rotation_std_rad).tolist()}
        d.update(self.extra)
        return d


@dataclass(frozen=True, eq=False)
class RigCalibration:
    """Result of :func:`calibrate_rig`.

    Attributes
    ----------
    rig : Rig
        The calibrated cameras (world = camera 0), metadata with units, residuals and SDs.
    cameras : tuple of CameraSummary
    sigma_px : float
        Residual SD per pixel coordinate over all inliers.
    rms_px, initial_rms_px : float
        Reprojection RMS after and before bundle adjustment (inliers).
    refined_intrinsics : tuple of str
    covariance : (P, P)
        Covariance of the free camera parameters, named by `parameter_names` ((camera, name)).
    parameter_names : tuple
    gauge : str
    n_frames : int
        Frames (board poses) used.
    dropped_views : tuple of dict
        Views left out, each with camera, frame and reason.
    rotation_residual_deg : float
        Median disagreement of the relative-rotation samples with the averaged rotations.
    nfev : int
        Residual evaluations of the bundle adjustment.
    """

    rig: Rig
    cameras: tuple
    sigma_px: float
    rms_px: float
    initial_rms_px: float
    refined_intrinsics: tuple
    covariance: np.ndarray
    parameter_names: tuple
    gauge: str
    n_frames: int
    dropped_views: tuple
    rotation_residual_deg: float
    nfev: int

    def to_dict(self) -> dict:
        """Machine-readable summary (the CLI's --json): per camera intrinsics, pose, residuals, SDs."""
        cams = []
        for cam, s in zip(self.rig.cameras, self.cameras):
            d = s.to_dict()
            d.update(camera_dict(cam))
            cams.append(d)
        return {"method": "board", "gauge": self.gauge, "n_frames": self.n_frames, "sigma_px": self.sigma_px,
                "rms_px": self.rms_px, "initial_rms_px": self.initial_rms_px,
                "refined_intrinsics": list(self.refined_intrinsics),
                "rotation_residual_deg": self.rotation_residual_deg, "nfev": self.nfev,
                "dropped_views": [dict(v) for v in self.dropped_views], "cameras": cams}


def camera_dict(cam: Camera) -> dict:
    """A camera's intrinsics and pose for a JSON summary (rotation vector, rad; translation, m)."""
    return {"size": list(cam.size), "fx": float(cam.K[0, 0]), "fy": float(cam.K[1, 1]), "cx": float(cam.K[0, 2]),
            "cy": float(cam.K[1, 2]), "dist": cam.dist.tolist(), "rotation": rotvec_from_matrix(cam.R_cam_world).tolist(),
            "translation_m": cam.t_cam_world.tolist()}


def camera_position_std(rvec: np.ndarray, tvec: np.ndarray, cov6: np.ndarray, R_world_gauge=None) -> np.ndarray:
    """SD (3,) of the optical centre -R(r)^T t from the covariance (6, 6) of (r, t), along the axes
    of the world R_world_gauge maps the gauge frame into (default: the gauge frame itself)."""
    def centre(x):
        return -matrix_from_rotvec(x[:3]).T @ x[3:]

    x0 = np.concatenate([rvec, tvec])
    J = np.empty((3, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = 1e-7
        J[:, k] = (centre(x0 + e) - centre(x0 - e)) / 2e-7
    if R_world_gauge is not None:
        J = np.asarray(R_world_gauge) @ J
    return np.sqrt(np.maximum(np.diag(J @ cov6 @ J.T), 0.0))


def summarize_cameras(ba: BundleResult, names: Sequence[str], camera_index: np.ndarray,
                      n_observations_total: np.ndarray, R_world_gauge=None, t_world_gauge=None) -> list[CameraSummary]:
    """Per camera RMS, counts, SDs and centre from a bundle adjustment; positions in the world
    p_world = R_world_gauge p_gauge + t_world_gauge when given (SDs rotated alike)."""
    Rw = np.eye(3) if R_world_gauge is None else np.asarray(R_world_gauge, dtype=np.float64)
    tw = np.zeros(3) if t_world_gauge is None else np.asarray(t_world_gauge, dtype=np.float64)
    out = []
    for c, name in enumerate(names):
        sel = ba.inlier & (camera_index == c)
        r = ba.residual_px[sel]
        std = {}
        idx6 = []
        for q, pname in enumerate(POSE_NAMES + INTRINSIC_NAMES):
            if (c, pname) in ba.names:
                k = ba.names.index((c, pname))
                std[pname] = float(np.sqrt(max(ba.covariance[k, k], 0.0)))
                if q < 6:
                    idx6.append(k)
        cov6 = np.zeros((6, 6))
        if len(idx6) == 6:
            cov6 = ba.covariance[np.ix_(idx6, idx6)]
        R, M = rotation_jacobian(ba.rvecs[c][None])
        A = R[0] @ M[0]                                   # psi = R M d(rvec)
        rot_sd = np.sqrt(np.maximum(np.diag(A @ cov6[:3, :3] @ A.T), 0.0))
        R = R[0]
        out.append(CameraSummary(
            name=str(name), rms_px=float(np.sqrt(np.mean(r**2))) if r.size else float("nan"),
            n_observations=int(sel.sum()), n_outliers=int(n_observations_total[c] - sel.sum()), std=std,
            position_m=Rw @ (-R.T @ ba.tvecs[c]) + tw,
            position_std_m=camera_position_std(ba.rvecs[c], ba.tvecs[c], cov6, Rw), rotation_std_rad=rot_sd))
    return out


def board_corner_table(board: Board) -> tuple[np.ndarray, np.ndarray]:
    """Corner ids and board-frame positions (N, 3) m of `board` (:func:`mocapfj.vision.boards.board_points`)."""
    from .boards import board_points

    ids, p = board_points(board)
    return np.asarray(ids, dtype=np.int64), np.asarray(p, dtype=np.float64)


def symmetry_maps(board: Board) -> list[np.ndarray]:
    """Id maps of the orientations a detection cannot tell apart (:func:`mocapfj.vision.boards.board_symmetry`):
    for each, ``m[id]`` is the corner the id names if the board lay turned by k quarter (or half)
    turns in its plane; the first map is the identity."""
    from .boards import board_symmetry

    n_sym = board_symmetry(board)
    ids, p = board_corner_table(board)
    c = p[:, :2].mean(axis=0)
    maps = []
    for k in range(n_sym):
        a = 2.0 * np.pi * k / n_sym
        Rz = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        q = (p[:, :2] - c) @ Rz.T + c
        d = np.linalg.norm(q[:, None, :] - p[None, :, :2], axis=2)
        maps.append(ids[np.argmin(d, axis=1)])
    return maps


def _resolve_symmetry(pose: dict, maps, p_of, cams, max_pnp_rms_px: float) -> dict:
    """Give each view of a symmetric board the orientation that agrees with the other cameras.

    In each frame the lowest-numbered camera keeps its detector's orientation; every other camera
    b takes the orientation whose relative rotation to it is nearest the pair's consensus, the
    candidate relative rotation that most other frames' candidates of the pair agree with (within
    3 deg)."""
    cand = {}
    for (c, f), (R, t, ids, xy) in pose.items():
        opts = []
        for m in maps:
            Rk, tk, rms = _pnp(p_of(m[ids]), xy, cams[c])
            opts.append((Rk, tk, m[ids], xy) if rms <= max_pnp_rms_px else None)
        cand[(c, f)] = opts
    by_frame: dict[int, list[int]] = {}
    for (c, f) in sorted(pose):
        by_frame.setdefault(f, []).append(c)
    pair_samples: dict = {}
    for f, cs in by_frame.items():
        r = cs[0]
        for b in cs[1:]:
            for k, o in enumerate(cand[(b, f)]):
                if o is not None:
                    pair_samples.setdefault((r, b), []).append((f, k, pose[(r, f)][0] @ o[0].T))
    out = dict(pose)
    for (r, b), samples in pair_samples.items():
        Rs = np.array([s[2] for s in samples])
        ang = np.linalg.norm(log_rotation(np.einsum("nij,mkj->nmik", Rs, Rs).reshape(-1, 3, 3)), axis=1)
        support = (ang.reshape(len(Rs), len(Rs)) < np.radians(3.0)).sum(axis=1)
        consensus = Rs[int(np.argmax(support))]
        for f in sorted({s[0] for s in samples}):
            ks = [(np.linalg.norm(log_rotation(s[2] @ consensus.T)), s[1]) for s in samples if s[0] == f]
            best = min(ks)[1]
            out[(b, f)] = cand[(b, f)][best]
    return out


def check_detections(det: Detections, n_cameras: int | None, where: str) -> None:
    """Refuse non-finite pixels (naming the row) and camera numbers beyond the rig's."""
    bad = ~np.isfinite(det.xy_px).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputError(where, f"row {k} (frame {int(det.frame[k])}, camera {int(det.camera[k])}) x_px/y_px",
                         "finite pixel coordinates", det.xy_px[k].tolist())
    if n_cameras is not None and det.camera.size and int(det.camera.max()) >= n_cameras:
        c = int(det.camera.max())
        raise InputError(where, "camera", f"camera numbers below {n_cameras} (the rig has {n_cameras} cameras)",
                         f"camera {c}")


def _pnp(p_board: np.ndarray, xy: np.ndarray, cam: Camera) -> tuple[np.ndarray, np.ndarray, float]:
    """Board pose in the camera (R, t) by IPPE + LM refinement, and its reprojection RMS (px).

    Corners off by more than max(3 px, 5 x the median residual) are set aside and the pose refitted
    (twice at most): a misdetected corner must not spoil the start of the bundle adjustment."""
    obj = p_board.astype(np.float64)
    img = xy.astype(np.float64)
    keep = np.ones(len(obj), bool)
    for _ in range(3):
        n, rvecs, tvecs, errs = cv2.solvePnPGeneric(obj[keep], img[keep], cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE)
        if n:
            best = int(np.argmin(np.asarray(errs).ravel()))
            rv, tv = rvecs[best], tvecs[best]
        else:
            _, rv, tv = cv2.solvePnP(obj[keep], img[keep], cam.K, cam.dist, flags=cv2.SOLVEPNP_SQPNP)
        rv, tv = cv2.solvePnPRefineLM(obj[keep], img[keep], cam.K, cam.dist, rv.copy(), tv.copy())
        proj, _ = cv2.projectPoints(obj, rv, tv, cam.K, cam.dist)
        e = np.linalg.norm(proj[:, 0] - img, axis=1)
        new = e <= max(3.0, 5.0 * float(np.median(e[keep])))
        if (new == keep).all() or new.sum() < 4:
            break
        keep = new
    rms = float(np.sqrt(np.mean(e[keep] ** 2)))
    return matrix_from_rotvec(rv.ravel()), tv.ravel(), rms


def _initial_intrinsics(views, board: Board, size, name: str) -> tuple[np.ndarray, np.ndarray]:
    """One camera's starting intrinsics from its own views: :func:`mocapfj.vision.intrinsics.calibrate_intrinsics`
    (k1, k2, p1, p2; outlier views and corners rejected)."""
    from .boards import BoardDetection
    from .intrinsics import calibrate_intrinsics

    dets = [BoardDetection(ids, xy, tuple(size), "given") for ids, xy in views]
    res = calibrate_intrinsics(dets, board, names=[f"{name} frame {f}" for f in range(len(views))], model="no_k3",
                               camera_name=name)
    return res.camera.K, np.r_[res.camera.dist[:4], 0.0]


def calibrate_rig(detections: Detections, board: Board, cameras: Rig | Sequence[Camera] | None = None, *,
                  image_sizes: Sequence[tuple[int, int]] | None = None, names: Sequence[str] | None = None,
                  intrinsics="default", loss: str = "soft_l1", f_scale_px: float = 1.0, min_corners: int = 6,
                  max_pnp_rms_px: float = 5.0, source: str | None = None) -> RigCalibration:
    """Calibrate a rig from board corners seen by several cameras at the same frames.

    Parameters
    ----------
    detections : Detections
        Board corners: frame (synchronised across cameras), camera number, xy_px, point_id = the
        board's corner id (:func:`board_corner_table`).
    board : Board
    cameras : Rig or sequence of Camera, optional
        Starting intrinsics (their poses are ignored). Without it each camera starts from its own
        views (:func:`mocapfj.vision.intrinsics.calibrate_intrinsics`, k3 = 0), which needs `image_sizes`.
    image_sizes : sequence of (width, height), optional
        Per camera, when `cameras` is not given.
    names : sequence of str, optional
        Camera names (default: those of `cameras`, else cam_<number>).
    intrinsics : "default", "all", "fixed" or a sequence of names
        Intrinsics refined in the bundle adjustment (default: all but k3).
    loss, f_scale_px : robust loss of the first bundle-adjustment pass and its scale, px.
    min_corners : int
        Views with fewer corners are left out.
    max_pnp_rms_px : float
        Views whose PnP reprojection RMS exceeds this (a misdetected board) are left out.
    source : str, optional
        What the detections came from, for error messages (a file or directory).

    Returns
    -------
    RigCalibration
    """
    where = source or "detections"
    if cameras is not None:
        cams0 = tuple(cameras.cameras if isinstance(cameras, Rig) else cameras)
        n_cam = len(cams0)
    else:
        if image_sizes is None:
            raise InputError(None, "image_sizes", "the image size of every camera (or starting intrinsics)", None)
        n_cam = len(image_sizes)
        cams0 = None
    check_detections(detections, n_cam, where)
    names = list(names) if names is not None else ([c.name for c in cams0] if cams0 else
                                                    [f"cam_{c}" for c in range(n_cam)])
    ids_all, p_all = board_corner_table(board)
    lookup = {int(i): k for k, i in enumerate(ids_all)}
    pid = detections.point_id
    unknown = ~np.isin(pid, ids_all)
    if unknown.any():
        k = int(np.flatnonzero(unknown)[0])
        raise InputError(where, f"row {k} point_id", f"a corner id of the board (0..{int(ids_all.max())})",
                         int(pid[k]))

    def p_of(ids):
        return p_all[[lookup[int(i)] for i in ids]]

    mask, refined = intrinsic_mask(intrinsics, n_cam)
    # views: (camera, frame) -> (ids, xy)
    order = np.lexsort((detections.point_id, detections.frame, detections.camera))
    cam_s, frame_s = detections.camera[order], detections.frame[order]
    key = cam_s.astype(np.int64) * (int(frame_s.max(initial=0)) + 1) + frame_s
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if key.size else np.zeros(0, np.intp)
    ends = np.r_[starts[1:], key.size]
    views: dict[int, list] = {c: [] for c in range(n_cam)}
    dropped = []
    for s, e in zip(starts, ends):
        rows = order[s:e]
        c, f = int(cam_s[s]), int(frame_s[s])
        ids = detections.point_id[rows]
        if np.unique(ids).size != ids.size:
            raise InputError(where, f"camera {c} frame {f} point_id", "each corner id once per view",
                             "a repeated id")
        if rows.size < min_corners:
            dropped.append({"camera": c, "frame": f, "reason": f"{rows.size} corners (< {min_corners})"})
            continue
        views[c].append((f, ids, detections.xy_px[rows]))
    for c in range(n_cam):
        need = 3 if (cams0 is None or mask[c].any()) else 1
        if len(views[c]) < need:
            what = "estimate its intrinsics" if need == 3 else "place it"
            raise InputError(where, f"camera {c} ({names[c]})", f"at least {need} board views to {what}",
                             f"{len(views[c])} view(s)")
    if cams0 is None:
        cams0 = []
        for c in range(n_cam):
            K, dist = _initial_intrinsics([(ids, xy) for _, ids, xy in views[c]], board, image_sizes[c], names[c])
            cams0.append(Camera(names[c], tuple(image_sizes[c]), K, dist, np.eye(3), np.zeros(3)))
        cams0 = tuple(cams0)
    # per-view PnP
    pose = {}
    for c in range(n_cam):
        for f, ids, xy in views[c]:
            R, t, rms = _pnp(p_of(ids), xy, cams0[c])
            if not rms <= max_pnp_rms_px:
                dropped.append({"camera": c, "frame": f, "reason": f"PnP RMS {rms:.1f} px (> {max_pnp_rms_px} px)"})
                continue
            pose[(c, f)] = (R, t, ids, xy)
    maps = symmetry_maps(board)
    if len(maps) > 1:
        pose = _resolve_symmetry(pose, maps, p_of, cams0, max_pnp_rms_px)
    # co-observation samples
    by_frame: dict[int, list[int]] = {}
    for (c, f) in sorted(pose):
        by_frame.setdefault(f, []).append(c)
    si, sj, sR, st = [], [], [], []
    for f, cs in sorted(by_frame.items()):
        for a_i, a in enumerate(cs):
            for b in cs[a_i + 1:]:
                Ra, ta = pose[(a, f)][:2]
                Rb, tb = pose[(b, f)][:2]
                Rab = Ra @ Rb.T
                si.append(a)
                sj.append(b)
                sR.append(Rab)
                st.append(ta - Rab @ tb)
    lab = components(n_cam, np.array(si, np.intp), np.array(sj, np.intp))
    for c in range(n_cam):
        if lab[c] != lab[0]:
            raise InputError(where, f"camera {c} ({names[c]})",
                             "board views at the same frames as camera 0 or a camera linked to it (co-observations)",
                             "none", hint="record frames where it and another camera see the board together")
    si, sj = np.array(si, np.intp), np.array(sj, np.intp)
    R_abs, rot_res = average_rotations(n_cam, si, sj, np.array(sR))
    t_abs, _ = average_translations(n_cam, si, sj, R_abs, np.array(st))
    # board pose per frame: chordal mean over the cameras that saw it
    frames = sorted(f for f, cs in by_frame.items())
    frame_index = {f: g for g, f in enumerate(frames)}
    groups = np.zeros((len(frames), 6))
    for f in frames:
        Rw = np.array([R_abs[c].T @ pose[(c, f)][0] for c in by_frame[f]])
        tw = np.array([R_abs[c].T @ (pose[(c, f)][1] - t_abs[c]) for c in by_frame[f]])
        groups[frame_index[f]] = np.r_[rotvec_from_matrix(chordal_mean(Rw)), tw.mean(axis=0)]
    cam_idx, grp, local, xy = [], [], [], []
    for (c, f), (_, _, ids, pts) in sorted(pose.items()):
        cam_idx.append(np.full(len(ids), c))
        grp.append(np.full(len(ids), frame_index[f]))
        local.append(p_of(ids))
        xy.append(pts)
    cam_idx = np.concatenate(cam_idx)
    params = [camera_parameters(c) for c in cams0]
    intr0 = np.stack([p[2] for p in params])
    extra0 = np.stack([p[3] for p in params])
    rv0 = rotvec_from_matrix(R_abs)
    pose_free = np.ones(n_cam, bool)
    pose_free[0] = False
    ba = bundle_adjust("rigid", cam_idx, np.concatenate(grp), np.concatenate(local), np.concatenate(xy), rv0, t_abs,
                       intr0, extra0, groups, pose_free=pose_free, intr_free=mask, loss=loss, f_scale_px=f_scale_px)
    if not (np.isfinite(ba.rvecs).all() and np.isfinite(ba.tvecs).all() and np.isfinite(ba.intrinsics).all()):
        raise InputError(where, "bundle adjustment", "a finite solution", "non-finite parameters",
                         hint="check the board definition against the printed board")
    n_obs = np.bincount(cam_idx, minlength=n_cam)
    summaries = summarize_cameras(ba, names, cam_idx, n_obs)
    out_cams = []
    for c in range(n_cam):
        i = ba.intrinsics[c]
        d = np.r_[i[4:9], extra0[c]]
        n_dist = max(cams0[c].dist.size, 5)
        K = np.array([[i[0], 0.0, i[2]], [0.0, i[1], i[3]], [0.0, 0.0, 1.0]])
        out_cams.append(Camera(names[c], cams0[c].size, K, d[:n_dist], matrix_from_rotvec(ba.rvecs[c]), ba.tvecs[c]))
        n_views = sum(1 for (cc, _) in pose if cc == c)
        summaries[c] = CameraSummary(**{**summaries[c].__dict__, "extra": {"n_views": n_views}})
    meta = rig_metadata("board", summaries, ba.sigma_px, refined, "camera 0 is the world (R = I, t = 0)")
    return RigCalibration(
        rig=Rig(tuple(out_cams), meta), cameras=tuple(summaries), sigma_px=ba.sigma_px, rms_px=ba.rms_px,
        initial_rms_px=ba.initial_rms_px, refined_intrinsics=refined, covariance=ba.covariance,
        parameter_names=ba.names, gauge="camera 0 is the world (R = I, t = 0); the board sets the scale",
        n_frames=len(frames), dropped_views=tuple(dropped),
        rotation_residual_deg=float(np.degrees(np.median(rot_res))), nfev=ba.nfev)


def rig_metadata(method: str, summaries: Sequence[CameraSummary], sigma_px: float, refined, gauge: str) -> dict:
    """The rig TOML's [metadata]: units, residuals and SDs per camera (docs/formats.md)."""
    return {
        "units": "m", "calibrated_by": "mocapfj", "method": method, "gauge": gauge, "sigma_px": float(sigma_px),
        "refined_intrinsics": list(refined),
        "cameras": [{"name": s.name, "rms_px": s.rms_px, "n_observations": s.n_observations,
                     "std": dict(s.std), "position_std_m": s.position_std_m.tolist(),
                     "rotation_std_deg": np.degrees(s.rotation_std_rad).tolist()} for s in summaries],
    }
