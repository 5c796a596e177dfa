"""mocapfj.vision.camera: projection against cv2.projectPoints, flags, look-at cameras."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mocapfj.errors import InputError
from mocapfj.types import Camera
from mocapfj.vision.camera import (DIST_LENGTHS, camera_centre_world, in_image, look_at_camera, project_points,
                                   project_rig)
from mocapfj.types import Rig


def random_camera(rng, n_dist):
    d = rng.normal(0.0, 0.02, n_dist)
    if n_dist == 14:
        d[12:] = (0.01, -0.02)                       # Scheimpflug tilt, rad
    R = Rotation.from_rotvec(rng.normal(0.0, 0.4, 3)).as_matrix()
    t = rng.normal(0.0, 0.2, 3) + (0.0, 0.0, 3.0)
    K = np.array([[1100.0 + rng.normal(0, 20), 0.0, 640.0 + rng.normal(0, 5)],
                  [0.0, 1100.0 + rng.normal(0, 20), 512.0 + rng.normal(0, 5)], [0.0, 0.0, 1.0]])
    return Camera("c", (1280, 1024), K, d, R, t)


@pytest.mark.parametrize("n_dist", DIST_LENGTHS)
def test_matches_cv2_project_points_to_1e9_px(n_dist):
    rng = np.random.default_rng(n_dist)
    cam = random_camera(rng, n_dist)
    p = rng.normal(0.0, 0.7, (300, 3))
    xy, front = project_points(cam, p)
    ref, _ = cv2.projectPoints(p, cv2.Rodrigues(cam.R_cam_world)[0], cam.t_cam_world, cam.K,
                               cam.dist if n_dist else None)
    assert front.all()
    assert np.abs(xy - ref[:, 0]).max() < 1e-9


def test_time_by_marker_shape_equals_flat():
    rng = np.random.default_rng(1)
    cam = random_camera(rng, 5)
    p = rng.normal(0.0, 0.5, (7, 4, 3))
    xy, front = project_points(cam, p)
    xy_flat, front_flat = project_points(cam, p.reshape(-1, 3))
    assert xy.shape == (7, 4, 2) and front.shape == (7, 4)
    np.testing.assert_array_equal(xy.reshape(-1, 2), xy_flat)
    np.testing.assert_array_equal(front.ravel(), front_flat)
    xy_rig, front_rig = project_rig(Rig((cam, cam)), p)
    assert xy_rig.shape == (2, 7, 4, 2) and front_rig.shape == (2, 7, 4)


def test_points_behind_camera_are_flagged_and_nan():
    cam = Camera("c", (640, 480), [[500, 0, 320], [0, 500, 240], [0, 0, 1]], [0.1, 0, 0, 0], np.eye(3), np.zeros(3))
    xy, front = project_points(cam, [[0.1, 0.1, 1.0], [0.1, 0.1, -1.0], [0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(front, [True, False, False])
    assert np.isfinite(xy[0]).all() and np.isnan(xy[1:]).all()


def test_in_image_uses_pixel_edges():
    cam = Camera("c", (640, 480), [[500, 0, 320], [0, 500, 240], [0, 0, 1]], [], np.eye(3), np.zeros(3))
    xy = np.array([[-0.5, 0.0], [-0.51, 0.0], [639.5, 479.5], [639.6, 10.0], [np.nan, 1.0]])
    np.testing.assert_array_equal(in_image(cam, xy), [True, False, True, False, False])
    np.testing.assert_array_equal(in_image(cam, xy, margin_px=1.0), [False, False, False, False, False])


def test_look_at_camera_aims_and_keeps_up_upward():
    pos, target = np.array([2.0, -1.5, 2.2]), np.array([0.1, 0.2, 1.0])
    cam = look_at_camera("a", pos, target, fx=1100.0, size=(1280, 1024))
    xy, front = project_points(cam, np.stack([target, target + (0, 0, 0.1)]))
    assert front.all()
    np.testing.assert_allclose(xy[0], (639.5, 511.5), atol=1e-9)
    assert xy[1, 1] < xy[0, 1]                       # world up appears up (smaller v)
    np.testing.assert_allclose(cam.R_cam_world @ cam.R_cam_world.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(cam.R_cam_world) == pytest.approx(1.0)
    np.testing.assert_allclose(camera_centre_world(cam), pos, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(rotvec=st.lists(st.floats(-3, 3), min_size=3, max_size=3),
       shift=st.lists(st.floats(-5, 5), min_size=3, max_size=3))
def test_rigid_motion_of_whole_scene_leaves_pixels_unchanged(rotvec, shift):
    rng = np.random.default_rng(7)
    cam = random_camera(rng, 8)
    p = rng.normal(0.0, 0.5, (20, 3))
    Q = Rotation.from_rotvec(rotvec).as_matrix()
    s = np.asarray(shift)
    # new world = Q old world + s: points move, camera extrinsics follow
    moved = Camera("c", cam.size, cam.K, cam.dist, cam.R_cam_world @ Q.T, cam.t_cam_world - cam.R_cam_world @ Q.T @ s)
    a, _ = project_points(cam, p)
    b, _ = project_points(moved, p @ Q.T + s)
    np.testing.assert_allclose(a, b, atol=1e-7)


def test_bad_inputs_raise_input_error():
    good = dict(name="c", size=(640, 480), K=[[500, 0, 320], [0, 500, 240], [0, 0, 1]], R_cam_world=np.eye(3),
                t_cam_world=np.zeros(3))
    with pytest.raises(InputError, match="dist"):
        project_points(Camera(dist=np.zeros(6), **good), [[0, 0, 1.0]])
    skewed = dict(good, K=[[500, 1.0, 320], [0, 500, 240], [0, 0, 1]])
    with pytest.raises(InputError, match="K"):
        project_points(Camera(dist=[], **skewed), [[0, 0, 1.0]])
    with pytest.raises(InputError, match="p_world"):
        project_points(Camera(dist=[], **good), np.zeros((4, 2)))
    with pytest.raises(InputError, match="up_world"):
        look_at_camera("a", [0, 0, 2], [0, 0, 0], fx=500.0, size=(640, 480))
