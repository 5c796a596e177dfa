"""N-view triangulation: exact without noise, errors covered by the covariance, robust views,
the undistortion table's bound, bad input (mocapfj.vision.triangulate)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.synth.cameras import ring_rig
from mocapfj.synth.markers import place_markers
from mocapfj.synth.render import render_markers
from mocapfj.synth.robot_mesh import base_pose, forward_kinematics, pa10_geometry
from mocapfj.types import Rig
from mocapfj.vision.camera import look_at_camera, project_points, project_rig
from mocapfj.vision.projection import normalized_from_pixels
from mocapfj.vision.triangulate import (observation_array, triangulate, triangulate_linear, undistortion_table)


def _points(rng, n):
    return rng.uniform([-0.5, -0.5, 0.7], [0.5, 0.5, 1.7], (n, 3))


@pytest.fixture(scope="module")
def rig():
    return ring_rig(8, rng=np.random.default_rng(11))


def test_undistortion_table_within_its_bound(rig):
    """The table's interpolation stays within its recorded bound (<= 1e-3 px) on random pixels."""
    rng = np.random.default_rng(0)
    for cam in rig.cameras[:3]:
        tab = undistortion_table(cam)
        assert tab.max_error_px <= 1e-3
        xy = rng.uniform([-0.5, -0.5], [cam.size[0] - 0.5, cam.size[1] - 0.5], (20000, 2))
        err = np.abs(tab.normalized(xy) - normalized_from_pixels(cam, xy)).max(axis=1) * cam.K[0, 0]
        assert err.max() <= 1.05 * tab.max_error_px
    # beyond the table: exact
    far = np.array([[-300.0, 20.0], [np.nan, 3.0]])
    out = tab.normalized(far)
    assert np.allclose(out[0], normalized_from_pixels(cam, far[:1])[0]) and np.isnan(out[1]).all()


@pytest.mark.parametrize("dist", [(-0.3, 0.1, 0.002, -0.0015, 0.0), (0.2, -0.05, 0.0, 0.0, 0.0, 0.05, 0.0, 0.0),
                                  (-0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.003, 0.0, -0.002, 0.0)])
def test_undistortion_table_bound_holds_for_strong_and_rational_distortion(dist):
    """The fitted approximate inverse plus the residual table keeps its bound where the
    approximation is poor: strong barrel (image corners at 0.8 of their undistorted radius) with
    tangential terms, a rational model (k4), thin prism."""
    cam = look_at_camera("c", (2.0, 0.0, 1.0), (0.0, 0.0, 1.0), fx=900.0, size=(1280, 1024), dist=dist)
    tab = undistortion_table(cam)
    assert tab.max_error_px <= 1e-3
    rng = np.random.default_rng(4)
    xy = rng.uniform([-0.5, -0.5], [cam.size[0] - 0.5, cam.size[1] - 0.5], (50000, 2))
    exact = normalized_from_pixels(cam, xy)
    err = np.abs(tab.normalized(xy) - exact).max(axis=1) * cam.K[0, 0]
    assert np.nanmax(err) <= 1.05 * tab.max_error_px
    assert np.array_equal(np.isnan(tab.normalized(xy)), np.isnan(exact))


def test_linear_step_beyond_the_tables_is_exact(rig):
    """Views far outside the image (beyond the undistortion tables) are undistorted exactly."""
    rng = np.random.default_rng(6)
    p = _points(rng, 500)
    p[:50] *= [4.0, 4.0, 1.0]                          # far off-centre: outside some images
    xy, front = project_rig(rig, p)
    xy[~front] = np.nan
    outside = np.zeros(xy.shape[:2], bool)
    for c, cam in enumerate(rig.cameras):
        w, h = cam.size
        outside[c] = (xy[c, :, 0] < -100) | (xy[c, :, 0] > w + 100) | (xy[c, :, 1] < -100) | (xy[c, :, 1] > h + 100)
    assert outside[:, :50].any()
    lin, nv = triangulate_linear(rig, xy)
    ok = nv >= 2
    assert np.abs(lin[ok] - p[ok]).max() < 2e-5


def test_noise_free_points_are_exact_from_any_camera_subset(rig):
    rng = np.random.default_rng(1)
    p = _points(rng, 3000)
    xy, _ = project_rig(rig, p)
    xy[rng.random(xy.shape[:2]) < 0.4] = np.nan
    nv = np.isfinite(xy[..., 0]).sum(axis=0)
    lin, n_views = triangulate_linear(rig, xy)
    assert np.array_equal(n_views, nv)
    ok = nv >= 2
    assert np.isnan(lin[~ok]).all()
    assert np.abs(lin[ok] - p[ok]).max() < 2e-5                  # the table's 1e-3 px bound
    tr = triangulate(rig, xy, sigma_px=0.1)
    assert np.abs(tr.p_world[ok] - p[ok]).max() < 1e-9
    assert tr.n_unseen == int((~ok).sum()) > 0 and np.isnan(tr.p_world[~ok]).all()
    assert np.array_equal(tr.used, np.isfinite(xy[..., 0]) & ok[None])


def test_error_rms_matches_the_covariance_through_the_simulator():
    """The simulator's cameras, occlusion by the arm's links and 0.15 px noise: the 3D error RMS is
    within 10 % of the covariance's prediction, and the z-scores have the chi-square's mean."""
    rng = np.random.default_rng(5)
    geometry = pa10_geometry()
    layout = place_markers(geometry, rng)
    t = np.arange(150) / 250.0
    q = np.zeros((t.size, 6))
    q[:, 0] = 0.6 * np.sin(2 * np.pi * 0.5 * t)
    q[:, 1] = 0.3 + 0.4 * np.sin(2 * np.pi * 0.3 * t + 1)
    q[:, 3] = np.sin(2 * np.pi * 0.4 * t)
    T = forward_kinematics(q, T_world_base=base_pose())
    rig = ring_rig(8, rng=rng)
    r = render_markers(t, T, layout, geometry, rig, rng, pixel_noise_px=0.15)
    d = r.detections
    xy, keys = observation_array(d.frame, d.camera, d.point_id, d.xy_px, 8)
    truth = r.xyz_true[keys[:, 0], keys[:, 1]]
    tr = triangulate(rig, xy, sigma_px=0.15)
    ok = np.isfinite(tr.p_world[:, 0])
    assert ok.sum() > 2500 and tr.n_unseen == int((np.isfinite(xy[..., 0]).sum(axis=0) < 2).sum())
    e = tr.p_world[ok] - truth[ok]
    ratio = np.sqrt(np.mean(np.sum(e**2, axis=1)) / np.mean(np.trace(tr.cov[ok], axis1=1, axis2=2)))
    assert 0.9 < ratio < 1.1, ratio
    z2 = np.einsum("ni,nij,nj->n", e, np.linalg.inv(tr.cov[ok]), e)
    assert 0.9 < z2.mean() / 3 < 1.1
    # the pixel noise estimated from the residuals, and the rig's own sigma_px
    est = triangulate(rig, xy)
    assert est.sigma_source == "residuals" and abs(est.sigma_px - 0.15) < 0.01
    from_rig = triangulate(Rig(rig.cameras, {"sigma_px": 0.15}), xy)
    assert from_rig.sigma_source == "rig" and np.allclose(from_rig.cov[ok], tr.cov[ok])


def test_robust_views_set_aside_outliers(rig):
    rng = np.random.default_rng(2)
    p = _points(rng, 4000)
    xy, _ = project_rig(rig, p)
    xy += rng.normal(0, 0.2, xy.shape)
    xy[rng.random(xy.shape[:2]) < 0.2] = np.nan
    seen = np.isfinite(xy[..., 0])
    bad = seen & (rng.random(seen.shape) < 0.08)
    shift = rng.normal(0, 1, (bad.sum(), 2))
    shift *= (5.0 + 30.0 * rng.random(bad.sum()))[:, None] / np.linalg.norm(shift, axis=1, keepdims=True)
    xy[bad] += shift
    tr = triangulate(rig, xy, sigma_px=0.2)
    plain = triangulate(rig, xy, sigma_px=0.2, robust=False)
    err = np.linalg.norm(tr.p_world - p, axis=1)
    # every planted outlier of a point that kept >= 3 good views is set aside, and no good view
    good_views = (seen & ~bad).sum(axis=0)
    sure = good_views >= 3
    assert not (tr.used & bad)[:, sure].any()
    assert (tr.used == (seen & ~bad))[:, sure & np.isfinite(err)].all()
    assert np.nanmax(err[sure]) < 5e-3
    assert np.sqrt(np.nanmean(err[sure] ** 2)) < 0.3 * np.sqrt(np.nanmean(np.linalg.norm(plain.p_world - p, axis=1)[sure] ** 2))
    assert tr.n_outlier_views >= int(bad[:, sure].sum())
    # a point is NaN or placed within 5 SDs: never a confident wrong answer where 3 good views agree
    z = err / tr.sd_m
    assert np.nanmax(z[sure]) < 6.0


def test_views_that_pass_the_gate_but_do_not_fit_together_leave_nan(rig):
    """Three views, one 1.5 px off at sigma 0.1 px: the fit spreads it to residuals of 0.3-0.5 px,
    each within the 1 px gate, but the chi-square (about 50 on 3 degrees of freedom) lies beyond its
    1e-6 tail (30.7): NaN and counted, not a point placed several SDs off."""
    rng = np.random.default_rng(12)
    p = _points(rng, 2)
    xy, _ = project_rig(rig, p)
    xy[3:] = np.nan
    xy[2, 0] += [1.5, 0.0]
    tr = triangulate(rig, xy, sigma_px=0.1)
    assert np.isnan(tr.p_world[0]).all() and np.isfinite(tr.p_world[1]).all()
    assert tr.n_inconsistent == 1 and tr.n_rejected == 1 and tr.n_unseen == 0 and tr.n_outlier_views == 0
    assert np.isfinite(triangulate(rig, xy, sigma_px=0.1, robust=False).p_world[0]).all()


def test_nonfinite_pixels_are_ignored_and_counted(rig):
    rng = np.random.default_rng(3)
    p = _points(rng, 50)
    xy, _ = project_rig(rig, p)
    xy[0, 0, 0] = np.inf
    xy[1, 1, 1] = np.nan                    # half a pixel
    xy[2, 2] = -np.inf
    tr = triangulate(rig, xy, sigma_px=0.2)
    assert tr.n_nonfinite == 3
    assert not tr.used[0, 0] and not tr.used[1, 1] and not tr.used[2, 2]
    assert np.abs(tr.p_world - p).max() < 1e-8


def test_fewer_than_two_cameras_nan_and_counted(rig):
    rng = np.random.default_rng(4)
    p = _points(rng, 10)
    xy, _ = project_rig(rig, p)
    xy[1:, :4] = np.nan                     # points 0-3 seen by camera 0 only
    xy[:, 4] = np.nan                       # point 4 by none
    tr = triangulate(rig, xy, sigma_px=0.2)
    assert np.isnan(tr.p_world[:5]).all() and np.isnan(tr.cov[:5]).all() and tr.n_unseen == 5
    assert np.isfinite(tr.p_world[5:]).all()
    assert tr.to_dict()["n_unseen"] == 5


def test_camera_count_mismatch_is_an_error(rig):
    xy = np.zeros((7, 3, 2))
    with pytest.raises(InputError, match="8 cameras"):
        triangulate(rig, xy)
    with pytest.raises(InputError, match="8 cameras"):
        triangulate_linear(rig, xy)
    with pytest.raises(InputError, match=r"\(C, N, 2\)"):
        triangulate(rig, np.zeros((8, 3)))


def test_order_of_points_does_not_matter_and_same_input_same_output(rig):
    rng = np.random.default_rng(6)
    p = _points(rng, 500)
    xy, _ = project_rig(rig, p)
    xy += rng.normal(0, 0.3, xy.shape)
    xy[rng.random(xy.shape[:2]) < 0.05] += 25.0
    a = triangulate(rig, xy, sigma_px=0.3)
    perm = rng.permutation(500)
    b = triangulate(rig, xy[:, perm], sigma_px=0.3)
    assert np.allclose(a.p_world[perm], b.p_world, equal_nan=True, atol=1e-12)
    c = triangulate(rig, xy, sigma_px=0.3)
    assert np.array_equal(a.p_world, c.p_world, equal_nan=True)


def test_rigid_motion_of_the_scene(rig):
    """Moving the world (cameras and points together) moves the points and rotates the covariance."""
    from mocapfj.rotations import matrix_from_rotvec

    rng = np.random.default_rng(8)
    p = _points(rng, 200)
    xy, _ = project_rig(rig, p)
    xy += rng.normal(0, 0.2, xy.shape)
    R = matrix_from_rotvec([0.3, -0.2, 0.5])
    t = np.array([0.4, -1.0, 0.2])
    moved = Rig(tuple(dataclasses.replace(c, R_cam_world=c.R_cam_world @ R.T,
                                          t_cam_world=c.t_cam_world - c.R_cam_world @ R.T @ t) for c in rig.cameras))
    a = triangulate(rig, xy, sigma_px=0.2)
    b = triangulate(moved, xy, sigma_px=0.2)
    assert np.allclose(a.p_world @ R.T + t, b.p_world, atol=1e-9)
    assert np.allclose(R @ a.cov @ R.T, b.cov, rtol=1e-6, atol=1e-14)


def test_observation_array_refuses_a_duplicate():
    xy, keys = observation_array([0, 0, 1], [0, 1, 0], [2, 2, 2], [[1, 2], [3, 4], [5, 6]], 2)
    assert xy.shape == (2, 2, 2) and keys.tolist() == [[0, 2], [1, 2]]
    with pytest.raises(InputError, match="row 1.*one detection per camera"):
        observation_array([0, 0], [0, 0], [2, 2], [[1, 2], [3, 4]], 2)
    with pytest.raises(InputError, match="camera numbers 0..1"):
        observation_array([0], [2], [0], [[1, 2]], 2)


def test_ray_residual_is_the_distance_to_the_rays(rig):
    """One view displaced by d px at depth z: the ray residual is about d z / f over sqrt(views)."""
    rng = np.random.default_rng(9)
    p = _points(rng, 1)
    xy, _ = project_rig(rig, p)
    tr = triangulate(rig, xy, sigma_px=0.2)
    assert tr.ray_residual_m[0] < 1e-9
    z = np.array([(c.R_cam_world @ p[0] + c.t_cam_world)[2] for c in rig.cameras])
    xy[0, 0, 0] += 0.8
    tr = triangulate(rig, xy, sigma_px=0.2)
    d = np.linalg.norm(tr.residual_px[:, 0], axis=1) * z / rig.cameras[0].K[0, 0]
    assert abs(tr.ray_residual_m[0] - np.sqrt(np.mean(d**2))) < 0.02 * tr.ray_residual_m[0]
    assert project_points(rig.cameras[0], tr.p_world)[0].shape == (1, 2)
