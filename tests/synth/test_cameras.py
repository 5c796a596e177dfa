"""mocapfj.synth.cameras: the ring rig around the robot (Lightcap and Banks (2007), §IV.A: eight cameras)."""

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.io import read_rig, write_rig
from mocapfj.synth.cameras import ring_rig
from mocapfj.synth.robot_mesh import forward_kinematics, pa10_geometry, posed_meshes
from mocapfj.vision.camera import camera_centre_world, in_image, project_points


def test_default_ring_geometry():
    rig = ring_rig()
    assert len(rig.cameras) == 8
    centres = np.stack([camera_centre_world(c) for c in rig.cameras])
    np.testing.assert_allclose(np.hypot(centres[:, 0], centres[:, 1]), 2.6, atol=1e-12)
    np.testing.assert_allclose(centres[:, 2], [2.3, 1.5] * 4, atol=1e-12)
    az = np.unwrap(np.arctan2(centres[:, 1], centres[:, 0]))
    np.testing.assert_allclose(np.diff(az), 2 * np.pi / 8, atol=1e-12)
    dist_to_target = np.linalg.norm(centres - (0.0, 0.0, 1.2), axis=1)
    assert np.all((dist_to_target > 2.0) & (dist_to_target < 3.0))
    for cam in rig.cameras:
        assert cam.size == (1280, 1024)
        assert 900 < cam.K[0, 0] < 1400 and np.abs(cam.dist).max() < 0.1
        xy, front = project_points(cam, [(0.0, 0.0, 1.2)])
        np.testing.assert_allclose(xy[0], (639.5, 511.5), atol=1e-9)


def test_every_camera_sees_the_whole_robot_at_rest_and_stretched():
    rig = ring_rig()
    g = pa10_geometry(table=False)
    for q in (np.zeros(6), [0.5, 1.2, 0.0, 0.0, 0.0, 0.0]):
        v = np.concatenate([m.vertices for m in posed_meshes(g, forward_kinematics(q))])
        for cam in rig.cameras:
            xy, front = project_points(cam, v)
            assert front.all() and in_image(cam, xy).all()


def test_jittered_rig_is_deterministic_and_round_trips_through_toml(tmp_path):
    a = ring_rig(6, rng=np.random.default_rng(5))
    b = ring_rig(6, rng=np.random.default_rng(5))
    c = ring_rig(6, rng=np.random.default_rng(6))
    assert len(a.cameras) == 6 and a.metadata["jittered"]
    for x, y, z in zip(a.cameras, b.cameras, c.cameras):
        assert x.K.tobytes() == y.K.tobytes() and x.t_cam_world.tobytes() == y.t_cam_world.tobytes()
        assert not np.array_equal(x.t_cam_world, z.t_cam_world)
    write_rig(tmp_path / "rig.toml", a)
    back = read_rig(tmp_path / "rig.toml")
    for x, y in zip(a.cameras, back.cameras):
        np.testing.assert_allclose(y.R_cam_world, x.R_cam_world, atol=1e-12)
        np.testing.assert_allclose(y.t_cam_world, x.t_cam_world, atol=1e-12)
        np.testing.assert_array_equal(y.dist, x.dist)


def test_too_few_cameras_raise():
    with pytest.raises(InputError, match="n_cameras"):
        ring_rig(1)
