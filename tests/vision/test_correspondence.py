"""Multi-view matching of unlabelled blobs into 3D candidates, with ghost rejection
(mocapfj.vision.correspondence)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.synth.cameras import ring_rig
from mocapfj.types import Detections
from mocapfj.vision.camera import in_image, project_rig
from mocapfj.vision.correspondence import match_detections


@pytest.fixture(scope="module")
def scene():
    """30 markers moving in a 1 m cube for 60 frames, 8 ring cameras, random occlusion (each view
    lost with 25 %), 0.2 px noise; detections unlabelled, plus 2 spurious blobs per camera and frame."""
    rng = np.random.default_rng(21)
    rig = ring_rig(8, rng=rng)
    n, m = 60, 30
    p = rng.uniform([-0.5, -0.5, 0.7], [0.5, 0.5, 1.7], (1, m, 3)) + np.cumsum(rng.normal(0, 0.002, (n, m, 3)), 0)
    xy, front = project_rig(rig, p)                                           # (C, n, m, 2)
    vis = front & np.stack([in_image(c, xy[i], 2.0) for i, c in enumerate(rig.cameras)]) & (rng.random(front.shape) > 0.25)
    c, f, k = np.nonzero(vis)
    obs = xy[c, f, k] + rng.normal(0, 0.2, (c.size, 2))
    g = 2 * 8 * n
    gc, gf = np.tile(np.arange(8), 2 * n), np.repeat(np.arange(n), 16)
    det = Detections(np.r_[f, gf], np.r_[c, gc], np.r_[obs, rng.uniform([0, 0], [1280, 1024], (g, 2))],
                     np.full(c.size + g, -1))
    truth_id = np.r_[k, np.full(g, -1)]
    return rig, p, vis, det, truth_id


def test_candidates_are_single_markers_and_ghosts_are_rejected(scene):
    rig, p, vis, det, truth_id = scene
    cand = match_detections(rig, det, sigma_px=0.2)
    ok = np.isfinite(cand.p_world[:, 0])
    rows = cand.detection[:, ok]
    ids = np.where(rows >= 0, truth_id[np.maximum(rows, 0)], -2)
    strong = (rows >= 0).sum(axis=0) >= 3
    # every candidate of three views or more is one marker's blobs, no spurious blob in it
    pure = np.array([len(set(col[col != -2])) == 1 and -1 not in col for col in ids.T])
    assert pure[strong].all()
    # and finds nearly every marker-frame that three cameras saw
    n_seen = vis.sum(axis=0)
    found = np.zeros(n_seen.shape, bool)
    marker = np.array([col[col >= 0][0] if (col >= 0).any() else -1 for col in ids.T])
    good = pure & (marker >= 0)
    found[cand.frame[ok][good], marker[good]] = True
    assert found[n_seen >= 3].mean() > 0.99
    # its 3D error is within the covariance's reach
    e = cand.p_world[ok][good] - p[cand.frame[ok][good], marker[good]]
    z2 = np.einsum("ni,nij,nj->n", e, np.linalg.inv(cand.triangulation.cov[ok][good]), e)
    assert np.mean(z2) / 3 < 1.3 and np.max(z2) < 60
    st = cand.stats
    assert st["ghost_pairs"] > 0 and st["n_detections"] == det.frame.size and st["n_nonfinite"] == 0
    # two-view candidates only where unambiguous; spurious pairs may pass that test (the labeller
    # rejects them); they are few
    two = (rows >= 0).sum(axis=0) == 2
    assert (~pure[two]).sum() <= 0.02 * ok.sum()


def test_same_answer_whatever_the_row_order(scene):
    rig, p, vis, det, truth_id = scene
    rng = np.random.default_rng(1)
    perm = rng.permutation(det.frame.size)
    a = match_detections(rig, det, sigma_px=0.2)
    b = match_detections(rig, Detections(det.frame[perm], det.camera[perm], det.xy_px[perm], det.point_id[perm]),
                         sigma_px=0.2)
    key = lambda c: sorted(map(tuple, np.round(c.p_world[np.isfinite(c.p_world[:, 0])], 9).tolist()))  # noqa: E731
    assert key(a) == key(b)


def test_nearly_overlapping_blobs_support_nothing():
    """Two markers 1 cm apart along camera 0's line of sight: their blobs in camera 0 are within
    the gate of each other, so camera 0 supports neither; the other cameras still find both."""
    rig = ring_rig(6, rng=np.random.default_rng(2))
    cam0 = rig.cameras[0]
    centre = -cam0.R_cam_world.T @ cam0.t_cam_world
    a = np.array([0.0, 0.0, 1.2])
    b = a + 0.01 * (a - centre) / np.linalg.norm(a - centre) + np.array([0.0, 0.0, 0.0003])
    p = np.stack([a, b])[None]
    xy, _ = project_rig(rig, p)
    c, f, k = np.nonzero(np.ones(xy.shape[:3], bool))
    det = Detections(f, c, xy[c, f, k], np.full(c.size, -1))
    cand = match_detections(rig, det, sigma_px=0.2)
    assert np.isfinite(cand.p_world[:, 0]).sum() == 2
    assert not cand.triangulation.used[0].any()
    assert np.sort(np.linalg.norm(cand.p_world[:, None] - p[0][None], axis=2).min(axis=1)).max() < 1e-6


def test_bad_detections():
    rig = ring_rig(3, rng=np.random.default_rng(3))
    p = np.array([[[0.0, 0.1, 1.2]]])
    xy, _ = project_rig(rig, p)
    det = Detections(np.zeros(4, int), np.array([0, 1, 2, 2]), np.r_[xy[:, 0, 0], [[np.nan, 4.0]]], np.full(4, -1))
    cand = match_detections(rig, det, sigma_px=0.2)
    assert cand.stats["n_nonfinite"] == 1 and np.isfinite(cand.p_world).all() and cand.p_world.shape == (1, 3)
    with pytest.raises(InputError, match="camera numbers 0..2"):
        match_detections(rig, Detections(np.zeros(1, int), np.array([3]), np.zeros((1, 2)), np.full(1, -1)))
