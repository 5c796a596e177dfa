"""A URDF of the synthetic PA-10-like arm whose kinematics and inertias match what is rendered.

Joint frames come from the same modified D-H chain as `robot_mesh.forward_kinematics`, so the
dynamics of a URDF scenario and its rendered markers agree exactly. Joints that a scenario does
not move are braked: they become fixed joints at their pose. Each link's mass, centre of mass
and inertia are those of its rendered primitives (`robot_mesh.pa10_geometry`) at a uniform
density, plus an optional payload at the flange (Lightcap and Banks (2007), §IV.A hung 44.5 N there). These
inertias are plausible for a PA-10-sized arm, not measured values of a PA-10.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from .robot_mesh import ArmGeometry, forward_kinematics, pa10_geometry

__all__ = ["pa10_urdf", "link_mass_properties", "DEFAULT_DENSITY"]

DEFAULT_DENSITY = 1650.0
"""kg/m^3 of the solid primitives: about 35 kg for links 1-6, the mass of a PA-10."""


def link_mass_properties(geometry: ArmGeometry, link: int, density: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass (kg), centre of mass (3,) m and inertia about it (3, 3) kg m^2 of one link, link frame.

    The link's primitives are summed part by part (parallel-axis theorem), each a watertight
    solid of the given density.
    """
    masses, coms, inertias = [], [], []
    for part in geometry.parts[link]:
        m = part.copy()
        m.density = density
        masses.append(m.mass)
        coms.append(m.center_mass)
        inertias.append(m.moment_inertia)
    return _combine(np.array(masses), np.array(coms), np.array(inertias))


def _combine(masses, coms, inertias):
    M = float(masses.sum())
    c = (masses[:, None] * coms).sum(0) / M
    d = coms - c
    shift = masses[:, None, None] * ((d * d).sum(1)[:, None, None] * np.eye(3) - d[:, :, None] * d[:, None, :])
    return M, c, (inertias + shift).sum(0)


def _origin(T: np.ndarray) -> str:
    rpy = Rotation.from_matrix(T[:3, :3]).as_euler("xyz")
    xyz = T[:3, 3]
    clean = lambda v: " ".join(f"{0.0 if abs(x) < 1e-15 else x:.15g}" for x in v)  # noqa: E731
    return f'<origin xyz="{clean(xyz)}" rpy="{clean(rpy)}"/>'


def _inertial(mass: float, com, inertia) -> str:
    I = inertia
    return (f'<inertial><origin xyz="{com[0]:.15g} {com[1]:.15g} {com[2]:.15g}" rpy="0 0 0"/>'
            f'<mass value="{mass:.15g}"/>'
            f'<inertia ixx="{I[0, 0]:.15g}" ixy="{I[0, 1]:.15g}" ixz="{I[0, 2]:.15g}" '
            f'iyy="{I[1, 1]:.15g}" iyz="{I[1, 2]:.15g}" izz="{I[2, 2]:.15g}"/></inertial>')


def pa10_urdf(moving: Sequence[int], pose_rad: Sequence[float] = (0.0,) * 6, *, joint_names: Sequence[str] | None = None,
              density: float = DEFAULT_DENSITY, payload_kg: float = 0.0, payload_offset_m=(0.0, 0.0, 0.10),
              table_height_m: float = 0.6) -> str:
    """URDF text of the PA-10-like arm with joints `moving` free and the others braked at `pose_rad`.

    Parameters
    ----------
    moving : sequence of int
        PA-10 joint numbers (1..6) that are revolute, in increasing order.
    pose_rad : (6,) float
        Angles of the braked joints (the moving joints' entries are ignored), rad.
    joint_names : sequence of str, optional
        URDF names of the moving joints (default ``joint<k>``).
    density : float
        kg/m^3 of the link primitives.
    payload_kg : float
        A point-like payload (a 5 cm solid cube) at `payload_offset_m` in the flange frame.

    Returns
    -------
    str
        URDF XML. Root link ``world`` (z up, gravity along -z), base on the table at
        `table_height_m`, links ``link1`` .. ``link6``; the generalized coordinates are the D-H
        joint angles of the moving joints.
    """
    moving = [int(j) for j in moving]
    if not moving or sorted(set(moving)) != moving or not all(1 <= j <= 6 for j in moving):
        raise InputError(None, "moving", "increasing PA-10 joint numbers from 1 to 6", moving)
    pose = np.asarray(pose_rad, dtype=np.float64)
    if pose.shape != (6,):
        raise InputError(None, "pose_rad", "six joint angles in rad", f"shape {pose.shape}")
    names = list(joint_names) if joint_names is not None else [f"joint{j}" for j in moving]
    if len(names) != len(moving):
        raise InputError(None, "joint_names", f"{len(moving)} names", len(names))
    q = pose.copy()
    q[np.array(moving) - 1] = 0.0
    from .robot_mesh import base_pose

    T = forward_kinematics(q, T_world_base=base_pose(table_height_m))  # (7, 4, 4)
    geometry = pa10_geometry(table=False)
    out = ['<?xml version="1.0"?>', '<robot name="pa10_like">', '<link name="world"/>',
           f'<joint name="table" type="fixed"><parent link="world"/><child link="base"/>{_origin(T[0])}</joint>',
           '<link name="base"/>']
    for j in range(1, 7):
        mass, com, inertia = link_mass_properties(geometry, j, density)
        if j == 6 and payload_kg > 0:
            side = 0.05
            Ip = np.eye(3) * payload_kg * side**2 / 6
            mass, com, inertia = _combine(np.array([mass, payload_kg]), np.array([com, payload_offset_m], float),
                                          np.array([inertia, Ip]))
        parent = "base" if j == 1 else f"link{j - 1}"
        origin = _origin(np.linalg.solve(T[j - 1], T[j]))
        if j in moving:
            name = names[moving.index(j)]
            out.append(f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="link{j}"/>{origin}'
                       f'<axis xyz="0 0 1"/><limit lower="-3.14" upper="3.14" effort="1000" velocity="10"/></joint>')
        else:
            out.append(f'<joint name="brake{j}" type="fixed"><parent link="{parent}"/><child link="link{j}"/>{origin}</joint>')
        out.append(f'<link name="link{j}">{_inertial(mass, com, inertia)}</link>')
    out.append("</robot>")
    return "\n".join(out) + "\n"
