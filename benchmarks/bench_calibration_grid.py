"""Do the rig calibration's standard deviations cover its errors? A grid of synthetic rigs on seeds
not used while developing (default base seed 7000).

Board rigs: ring rigs of 3, 4 or 6 cameras (2 m radius, jittered intrinsics), 30 views of a 7 x 5
ChArUco board, pixel noise 0.15, 0.3 or 0.6 px, intrinsics held or refined (fx fy cx cy k1 k2 p1 p2).
Wand rigs: 6 or 8 cameras (2.6 m ring), 600 frames of the 3-marker 500 mm wand with the waver's
body occluding, noise 0.1, 0.2 or 0.4 px, intrinsics held.

For every estimated parameter z = error / SD, in the gauge of camera 0 (orientations about each
camera's own axes; translations; intrinsics). A calibrated uncertainty has mean z^2 = 1, 4.6 % of
|z| beyond 2 and 0.27 % beyond 3. The wand rows also give the wand length's SD (mm).

Run: ``.venv/bin/python benchmarks/bench_calibration_grid.py [--seeds N] [--base-seed S]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mocapfj.io.calib import read_wand  # noqa: E402
from mocapfj.rotations import rotvec_from_matrix  # noqa: E402
from mocapfj.synth.cameras import ring_rig  # noqa: E402
from mocapfj.synth.rig_views import board_observations  # noqa: E402
from mocapfj.synth.wand import wand_wave  # noqa: E402
from mocapfj.types import Board, Camera, Rig  # noqa: E402
from mocapfj.vision.rig import calibrate_rig  # noqa: E402
from mocapfj.vision.wand import calibrate_wand  # noqa: E402

BOARD = Board("charuco", 7, 5, square_m=0.06, marker_m=0.042, dictionary="DICT_5X5_100")
WAND = read_wand(ROOT / "calibration" / "wands" / "wand_3marker_500mm.toml")
INTR = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")


def unposed(rig):
    return Rig(tuple(Camera(c.name, c.size, c.K, c.dist, np.eye(3), np.zeros(3)) for c in rig.cameras))


def zscores(rig, res) -> np.ndarray:
    R0, t0 = rig.cameras[0].R_cam_world, rig.cameras[0].t_cam_world
    E0R, E0t = res.rig.cameras[0].R_cam_world, res.rig.cameras[0].t_cam_world
    z = []
    for c, (cam, est) in enumerate(zip(rig.cameras, res.rig.cameras)):
        s = res.cameras[c]
        if c:
            Rt = cam.R_cam_world @ R0.T
            Re = est.R_cam_world @ E0R.T
            z += list(rotvec_from_matrix(Re @ Rt.T) / s.rotation_std_rad)
            te = est.t_cam_world - Re @ E0t
            tt = cam.t_cam_world - Rt @ t0
            z += list((te - tt) / [s.std["tx"], s.std["ty"], s.std["tz"]])
        true = dict(zip(INTR, np.r_[cam.K[[0, 1, 0, 1], [0, 1, 2, 2]], cam.dist[:4]]))
        got = dict(zip(INTR, np.r_[est.K[[0, 1, 0, 1], [0, 1, 2, 2]], est.dist[:4]]))
        z += [(got[n] - true[n]) / s.std[n] for n in res.refined_intrinsics if n in true]
    return np.array(z)


def row(label, zs, times, extra=""):
    z = np.concatenate(zs)
    print(f"| {label} | {len(zs)} | {z.size} | {np.mean(z**2):.2f} | {100 * np.mean(np.abs(z) > 2):.1f} | "
          f"{100 * np.mean(np.abs(z) > 3):.2f} | {np.abs(z).max():.1f} | {np.median(times):.1f} | {extra} |", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--base-seed", type=int, default=7000)
    a = ap.parse_args()
    print("| case | rigs | values | mean z^2 | % abs(z) > 2 | % abs(z) > 3 | max abs(z) | s per rig | wand length SD (mm) |")
    print("|" + "---|" * 9)
    all_z = []
    for n_cam in (3, 4, 6):
        for noise in (0.15, 0.3, 0.6):
            for refine in ("fixed", "default"):
                zs, times = [], []
                for k in range(a.seeds):
                    seed = a.base_seed + 1000 * n_cam + int(100 * noise) + 10 * k + (refine == "default")
                    rng = np.random.default_rng(seed)
                    rig = ring_rig(n_cam, rng=rng, radius_m=2.0)
                    det = board_observations(rig, BOARD, 30, rng, noise_px=noise).detections
                    t0 = time.perf_counter()
                    try:
                        res = calibrate_rig(det, BOARD, unposed(rig), intrinsics=refine)
                    except Exception as e:          # noqa: BLE001 - a failure is a result of the grid
                        print(f"  seed {seed}: {type(e).__name__}: {e}")
                        continue
                    times.append(time.perf_counter() - t0)
                    zs.append(zscores(rig, res))
                if zs:
                    row(f"board, {n_cam} cameras, {noise} px, intrinsics {refine}", zs, times)
                    all_z += zs
    for n_cam in (6, 8):
        for noise in (0.1, 0.2, 0.4):
            zs, times, sds = [], [], []
            for k in range(a.seeds):
                seed = a.base_seed + 50000 + 1000 * n_cam + int(100 * noise) + 10 * k
                rng = np.random.default_rng(seed)
                rig = ring_rig(n_cam, rng=rng)
                det = wand_wave(rig, WAND, 600, rng, noise_px=noise).detections
                t0 = time.perf_counter()
                try:
                    res = calibrate_wand(det, WAND, unposed(rig))
                except Exception as e:              # noqa: BLE001
                    print(f"  seed {seed}: {type(e).__name__}: {e}")
                    continue
                times.append(time.perf_counter() - t0)
                zs.append(zscores(rig, res))
                sds.append(res.wand_length_sd_mm)
            if zs:
                row(f"wand, {n_cam} cameras, {noise} px", zs, times, f"{min(sds):.2f}-{max(sds):.2f}")
                all_z += zs
    row("all", all_z, [0.0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
