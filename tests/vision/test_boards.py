"""mocapfj.vision.boards: feature numbering, detection against rendered truth (sub-pixel,
orientation, partial and inverted boards, strong distortion), and bad input."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapfj.errors import InputError
from mocapfj.synth.images import render_board_view
from mocapfj.types import Board, Camera
from mocapfj.vision.boards import (BoardDetection, aruco_dictionary, board_points, board_symmetry, charuco_board,
                                   chessboard_size, detect_board, grey_image)

CAM = Camera("c", (640, 480), np.array([[520.0, 0.0, 321.3], [0.0, 521.0, 238.6], [0.0, 0.0, 1.0]]),
             np.array([-0.12, 0.05, 0.0004, -0.0003, 0.0]), np.eye(3), np.zeros(3))
CHESS = Board("chessboard", 9, 6, square_m=0.03)
CHESS_SYM = Board("chessboard", 8, 6, square_m=0.03)
CHARUCO_INV = Board("charuco", 4, 5, square_m=0.054, marker_m=0.0405, dictionary="DICT_4X4_1000", inverted=True)
APRIL = Board("aprilgrid", 6, 4, tag_m=0.04, spacing_m=0.012, family="tag36h11")


def view(board, rotvec, centre, cam=CAM, seed=0, blur=0.8, **kw):
    """The board's pattern centred at `centre` (camera frame, m), turned by `rotvec`."""
    _, p = board_points(board)
    R = Rotation.from_rotvec(rotvec).as_matrix()
    t = np.asarray(centre, float) - R @ (p.min(0) + p.max(0)) / 2
    return render_board_view(cam, board, R, t, blur_sigma_px=blur, noise_sd=2.0, rng=np.random.default_rng(seed), **kw)


def errors(det, v):
    return np.linalg.norm(det.xy_px - v.corners_px[det.ids], axis=1)


def test_feature_numbering_follows_the_board_frame():
    ids, p = board_points(CHESS)
    assert ids.tolist() == list(range(54))
    np.testing.assert_allclose(p[10], [0.06, 0.06, 0.0])                     # (i, j) = (1, 1)
    np.testing.assert_allclose(p[8], [0.27, 0.03, 0.0])                      # last of the first row
    ids, p = board_points(CHARUCO_INV)
    np.testing.assert_allclose(p, charuco_board(CHARUCO_INV).getChessboardCorners())
    ids, p = board_points(APRIL)
    np.testing.assert_allclose(p[4 * 7:4 * 8, :2], [[0.052, 0.052], [0.092, 0.052], [0.092, 0.092], [0.052, 0.092]])
    assert aruco_dictionary(APRIL).bytesList.shape[0] == 587                  # tag36h11


def test_symmetry_of_each_board():
    assert board_symmetry(CHESS) == 1 and board_symmetry(CHESS_SYM) == 2
    assert board_symmetry(Board("chessboard", 7, 7, square_m=0.02)) == 2
    assert board_symmetry(Board("chessboard", 6, 6, square_m=0.02)) == 4
    assert board_symmetry(CHARUCO_INV) == 1 and board_symmetry(APRIL) == 1


@pytest.mark.parametrize("rotvec, centre", [([0.3, -0.4, 0.1], [0.01, -0.02, 0.42]),
                                            ([-0.2, 0.35, np.pi], [-0.03, 0.02, 0.45]),    # upside down
                                            ([0.1, 0.1, 1.7], [0.0, 0.0, 0.5])])
def test_chessboard_corners_sub_pixel_and_numbered_by_the_squares(rotvec, centre):
    v = view(CHESS, rotvec, centre)
    assert v.in_view.all()
    det = detect_board(v.image, CHESS)
    assert det.ids.tolist() == list(range(54)) and det.image_size == (640, 480)
    # numbering checked by matching each id to its own true corner (a half turn would be ~ a board away)
    e = errors(det, v)
    assert e.max() < 0.1 and np.sqrt(np.mean(e**2)) < 0.04


def test_symmetric_chessboard_is_one_of_its_two_orientations_with_id0_nearest_the_top_left():
    for rotvec in ([0.2, -0.3, 0.2], [0.2, -0.3, np.pi + 0.2]):
        v = view(CHESS_SYM, rotvec, [0.0, 0.0, 0.45])
        det = detect_board(v.image, CHESS_SYM)
        direct = np.linalg.norm(det.xy_px - v.corners_px, axis=1).max()
        turned = np.linalg.norm(det.xy_px - v.corners_px[::-1], axis=1).max()   # half turn: id k <-> 47 - k
        assert min(direct, turned) < 0.1
        assert det.xy_px[0].sum() < det.xy_px[-1].sum()


def test_charuco_inverted_print_and_partial_view():
    v = view(CHARUCO_INV, [0.3, 0.2, 0.3], [0.28, 0.0, 0.5])                # part of it beyond the right edge
    assert 0 < v.in_view.sum() < len(v.ids)
    det = detect_board(v.image, CHARUCO_INV)
    assert det.method == "charuco" and 4 <= len(det.ids) <= v.in_view.sum()
    assert v.in_view[det.ids].all() and errors(det, v).max() < 0.1
    normal = Board("charuco", 4, 5, square_m=0.054, marker_m=0.0405, dictionary="DICT_4X4_1000")
    assert detect_board(v.image, normal) is None                              # not inverted: no markers


def test_aprilgrid_corners_beat_arucos_own_refinement():
    v = view(APRIL, [0.25, -0.3, 0.2], [0.0, 0.0, 0.5], blur=1.0)
    det = detect_board(v.image, APRIL)
    assert det.method == "aprilgrid" and len(det.ids) == 96
    e = errors(det, v)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    corners, tags, _ = cv2.aruco.ArucoDetector(aruco_dictionary(APRIL), params).detectMarkers(v.image)
    peer = np.linalg.norm(np.array(corners).reshape(-1, 4, 2) - v.corners_px.reshape(24, 4, 2)[tags.ravel()], axis=2)
    rms, rms_peer = np.sqrt(np.mean(e**2)), np.sqrt(np.mean(peer**2))
    assert rms < 0.15 and rms < 0.3 * rms_peer, (rms, rms_peer)


WIDE = Camera("wide", (800, 600), np.array([[265.0, 0.0, 392.346], [0.0, 265.265, 294.817], [0.0, 0.0, 1.0]]),
              np.array([-0.26, 0.06, 0.0004, -0.0003, -0.004]), np.eye(3), np.zeros(3))


def test_strongly_distorted_board_that_the_classic_detector_misses():
    """A 106 deg lens, the board near the image's edge with a thin quiet zone, blurred."""
    R = Rotation.from_rotvec([0.02737, 0.1909, -0.80983]).as_matrix()
    v = render_board_view(WIDE, CHESS, R, [-0.23059, 0.0618, 0.12011], blur_sigma_px=1.5, margin_m=0.0045,
                          noise_sd=3.0, rng=np.random.default_rng(1))
    assert v.in_view.all()
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    ok, _ = cv2.findChessboardCorners(v.image, (9, 6), flags=flags)
    assert not ok
    det = detect_board(v.image, CHESS)
    assert det is not None and det.method == "grow"
    assert errors(det, v).max() < 0.15


def test_no_board_and_a_board_file_of_the_wrong_size():
    blank = np.full((480, 640), 128, np.uint8)
    assert detect_board(blank, CHESS) is None and detect_board(blank, CHARUCO_INV) is None
    v = view(CHESS, [0.2, -0.2, 0.1], [0.0, 0.0, 0.45])
    assert detect_board(v.image, CHESS_SYM) is None               # 8 x 6 inside a 9 x 6 print: which 8?
    assert chessboard_size(v.image) == (9, 6)


def test_images_in_any_depth_and_bad_arrays():
    v = view(CHESS, [0.2, -0.2, 0.1], [0.0, 0.0, 0.45])
    ref = detect_board(v.image, CHESS)
    colour = cv2.cvtColor(v.image, cv2.COLOR_GRAY2BGR)
    deep = v.image.astype(np.uint16) * 257
    for img in (colour, deep, v.image / 255.0):
        assert np.abs(detect_board(img, CHESS).xy_px - ref.xy_px).max() < 0.02
    with pytest.raises(InputError, match="image"):
        grey_image(np.zeros((4, 4), np.uint8))
    with pytest.raises(InputError, match="image"):
        grey_image(np.array([[np.nan] * 10] * 10))
    with pytest.raises(InputError, match="as many ids"):
        BoardDetection(np.arange(3), np.zeros((2, 2)), (10, 10), "x")
    with pytest.raises(InputError, match="marker_m"):
        detect_board(v.image, Board("charuco", 4, 5, square_m=0.04, marker_m=0.05, dictionary="DICT_4X4_50"))
    with pytest.raises(InputError, match="family"):
        detect_board(v.image, Board("aprilgrid", 4, 4, tag_m=0.04, spacing_m=0.01, family="tag99"))


def test_real_chessboard_frames(realdata):
    """caliscope's chessboard frames (D. Prible, BSD-2): all 54 corners where the board is whole,
    none where it is cut by the image's edge (cam_0_frame_000), on each of the four cameras."""
    d = realdata / "caliscope" / "chessboard_intrinsic"
    assert detect_board(cv2.imread(str(d / "cam_0_frame_000.jpg")), CHESS) is None
    for name in ["cam_0_frame_100.jpg"] + [f"cam_{c}_frame_1070.jpg" for c in range(4)]:
        det = detect_board(cv2.imread(str(d / name)), CHESS)
        assert det is not None and len(det.ids) == 54, name
