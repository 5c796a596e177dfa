"""mocapfj.synth.robot_mesh: PA-10 modified D-H kinematics (Bompos et al. (2007), Table I) and link meshes."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapfj.errors import InputError
from mocapfj.synth.robot_mesh import (PA10_MDH, TABLE_HEIGHT_M, base_pose, forward_kinematics, mdh_transform,
                                      pa10_geometry, posed_meshes)

D1, D3, D5, D7 = 0.317, 0.45, 0.48, 0.07             # Bompos et al. (2007), Table I, d_i in metres


def _rx(a):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("x", a).as_matrix()
    return T


def _rz(a):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", a).as_matrix()
    return T


def _tr(x, y, z):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def test_mdh_transform_is_rotx_transx_rotz_transz():
    # Bompos et al. (2007), eq. (1) is the product Rot_x(alpha) Trans_x(a) Rot_z(theta) Trans_z(d)
    rng = np.random.default_rng(0)
    for alpha, a, d, theta in rng.normal(0, 1, (10, 4)):
        ref = _rx(alpha) @ _tr(a, 0, 0) @ _rz(theta) @ _tr(0, 0, d)
        np.testing.assert_allclose(mdh_transform(alpha, a, d, theta), ref, atol=1e-15)


def test_table_i_values():
    np.testing.assert_allclose(PA10_MDH[:, 2], [D1, 0, D3, 0, D5, 0, D7])
    np.testing.assert_allclose(np.degrees(PA10_MDH[:, 0]), [0, -90, 90, -90, 90, -90, 90])
    np.testing.assert_array_equal(PA10_MDH[:, 1], 0.0)


def test_zero_pose_stacks_the_d_offsets_on_the_table():
    T = forward_kinematics(np.zeros(6))
    h = TABLE_HEIGHT_M
    # by hand: base, S1 (d1), S2 (same origin), E1 (+d3), E2/wrist centre (+d5), W1 (same), flange (+d7)
    z = [h, h + D1, h + D1, h + D1 + D3, h + D1 + D3 + D5, h + D1 + D3 + D5, h + D1 + D3 + D5 + D7]
    np.testing.assert_allclose(T[:, :3, 3], np.c_[np.zeros(7), np.zeros(7), z], atol=1e-15)
    np.testing.assert_allclose(T[6, :3, 3], (0.0, 0.0, 0.6 + 1.317), atol=1e-15)
    np.testing.assert_allclose(T[6, :3, :3], np.eye(3), atol=1e-15)   # alphas cancel in pairs


def test_shoulder_at_90_deg_lays_the_arm_along_x():
    T = forward_kinematics([0.0, np.pi / 2, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(T[6, :3, 3], (D3 + D5 + D7, 0.0, TABLE_HEIGHT_M + D1), atol=1e-12)


def test_elbow_angle_sets_shoulder_wrist_distance_by_law_of_cosines():
    rng = np.random.default_rng(1)
    q = rng.uniform(-2.5, 2.5, (50, 6))
    T = forward_kinematics(q)
    d = np.linalg.norm(T[:, 4, :3, 3] - T[:, 1, :3, 3], axis=1)          # wrist centre - shoulder
    np.testing.assert_allclose(d**2, D3**2 + D5**2 + 2 * D3 * D5 * np.cos(q[:, 2]), atol=1e-12)


def test_joint_1_turns_everything_about_the_base_axis():
    rng = np.random.default_rng(2)
    q = rng.uniform(-2, 2, 6)
    q2 = q.copy()
    q2[0] += 0.7
    a, b = forward_kinematics(q), forward_kinematics(q2)
    Rz = Rotation.from_euler("z", 0.7).as_matrix()
    np.testing.assert_allclose(b[1:, :3, 3], a[1:, :3, 3] @ Rz.T, atol=1e-12)


def test_vectorised_equals_per_frame_and_rotations_are_proper():
    rng = np.random.default_rng(3)
    q = rng.uniform(-3, 3, (2, 5, 6))
    Tb = _tr(0.1, -0.2, 0.3) @ _rz(0.4)
    T = forward_kinematics(q, T_world_base=Tb)
    assert T.shape == (2, 5, 7, 4, 4)
    for i in range(2):
        for j in range(5):
            np.testing.assert_array_equal(T[i, j], forward_kinematics(q[i, j], T_world_base=Tb))
    R = T[..., :3, :3]
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_array_equal(T[..., 0, :, :], np.broadcast_to(Tb, T[..., 0, :, :].shape))


def test_bad_joint_count_raises():
    with pytest.raises(InputError, match="q"):
        forward_kinematics(np.zeros((3, 7)))


def test_geometry_is_watertight_and_plausible():
    g = pa10_geometry()
    assert g.n_links == 7 and g.names[0] == "base"
    assert all(p.is_watertight for parts in g.parts for p in parts)
    meshes = posed_meshes(g, forward_kinematics(np.zeros(6)))
    top = meshes[6].bounds[1, 2]
    assert top == pytest.approx(TABLE_HEIGHT_M + 1.317 + 0.12)           # flange + 120 mm tool block
    assert meshes[0].bounds[0, 2] == pytest.approx(0.0)                 # table stands on the floor
    assert pa10_geometry(table=False).mesh(0).bounds[0, 2] == pytest.approx(0.0)
    assert base_pose()[2, 3] == TABLE_HEIGHT_M
    # link radii like a PA-10: every moving link fits in a 0.3 m wide tube around its axis chain
    for m in meshes[1:]:
        assert np.ptp(m.vertices[:, 0]) < 0.3 and np.ptp(m.vertices[:, 1]) < 0.3
