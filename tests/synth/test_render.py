"""mocapfj.synth.render: self-occlusion, 2D detections and noisy 3D trajectories."""

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.synth.cameras import ring_rig
from mocapfj.synth.markers import MarkerLayout, marker_positions, place_markers
from mocapfj.synth.render import has_embree, marker_visibility, render_markers
from mocapfj.synth.robot_mesh import TABLE_HEIGHT_M, forward_kinematics, pa10_geometry
from mocapfj.types import Rig
from mocapfj.vision.camera import look_at_camera, project_points

BACKENDS = ["triangle"] + (["embree"] if has_embree() else [])
RATE = 250.0


@pytest.fixture(scope="module")
def scene():
    g = pa10_geometry()
    layout = place_markers(g, np.random.default_rng(0))
    rig = ring_rig()
    t = np.arange(2000) / RATE
    w = 2 * np.pi * np.array([0.11, 0.23, 0.17, 0.31, 0.27, 0.41])
    q = np.array([1.5, 0.8, 1.2, 1.5, 1.2, 2.0]) * np.sin(w * t[:, None] + np.arange(6))
    return g, layout, rig, t, forward_kinematics(q)


@pytest.fixture(scope="module")
def rendering(scene):
    g, layout, rig, t, T = scene
    return render_markers(t, T, layout, g, rig, np.random.default_rng(1), pixel_noise_px=0.15, noise_m=2e-4)


def test_cluster_distances_stay_rigid_within_the_noise(rendering, scene):
    _, layout, _, _, _ = scene
    sigma = 2e-4
    xyz = rendering.markers.xyz
    for link in (1, 2, 3, 4, 6):
        i = layout.cluster(link)
        for a in range(len(i)):
            for b in range(a + 1, len(i)):
                d = np.linalg.norm(xyz[:, i[a]] - xyz[:, i[b]], axis=1)
                d = d[np.isfinite(d)]
                d0 = np.linalg.norm(layout.p_link[i[a]] - layout.p_link[i[b]])
                assert d.size > 1000
                # distance noise = projection of the difference of two N(0, sigma^2 I) errors
                assert d.std() == pytest.approx(np.sqrt(2) * sigma, rel=0.1)
                assert abs(d.mean() - d0) < 4 * np.sqrt(2) * sigma / np.sqrt(d.size)


def test_missing_exactly_where_fewer_than_two_cameras_see(rendering):
    seen = rendering.visible.sum(axis=0)
    missing = np.isnan(rendering.markers.xyz).any(axis=-1)
    np.testing.assert_array_equal(missing, seen < 2)
    assert np.isnan(rendering.markers.xyz[missing]).all()
    np.testing.assert_array_equal(np.isnan(rendering.markers.residual), missing)
    err = rendering.markers.xyz - rendering.xyz_true
    np.testing.assert_allclose(rendering.markers.residual[~missing], np.sqrt(np.mean(err**2, -1))[~missing],
                               rtol=1e-9)
    assert 0.0 < missing.mean() < 0.2                 # some dropouts, mostly measured
    assert 0.0 < 1 - rendering.visible.mean() < 0.7   # self-occlusion hides a share of the rays


def test_detections_are_noisy_projections_of_visible_markers(rendering, scene):
    _, _, rig, _, _ = scene
    det = rendering.detections
    assert len(det.frame) == rendering.visible.sum()
    key = (det.frame * len(rig.cameras) + det.camera) * 100 + det.point_id
    assert np.all(np.diff(key) > 0)                   # sorted by frame, camera, marker
    np.testing.assert_array_equal(rendering.visible[det.camera, det.frame, det.point_id], True)
    res = []
    for c, cam in enumerate(rig.cameras):
        s = det.camera == c
        xy, _ = project_points(cam, rendering.xyz_true[det.frame[s], det.point_id[s]])
        res.append(det.xy_px[s] - xy)
    res = np.concatenate(res)
    assert np.abs(res.mean(axis=0)).max() < 0.005
    np.testing.assert_allclose(res.std(axis=0), 0.15, rtol=0.02)
    assert rendering.markers.labels == scene[1].labels and rendering.markers.rate_hz == RATE


@pytest.mark.parametrize("backend", BACKENDS)
def test_marker_behind_a_link_is_hidden_only_from_the_camera_looking_through_it(backend):
    g = pa10_geometry()
    T = forward_kinematics(np.zeros((1, 6)))
    # zero pose: the upper arm (radius 65 mm) stands along world z through (0, 0); link 2's z axis
    # is world y. A marker 150 mm behind the arm on -y, 250 mm up the arm:
    layout = MarkerLayout(labels=("X_1",), link=np.array([2]), p_link=np.array([[0.0, -0.25, -0.15]]),
                          normal_link=np.array([[0.0, 0.0, -1.0]]), radius_m=0.007)
    p = marker_positions(layout, T)
    np.testing.assert_allclose(p[0, 0], (0.0, -0.15, TABLE_HEIGHT_M + 0.317 + 0.25), atol=1e-12)
    target = p[0, 0]
    cams = [look_at_camera("through", target + (0, 3.0, 0), target, fx=1100, size=(1280, 1024)),
            look_at_camera("front", target + (0, -3.0, 0), target, fx=1100, size=(1280, 1024)),
            look_at_camera("side", target + (3.0, 0, 0), target, fx=1100, size=(1280, 1024)),
            look_at_camera("away", target + (3.0, 0, 0), target + (6.0, 0, 0), fx=1100, size=(1280, 1024))]
    vis = marker_visibility(Rig(tuple(cams)), p, T, g, backend=backend)
    np.testing.assert_array_equal(vis[:, 0, 0], [False, True, True, False])


def test_embree_and_pure_python_backends_agree(scene):
    if not has_embree():
        pytest.skip("embreex not installed")
    g, layout, rig, _, T = scene
    p = marker_positions(layout, T[:40:4])
    a = marker_visibility(rig, p, T[:40:4], g, backend="embree")
    b = marker_visibility(rig, p, T[:40:4], g, backend="triangle")
    np.testing.assert_array_equal(a, b)


def test_same_seed_gives_byte_identical_outputs(scene, rendering):
    g, layout, rig, t, T = scene
    again = render_markers(t, T, layout, g, rig, np.random.default_rng(1))
    assert again.markers.xyz.tobytes() == rendering.markers.xyz.tobytes()
    assert again.markers.residual.tobytes() == rendering.markers.residual.tobytes()
    for f in ("frame", "camera", "xy_px", "point_id"):
        assert getattr(again.detections, f).tobytes() == getattr(rendering.detections, f).tobytes()
    other = render_markers(t[:50], T[:50], layout, g, rig, np.random.default_rng(2))
    assert not np.array_equal(other.detections.xy_px, rendering.detections.xy_px[:len(other.detections.xy_px)])


def test_bad_inputs_raise(scene):
    g, layout, rig, t, T = scene
    with pytest.raises(InputError, match="t"):
        render_markers(t[::-1], T, layout, g, rig, np.random.default_rng(0))
    with pytest.raises(InputError, match="T_world_link"):
        marker_visibility(rig, np.zeros((3, 2, 3)), T[:2], g)
    with pytest.raises(InputError, match="backend"):
        marker_visibility(rig, np.zeros((2, 2, 3)), T[:2], g, backend="optix")


def test_outputs_write_through_io(rendering, tmp_path):
    from mocapfj.io import read_c3d, read_detections, write_c3d, write_detections

    write_c3d(tmp_path / "markers.c3d", rendering.markers)
    back = read_c3d(tmp_path / "markers.c3d")
    assert back.labels == rendering.markers.labels and back.rate_hz == RATE
    np.testing.assert_array_equal(np.isnan(back.xyz), np.isnan(rendering.markers.xyz))
    assert np.nanmax(np.abs(back.xyz - rendering.markers.xyz)) < 1e-6          # float32 storage in mm
    write_detections(tmp_path / "detections.csv", rendering.detections)
    det = read_detections(tmp_path / "detections.csv")
    np.testing.assert_array_equal(det.point_id, rendering.detections.point_id)
    np.testing.assert_allclose(det.xy_px, rendering.detections.xy_px, atol=1e-9)
