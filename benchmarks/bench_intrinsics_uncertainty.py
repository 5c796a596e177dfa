"""Do calibrate_intrinsics' SDs cover its errors? z = (estimate - truth) / SD over synthetic cameras.

Two levels, on seeds not used while developing (base seed 50000 by default):

1. **Points**: the board's corners projected through a random camera (focal 0.5-1.3 x width,
   k1 -0.4..0.1, k2, tangential terms, 3 image sizes) with Gaussian noise, on a grid of noise
   (0.1, 0.3, 1 px), views (5, 10, 20) and model (standard, no_k3): the SD's own formula.
2. **Images**: board views rendered by mocapfj.synth (blur 0.5-1.2 px, grey noise 2) and found
   by detect_board: the whole chain, where the noise is the detector's.

A table of mean z^2 (1 when the SDs are right) and the share beyond 2 and 3 SDs (4.6 %, 0.27 %
for a normal) per cell, over fx, fy, cx, cy and the distortion coefficients.

    python benchmarks/bench_intrinsics_uncertainty.py [--cameras 30] [--rendered 10] [--seed 50000]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mocapfj.errors import InputError  # noqa: E402
from mocapfj.synth.images import render_board_view  # noqa: E402
from mocapfj.types import Board, Camera  # noqa: E402
from mocapfj.vision.boards import BoardDetection, board_points, detect_board  # noqa: E402
from mocapfj.vision.intrinsics import MODELS, calibrate_intrinsics  # noqa: E402

BOARD = Board("chessboard", 9, 6, square_m=0.03)
IDS, P = board_points(BOARD)
SIZES = [(1280, 960), (640, 480), (1920, 1080)]


def camera(rng, size):
    w, h = size
    f = rng.uniform(0.5, 1.3) * w
    K = np.array([[f, 0, w / 2 + rng.normal(0, 10)], [0, f * rng.uniform(0.99, 1.01), h / 2 + rng.normal(0, 10)],
                  [0, 0, 1.0]])
    k1 = rng.uniform(-0.4, 0.1)
    return K, np.array([k1, 0.3 * k1 * k1 + rng.normal(0, 0.02), rng.normal(0, 1e-3), rng.normal(0, 1e-3), 0.0])


def poses(rng, K, size, n):
    w, h = size
    f = K[0, 0]
    while n:
        R = Rotation.from_rotvec(rng.normal(0, 1, 3) * np.radians(rng.uniform(10, 45)) / np.sqrt(3)).as_matrix()
        z = f * 0.27 / (rng.uniform(0.3, 0.7) * w)
        c = np.array([rng.uniform(-0.3, 0.3) * w / f * z, rng.uniform(-0.3, 0.3) * h / f * z, z])
        yield R, c - R @ P.mean(0)
        n -= 1


def point_views(rng, K, dist, size, n, noise):
    w, h = size
    out = []
    while len(out) < n:
        for R, t in poses(rng, K, size, 1):
            x, _ = cv2.projectPoints(P, cv2.Rodrigues(R)[0], t, K, dist)
            x = x.reshape(-1, 2)
            if x.min() >= 0 and x[:, 0].max() <= w - 1 and x[:, 1].max() <= h - 1:
                out.append(BoardDetection(IDS, x + rng.normal(0, noise, x.shape), size, "synthetic"))
    return out


def image_views(rng, K, dist, size, n):
    cam = Camera("c", size, K, dist, np.eye(3), np.zeros(3))
    out = []
    while len(out) < n:
        for R, t in poses(rng, K, size, 1):
            v = render_board_view(cam, BOARD, R, t, blur_sigma_px=rng.uniform(0.5, 1.2), noise_sd=2.0, rng=rng)
            if v.in_view.all():
                d = detect_board(v.image, BOARD)
                if d is not None:
                    out.append(d)
    return out


def z_of(res, K, dist, model):
    n = len(MODELS[model])
    truth = np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist[:n]]
    return (res.values - truth) / res.std


def row(label, z):
    z = np.asarray(z)
    print(f"| {label} | {z.size} | {np.mean(z ** 2):.2f} | {100 * np.mean(np.abs(z) > 2):.1f} | "
          f"{100 * np.mean(np.abs(z) > 3):.2f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cameras", type=int, default=30, help="cameras per point-level cell")
    ap.add_argument("--rendered", type=int, default=10, help="cameras calibrated from rendered images")
    ap.add_argument("--seed", type=int, default=50000)
    a = ap.parse_args()
    print("| cell | values | mean z^2 | beyond 2 SD (%) | beyond 3 SD (%) |")
    print("|---|---|---|---|---|")
    allz = []
    for noise in (0.1, 0.3, 1.0):
        for n_views in (5, 10, 20):
            for model in ("standard", "no_k3"):
                z, refused = [], 0
                for k in range(a.cameras):
                    rng = np.random.default_rng([a.seed, int(noise * 10), n_views, k])
                    size = SIZES[k % 3]
                    K, dist = camera(rng, size)
                    if model == "no_k3":
                        dist[4] = 0.0
                    try:
                        res = calibrate_intrinsics(point_views(rng, K, dist, size, n_views, noise), BOARD, model=model,
                                                   reject_outliers=False)
                    except InputError:                   # focal length not determined (SD above 5 %)
                        refused += 1
                        continue
                    z.append(z_of(res, K, dist, model))
                row(f"points, {noise:g} px, {n_views} views, {model}" + (f" ({refused} refused)" if refused else ""),
                    np.concatenate(z))
                allz.append(np.concatenate(z))
    row("points, all cells", np.concatenate(allz))
    z = []
    for k in range(a.rendered):
        rng = np.random.default_rng([a.seed, 99, k])
        size = (1024, 768)
        K, dist = camera(rng, size)
        K[0, 0] = K[1, 1] = rng.uniform(0.6, 1.0) * size[0]
        res = calibrate_intrinsics(image_views(rng, K, dist, size, 12), BOARD)
        z.append(z_of(res, K, dist, "standard"))
    if z:
        row(f"rendered images, 1024 x 768, 12 views, {a.rendered} cameras", np.concatenate(z))


if __name__ == "__main__":
    main()
