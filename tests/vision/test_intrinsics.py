"""mocapfj.vision.intrinsics: SDs that cover the error over many synthetic cameras, recovery
through rendered images, outliers, degenerate views, and the published answers of real data."""

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapfj.errors import InputError
from mocapfj.io.calib import read_board
from mocapfj.synth.images import render_board_view
from mocapfj.types import Board, Camera
from mocapfj.vision.boards import BoardDetection, board_points, detect_board
from mocapfj.vision.intrinsics import calibrate_intrinsics

BOARDS = Path(__file__).resolve().parents[2] / "calibration" / "boards"
CHESS = Board("chessboard", 9, 6, square_m=0.03)
IDS, P = board_points(CHESS)


def synthetic_camera(rng, size=(1280, 960)):
    w, h = size
    f = rng.uniform(0.6, 1.2) * w
    K = np.array([[f, 0.0, w / 2 + rng.normal(0, 10)], [0.0, f * rng.uniform(0.99, 1.01), h / 2 + rng.normal(0, 10)],
                  [0.0, 0.0, 1.0]])
    dist = np.array([rng.uniform(-0.35, 0.1), rng.uniform(-0.05, 0.15), rng.normal(0, 1e-3), rng.normal(0, 1e-3), 0.0])
    return K, dist


def synthetic_views(rng, K, dist, size, n, noise_px=0.3, tilt_deg=(10, 45)):
    """Projected board corners with Gaussian noise, boards tilted by `tilt_deg` and fully in view."""
    w, h = size
    f = K[0, 0]
    dets = []
    while len(dets) < n:
        R = Rotation.from_rotvec(rng.normal(0, 1, 3) * np.radians(rng.uniform(*tilt_deg)) / np.sqrt(3)).as_matrix()
        z = f * 0.27 / (rng.uniform(0.3, 0.7) * w)
        c = np.array([rng.uniform(-0.3, 0.3) * w / f * z, rng.uniform(-0.3, 0.3) * h / f * z, z])
        x, _ = cv2.projectPoints(P, cv2.Rodrigues(R)[0], c - R @ P.mean(0), K, dist)
        x = x.reshape(-1, 2)
        if (x < 0).any() or (x[:, 0] > w - 1).any() or (x[:, 1] > h - 1).any():
            continue
        dets.append(BoardDetection(IDS, x + rng.normal(0, noise_px, x.shape), size, "synthetic"))
    return dets


def test_sds_cover_the_error_over_many_synthetic_cameras():
    """40 cameras (focal 0.6-1.2 x width, k1 -0.35..0.1, 3 image sizes, 6-19 views) at 0.3 px:
    the mean squared z-score of fx, fy, cx, cy, k1, k2, p1, p2, k3 is about 1."""
    z = []
    for seed in range(40):
        rng = np.random.default_rng(seed)
        size = [(1280, 960), (640, 480), (1920, 1080)][seed % 3]
        K, dist = synthetic_camera(rng, size)
        res = calibrate_intrinsics(synthetic_views(rng, K, dist, size, int(rng.integers(6, 20))), CHESS,
                                   reject_outliers=False)
        truth = np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist]
        z.append((res.values - truth) / res.std)
        assert 0.2 < res.sigma_px / 0.3 < 1.5
    z = np.array(z)
    per_param = (z**2).mean(axis=0)
    assert 0.75 < (z**2).mean() < 1.3, per_param
    assert per_param.max() < 2.0 and np.abs(z).max() < 5.0, per_param


def test_recovery_through_rendered_images_within_the_predicted_sds():
    """Board views rendered through a distorted camera, found by detect_board, calibrated."""
    rng = np.random.default_rng(7)
    K = np.array([[560.0, 0.0, 322.4], [0.0, 561.5, 236.9], [0.0, 0.0, 1.0]])
    dist = np.array([-0.21, 0.06, 0.0006, -0.0004, 0.0])
    cam = Camera("c", (640, 480), K, dist, np.eye(3), np.zeros(3))
    dets = []
    while len(dets) < 8:
        R = Rotation.from_rotvec(rng.normal(0, 1, 3) * np.radians(rng.uniform(15, 40)) / np.sqrt(3)).as_matrix()
        z = rng.uniform(0.33, 0.45)
        c = np.array([rng.uniform(-0.15, 0.15) * z, rng.uniform(-0.12, 0.12) * z, z])
        v = render_board_view(cam, CHESS, R, c - R @ P.mean(0), supersample=3, blur_sigma_px=0.8, noise_sd=2.0, rng=rng)
        if v.in_view.all():
            dets.append(detect_board(v.image, CHESS))
    res = calibrate_intrinsics(dets, CHESS)
    z = (res.values - np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist]) / res.std
    assert res.n_views_used == 8 and res.rms_px < 0.06
    assert np.abs(z).max() < 4.0, z
    assert abs(res.values[0] / K[0, 0] - 1) < 1e-3


def test_an_outlier_view_is_rejected_and_named():
    rng = np.random.default_rng(3)
    K, dist = synthetic_camera(rng)
    dets = synthetic_views(rng, K, dist, (1280, 960), 10)
    bad = dets[4]
    dets[4] = BoardDetection(bad.ids, bad.xy_px + rng.normal(0, 3.0, bad.xy_px.shape), bad.image_size, "synthetic")
    slip = dets[7].xy_px.copy()
    slip[20] += (9.0, -6.0)                                    # one corner on the wrong junction
    dets[7] = BoardDetection(dets[7].ids, slip, (1280, 960), "synthetic")
    res = calibrate_intrinsics(dets, CHESS, names=[f"img{k}.png" for k in range(10)])
    assert res.views[4].status == "rejected" and res.n_views_used == 9
    assert any("img4.png" in w for w in res.warnings)
    assert res.views[7].status == "used" and res.views[7].n_points == 53 and res.n_points_rejected == 1
    z = (res.values - np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], dist]) / res.std
    assert np.abs(z).max() < 4.0
    d = res.to_dict()
    assert {"fx", "fy", "cx", "cy", "dist", "rms_px", "n_views_used", "n_views", "std", "views"} <= d.keys()
    assert d["views"][4]["status"] == "rejected" and d["n_views"] == 10 and set(d["std"]) >= {"fx", "k3"}


def test_parallel_views_are_refused_naming_them():
    rng = np.random.default_rng(1)
    K, dist = synthetic_camera(rng)
    dets = synthetic_views(rng, K, dist, (1280, 960), 8, tilt_deg=(0.0, 0.5))
    with pytest.raises(InputError, match="focal length") as e:
        calibrate_intrinsics(dets, CHESS, names=[f"v{k}" for k in range(8)])
    assert "v0" in str(e.value) and "deg" in str(e.value)


def test_too_few_views_and_foreign_ids_are_refused():
    rng = np.random.default_rng(2)
    K, dist = synthetic_camera(rng)
    one = synthetic_views(rng, K, dist, (1280, 960), 1)
    with pytest.raises(InputError, match="at least 3 views") as e:
        calibrate_intrinsics([None, one[0], None], CHESS, names=["a.png", "b.png", "c.png"])
    assert "a.png" in str(e.value) and "c.png" in str(e.value)
    few = BoardDetection(IDS[:5], one[0].xy_px[:5], (1280, 960), "x")
    with pytest.raises(InputError, match="at least 3 views"):
        calibrate_intrinsics([few] * 5, CHESS)
    with pytest.raises(InputError, match="feature ids"):
        calibrate_intrinsics([BoardDetection(IDS + 100, one[0].xy_px, (1280, 960), "x")] * 3, CHESS)
    with pytest.raises(InputError, match="model"):
        calibrate_intrinsics(one * 3, CHESS, model="fisheye")


def test_distortion_models():
    rng = np.random.default_rng(5)
    K, dist = synthetic_camera(rng)
    dets = synthetic_views(rng, K, dist, (1280, 960), 12)
    four = calibrate_intrinsics(dets, CHESS, model="no_k3")
    eight = calibrate_intrinsics(dets, CHESS, model="rational")
    assert four.camera.dist.size == 4 and len(four.std) == 8
    assert eight.camera.dist.size == 8 and eight.param_names[-1] == "k6"
    assert abs(four.values[0] / K[0, 0] - 1) < 5 * four.std[0] / K[0, 0]


BOUGUET = {"left": ((533.004, 533.153), (341.586, 234.259)), "right": ((536.983, 536.569), (326.472, 249.333))}


@pytest.mark.parametrize("side", ["left", "right"])
def test_bouguet_stereo_intrinsics(realdata, side):
    """J.-Y. Bouguet's 14-view stereo example (his toolbox: fx, fy and the 1-based principal
    point; OpenCV's findChessboardCorners + calibrateCamera reaches RMS 0.41 px on the left)."""
    board = read_board(BOARDS / "chessboard_9x6_30mm.toml")
    files = sorted((realdata / "bouguet_stereo" / "images").glob(f"{side}*.jpg"))
    dets = [detect_board(cv2.imread(str(f), cv2.IMREAD_GRAYSCALE), board) for f in files]
    assert len(files) == 14 and all(d is not None for d in dets)
    res = calibrate_intrinsics(dets, board, names=[f.name for f in files])
    (fx, fy), (cx1, cy1) = BOUGUET[side]
    assert res.n_views_used == 14
    assert abs(res.values[0] / fx - 1) < 0.01 and abs(res.values[1] / fy - 1) < 0.01
    assert abs(res.values[2] - (cx1 - 1)) < 3.0 and abs(res.values[3] - (cy1 - 1)) < 3.0
    assert res.rms_px <= 0.41


CALISCOPE_RMS = (0.54, 0.40, 0.37, 0.33)


def test_caliscope_webcams_from_their_inverted_charuco_videos(realdata):
    """caliscope's four webcams (D. Prible, BSD-2) from the mp4s of its inverted ChArUco board,
    every third frame: each camera's RMS no worse than caliscope's own intrinsic RMS."""
    from mocapfj.pipeline.calibrate import detect_views

    board = read_board(BOARDS / "charuco_4x5_caliscope.toml")
    base = realdata / "caliscope" / "post_optimization" / "calibration" / "extrinsic"
    for cam, theirs in enumerate(CALISCOPE_RMS):
        names, dets = detect_views([base / f"cam_{cam}.mp4"], board, every=3, progress=False)
        res = calibrate_intrinsics(dets, board, names=names)
        assert res.n_views_used >= 10 and res.rms_px <= theirs, (cam, res.rms_px)
