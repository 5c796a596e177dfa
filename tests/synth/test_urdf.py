"""The PA-10-like URDF (mocapfj.synth.urdf) agrees with the rendered arm."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from mocapfj.synth.robot_mesh import base_pose, forward_kinematics, pa10_geometry
from mocapfj.synth.urdf import DEFAULT_DENSITY, link_mass_properties, pa10_urdf


def test_pinocchio_kinematics_equal_the_rendered_kinematics():
    pose = np.array([0.3, 0.0, 0.0, 0.2, -0.4, 0.1])
    model = pin.buildModelFromXML(pa10_urdf([2, 3], pose, joint_names=["j2", "j3"], payload_kg=4.54))
    data = model.createData()
    rng = np.random.default_rng(0)
    for q in rng.uniform(-1.5, 1.5, (5, 2)):
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        full = pose.copy()
        full[[1, 2]] = q
        T = forward_kinematics(full, T_world_base=base_pose())
        for k in range(1, 7):
            np.testing.assert_allclose(data.oMf[model.getFrameId(f"link{k}")].homogeneous, T[k], atol=1e-12)


def test_masses_and_gravity():
    g = pa10_geometry(table=False)
    total = sum(link_mass_properties(g, j, DEFAULT_DENSITY)[0] for j in range(1, 7))
    assert 33.0 < total < 37.0  # a PA-10 weighs 35 kg
    model = pin.buildModelFromXML(pa10_urdf([2], np.zeros(6)))
    data = model.createData()
    # independent: the holding torque of joint 2 is -axis . sum_k (c_k - o) x m_k g over links 2..6
    for q2 in (-0.8, 0.0, 0.3, 1.2):
        full = np.zeros(6)
        full[1] = q2
        T = forward_kinematics(full, T_world_base=base_pose())
        axis, origin = T[2][:3, 2], T[2][:3, 3]
        moment = np.zeros(3)
        for k in range(2, 7):
            m, c, _ = link_mass_properties(g, k, DEFAULT_DENSITY)
            c_world = T[k][:3, :3] @ c + T[k][:3, 3]
            moment += np.cross(c_world - origin, m * np.array([0.0, 0.0, -9.81]))
        tau = pin.computeGeneralizedGravity(model, data, np.array([q2]))[0]
        assert tau == pytest.approx(-axis @ moment, rel=1e-9, abs=1e-9)
    # arm tilted forward: gravity pulls it further (Lightcap and Banks (2007), eq. 4: G = -mglx sin q, mglx > 0)
    assert pin.computeGeneralizedGravity(model, data, np.array([0.5]))[0] < -10.0
