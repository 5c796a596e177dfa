"""mocapfj.synth.images: rendered boards and blobs, checked with OpenCV's own detectors."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapfj.errors import InputError
from mocapfj.synth.cameras import ring_rig
from mocapfj.synth.images import board_points, board_texture, render_blob_clip, render_board_view
from mocapfj.types import Board, Camera
from mocapfj.vision.camera import camera_centre_world

K = np.array([[1100.0, 0.0, 641.2], [0.0, 1100.0, 508.7], [0.0, 0.0, 1.0]])
CAM = Camera("c", (1280, 1024), K, [-0.04, 0.015, 0.0005, -0.0003, 0.0], np.eye(3), np.zeros(3))

CHESS = Board("chessboard", 9, 6, square_m=0.03)
CHARUCO = Board("charuco", 7, 5, square_m=0.04, marker_m=0.028, dictionary="DICT_5X5_100")
APRIL = Board("aprilgrid", 6, 4, tag_m=0.04, spacing_m=0.012, family="tag36h11")
POSES = [([0.3, -0.4, 0.1], [0.02, -0.03, 0.6]),      # (rotation vector, pattern centre in camera frame, m)
         ([-0.2, 0.3, 0.0], [-0.1, 0.05, 0.7]),
         ([0.0, 0.0, 0.4], [0.0, 0.0, 0.55])]


def centred_pose(board, rotvec, centre_cam):
    """Board pose in the camera frame with the pattern centre at `centre_cam`."""
    _, p = board_points(board)
    R = Rotation.from_rotvec(rotvec).as_matrix()
    return R, np.asarray(centre_cam) - R @ (p.min(0) + p.max(0)) / 2


def nearest_errors(found, truth):
    d = np.linalg.norm(found.reshape(-1, 2)[:, None] - truth[None], axis=2)
    return d.min(axis=1), d.argmin(axis=1)


@pytest.mark.parametrize("rotvec, centre", POSES)
def test_chessboard_corners_found_within_0p1_px(rotvec, centre):
    view = render_board_view(CAM, CHESS, *centred_pose(CHESS, rotvec, centre))
    assert view.in_view.all()
    ok, corners = cv2.findChessboardCornersSB(view.image, (9, 6), flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    assert ok
    err, idx = nearest_errors(corners, view.corners_px)   # SB may return the grid reversed: match by position
    assert len(set(idx)) == 54
    assert err.max() < 0.1


def test_chessboard_seen_by_a_rig_camera_from_a_world_pose():
    cam = ring_rig().cameras[3]
    c = camera_centre_world(cam)
    towards = (np.array([0.0, 0.0, 1.2]) - c) / np.linalg.norm(np.array([0.0, 0.0, 1.2]) - c)
    centre = c + 0.8 * towards
    R_cam_board = Rotation.from_rotvec([0.2, 0.1, 0.0]).as_matrix()
    R_world_board = cam.R_cam_world.T @ R_cam_board          # board facing the camera, a little tilted
    _, p = board_points(CHESS)
    t_world_board = centre - R_world_board @ (p.min(0) + p.max(0)) / 2
    view = render_board_view(cam, CHESS, R_world_board, t_world_board)
    ok, corners = cv2.findChessboardCornersSB(view.image, (9, 6), flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    assert ok and nearest_errors(corners, view.corners_px)[0].max() < 0.1


@pytest.mark.parametrize("rotvec, centre", POSES)
def test_charuco_detector_finds_90_percent_of_corners_within_0p2_px(rotvec, centre):
    view = render_board_view(CAM, CHARUCO, *centred_pose(CHARUCO, rotvec, centre))
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100)
    det = cv2.aruco.CharucoDetector(cv2.aruco.CharucoBoard((7, 5), 0.04, 0.028, d))
    cc, ci, _, _ = det.detectBoard(view.image)
    assert ci is not None
    err = np.linalg.norm(cc.reshape(-1, 2) - view.corners_px[ci.ravel()], axis=1)
    assert (err < 0.2).sum() >= 0.9 * len(view.ids)


@pytest.mark.parametrize("rotvec, centre", POSES)
def test_aruco_detector_finds_every_apriltag(rotvec, centre):
    view = render_board_view(CAM, APRIL, *centred_pose(APRIL, rotvec, centre))
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11), params)
    corners, ids, _ = det.detectMarkers(view.image)
    assert sorted(ids.ravel().tolist()) == list(range(24))
    truth = view.corners_px.reshape(24, 4, 2)
    err = np.array([np.linalg.norm(c.reshape(4, 2) - truth[i], axis=1) for c, i in zip(corners, ids.ravel())])
    # corner order and geometry agree with the truth; ArUco's contour corners sit ~0.2 px inside the
    # true outline even after SUBPIX refinement (the chessboard tests bound the rendering itself)
    assert err.max() < 0.6 and np.median(err) < 0.3


def test_blobs_found_within_0p1_px_and_hidden_ones_not_drawn():
    cam = ring_rig().cameras[0]
    rng = np.random.default_rng(3)
    gx, gy = np.meshgrid(np.linspace(-0.5, 0.5, 6), np.linspace(0.7, 1.7, 4))
    p = np.stack([np.zeros(gx.size), gx.ravel(), gy.ravel()], 1)[None] + rng.normal(0, 0.01, (4, 24, 3))
    visible = np.ones((4, 24), bool)
    visible[1, 5] = False
    clip = render_blob_clip(cam, p, radius_px=4.0, noise_sd=2.0, visible=visible, rng=np.random.default_rng(0))
    assert clip.images.shape == (4, 1024, 1280) and clip.images.dtype == np.uint8
    assert clip.drawn.sum() == 95 and np.isnan(clip.centroids_px[1, 5]).all()
    bp = cv2.SimpleBlobDetector_Params()
    bp.blobColor = 255
    bp.minArea, bp.maxArea = 10, 5000
    bp.filterByCircularity = bp.filterByInertia = bp.filterByConvexity = False
    detector = cv2.SimpleBlobDetector_create(bp)
    for f in range(4):
        found = np.array([k.pt for k in detector.detect(clip.images[f])])
        truth = clip.centroids_px[f][clip.drawn[f]]
        assert len(found) == len(truth)
        err = np.linalg.norm(truth[:, None] - found[None], axis=2).min(axis=1)
        assert err.max() < 0.1
    again = render_blob_clip(cam, p, radius_px=4.0, noise_sd=2.0, visible=visible, rng=np.random.default_rng(0))
    assert again.images.tobytes() == clip.images.tobytes()


def test_texture_layout_and_feature_ids():
    tex, m = board_texture(CHESS, px_per_m=1000.0)
    assert m == 30 and tex.shape == (7 * 30 + 60, 10 * 30 + 60)
    assert tex[m, m] == 0 and tex[m, m + 30] == 255 and tex[0, 0] == 255   # black corner square, white margin
    ids, p = board_points(APRIL)
    np.testing.assert_allclose(p[4:8, :2], [[0.052, 0], [0.092, 0], [0.092, 0.04], [0.052, 0.04]])
    assert ids.tolist() == list(range(96))
    ids, p = board_points(CHARUCO)
    assert len(ids) == 24 and np.allclose(p[0], (0.04, 0.04, 0.0))


def test_board_dimensions_off_the_texel_grid_raise():
    with pytest.raises(InputError, match="square_m"):
        board_texture(Board("chessboard", 9, 6, square_m=0.03333), px_per_m=1000.0, margin_m=0.03)
    with pytest.raises(InputError, match="rng"):
        render_board_view(CAM, CHESS, np.eye(3), (0, 0, 1.0), noise_sd=1.0)
