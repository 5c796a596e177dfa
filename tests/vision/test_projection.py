"""mocapfj.vision.projection: analytic Jacobians against finite differences and against the
Jacobian of cv2.projectPoints; Newton undistortion against cv2.undistortPoints."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapfj.errors import InputError
from mocapfj.types import Camera
from mocapfj.vision.camera import project_points
from mocapfj.vision.projection import (camera_parameters, normalized_from_pixels, project_batch,
                                       project_jacobians, undistort_points)


def camera(rng, n_dist, scale=0.05, rotvec=None):
    d = rng.normal(0.0, scale, n_dist)
    r = rng.normal(0.0, 0.6, 3) if rotvec is None else np.asarray(rotvec, float)
    K = np.array([[1100.0 + rng.normal(0, 30), 0, 640 + rng.normal(0, 9)],
                  [0, 1080.0 + rng.normal(0, 30), 512 + rng.normal(0, 9)], [0, 0, 1]])
    return Camera("c", (1280, 1024), K, d, Rotation.from_rotvec(r).as_matrix(), rng.normal(0, 0.2, 3) + (0, 0, 3.0))


def numeric(fun, x0, h):
    cols = []
    for i in range(x0.size):
        e = np.zeros_like(x0)
        e[i] = h
        cols.append((fun(x0 + e) - fun(x0 - e)) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("n_dist", [0, 4, 5, 8, 12])
def test_jacobians_match_cv2_project_points(n_dist):
    rng = np.random.default_rng(100 + n_dist)
    cam = camera(rng, n_dist)
    p = rng.normal(0.0, 0.6, (60, 3))
    J = project_jacobians(cam, p)
    ref, Jc = cv2.projectPoints(p, cv2.Rodrigues(cam.R_cam_world)[0], cam.t_cam_world, cam.K,
                                cam.dist if n_dist else None)
    Jc = Jc.reshape(60, 2, -1)
    assert np.abs(J.xy_px - ref[:, 0]).max() < 1e-9
    scale = np.abs(Jc).max()
    np.testing.assert_allclose(J.d_pose, Jc[:, :, :6], atol=1e-10 * scale)
    np.testing.assert_allclose(J.d_intrinsics[:, :, :4], Jc[:, :, 6:10], atol=1e-10 * scale)
    if n_dist:
        m = min(n_dist, 5)
        np.testing.assert_allclose(J.d_intrinsics[:, :, 4:4 + m], Jc[:, :, 10:10 + m], atol=1e-10 * scale)


@pytest.mark.parametrize("rotvec", [None, [0.0, 0.0, 0.0], [1e-9, -2e-9, 0.5e-9], [0.0, np.pi - 1e-3, 0.0]])
def test_jacobians_match_finite_differences(rotvec):
    rng = np.random.default_rng(7)
    cam = camera(rng, 8, rotvec=rotvec)
    p = rng.normal(0.0, 0.6, (25, 3))
    r, t, intr, extra = camera_parameters(cam)
    ci = np.zeros(len(p), np.intp)
    J = project_batch(r[None], t[None], intr[None], extra[None], ci, p)

    def by_pose(x):
        return project_batch(x[None, :3], x[None, 3:], intr[None], extra[None], ci, p, jacobians=False).xy_px

    def by_intr(x):
        return project_batch(r[None], t[None], x[None], extra[None], ci, p, jacobians=False).xy_px

    np.testing.assert_allclose(J.d_pose, numeric(by_pose, np.concatenate([r, t]), 1e-6), rtol=1e-6, atol=1e-4)
    np.testing.assert_allclose(J.d_intrinsics, numeric(by_intr, intr, 1e-7), rtol=1e-6, atol=1e-4)
    for i in range(3):                                   # by point: each coordinate of every point at once
        e = np.zeros(3)
        e[i] = 1e-6
        num = (project_batch(r[None], t[None], intr[None], extra[None], ci, p + e, jacobians=False).xy_px
               - project_batch(r[None], t[None], intr[None], extra[None], ci, p - e, jacobians=False).xy_px) / 2e-6
        np.testing.assert_allclose(J.d_point[:, :, i], num, rtol=1e-6, atol=1e-4)


def test_batch_over_several_cameras_equals_each_camera():
    rng = np.random.default_rng(3)
    cams = [camera(rng, 5) for _ in range(3)]
    params = [camera_parameters(c) for c in cams]
    p = rng.normal(0.0, 0.5, (30, 3))
    ci = rng.integers(0, 3, 30)
    J = project_batch(*(np.stack([q[k] for q in params]) for k in range(4)), ci, p)
    for c in range(3):
        xy, _ = project_points(cams[c], p[ci == c])
        np.testing.assert_allclose(J.xy_px[ci == c], xy, atol=1e-10)
        np.testing.assert_allclose(J.d_pose[ci == c], project_jacobians(cams[c], p[ci == c]).d_pose, atol=1e-10)


def test_points_behind_camera_are_nan():
    cam = Camera("c", (640, 480), [[500, 0, 320], [0, 500, 240], [0, 0, 1]], [0.1, 0, 0, 0], np.eye(3), np.zeros(3))
    J = project_jacobians(cam, [[0.1, 0.0, 1.0], [0.1, 0.0, -1.0]])
    assert np.isfinite(J.d_pose[0]).all() and np.isnan(J.xy_px[1]).all() and np.isnan(J.d_point[1]).all()


@pytest.mark.parametrize("n_dist", [0, 5, 8, 12, 14])
def test_undistortion_inverts_projection_and_matches_cv2(n_dist):
    rng = np.random.default_rng(200 + n_dist)
    cam = camera(rng, n_dist, scale=0.03)
    if n_dist == 14:
        cam = Camera("c", cam.size, cam.K, np.r_[cam.dist[:12], 0.01, -0.02], cam.R_cam_world, cam.t_cam_world)
    p = rng.normal(0.0, 0.6, (200, 3))
    xy, _ = project_points(cam, p)
    pc = p @ cam.R_cam_world.T + cam.t_cam_world
    n = normalized_from_pixels(cam, xy)
    np.testing.assert_allclose(n, pc[:, :2] / pc[:, 2:], atol=1e-11)
    ref = cv2.undistortPoints(xy.reshape(-1, 1, 2), cam.K, cam.dist if n_dist else None, P=cam.K,
                              criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14))[:, 0]
    np.testing.assert_allclose(undistort_points(cam, xy), ref, atol=1e-6)


def test_strong_barrel_distortion_converges_where_opencv_default_iteration_does_not():
    """Strong barrel distortion (k1 = -0.3, k2 = 0.05, monotonic, wide angle): Newton inverts the image
    corners to 1e-8 px; OpenCV's default (5 fixed-point steps) is off by over 100 px there."""
    cam = Camera("c", (1280, 1024), [[600, 0, 640], [0, 600, 512], [0, 0, 1]], [-0.3, 0.05, 0, 0, 0],
                 np.eye(3), np.zeros(3))
    g = np.stack(np.meshgrid(np.linspace(0, 1279, 9), np.linspace(0, 1023, 7)), -1).reshape(-1, 2)
    n = normalized_from_pixels(cam, g)
    assert np.isfinite(n).all()
    back, _ = project_points(cam, np.column_stack([n, np.ones(len(n))]))
    np.testing.assert_allclose(back, g, atol=1e-8)
    default = cv2.undistortPoints(g.reshape(-1, 1, 2), cam.K, cam.dist, P=cam.K)[:, 0]   # 5 fixed-point steps
    assert np.abs(default - undistort_points(cam, g)).max() > 100.0
    beyond = Camera("c", cam.size, cam.K, [-0.45, 0.2, 0, 0, -0.04], np.eye(3), np.zeros(3))
    assert np.isnan(normalized_from_pixels(beyond, [[1279.0, 1023.0]])).all()   # past the fold: no inverse


def test_nan_pixels_stay_nan_and_shapes_are_kept():
    cam = Camera("c", (640, 480), [[500, 0, 320], [0, 500, 240], [0, 0, 1]], [0.1, 0.01, 0, 0, 0], np.eye(3), np.zeros(3))
    out = undistort_points(cam, np.array([[[100.0, 50.0], [np.nan, 3.0]]]))
    assert out.shape == (1, 2, 2) and np.isfinite(out[0, 0]).all() and np.isnan(out[0, 1]).all()
    with pytest.raises(InputError, match="xy_px"):
        undistort_points(cam, np.zeros((3, 3)))
    with pytest.raises(InputError, match="tilt"):
        camera_parameters(Camera("c", (640, 480), cam.K, np.r_[np.zeros(12), 0.01, 0.0], np.eye(3), np.zeros(3)))
