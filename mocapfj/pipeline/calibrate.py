"""Files over camera calibration (``mocapfj calibrate-camera``): views read from images or
videos, the board found in each (:func:`mocapfj.vision.boards.detect_board`), the intrinsics
fitted (:func:`mocapfj.vision.intrinsics.calibrate_intrinsics`), and the results written."""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path

from ..errors import InputError
from ..io import write_json

__all__ = ["IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "expand_view_paths", "read_views", "detect_views",
           "run_calibrate_camera", "run_calibrate_rig"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm", ".ppm", ".webp")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg")


def expand_view_paths(paths: Sequence[str | os.PathLike]) -> list[Path]:
    """Image and video files from `paths` (a directory stands for its images and videos, sorted);
    a path that does not exist or has another suffix is refused, naming it."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in IMAGE_SUFFIXES + VIDEO_SUFFIXES)
            if not found:
                raise InputError(p, "IMAGES", "a directory holding images or videos", "none in it")
            out += found
        elif not p.exists():
            raise InputError(p, "IMAGES", "an image or video file, or a directory of them", "no such file")
        elif p.suffix.lower() not in IMAGE_SUFFIXES + VIDEO_SUFFIXES:
            raise InputError(p, "IMAGES", f"an image ({', '.join(IMAGE_SUFFIXES)}) or a video "
                             f"({', '.join(VIDEO_SUFFIXES)})", repr(p.suffix or "no suffix"))
        else:
            out.append(p)
    if not out:
        raise InputError(None, "IMAGES", "at least one image or video", "none")
    return out


def _open_video(path: Path):
    import cv2

    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise InputError(path, "video", "a video OpenCV can read", "could not be opened")
    return cap


def count_views(files: Sequence[Path], every: int = 1) -> int:
    """How many views `read_views` yields (video frame counts as the container states them)."""
    import cv2

    n = 0
    for f in files:
        if f.suffix.lower() in VIDEO_SUFFIXES:
            cap = _open_video(f)
            frames = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
            cap.release()
            n += -(-max(frames, 0) // every)
        else:
            n += 1
    return n


def read_views(files: Sequence[Path], every: int = 1) -> Iterator[tuple[str, object]]:
    """(name, image) for every image file and every `every`-th frame of every video, in order.

    Images keep their bit depth (8 or 16 bit, grey or colour); a video frame is named
    ``file:frame``. A file OpenCV cannot read is refused, naming it.
    """
    import cv2

    if every < 1:
        raise InputError(None, "--every", "a positive whole number", every)
    for f in files:
        if f.suffix.lower() in VIDEO_SUFFIXES:
            cap = _open_video(f)
            k = 0
            try:
                while True:
                    ok, frame = cap.read()
                    if not ok:
                        break
                    if k % every == 0:
                        yield f"{f}:{k}", frame
                    k += 1
            finally:
                cap.release()
            if k == 0:
                raise InputError(f, "video", "a video with frames OpenCV can decode", "no frame decoded")
        else:
            img = cv2.imread(str(f), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
            if img is None:
                raise InputError(f, "image", "an image file OpenCV can read (PNG, JPEG, TIFF, BMP ...)",
                                 "unreadable or not an image")
            yield str(f), img


def detect_views(files: Sequence[Path], board, every: int = 1, progress: bool = True):
    """The board found in every view: (names, detections), a detection None where it is not."""
    from tqdm import tqdm

    from ..vision.boards import detect_board, grey_image

    names, dets = [], []
    bar = tqdm(total=count_views(files, every), desc="finding the board", unit="view", leave=False,
               disable=None if progress else True)
    try:
        for name, img in read_views(files, every):
            names.append(name)
            dets.append(detect_board(grey_image(img, name), board))
            bar.update(1)
    finally:
        bar.close()
    return names, dets


def _check_chessboard_size(files, every, names, dets, brd, board_path, n: int = 5) -> None:
    """When a chessboard is (nearly) never found: refuse a board file whose size differs from the
    chessboard lattice the images show (looked for in up to `n` views without a detection)."""
    from ..vision.boards import chessboard_size

    missing = {nm for nm, d in zip(names, dets) if d is None}
    sizes = []
    for nm, img in read_views(files, every):
        if nm in missing:
            size = chessboard_size(img)
            if size is not None:
                sizes.append(size)
            if len(sizes) >= n or len(missing) == 0:
                break
            missing.discard(nm)
    if not sizes:
        return
    seen = max(sizes, key=lambda t: t[0] * t[1])
    want = tuple(sorted((brd.columns, brd.rows), reverse=True))
    if seen != want:
        raise InputError(board_path, "board.columns, board.rows",
                         f"the chessboard's inner corners (the images show a lattice of up to {seen[0]} x {seen[1]})",
                         f"{brd.columns} x {brd.rows}", hint="count inner corners, not squares")


def run_calibrate_camera(images: Sequence[str | os.PathLike], board: str | os.PathLike, out: str | Path, *,
                         model: str = "standard", name: str = "cam_0", every: int = 1,
                         progress: bool = True) -> dict:
    """``mocapfj calibrate-camera``: one camera's intrinsics from views of a board.

    Writes into OUT:

    - ``camera.toml``: the camera as a rig file (anipose-compatible ``[cam_0]``; its
      ``[metadata]`` holds the RMS, the model and the parameters' SDs);
    - ``intrinsics.json``: the summary (:meth:`mocapfj.vision.intrinsics.Intrinsics.to_dict`)
      with the covariance, the board file and every view's status;
    - ``detections.json``: the features found in each view (ids, pixels, detector);
    - ``coverage.png``: where in the image features were seen, and the residuals.

    Returns the summary printed by ``--json``.
    """
    from ..io.calib import read_board, write_rig
    from ..types import Rig
    from ..vision.intrinsics import calibrate_intrinsics

    brd = read_board(board)
    files = expand_view_paths(images)
    names, dets = detect_views(files, brd, every=every, progress=progress)
    if brd.type == "chessboard" and sum(d is not None for d in dets) < 3:
        _check_chessboard_size(files, every, names, dets, brd, board)
    result = calibrate_intrinsics(dets, brd, names=names, model=model, camera_name=name)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = result.to_dict()
    summary["camera"] = name
    summary["board"] = str(board)
    from ..viz.calibration import write_coverage_figure

    write_coverage_figure(out / "coverage.png", result)
    summary["files"] = {"rig": "camera.toml", "summary": "intrinsics.json", "detections": "detections.json",
                        "coverage": "coverage.png"}
    meta = {"tool": "mocapfj calibrate-camera", "model": model, "rms_px": result.rms_px,
            "n_views_used": result.n_views_used, "std": result.std_by_name, "board": str(board)}
    write_rig(out / "camera.toml", Rig((result.camera,), metadata=meta))
    write_json(out / "detections.json", {"board": str(board), "views": [
        {"name": n} | ({"found": False} if d is None else {"found": True} | d.to_dict()) for n, d in zip(names, dets)]})
    full = dict(summary)
    full["param_names"] = list(result.param_names)
    full["covariance"] = result.covariance
    full["poses"] = [{"name": v.name, "rvec": v.rvec, "tvec_m": v.tvec} for v in result.views if v.status == "used"]
    write_json(out / "intrinsics.json", full)
    return summary


def run_calibrate_rig(out: str | Path, *, board: str | os.PathLike | None = None,
                      cameras: Sequence[Sequence[str | os.PathLike]] | None = None,
                      wand: str | os.PathLike | None = None, detections: str | os.PathLike | None = None,
                      intrinsics: str | os.PathLike | None = None, lframe: str | os.PathLike | None = None,
                      refine_intrinsics: str | None = None, every: int = 1, progress: bool = True) -> dict:
    """``mocapfj calibrate-rig``: a multi-camera rig from board views or from a wand wave.

    Board: `board` and, per camera, its views (`cameras[c]`: images, directories or videos; the
    k-th view of every camera is frame k); `intrinsics` (a rig file) gives starting intrinsics,
    else each camera starts from its own views (:func:`mocapfj.vision.rig.calibrate_rig`).
    Wand: `wand` (a wand TOML), `detections` (CSV: frame, camera, x_px, y_px[, point_id]),
    `intrinsics` (required) and optionally `lframe` (CSV of the still L-frame's blobs)
    (:func:`mocapfj.vision.wand.calibrate_wand`).

    Writes into OUT ``rig.toml`` (anipose-compatible, metres; ``[metadata]`` with residuals and
    SDs), ``calibrate_rig.json`` (the summary with the covariance of the camera parameters) and,
    for boards, ``detections.csv`` (the corners found). Returns the summary printed by ``--json``.
    """
    import numpy as np

    from ..io import read_detections, write_detections
    from ..io.calib import read_board, read_rig, read_wand, write_rig
    from ..types import Detections

    if (board is None) == (wand is None):
        raise InputError(None, "--board/--wand", "exactly one of --board (board views) or --wand (a wand wave)",
                         "both" if board is not None else "neither")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = {"rig": "rig.toml", "summary": "calibrate_rig.json"}
    if board is not None:
        from ..vision.rig import calibrate_rig

        if not cameras or len(cameras) < 2:
            raise InputError(None, "--camera", "the views of at least two cameras (one --camera per camera)",
                             f"{len(cameras or [])} camera(s)")
        if detections is not None or lframe is not None:
            raise InputError(None, "--detections/--lframe", "nothing with --board (they belong to --wand)", "given")
        brd = read_board(board)
        start = read_rig(intrinsics) if intrinsics is not None else None
        if start is not None and len(start.cameras) != len(cameras):
            raise InputError(intrinsics, "cameras", f"{len(cameras)} cameras (one per --camera)",
                             f"{len(start.cameras)} camera(s)")
        rows, sizes = [], []
        for c, paths in enumerate(cameras):
            _, dets = detect_views(expand_view_paths(paths), brd, every=every, progress=progress)
            found = [(k, d) for k, d in enumerate(dets) if d is not None]
            if not found:
                raise InputError(str(paths[0]), f"camera {c} views", "views in which the board is found", "none")
            sizes.append(found[0][1].image_size)
            if start is not None and tuple(start.cameras[c].size) != tuple(sizes[-1]):
                raise InputError(intrinsics, f"camera {c} size", f"the size of its images {list(sizes[-1])}",
                                 list(start.cameras[c].size))
            for k, d in found:
                rows.append((np.full(d.ids.size, k), np.full(d.ids.size, c), d.xy_px, d.ids))
        det = Detections(*(np.concatenate([r[i] for r in rows]) for i in range(4)))
        result = calibrate_rig(det, brd, start, image_sizes=sizes if start is None else None,
                               intrinsics=refine_intrinsics or "default", source="board views")
        write_detections(out / "detections.csv", det)
        files["detections"] = "detections.csv"
    else:
        from ..vision.wand import calibrate_wand

        if cameras:
            raise InputError(None, "--camera", "no board views with --wand (the blobs come from --detections)",
                             "given")
        if detections is None or intrinsics is None:
            raise InputError(None, "--detections/--intrinsics" if detections is None else "--intrinsics",
                             "the wand's blob detections (CSV) and the cameras' intrinsics (a rig file)", "missing")
        w = read_wand(wand)
        result = calibrate_wand(read_detections(detections), w, read_rig(intrinsics),
                                lframe=read_detections(lframe) if lframe is not None else None,
                                refine_intrinsics=refine_intrinsics or "fixed", source=str(detections),
                                lframe_source=None if lframe is None else str(lframe))
    summary = result.to_dict()
    summary["inputs"] = {k: str(v) for k, v in (("board", board), ("wand", wand), ("detections", detections),
                                                ("intrinsics", intrinsics), ("lframe", lframe)) if v is not None}
    summary["files"] = files
    write_rig(out / "rig.toml", result.rig)
    full = dict(summary)
    full["parameter_names"] = [f"{c}:{n}" for c, n in result.parameter_names]
    full["covariance"] = result.covariance
    write_json(out / "calibrate_rig.json", full)
    return summary
