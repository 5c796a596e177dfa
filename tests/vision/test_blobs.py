"""Blob detection: sub-pixel centroids against rendered truth and OpenCV's SimpleBlobDetector,
centroid SDs that cover the error, shape and size filters (mocapfj.vision.blobs)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.special import ndtr

from mocapfj.errors import InputError
from mocapfj.synth.cameras import ring_rig
from mocapfj.synth.images import render_blob_clip
from mocapfj.vision.blobs import detect_blobs


def _match(found, truth, tol=1.0):
    d, i = cKDTree(found).query(truth)
    ok = d < tol
    return found[i[ok]] - truth[ok], i[ok], ok


@pytest.fixture(scope="module")
def clip():
    """Markers moving in front of a ring camera, rendered as anti-aliased discs (radius 4 px)."""
    rng = np.random.default_rng(1)
    cam = ring_rig(4, rng=np.random.default_rng(0)).cameras[0]
    p = rng.uniform([-0.6, -0.6, 0.6], [0.6, 0.6, 1.8], (1, 25, 3)) + np.cumsum(rng.normal(0, 0.003, (8, 25, 3)), 0)
    return render_blob_clip(cam, p, radius_px=4.0, noise_sd=1.0, supersample=16, rng=rng)


def test_centroids_against_the_truth_and_opencv(clip):
    b = detect_blobs(clip.images)
    assert len(b) == clip.drawn.sum() and b.rejected == {"area": 0, "border": 0, "circularity": 0}
    ours, sbd = [], []
    params = cv2.SimpleBlobDetector_Params()
    params.blobColor = 255
    params.minArea, params.maxArea = 5, 5000
    params.filterByCircularity = params.filterByInertia = params.filterByConvexity = False
    detector = cv2.SimpleBlobDetector_create(params)
    for f in range(clip.images.shape[0]):
        truth = clip.centroids_px[f][clip.drawn[f]]
        e, _, ok = _match(b.xy_px[b.frame == f], truth)
        assert ok.all()
        ours.append(e)
        e2, _, _ = _match(np.array([k.pt for k in detector.detect(clip.images[f])]), truth)
        sbd.append(e2)
    rms = np.sqrt(np.mean(np.concatenate(ours) ** 2))
    rms_cv = np.sqrt(np.mean(np.concatenate(sbd) ** 2))
    assert rms < 0.01 and rms < 0.6 * rms_cv, (rms, rms_cv)
    assert np.all(b.circularity > 0.97) and np.allclose(b.radius_px, 4.0, atol=0.15)
    assert np.all((b.quality > 0.8) & (b.quality <= 1.0))
    det = b.detections(camera=3, frame_offset=100)
    assert det.camera.tolist() == [3] * len(b) and det.frame.min() == 100 and (det.point_id == -1).all()


def _gaussian_blobs(rng, n_frames, centres, sd_px, amplitude, noise, shape=(120, 160), bg=20.0):
    """Float images of Gaussian spots integrated exactly over each pixel, plus white noise."""
    h, w = shape
    x = np.arange(w)
    y = np.arange(h)
    out = np.full((n_frames, h, w), bg)
    for f in range(n_frames):
        for cx, cy in centres[f]:
            gx = ndtr((x + 0.5 - cx) / sd_px) - ndtr((x - 0.5 - cx) / sd_px)
            gy = ndtr((y + 0.5 - cy) / sd_px) - ndtr((y - 0.5 - cy) / sd_px)
            out[f] += amplitude * np.outer(gy, gx)
    return out + rng.normal(0, noise, out.shape)


def test_centroid_sd_covers_the_error():
    """Gaussian spots (exact pixel integrals) in white noise: the predicted centroid SDs give
    z-scores of unit RMS over 600 blobs (two noise levels)."""
    rng = np.random.default_rng(3)
    for noise in (2.0, 6.0):
        centres = [rng.uniform([15, 15], [145, 105], (6, 2)) for _ in range(50)]
        for c in centres:                                   # keep spots apart
            c[:, 0] = 15 + 22 * np.arange(6) + rng.uniform(0, 6, 6)
        imgs = _gaussian_blobs(rng, 50, centres, 1.4, 2500.0, noise)
        b = detect_blobs(imgs, ring_px=2)
        z = []
        for f in range(50):
            e, i, ok = _match(b.xy_px[b.frame == f], centres[f])
            assert ok.all()
            z.append(e / b.sigma_px[b.frame == f][i, None])
        z = np.concatenate(z)
        assert 0.85 < np.sqrt(np.mean(z**2)) < 1.15, (noise, np.sqrt(np.mean(z**2)))
        assert abs(np.median(b.noise) - noise) < 0.1 * noise


def test_merged_markers_fail_the_circularity_test():
    """Two discs of radius 4 px closer than 1.5 radii merge into one blob: left out and counted."""
    cam = ring_rig(4, rng=np.random.default_rng(0)).cameras[0]
    rng = np.random.default_rng(4)
    single = render_blob_clip(cam, np.array([[[0.0, 0.0, 1.2]]]), noise_sd=1.0, rng=rng)
    b = detect_blobs(single.images)
    assert len(b) == 1 and b.circularity[0] > 0.97
    # a second marker 6 px away in the image (depth ~2.6 m, f = 1100 px: 14 mm)
    img = single.images[0].astype(float)
    shifted = np.roll(img, 6, axis=1)
    merged = np.maximum(img, shifted).astype(np.uint8)[None]
    b = detect_blobs(merged)
    assert len(b) == 0 and b.rejected["circularity"] == 1
    loose = detect_blobs(merged, min_circularity=0.3)
    assert len(loose) == 1 and loose.circularity[0] < 0.7


def test_size_and_border_filters_and_noise_alone():
    rng = np.random.default_rng(5)
    img = np.full((2, 100, 120), 10, np.uint8)
    img[0, 50:52, 60:62] = 200                  # 4 px: kept with min_area 3, dropped with 5
    img[0, 10:40, 10:40] = 200                  # 900 px
    img[0, 0:5, 100:105] = 200                  # touches the border
    b = detect_blobs(img, max_area_px=500)
    assert len(b) == 1 and b.rejected["area"] == 1 and b.rejected["border"] == 1
    assert np.allclose(b.xy_px[0], [60.5, 50.5])
    assert len(detect_blobs(img, min_area_px=5, max_area_px=500)) == 0
    noise = np.clip(rng.normal(30, 3, (20, 200, 200)), 0, 255).astype(np.uint8)
    assert len(detect_blobs(noise)) == 0                       # 6-sigma threshold: no false blobs


def test_other_image_types_and_a_fixed_threshold():
    img8 = np.full((60, 80), 10, np.uint8)
    img8[20:25, 30:35] = 250
    b8 = detect_blobs(img8)
    b16 = detect_blobs(img8.astype(np.uint16) * 256)
    bf = detect_blobs(img8.astype(np.float32) / 255.0)
    for b in (b16, bf):
        assert np.allclose(b.xy_px, b8.xy_px) and np.allclose(b.xy_px, [[32.0, 22.0]])
    assert b8.saturated.tolist() == [False] and b16.saturated.tolist() == [False]
    assert len(detect_blobs(img8, threshold=251)) == 0
    with pytest.raises(InputError, match="images"):
        detect_blobs(np.zeros((2, 3, 4, 5)))
    with pytest.raises(InputError, match="grey levels"):
        detect_blobs(np.zeros((10, 10), dtype=bool))
