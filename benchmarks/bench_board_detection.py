"""Chessboard detection on strongly distorted views: mocapfj against OpenCV's detectors.

Synthetic stand-in for the well-known strongly distorted real sequence on which OpenCV's classic
detector finds about 12 of 20 boards: a 106 deg lens (1280 x 960, fx 420 px, k1 -0.26), a 9 x 6
board filling 60-110 % of the image diagonal, placed anywhere up to the image's edge, tilted up
to 50 deg, with a thin white border (0.15 square), 1-2 px of blur (``--blur``), uneven light and sensor noise,
rendered by mocapfj.synth (exact truth). Per set of 20 views:

- boards found by ``cv2.findChessboardCorners`` (+ ``cornerSubPix`` 11 x 11, as OpenCV's
  tutorial does), by ``cv2.findChessboardCornersSB`` (exhaustive, accuracy) and by
  ``mocapfj.vision.detect_board``;
- their corner error against the truth (RMS and max, px) and time per image;
- the focal length each calibrates (OpenCV's views with ``cv2.calibrateCamera``; mocapfj's with
  ``calibrate_intrinsics``), its error and mocapfj's SD, and the mean z^2 of mocapfj's
  parameters over the sets (``--no-peers`` skips OpenCV's detectors, which take seconds on a
  view they miss).

    python benchmarks/bench_board_detection.py [--sets 3] [--views 20] [--seed 1000] [--blur 1 2]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mocapfj.synth.images import render_board_view  # noqa: E402
from mocapfj.types import Board, Camera  # noqa: E402
from mocapfj.vision.boards import board_points, detect_board  # noqa: E402
from mocapfj.vision.intrinsics import calibrate_intrinsics  # noqa: E402

BOARD = Board("chessboard", 9, 6, square_m=0.03)
W, H, F = 1280, 960, 420.0
DIST = np.array([-0.26, 0.06, 0.0004, -0.0003, -0.004])


def _fold_radius(dist) -> float:
    """Normalised radius (distorted) beyond which the radial polynomial folds back."""
    k1, k2, _, _, k3 = dist
    r = np.linspace(0, 3, 3001)
    rd = r * (1 + k1 * r**2 + k2 * r**4 + k3 * r**6)
    bad = np.gradient(rd, r) <= 0
    return float(rd[np.argmax(bad)]) if bad.any() else np.inf


def views(seed: int, n: int, blur=(1.0, 2.0)):
    """n rendered views (image, truth corners (54, 2)) and the camera."""
    rng = np.random.default_rng(seed)
    K = np.array([[F, 0, W / 2 - 0.5 + rng.normal(0, 5)], [0, F * 1.001, H / 2 - 0.5 + rng.normal(0, 5)], [0, 0, 1]])
    cam = Camera("c", (W, H), K, DIST, np.eye(3), np.zeros(3))
    r_max = _fold_radius(DIST)
    _, p = board_points(BOARD)
    diag = np.linalg.norm((p.max(0) - p.min(0))[:2])
    yy, xx = np.mgrid[0:H, 0:W]
    out = []
    while len(out) < n:
        rv = rng.normal(0, 1, 3)
        rv *= np.radians(rng.uniform(5, 50)) / np.linalg.norm(rv)
        R = Rotation.from_rotvec(rv).as_matrix() @ Rotation.from_rotvec([0, 0, rng.uniform(-0.6, 0.6)]).as_matrix()
        z = F * diag / (rng.uniform(0.6, 1.1) * np.hypot(W, H))
        u, v = rng.uniform(0.05, 0.95) * W, rng.uniform(0.05, 0.95) * H
        t = np.array([(u - K[0, 2]) / F, (v - K[1, 2]) / F, 1.0]) * z - R @ (p.min(0) + p.max(0)) / 2
        pc = p @ R.T + t
        if np.hypot(*(pc[:, :2] / pc[:, 2:]).T).max() > 0.9 * r_max:
            continue
        bv = render_board_view(cam, BOARD, R, t, blur_sigma_px=rng.uniform(*blur), margin_m=0.15 * BOARD.square_m)
        xy = bv.corners_px
        if not bv.in_view.all() or (xy.min(0) < 2).any() or xy[:, 0].max() > W - 3 or xy[:, 1].max() > H - 3:
            continue
        a = rng.uniform(0, 2 * np.pi)                       # light falling off across the image and to its edges
        gain = 1 - 0.25 * (1 + np.cos(a) * (xx / W * 2 - 1) + np.sin(a) * (yy / H * 2 - 1))
        gain *= 1 - 0.35 * ((xx - W / 2) ** 2 + (yy - H / 2) ** 2) / (W * W / 4 + H * H / 4)
        img = np.clip(np.rint(bv.image * gain + rng.normal(0, 3.0, gain.shape)), 0, 255).astype(np.uint8)
        out.append((img, xy))
    return cam, out


def _err_any_order(found: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Corner errors when the detector's numbering is unknown: each corner to its nearest truth."""
    return np.linalg.norm(found[:, None] - truth[None], axis=2).min(axis=1)


def run_set(seed: int, n: int, blur=(1.0, 2.0), peers: bool = True) -> dict:
    cam, vs = views(seed, n, blur)
    _, p = board_points(BOARD)
    res = {name: {"found": 0, "err": [], "t": [], "obj": [], "img": [], "dets": []}
           for name in ("classic", "sb", "mocapfj")}
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-3)
    for img, truth in vs:
        ok = ok2 = False
        c = c2 = None
        if peers:
            t0 = time.perf_counter()
            ok, c = cv2.findChessboardCorners(img, (9, 6), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
            if ok:
                c = cv2.cornerSubPix(img, c, (11, 11), (-1, -1), crit)
            res["classic"]["t"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            ok2, c2 = cv2.findChessboardCornersSB(img, (9, 6), flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
            res["sb"]["t"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        det = detect_board(img, BOARD)
        res["mocapfj"]["t"].append(time.perf_counter() - t0)
        res["mocapfj"]["dets"].append(det)
        for name, good, xy in (("classic", ok, c), ("sb", ok2, c2)):
            if good:
                xy = xy.reshape(-1, 2).astype(np.float64)
                res[name]["found"] += 1
                res[name]["err"] += list(_err_any_order(xy, truth))
                res[name]["obj"].append(p.astype(np.float32))
                res[name]["img"].append(xy.astype(np.float32))
        if det is not None:
            res["mocapfj"]["found"] += 1
            res["mocapfj"]["err"] += list(np.linalg.norm(det.xy_px - truth[det.ids], axis=1))
    for name in ("classic", "sb"):
        r = res[name]
        if r["found"] >= 3:
            # OpenCV's own ordering can be reversed from view to view: as object points, each view's
            # corners in the order found is a valid (rotated) board, so calibration does not care
            _, K, _, _, _ = cv2.calibrateCamera(r["obj"], r["img"], (W, H), None, None)
            r["fx"] = K[0, 0]
    cal = calibrate_intrinsics(res["mocapfj"]["dets"], BOARD)
    res["mocapfj"]["fx"], res["mocapfj"]["fx_sd"] = cal.values[0], cal.std[0]
    res["truth_fx"] = cam.K[0, 0]
    res["z"] = (cal.values - np.r_[cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2], DIST]) / cal.std
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=3)
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--blur", type=float, nargs=2, default=(1.0, 2.0), help="range of the Gaussian blur, px")
    ap.add_argument("--no-peers", action="store_true", help="mocapfj only (the z-scores of its calibrations)")
    a = ap.parse_args()
    print(f"{a.sets} sets of {a.views} views, 1280 x 960, fx {F:g} px, k1 {DIST[0]:g}, blur {a.blur[0]:g}-{a.blur[1]:g} px, "
          f"seeds {a.seed}..")
    print("| set | detector | boards found | corner RMS (px) | corner max (px) | ms per image | fx error (%) |")
    print("|---|---|---|---|---|---|---|")
    totals = {n: [0, 0] for n in ("classic", "sb", "mocapfj")}
    zs = []
    for s in range(a.sets):
        res = run_set(a.seed + s, a.views, tuple(a.blur), peers=not a.no_peers)
        zs.append(res["z"])
        for name, label in (("classic", "OpenCV classic + cornerSubPix"), ("sb", "OpenCV sector-based"),
                            ("mocapfj", "mocapfj detect_board")):
            if a.no_peers and name != "mocapfj":
                continue
            r = res[name]
            e = np.array(r["err"]) if r["err"] else np.array([np.nan])
            fx = r.get("fx")
            fx_txt = "-" if fx is None else f"{100 * (fx / res['truth_fx'] - 1):+.3f}"
            if name == "mocapfj":
                fx_txt += f" (SD {100 * r['fx_sd'] / res['truth_fx']:.3f})"
            totals[name][0] += r["found"]
            totals[name][1] += a.views
            print(f"| {a.seed + s} | {label} | {r['found']}/{a.views} | {np.sqrt(np.nanmean(e ** 2)):.3f} | "
                  f"{np.nanmax(e):.3f} | {1e3 * np.median(r['t']):.0f} | {fx_txt} |", flush=True)
    print("\ntotal found: " + ", ".join(f"{n} {f}/{v}" for n, (f, v) in totals.items() if v))
    z = np.array(zs)
    print("mocapfj's calibrations, (estimate - truth) / SD: mean z^2 of fx, fy, cx, cy, k1, k2, p1, p2, k3 = "
          + ", ".join(f"{v:.2f}" for v in (z ** 2).mean(axis=0)) + f"; all {np.mean(z ** 2):.2f} over {z.size} values")


if __name__ == "__main__":
    main()
