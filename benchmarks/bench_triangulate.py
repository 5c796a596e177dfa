"""Pixels to labelled markers: triangulation speed and accuracy against aniposelib, and labelling of
the PA-10 scenarios from unlabelled detections with ghosts and dropouts.

Goals (issue: from pixels to labelled 3D markers):

- linear step >= 1,000,000 points/s for 8 cameras on 2 cores;
- >= 10x aniposelib 0.8 ``CameraGroup.triangulate`` at equal accuracy, and robust triangulation
  >= 10x its ``triangulate_ransac``;
- zero label swaps on the pa10 scenarios from unlabelled detections with ghosts and dropouts;
  labelling 60 s of 20 markers at 250 Hz in under 10 s.

Data. Speed: a jittered 8-camera ring (``mocapfj.synth.cameras.ring_rig``, 1280 x 1024, small
barrel distortion), points uniform in a 1 m cube at the rig's centre, 0.2 px noise, each view lost
with 20 % (NaN). Robust: the same with 5 % of the views moved by 5-35 px. Labelling: each
``datasets/pa10_*.toml`` simulated for `--duration` s (its own seed, rig and marker layout), every
frame's markers rendered through its cameras with occlusion by the arm's links
(``mocapfj.synth.render``), 0.15 px noise, then the point ids dropped, 3 % of the blobs lost and
one spurious blob per camera and frame added on average.

Columns: wall time, points/s, 3D RMS error against the truth (mm) and the ratio of the times
measured in the same run; for the scenarios also the process's CPU time (on a machine shared with
other jobs the wall time is the CPU time stretched by the load) and the load average. aniposelib's ``triangulate`` undistorts with OpenCV and solves each point's
DLT by SVD under JAX (x64); ``triangulate_ransac`` tries camera subsets per point in Python.
mocapfj's linear step: the undistortion (approximate inverse plus residual table, bounded at
1e-3 px), the DLT normal equations and their solve in one compiled pass per point (numba; the
first run after installation compiles the kernels into numba's on-disk cache, later runs load
them); the "normalised coordinates" row is the linear algebra alone in numpy (one matrix product
(N, 4C) x (4C, 9)) from coordinates undistorted beforehand; "refined" adds Gauss-Newton and the
covariance; "robust" adds the vectorised MSAC over camera pairs.

Run: ``.venv/bin/python benchmarks/bench_triangulate.py [--quick] [--duration S]`` (aniposelib and jax
are optional bench dependencies: ``pip install --no-deps aniposelib toml``; skipped when absent).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mocapfj.rotations import rotvec_from_matrix  # noqa: E402
from mocapfj.synth.cameras import ring_rig  # noqa: E402
from mocapfj.types import Detections, MarkerCluster  # noqa: E402
from mocapfj.vision.camera import project_rig  # noqa: E402
from mocapfj.vision.correspondence import match_detections  # noqa: E402
from mocapfj.vision.track import label_points  # noqa: E402
from mocapfj.vision.triangulate import (dlt_feature_matrix, solve_dlt, triangulate, triangulate_linear,  # noqa: E402
                                        undistortion_table)


def best_of(fn, repeat=2):
    out, best = None, np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return out, best


def points(rig, n, rng, drop=0.2):
    p = rng.uniform([-0.5, -0.5, 0.7], [0.5, 0.5, 1.7], (n, 3))
    xy, _ = project_rig(rig, p)
    xy = xy + rng.normal(0, 0.2, xy.shape)
    xy[rng.random(xy.shape[:2]) < drop] = np.nan
    return p, xy


def rms_mm(p, truth):
    e = np.linalg.norm(p - truth, axis=1)
    return float(np.sqrt(np.nanmean(e**2)) * 1e3)


def anipose_group(rig):
    try:
        from aniposelib.cameras import Camera as ACam, CameraGroup
    except ImportError:
        return None
    return CameraGroup([ACam(matrix=c.K, dist=c.dist, size=c.size, rvec=rotvec_from_matrix(c.R_cam_world),
                             tvec=c.t_cam_world, name=c.name) for c in rig.cameras])


def linear_from_normalized(rig, nrm):
    """The linear step alone from undistorted normalised coordinates (C, N, 2), NaN unseen."""
    G = dlt_feature_matrix(rig)
    C, N = nrm.shape[:2]
    out = np.empty((N, 3))
    for s in range(0, N, 32768):
        sl = slice(s, min(N, s + 32768))
        x, y = nrm[:, sl, 0], nrm[:, sl, 1]
        ok = np.isfinite(x)
        x, y = np.where(ok, x, 0.0), np.where(ok, y, 0.0)
        F = np.stack([x * x + y * y, x, y, ok], axis=1).reshape(4 * C, -1)
        out[sl] = solve_dlt((G.T @ F).T)[0]
    out[(np.isfinite(nrm[..., 0]).sum(axis=0) < 2)] = np.nan
    return out


def speed_table(quick: bool):
    rng = np.random.default_rng(0)
    rig = ring_rig(8, rng=rng)
    for c in rig.cameras:
        undistortion_table(c)                         # built once per camera (cached), not timed
    group = anipose_group(rig)
    rows = []
    n_big = 300_000 if quick else 1_000_000
    p, xy = points(rig, n_big, rng)
    nrm = np.stack([undistortion_table(c).normalized(xy[i]) for i, c in enumerate(rig.cameras)])
    est, t = best_of(lambda: linear_from_normalized(rig, nrm))
    rows.append(("mocapfj linear step (normalised coordinates)", n_big, t, rms_mm(est, p), None))
    est, t = best_of(lambda: triangulate_linear(rig, xy)[0])
    rows.append(("mocapfj linear step + undistortion (pixels)", n_big, t, rms_mm(est, p), None))
    n = 100_000 if quick else 300_000
    p, xy = points(rig, n, rng)
    lin, t_lin = best_of(lambda: triangulate_linear(rig, xy)[0])
    ref, t_ref = best_of(lambda: triangulate(rig, xy, sigma_px=0.2, robust=False))
    t_anip = None
    if group is not None:
        group.triangulate(xy[:, :1000])               # JAX compilation, not timed
        ap, t_anip = best_of(lambda: group.triangulate(xy), repeat=1)
        rows.append(("aniposelib CameraGroup.triangulate", n, t_anip, rms_mm(ap, p), 1.0))
    rows.append(("mocapfj triangulate_linear", n, t_lin, rms_mm(lin, p), t_anip / t_lin if t_anip else None))
    rows.append(("mocapfj triangulate (refined, covariance)", n, t_ref, rms_mm(ref.p_world, p),
                 t_anip / t_ref if t_anip else None))
    # robust
    n_r = 100 if quick else 200
    p, xy = points(rig, 20_000, rng)
    seen = np.isfinite(xy[..., 0])
    bad = seen & (rng.random(seen.shape) < 0.05)
    shift = rng.normal(0, 1, (bad.sum(), 2))
    xy[bad] += shift * (5 + 30 * rng.random(bad.sum()))[:, None] / np.linalg.norm(shift, axis=1, keepdims=True)
    rob, t_rob = best_of(lambda: triangulate(rig, xy, sigma_px=0.2))
    t_ran = None
    if group is not None:
        ar, t_ran = best_of(lambda: group.triangulate_ransac(xy[:, :n_r])[0], repeat=1)
        rows.append(("aniposelib triangulate_ransac", n_r, t_ran, rms_mm(ar, p[:n_r]), 1.0))
    sub, t_sub = best_of(lambda: triangulate(rig, xy[:, :n_r], sigma_px=0.2))
    rows.append(("mocapfj triangulate (robust), same points", n_r, t_sub, rms_mm(sub.p_world, p[:n_r]),
                 t_ran / t_sub if t_ran else None))
    rows.append(("mocapfj triangulate (robust)", 20_000, t_rob, rms_mm(rob.p_world, p),
                 (t_ran / n_r) / (t_rob / 20_000) if t_ran else None))
    print("| method (8 cameras, 20 % views missing, 0.2 px) | points | time (s) | points/s | 3D RMS (mm) | speed-up vs aniposelib |")
    print("|---|---|---|---|---|---|")
    for name, n, t, e, ratio in rows:
        print(f"| {name} | {n} | {t:.3f} | {n / t:,.0f} | {e:.3f} | {'' if ratio is None else f'{ratio:.1f}x'} |")
    print("\nrobust rows: 5 % of the views moved by 5-35 px; the speed-up of the 20,000-point row compares points/s.")


def build_scenario(name: str, duration: float):
    """One PA-10 scenario as unlabelled detections with dropouts and spurious blobs (module docstring):
    (rig, det, clusters, rend, keep, layout, n, rate_hz, sigma_px)."""
    from mocapfj.synth.record import marker_layout, scenario_rngs, simulate_scenario
    from mocapfj.synth.render import render_markers
    from mocapfj.synth.robot_mesh import base_pose, forward_kinematics, pa10_geometry
    from mocapfj.synth.scenario import load_scenario
    import dataclasses

    scn = load_scenario(ROOT / "datasets" / f"{name}.toml")
    scn = dataclasses.replace(scn, duration_s=duration)
    sim = simulate_scenario(scn)
    rng_layout, rng_rig, _, _ = scenario_rngs(scn)
    m = scn.measurement
    n = int(round(duration * m.mocap_hz))
    t = np.arange(n) / m.mocap_hz
    q_full = np.tile(np.asarray(scn.pose_rad, float), (n, 1))
    for j in scn.joints:
        r = sim[j.name]
        col = r.joint_names.index(j.name) if r.q.shape[1] > 1 else 0
        q_full[:, j.axis - 1] = np.interp(t, r.t, r.q[:, col])
    geometry = pa10_geometry()
    T = forward_kinematics(q_full, T_world_base=base_pose())
    layout = marker_layout(scn, geometry, rng_layout)
    rig = ring_rig(m.n_cameras, rng=rng_rig)
    rng = np.random.default_rng(scn.seed + 1000)
    rend = render_markers(t, T, layout, geometry, rig, rng, pixel_noise_px=m.pixel_noise_px)
    d = rend.detections
    keep = rng.random(d.frame.size) > 0.03
    k = rng.poisson(1.0, (n, len(rig.cameras)))
    gf, gc = np.nonzero(k)
    gf, gc = np.repeat(gf, k[gf, gc]), np.repeat(gc, k[gf, gc])
    det = Detections(np.r_[d.frame[keep], gf], np.r_[d.camera[keep], gc],
                     np.r_[d.xy_px[keep], rng.uniform([0, 0], rig.cameras[0].size, (gf.size, 2))],
                     np.full(keep.sum() + gf.size, -1))
    clusters = [MarkerCluster(f"link{li}", [layout.labels[i] for i in layout.cluster(li)],
                              layout.p_link[layout.cluster(li)]) for li in np.unique(layout.link)]
    return rig, det, clusters, rend, keep, layout, n, m.mocap_hz, m.pixel_noise_px


def score_labelling(lab, rend, keep, layout, n):
    """(labelled samples, wrong labels, found share of the markers seen by >= 2 cameras, NaN share)."""
    d = rend.detections
    order = [layout.labels.index(s) for s in lab.markers.labels]
    truth = rend.xyz_true[:, order]
    xyz = lab.markers.xyz
    have = np.isfinite(xyz[..., 0])
    dist = np.linalg.norm(xyz[:, :, None] - truth[:, None], axis=3)
    nearest = np.argmin(np.where(np.isfinite(dist), dist, np.inf), axis=2)
    wrong = have & ((nearest != np.arange(len(order))[None]) | (np.linalg.norm(xyz - truth, axis=2) > 0.01))
    seen = np.zeros((n, len(order)), int)
    np.add.at(seen, (d.frame[keep], np.argsort(order)[d.point_id[keep]]), 1)
    seen = seen >= 2
    return int(have.sum()), int(wrong.sum()), (have & seen).sum() / seen.sum(), 1 - have.mean()


def scenario_table(duration: float, names):
    print("\n| scenario | frames | detections | spurious | correspondence (s) | labelling (s) | CPU s (corr. + lab.) | "
          "labelled samples | wrong labels | found of seen by >= 2 cameras | NaN share | gaps filled | long gaps | load |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        rig, det, clusters, rend, keep, layout, n, rate, sigma = build_scenario(name, duration)
        n_spurious = det.frame.size - int(keep.sum())
        tic, cpu = time.perf_counter(), time.process_time()
        cand = match_detections(rig, det, sigma_px=sigma)
        t_corr, c_corr = time.perf_counter() - tic, time.process_time() - cpu
        ok = np.isfinite(cand.p_world[:, 0])
        tic, cpu = time.perf_counter(), time.process_time()
        lab = label_points(cand.frame[ok], cand.p_world[ok], clusters, n_frames=n, rate_hz=rate,
                           residual_m=cand.triangulation.ray_residual_m[ok])
        t_lab, c_lab = time.perf_counter() - tic, time.process_time() - cpu
        n_have, n_wrong, found, nan_share = score_labelling(lab, rend, keep, layout, n)
        print(f"| {name} | {n} | {det.frame.size} | {n_spurious} | {t_corr:.2f} | {t_lab:.2f} | "
              f"{c_corr:.2f} + {c_lab:.2f} | {n_have} | {n_wrong} | {100 * found:.2f} % | {100 * nan_share:.2f} % | "
              f"{lab.stats['gaps_filled']} | {lab.stats['n_long_gaps']} | {os.getloadavg()[0]:.1f} |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="smaller speed cases")
    ap.add_argument("--duration", type=float, default=60.0, help="seconds of each PA-10 scenario (default 60)")
    ap.add_argument("--scenarios", default="pa10_joint1,pa10_joint2,pa10_joints23")
    ap.add_argument("--skip-speed", action="store_true")
    args = ap.parse_args()
    print(f"cores: {os.cpu_count()}, load average {os.getloadavg()[0]:.1f}")
    if not args.skip_speed:
        speed_table(args.quick)
    if args.duration > 0:
        scenario_table(args.duration, args.scenarios.split(","))


if __name__ == "__main__":
    main()
