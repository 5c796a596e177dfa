"""Tracking and labelling from rigid clusters: no wrong label from unlabelled detections with ghosts
and dropouts, occlusions NaN, swaps repaired, late markers, gaps filled from the rigid fit
(mocapfj.vision.track)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.rotations import matrix_from_rotvec
from mocapfj.synth.cameras import ring_rig
from mocapfj.synth.markers import place_markers
from mocapfj.synth.render import render_markers
from mocapfj.synth.robot_mesh import base_pose, forward_kinematics, pa10_geometry
from mocapfj.types import Detections, MarkerCluster
from mocapfj.vision.correspondence import match_detections
from mocapfj.vision.track import cluster_symmetry, fill_gaps, fit_clusters, label_points, link_points, rigid_fit


def _wrong(xyz, truth, tol=0.01):
    """Samples given to a marker that is not the nearest true marker, or more than tol from its own."""
    have = np.isfinite(xyz[..., 0])
    d = np.linalg.norm(xyz[:, :, None] - truth[:, None], axis=3)
    nearest = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=2)
    own = np.linalg.norm(xyz - truth, axis=2)
    return have & ((nearest != np.arange(truth.shape[1])[None]) | (own > tol))


@pytest.mark.parametrize("seed", [3, 7])
def test_pa10_clip_from_unlabelled_detections_with_ghosts_and_dropouts(seed):
    """The simulator's PA-10 (20 markers in 6 clusters, 8 cameras, occlusion by its links), 0.15 px
    noise, 3 % of blobs dropped, a spurious blob per camera and frame on average: no label is
    wrong, markers seen by two cameras or more are found, occluded ones are NaN."""
    rng = np.random.default_rng(seed)
    geometry = pa10_geometry()
    layout = place_markers(geometry, rng)
    n = 200
    t = np.arange(n) / 250.0
    q = np.zeros((n, 6))
    q[:, 0] = 0.6 * np.sin(2 * np.pi * 0.5 * t + seed)
    q[:, 1] = 0.3 + 0.4 * np.sin(2 * np.pi * 0.3 * t + 1)
    q[:, 2] = 0.5 * np.sin(2 * np.pi * 0.7 * t)
    q[:, 3] = np.sin(2 * np.pi * 0.4 * t)
    q[:, 4] = 0.8 * np.sin(2 * np.pi * 0.6 * t)
    T = forward_kinematics(q, T_world_base=base_pose())
    rig = ring_rig(8, rng=rng)
    r = render_markers(t, T, layout, geometry, rig, rng, pixel_noise_px=0.15)
    d = r.detections
    keep = rng.random(d.frame.size) > 0.03
    k = rng.poisson(1.0, (n, 8))
    gf, gc = np.nonzero(k)
    gf, gc = np.repeat(gf, k[gf, gc]), np.repeat(gc, k[gf, gc])
    det = Detections(np.r_[d.frame[keep], gf], np.r_[d.camera[keep], gc],
                     np.r_[d.xy_px[keep], rng.uniform([0, 0], [1280, 1024], (gf.size, 2))],
                     np.full(keep.sum() + gf.size, -1))
    perm = rng.permutation(det.frame.size)                    # row order carries no information
    det = Detections(det.frame[perm], det.camera[perm], det.xy_px[perm], det.point_id[perm])
    clusters = [MarkerCluster(f"link{li}", [layout.labels[i] for i in layout.cluster(li)],
                              layout.p_link[layout.cluster(li)]) for li in np.unique(layout.link)]
    cand = match_detections(rig, det, sigma_px=0.15)
    ok = np.isfinite(cand.p_world[:, 0])
    lab = label_points(cand.frame[ok], cand.p_world[ok], clusters, n_frames=n, rate_hz=250.0,
                       residual_m=cand.triangulation.ray_residual_m[ok])
    order = [layout.labels.index(s) for s in lab.markers.labels]
    truth = r.xyz_true[:, order]
    assert not _wrong(lab.markers.xyz, truth).any()
    seen = np.zeros((n, 20), int)
    np.add.at(seen, (d.frame[keep], d.point_id[keep]), 1)
    seen = seen[:, order] >= 2
    have = np.isfinite(lab.markers.xyz[..., 0])
    assert (have & seen).sum() / seen.sum() > 0.98
    assert not (have & ~seen & ~lab.filled).any()            # nothing where no two cameras saw it
    err = np.linalg.norm(lab.markers.xyz - truth, axis=2)
    assert np.nanmax(np.where(lab.filled, err, np.nan), initial=0.0) < 3e-3
    assert lab.stats["n_labelled"] > 0.97 * have.sum() - lab.stats["gaps_filled"]
    assert np.all(lab.markers.residual[lab.filled] == 0.0)


def _two_clusters():
    a = MarkerCluster("a", ["a1", "a2", "a3", "a4"], [[0, 0, 0], [0.12, 0, 0], [0.02, 0.09, 0], [0.05, 0.03, 0.07]])
    b = MarkerCluster("b", ["b1", "b2", "b3"], [[0, 0, 0], [0.15, 0.0, 0], [0.03, 0.11, 0.01]])
    return a, b


def _motion(cluster, n, origin, velocity, omega):
    t = np.arange(n)[:, None]
    R = np.stack([matrix_from_rotvec(omega * k) for k in range(n)])
    return np.einsum("nij,kj->nki", R, cluster.template_m) + (origin + velocity * t)[:, None]


def test_crossing_markers_do_not_swap_where_nearest_neighbours_would():
    """Two clusters pass through each other: marker a1 meets b1 within 1 mm at frame 40, moving in
    opposite directions at 5 mm per frame. Nearest-neighbour linking across frames 39-41 would
    swap them; the labels stay right."""
    a, b = _two_clusters()
    n = 80
    pa = _motion(a, n, np.array([0.0, 0.0, 1.0]) - 40 * np.array([0.005, 0, 0]), np.array([0.005, 0, 0]),
                 np.array([0, 0, 0.002]))
    pb = _motion(b, n, np.array([0.0, 0.0005, 1.0]) + 40 * np.array([0.005, 0.0, 0.0]), np.array([-0.005, 0, 0]),
                 np.array([0.001, 0, 0]))
    pa -= pa[40, 0] - np.array([0.0, 0.0, 1.0])
    pb -= pb[40, 0] - np.array([0.0, 0.0008, 1.0])
    truth = np.concatenate([pa, pb], axis=1)
    rng = np.random.default_rng(0)
    noisy = truth + rng.normal(0, 2e-4, truth.shape)
    frame = np.repeat(np.arange(n), 7)
    p = noisy.reshape(-1, 3)
    shuffle = rng.permutation(p.shape[0])
    lab = label_points(frame[shuffle], p[shuffle], [a, b], n_frames=n, rate_hz=250.0)
    assert not _wrong(lab.markers.xyz, truth, tol=0.002).any()
    assert np.isfinite(lab.markers.xyz[..., 0]).mean() > 0.97
    # the naive tracker: nearest neighbour from frame to frame, starting from the truth
    cur = noisy[0].copy()
    swapped = False
    for f in range(1, n):
        d = np.linalg.norm(cur[:, None] - noisy[f][None], axis=2)
        nxt = noisy[f][np.argmin(d, axis=1)]
        swapped |= bool(np.any(np.linalg.norm(nxt - truth[f], axis=1) > 0.003))
        cur = nxt
    assert swapped


def test_swapped_tracklets_are_cut_and_counted():
    """Tracklets from elsewhere (another system's unlabelled trajectories) that swap two markers of
    a cluster halfway: each half takes its own label and the swap is counted."""
    a, b = _two_clusters()
    n = 60
    pa = _motion(a, n, np.array([0.3, 0.2, 1.0]), np.array([0.001, 0, 0]), np.array([0, 0.003, 0]))
    pb = _motion(b, n, np.array([-0.3, 0.0, 1.1]), np.array([0, 0.001, 0]), np.array([0.002, 0, 0]))
    truth = np.concatenate([pa, pb], axis=1)
    frame = np.repeat(np.arange(n), 7)
    track = np.tile(np.arange(7), n)
    swap = (frame >= 30)
    track = np.where(swap & (track == 0), 1, np.where(swap & (track == 1), 0, track))   # a1 <-> a2 from frame 30
    lab = label_points(frame, truth.reshape(-1, 3), [a, b], n_frames=n, rate_hz=100.0, tracklet=track)
    assert np.allclose(lab.markers.xyz, truth)
    assert lab.stats["swaps_repaired"] == 2


def test_late_markers_occlusion_gaps_and_ghost_points():
    """Cluster b enters at frame 30; a3 is hidden for 8 frames (filled from the rigid fit) and for
    60 frames (left NaN and reported); random ghost points take no label."""
    a, b = _two_clusters()
    n = 150
    pa = _motion(a, n, np.array([0.3, 0.2, 1.0]), np.array([0.002, 0, 0]), np.array([0.004, 0.003, 0]))
    pb = _motion(b, n, np.array([-0.3, 0.0, 1.1]), np.array([0, 0.002, 0]), np.array([0.002, 0, 0.003]))
    truth = np.concatenate([pa, pb], axis=1)
    rng = np.random.default_rng(2)
    obs = truth + rng.normal(0, 2e-4, truth.shape)
    obs[:30, 4:] = np.nan
    obs[50:58, 2] = np.nan
    obs[80:140, 2] = np.nan
    ghosts = rng.uniform([-0.5, -0.5, 0.6], [0.5, 0.5, 1.5], (n, 2, 3))
    pts = np.concatenate([obs, ghosts], axis=1)
    frame = np.repeat(np.arange(n), 9)
    flat = pts.reshape(-1, 3)
    lab = label_points(frame, flat, [a, b], n_frames=n, rate_hz=250.0, max_gap_s=0.04)
    xyz = lab.markers.xyz
    assert not _wrong(xyz, truth, tol=0.002).any()
    assert np.isnan(xyz[:30, 4:]).all() and np.isfinite(xyz[32:, 4:]).all()
    assert lab.filled[50:58, 2].all() and np.abs(xyz[50:58, 2] - truth[50:58, 2]).max() < 1e-3
    assert np.isnan(xyz[80:140, 2]).all() and not lab.filled[80:140].any()
    gaps = [(g["label"], g["start_frame"], g["n_frames"]) for g in lab.long_gaps]
    assert ("a3", 80, 60) in gaps
    assert lab.stats["gaps_filled"] == 8
    assert (lab.point_label.reshape(n, 9)[:, 7:] == -1).all()


def test_symmetric_template_refused_and_nearly_symmetric_resolved_over_time():
    eq = MarkerCluster("eq", ["e1", "e2", "e3"], [[0, 0, 0], [0.1, 0, 0], [0.05, 0.0866025, 0]])
    assert cluster_symmetry(eq, 1e-4) is not None
    with pytest.raises(InputError, match="symmetric template"):
        label_points(np.zeros(3, int), eq.template_m, [eq], n_frames=1, rate_hz=100.0)
    # an isosceles triangle whose legs differ by 1 mm (within the 3 mm tolerance of a single frame):
    # the frames of a tracklet decide together
    iso = MarkerCluster("iso", ["i1", "i2", "i3"], [[0, 0, 0], [0.1, 0, 0], [0.0516, 0.15, 0.0]])
    n = 120
    p = _motion(iso, n, np.array([0.1, 0.0, 1.0]), np.array([0.001, 0.0005, 0]), np.array([0.003, 0.004, 0.002]))
    rng = np.random.default_rng(4)
    obs = p + rng.normal(0, 2e-4, p.shape)
    lab = label_points(np.repeat(np.arange(n), 3), obs.reshape(-1, 3), [iso], n_frames=n, rate_hz=250.0)
    assert not _wrong(lab.markers.xyz, p, tol=0.002).any()
    assert np.isfinite(lab.markers.xyz[..., 0]).mean() > 0.95


def test_link_points_and_fits():
    a, _ = _two_clusters()
    p = _motion(a, 20, np.array([0.0, 0.0, 1.0]), np.array([0.003, 0, 0]), np.array([0, 0, 0.01]))
    frame = np.repeat(np.arange(20), 4)
    tid = link_points(frame, p.reshape(-1, 3), 20, rate_hz=100.0)
    assert np.unique(tid).size == 4 and (tid.reshape(20, 4) == tid.reshape(20, 4)[0]).all()
    pred, resid, npres = fit_clusters(p, a.labels, [a])
    assert np.allclose(pred, p) and np.nanmax(resid) < 1e-12 and (npres == 4).all()
    holes = p.copy()
    holes[5:8, 1] = np.nan
    holes[10:16, 0:2] = np.nan                # two of four left: no fit
    out, filled, gaps = fill_gaps(holes, a.labels, [a], max_gap_frames=5)
    assert filled[5:8, 1].all() and np.allclose(out[5:8, 1], p[5:8, 1])
    assert not filled[10:16].any() and {g["label"] for g in gaps} == {"a1", "a2"}
    with pytest.raises(InputError, match="frames 0..19"):
        label_points(np.array([20]), np.zeros((1, 3)), [a], n_frames=20, rate_hz=100.0)


def _kabsch_svd(p, q, w):
    """Kabsch (1976) by SVD with the reflection correction: the reference for rigid_fit."""
    pc = (w[..., None] * p).sum(1) / w.sum(1, keepdims=True)
    qc = (w[..., None] * np.nan_to_num(q)).sum(1) / w.sum(1, keepdims=True)
    H = np.einsum("nk,nki,nkj->nij", w, p - pc[:, None], np.nan_to_num(q) - qc[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)))
    D = np.zeros_like(H)
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = np.swapaxes(Vt, 1, 2) @ D @ np.swapaxes(U, 1, 2)
    return R, qc - np.einsum("nij,nj->ni", R, pc)


def test_rigid_fit_is_kabsch():
    """Horn's quaternion gives Kabsch's (reflection-corrected SVD) fit: noise-free poses exactly,
    noisy ones, three markers (a plane), a point set mirrored by noise, absent markers ignored."""
    rng = np.random.default_rng(8)
    n, K = 2000, 5
    tpl = rng.normal(0, 0.05, (K, 3))
    R_true = np.stack([matrix_from_rotvec(v) for v in rng.normal(0, 1.5, (n, 3))])
    q = np.einsum("nij,kj->nki", R_true, tpl) + rng.normal(0, 1, (n, 1, 3))
    w = np.ones((n, K))
    w[: n // 2, 3:] = 0.0                             # three markers only
    q[w == 0] = np.nan
    p = np.broadcast_to(tpl, (n, K, 3))
    R, t = rigid_fit(p, q, w)
    assert np.abs(R - R_true).max() < 1e-12
    assert np.abs(np.linalg.det(R) - 1).max() < 1e-12
    noisy = q + rng.normal(0, 0.01, q.shape)          # 1 cm on 5 cm: some fits want a reflection
    R1, t1 = rigid_fit(p, noisy, w)
    R2, t2 = _kabsch_svd(p, noisy, w)
    assert np.abs(R1 - R2).max() < 1e-9 and np.abs(t1 - t2).max() < 1e-10
    assert np.abs(np.linalg.det(R1) - 1).max() < 1e-12
    R0, t0 = rigid_fit(p[:1], q[:1], np.zeros((1, K)))
    assert np.isnan(t0).all()
