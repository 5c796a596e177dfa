"""Files over pixels-to-markers (``mocapfj triangulate``): detections (a CSV, or images and videos
per camera) and a rig to labelled 3D markers in a C3D file, with a summary. No maths here: the
stages are :mod:`mocapfj.vision.blobs`, :mod:`~mocapfj.vision.tags`, :mod:`~mocapfj.vision.triangulate`,
:mod:`~mocapfj.vision.correspondence` and :mod:`~mocapfj.vision.track`.

Labels: a detection's ``point_id`` k >= 0 names the k-th label of the clusters (all clusters' labels
in file order) when a clusters file is given, else ``P<k>``; unlabelled detections (-1) are
matched across cameras and labelled from the clusters' rigid geometry. From images, blobs are
unlabelled and the corners of the clusters file's AprilTags carry their labels.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import write_json
from ..io.csvio import write_csv_columns

__all__ = ["run_triangulate", "read_camera_views"]

_CHUNK_FRAMES = 16


def _frame_rate(files: Sequence[Path]) -> float | None:
    import cv2

    from .calibrate import VIDEO_SUFFIXES

    for f in files:
        if f.suffix.lower() in VIDEO_SUFFIXES:
            cap = cv2.VideoCapture(str(f))
            fps = cap.get(cv2.CAP_PROP_FPS) if cap.isOpened() else 0.0
            cap.release()
            if fps and np.isfinite(fps) and fps > 0:
                return float(fps)
    return None


def read_camera_views(paths: Sequence[str | os.PathLike], clusters, progress: bool = True):
    """Blobs (and the clusters' AprilTags) in every frame of every camera's images or video.

    ``paths[c]`` is camera c's video, directory of images or single image. Returns the detections
    (blobs unlabelled; a tag corner's point id is its index among the tags' corner labels, in the
    clusters' order), the blob summary per camera, the number of frames and the video frame rate
    (None for images)."""
    from tqdm import tqdm

    from ..types import Detections
    from ..vision.blobs import detect_blobs
    from ..vision.boards import grey_image
    from ..vision.tags import detect_tags
    from .calibrate import count_views, expand_view_paths, read_views

    tags = [c for c in clusters if c.tag_id is not None]
    families = sorted({c.tag_family for c in tags})
    lookup = {(c.tag_family, 4 * c.tag_id + k): i for i, (c, k) in enumerate((c, k) for c in tags for k in range(4))}
    parts, summaries = [], []
    n_frames = 0
    rate = None
    for cam, path in enumerate(paths):
        files = expand_view_paths([path])
        rate = rate or _frame_rate(files)
        bar = tqdm(total=count_views(files), desc=f"camera {cam}: blobs", unit="frame", leave=False,
                   disable=None if progress else True)
        frames, buf, k = [], [], 0
        blob_stats = {"n_blobs": 0, "rejected": {}}

        def flush():
            if not buf:
                return
            b = detect_blobs(np.stack(buf))
            parts.append(b.detections(cam, frame_offset=k - len(buf)))
            blob_stats["n_blobs"] += len(b)
            for key, v in b.rejected.items():
                blob_stats["rejected"][key] = blob_stats["rejected"].get(key, 0) + v
            buf.clear()

        try:
            for name, img in read_views(files):
                grey = grey_image(img, name)
                if buf and grey.shape != buf[0].shape:
                    raise InputError(name, "image", f"the size of camera {cam}'s other images {buf[0].shape[::-1]}",
                                     f"{grey.shape[::-1]}")
                buf.append(grey)
                for fam in families:
                    td = detect_tags(grey, family=fam, frame=k)
                    wanted = np.isin(td.ids, [c.tag_id for c in tags if c.tag_family == fam])
                    if wanted.any():
                        d = td.detections(cam)
                        keep = np.repeat(wanted, 4)
                        corner_label = np.array([lookup[(fam, int(v))] for v in d.point_id[keep]], dtype=np.int64)
                        parts.append(Detections(d.frame[keep], d.camera[keep], d.xy_px[keep], corner_label))
                k += 1
                if len(buf) == _CHUNK_FRAMES:
                    flush()
                bar.update(1)
            flush()
        finally:
            bar.close()
        frames.append(k)
        n_frames = max(n_frames, k)
        summaries.append({"camera": cam, "frames": k} | blob_stats)
    det = Detections(*(np.concatenate([getattr(p, f) for p in parts]) if parts else np.zeros((0, 2) if f == "xy_px" else 0)
                       for f in ("frame", "camera", "xy_px", "point_id")))
    return det, summaries, n_frames, rate


def run_triangulate(inputs: Sequence[str | os.PathLike], rig: str | os.PathLike, out: str | Path, *,
                    clusters: Sequence[str | os.PathLike] | None = None, rate_hz: float | None = None,
                    sigma_px: float | None = None, max_gap_s: float = 0.1, tol_m: float = 0.003,
                    progress: bool = True) -> dict:
    """``mocapfj triangulate``: 2D detections to labelled 3D markers.

    Parameters
    ----------
    inputs : paths
        One detections CSV (frame, camera, x_px, y_px[, point_id]), or one path per camera of the
        rig (its video, a directory of its images, or one image), in camera order.
    rig : path
        Rig TOML (anipose-compatible, docs/formats.md).
    out : path
        Output directory: ``markers.c3d``, ``triangulate.json`` and, with tags, ``tag_poses.csv``.
    clusters : paths, optional
        Clusters files (``mocapfj.clusters/1``) or joint calibrations (``mocapfj.joint/1``).
    rate_hz : float, optional
        Frame rate; required for a CSV and for images (a video says its own).
    sigma_px : float, optional
        Pixel noise SD; default the rig's ``sigma_px``, else estimated from the residuals.

    Returns the summary printed by ``--json``.
    """
    from ..io import read_detections, write_c3d
    from ..io.calib import read_rig
    from ..io.clusters import read_clusters
    from ..types import MarkerTrajectories
    from ..vision.correspondence import match_detections
    from ..vision.tags import tag_poses
    from ..vision.track import fill_gaps, label_points
    from ..vision.triangulate import observation_array, triangulate

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rig_obj = read_rig(rig)
    C = len(rig_obj.cameras)
    cl = []
    for f in clusters or ():
        cl.extend(read_clusters(f))
    names = [s for c in cl for s in c.labels]
    if len(set(names)) != len(names):
        raise InputError(None, "--clusters", "each label in one cluster across the files", "a label twice")
    tags = [c for c in cl if c.tag_id is not None]
    inputs = [Path(p) for p in inputs]
    summary: dict = {"rig": str(rig), "inputs": [str(p) for p in inputs], "n_cameras": C,
                     "clusters": [c.name for c in cl]}
    if len(inputs) == 1 and inputs[0].suffix.lower() == ".csv":
        det = read_detections(inputs[0])
        where = str(inputs[0])
        if det.camera.size and int(det.camera.max()) >= C:
            raise InputError(where, "camera", f"camera numbers 0..{C - 1} (the rig {rig} has {C} cameras)",
                             f"camera {int(det.camera.max())}")
        n_frames = int(det.frame.max()) + 1 if det.frame.size else 0
        if rate_hz is None:
            raise InputError(None, "--rate", "the detections' frame rate in Hz (a CSV does not say it)", "nothing")
        plain_labels = [s for c in cl if c.tag_id is None for s in c.labels]
        labelled = det.point_id >= 0
        if labelled.any() and cl and int(det.point_id.max()) >= len(plain_labels):
            raise InputError(where, "point_id", f"ids 0..{len(plain_labels) - 1} (the clusters' labels in order)",
                             int(det.point_id.max()))
        label_of = (lambda k: plain_labels[k]) if cl else (lambda k: f"P{k}")
    else:
        if len(inputs) != C:
            raise InputError(None, "DETECTIONS", f"one video or image directory per camera of the rig ({C})",
                             f"{len(inputs)} path(s)")
        det, blob_summary, n_frames, video_rate = read_camera_views(inputs, cl, progress=progress)
        summary["blobs"] = blob_summary
        where = "images"
        rate_hz = rate_hz or video_rate
        if rate_hz is None:
            raise InputError(None, "--rate", "the frame rate in Hz (images do not say it)", "nothing")
        labelled = det.point_id >= 0
        tag_labels = [s for c in cl if c.tag_id is not None for s in c.labels]
        label_of = tag_labels.__getitem__
    rate_hz = float(rate_hz)
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(None, "--rate", "a positive frame rate in Hz", rate_hz)
    if n_frames == 0:
        raise InputError(where, "detections", "at least one detection", "none")
    finite = np.isfinite(det.xy_px).all(axis=1)
    summary["n_detections"] = int(det.frame.size)
    summary["n_nonfinite_ignored"] = int((~finite).sum())
    unl = (det.point_id == -1) & finite
    if where == "images" and cl and all(c.tag_id is not None for c in cl):
        # images with tag clusters only: the blobs (a tag's white border reads as one) name no marker
        summary["n_blobs_ignored"] = int(unl.sum())
        unl[:] = False

    columns: dict[str, dict] = {}                # label -> {"xyz", "res", "mask", "filled"} (T, ...)
    tri_parts = []

    def put(label, frames, xyz, res, mask, filled=False):
        col = columns.setdefault(label, {"xyz": np.full((n_frames, 3), np.nan), "res": np.full(n_frames, np.nan),
                                         "mask": np.zeros(n_frames, np.int64), "filled": np.zeros(n_frames, bool)})
        col["xyz"][frames] = xyz
        col["res"][frames] = res
        col["mask"][frames] = mask
        col["filled"][frames] = filled

    # labelled points (point_id, or tag corners): triangulated per frame and label
    lab_rows = labelled & finite
    if lab_rows.any():
        pid = det.point_id[lab_rows]
        xy, keys = observation_array(det.frame[lab_rows], det.camera[lab_rows], pid, det.xy_px[lab_rows], C, where)
        tri = triangulate(rig_obj, xy, sigma_px=sigma_px)
        tri_parts.append(("labelled", tri))
        bits = (tri.used * (1 << np.arange(C))[:, None]).sum(axis=0)
        for k in np.unique(keys[:, 1]):
            sel = keys[:, 1] == k
            put(label_of(int(k)), keys[sel, 0], tri.p_world[sel], tri.ray_residual_m[sel], bits[sel])
    lab_stats = None
    plain = [c for c in cl if c.tag_id is None]
    if unl.any():
        if not plain:
            raise InputError(None, "--clusters", "a clusters file to label the unlabelled detections",
                             f"{int(unl.sum())} detections without a point_id")
        from ..types import Detections

        sub = Detections(det.frame[unl], det.camera[unl], det.xy_px[unl], det.point_id[unl])
        cand = match_detections(rig_obj, sub, sigma_px=sigma_px)
        tri_parts.append(("unlabelled", cand.triangulation))
        ok = np.isfinite(cand.p_world[:, 0])
        bits = (cand.triangulation.used * (1 << np.arange(C))[:, None]).sum(axis=0)
        lab = label_points(cand.frame[ok], cand.p_world[ok], plain, n_frames=n_frames, rate_hz=rate_hz,
                           residual_m=cand.triangulation.ray_residual_m[ok], camera_mask=bits[ok], tol_m=tol_m,
                           max_gap_s=max_gap_s)
        summary["correspondence"] = cand.to_dict()
        lab_stats = lab.to_dict()
        for i, name in enumerate(lab.markers.labels):
            if name in columns:
                continue                     # a label given by point_id wins
            put(name, np.arange(n_frames), lab.markers.xyz[:, i], lab.markers.residual[:, i], lab.camera_mask[:, i],
                lab.filled[:, i])
    labels = [s for s in names if s in columns] + [s for s in columns if s not in names]
    if not labels:
        raise InputError(where, "detections", "points seen by two cameras or more", "none triangulated")
    if len(labels) > 255:
        raise InputError(where, "point_id", "at most 255 labels (one C3D file)", len(labels))
    xyz = np.stack([columns[s]["xyz"] for s in labels], axis=1)
    res = np.stack([columns[s]["res"] for s in labels], axis=1)
    mask = np.stack([columns[s]["mask"] for s in labels], axis=1)
    filled = np.stack([columns[s]["filled"] for s in labels], axis=1)
    if plain and lab_rows.any():                       # gaps of labelled markers: the rigid fit
        xyz, more, _ = fill_gaps(xyz, labels, plain, int(round(max_gap_s * rate_hz)))
        res[more] = 0.0
        filled |= more
    measured = np.isfinite(xyz[..., 0]) & ~filled
    res = np.where(measured, np.maximum(res, 1.5e-5), res)     # a measured sample never reads as "modelled" (0)
    markers = MarkerTrajectories(t=np.arange(n_frames) / rate_hz, xyz=xyz, labels=tuple(labels), rate_hz=rate_hz,
                                 residual=res)
    write_c3d(out / "markers.c3d", markers, camera_mask=np.where(measured, mask, 0))
    files = {"markers": "markers.c3d", "summary": "triangulate.json"}
    # tag poses
    if tags:
        cols = {"frame": np.arange(n_frames), "time_s": np.arange(n_frames) / rate_hz}
        for c in tags:
            idx = [labels.index(s) if s in labels else None for s in c.labels]
            corners = np.stack([xyz[:, i] if i is not None else np.full((n_frames, 3), np.nan) for i in idx], axis=1)
            R, t, rms = tag_poses(corners, float(np.linalg.norm(c.template_m[1] - c.template_m[0])))
            from ..rotations import rotvec_from_matrix

            rv = np.full((n_frames, 3), np.nan)
            ok = np.isfinite(t[:, 0])
            if ok.any():
                rv[ok] = rotvec_from_matrix(R[ok])
            for k, ax in enumerate("xyz"):
                cols[f"{c.name}_t{ax}_m"] = t[:, k]
            for k, ax in enumerate("xyz"):
                cols[f"{c.name}_r{ax}_rad"] = rv[:, k]
            cols[f"{c.name}_rms_m"] = rms
        write_csv_columns(out / "tag_poses.csv", cols)
        files["tag_poses"] = "tag_poses.csv"
    # the summary
    present = np.isfinite(xyz[..., 0])
    used_res = [t.residual_px[t.used] for _, t in tri_parts]
    r = np.concatenate(used_res) if used_res else np.zeros((0, 2))
    tri_summary = {name: t.to_dict() for name, t in tri_parts}
    summary.update({
        "n_frames": n_frames, "rate_hz": rate_hz, "labels": labels,
        "points_per_frame": float(present.sum(axis=1).mean()),
        "reprojection_rms_px": float(np.sqrt(np.mean(r**2))) if r.size else None,
        "nan_share": float(1.0 - present.mean()),
        "n_unseen": int(sum(t.n_unseen for _, t in tri_parts)),
        "n_rejected": int(sum(t.n_rejected for _, t in tri_parts)),
        "gaps_filled": int(filled.sum()),
        "swaps_repaired": int(lab_stats["swaps_repaired"]) if lab_stats else 0,
        "long_gaps": (lab_stats["long_gaps"] if lab_stats else [])[:200],
        "triangulation": tri_summary, "labelling": lab_stats, "files": files,
    })
    if lab_stats is not None:
        summary["n_long_gaps"] = lab_stats["n_long_gaps"]
    write_json(out / "triangulate.json", summary)
    return summary
