"""A PA-10-like 6-DoF arm: modified D-H kinematics and link meshes for synthetic recordings.

Kinematics follow Bompos et al. (2007) (Mitsubishi PA-10, Table I), which uses the **modified**
Denavit-Hartenberg convention (Craig), eq. (1):

    T_{i-1,i} = Rot_x(alpha_{i-1}) Trans_x(a_{i-1}) Rot_z(theta_i) Trans_z(d_i)

Table I describes the 7-DoF PA-10. The 6-DoF arm here is the PA10-6C(E) of Lightcap and Banks (2007) (§IV.A):
the redundant joint 3 (S3) is locked at theta_3 = 0, as in Bompos et al.'s reference [1], so joints
1..6 of this arm are rows 1, 2, 4, 5, 6, 7 of Table I. Link k is the rigid body moved by joint k;
its frame is the D-H frame of its row (link 2 carries the locked frame 3). Link 0 is the base
(and the table it stands on), fixed in the world. The frame of link 6 has its origin at the tool
flange. The robot stands upright on a 0.6 m table (Lightcap and Banks (2007), §IV.A), so the default base pose is
a translation of 0.6 m along world z.

Link meshes are built from trimesh primitives sized like a PA-10 (radii 45-90 mm); they are
plausible, not a CAD model. All lengths in metres, angles in radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from ..errors import InputError

__all__ = [
    "PA10_MDH",
    "PA10_6DOF_ROWS",
    "TABLE_HEIGHT_M",
    "ArmGeometry",
    "mdh_transform",
    "base_pose",
    "forward_kinematics",
    "pa10_geometry",
    "posed_meshes",
]

_D = np.pi / 180.0
PA10_MDH = np.array([
    # alpha_{i-1} [rad], a_{i-1} [m], d_i [m], theta_i offset [rad]   (Bompos et al. (2007), Table I)
    [0.0, 0.0, 0.317, 0.0],
    [-90.0 * _D, 0.0, 0.0, 0.0],
    [90.0 * _D, 0.0, 0.45, 0.0],
    [-90.0 * _D, 0.0, 0.0, 0.0],
    [90.0 * _D, 0.0, 0.48, 0.0],
    [-90.0 * _D, 0.0, 0.0, 0.0],
    [90.0 * _D, 0.0, 0.07, 0.0],
])
"""Modified D-H table of the 7-DoF PA-10, (7, 4): alpha_{i-1}, a_{i-1}, d_i, theta offset."""

PA10_6DOF_ROWS = (0, 1, 3, 4, 5, 6)
"""Rows of PA10_MDH driven by joints 1..6 of the 6-DoF arm; row 2 (S3) is locked at 0."""

TABLE_HEIGHT_M = 0.6
"""Height of the table the robot stands on, Lightcap and Banks (2007), §IV.A."""


def mdh_transform(alpha, a, d, theta) -> np.ndarray:
    """Modified D-H transform T_{i-1,i} of Bompos et al. (2007), eq. (1), broadcast over the inputs.

    Parameters
    ----------
    alpha, a, d, theta : array_like, broadcastable
        alpha_{i-1} (rad), a_{i-1} (m), d_i (m), theta_i (rad).

    Returns
    -------
    (..., 4, 4) float
        Homogeneous transform mapping frame-i coordinates into frame i-1.
    """
    alpha, a, d, theta = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (alpha, a, d, theta)))
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    T = np.zeros(alpha.shape + (4, 4))
    T[..., 0, 0], T[..., 0, 1], T[..., 0, 3] = ct, -st, a
    T[..., 1, 0], T[..., 1, 1], T[..., 1, 2], T[..., 1, 3] = st * ca, ct * ca, -sa, -sa * d
    T[..., 2, 0], T[..., 2, 1], T[..., 2, 2], T[..., 2, 3] = st * sa, ct * sa, ca, ca * d
    T[..., 3, 3] = 1.0
    return T


def base_pose(height_m: float = TABLE_HEIGHT_M) -> np.ndarray:
    """T_world_base, (4, 4): the robot upright on a table of `height_m` at the world origin."""
    T = np.eye(4)
    T[2, 3] = height_m
    return T


def forward_kinematics(q, *, T_world_base=None, mdh=PA10_MDH, joint_rows=PA10_6DOF_ROWS) -> np.ndarray:
    """Poses of the base and of every link for joint angles `q`.

    Parameters
    ----------
    q : (..., J) float
        Joint angles, rad, J = len(joint_rows) (6 for the PA-10 6-DoF arm); e.g. (T, 6).
    T_world_base : (4, 4) float, optional
        Pose of the robot base in the world; default `base_pose()` (0.6 m table).
    mdh : (R, 4) float
        Modified D-H rows (alpha_{i-1}, a_{i-1}, d_i, theta offset); default Bompos et al. (2007), Table I.
    joint_rows : sequence of J int
        Rows of `mdh` that are actuated, increasing; the others are locked at their offset.

    Returns
    -------
    T_world_link : (..., J + 1, 4, 4) float
        Index 0 is the base, index k the frame of link k (the D-H frame of row joint_rows[k-1]).
    """
    mdh = np.asarray(mdh, dtype=np.float64)
    rows = tuple(int(r) for r in joint_rows)
    if mdh.ndim != 2 or mdh.shape[1] != 4 or list(rows) != sorted(set(rows)) or not set(rows) <= set(range(len(mdh))):
        raise InputError(None, "joint_rows", f"increasing row indices of the ({len(mdh)}, 4) D-H table", rows)
    q = np.asarray(q, dtype=np.float64)
    if q.ndim < 1 or q.shape[-1] != len(rows):
        raise InputError(None, "q", f"an array of shape (..., {len(rows)}) in rad", f"shape {q.shape}")
    Tb = base_pose() if T_world_base is None else np.asarray(T_world_base, dtype=np.float64)
    if Tb.shape != (4, 4):
        raise InputError(None, "T_world_base", "shape (4, 4)", f"shape {Tb.shape}")
    lead = q.shape[:-1]
    out = np.empty(lead + (len(rows) + 1, 4, 4))
    out[..., 0, :, :] = Tb
    T = np.broadcast_to(Tb, lead + (4, 4))
    k = 0
    for i, (alpha, a, d, off) in enumerate(mdh):
        theta = off + (q[..., k] if k < len(rows) and rows[k] == i else 0.0)
        T = T @ mdh_transform(alpha, a, d, theta)
        if k < len(rows) and rows[k] == i:
            k += 1
            out[..., k, :, :] = T
    return out


@dataclass(frozen=True, eq=False)
class ArmGeometry:
    """Link meshes of an arm, each in its own link frame (metres).

    Attributes
    ----------
    names : tuple of L str
        "base", "link1", ...
    parts : tuple of L tuples of trimesh.Trimesh
        Watertight convex primitives of each link, link frame.
    marker_parts : tuple of L tuples of int
        Indices into `parts[l]` of the surfaces that may carry markers (empty: none).
    """

    names: tuple[str, ...]
    parts: tuple[tuple[trimesh.Trimesh, ...], ...]
    marker_parts: tuple[tuple[int, ...], ...]

    @property
    def n_links(self) -> int:
        return len(self.parts)

    def mesh(self, link: int) -> trimesh.Trimesh:
        """All primitives of `link` as one mesh, link frame."""
        return trimesh.util.concatenate(list(self.parts[link]))

    def marker_surface(self, link: int) -> trimesh.Trimesh | None:
        """The marker-bearing primitives of `link` as one mesh, link frame; None if none."""
        idx = self.marker_parts[link]
        return trimesh.util.concatenate([self.parts[link][i] for i in idx]) if idx else None


def _cyl(p0, p1, r: float, sections: int = 24) -> trimesh.Trimesh:
    """Cylinder of radius r whose axis runs from p0 to p1 (link frame, metres)."""
    return trimesh.creation.cylinder(radius=r, segment=np.array([p0, p1], dtype=np.float64), sections=sections)


def _box(extents, centre) -> trimesh.Trimesh:
    T = np.eye(4)
    T[:3, 3] = centre
    return trimesh.creation.box(extents=extents, transform=T)


def pa10_geometry(*, table: bool = True, table_height_m: float = TABLE_HEIGHT_M) -> ArmGeometry:
    """Primitive meshes of the PA-10-like 6-DoF arm (module docstring), in link frames.

    Frame facts used (zero pose, from PA10_MDH): link 1's frame sits 0.317 m above the base
    with joint 2's axis along its y axis; the upper arm runs along -y of link 2's frame to the
    elbow at (0, -0.45, 0); the forearm runs from link 3's frame along its -y axis to the wrist
    centre at (0, -0.48, 0), which is link 4's origin, with link 4's z axis along the forearm;
    link 6's origin is the flange, its z axis pointing out of the tool.

    Parameters
    ----------
    table : bool
        Add the table (0.8 m x 0.8 m, `table_height_m` high) under the base to link 0.

    Returns
    -------
    ArmGeometry with 7 links: base, link1..link6.
    """
    base = [_cyl([0, 0, 0], [0, 0, 0.20], 0.10)]
    if table:
        base.append(_box([0.8, 0.8, table_height_m], [0, 0, -table_height_m / 2]))
    link1 = [_cyl([0, -0.12, 0], [0, 0.12, 0], 0.09),                      # shoulder housing (J2 axis)
             _cyl([0, 0, -0.117], [0, 0, -0.05], 0.085)]                    # turning column
    link2 = [_cyl([0, -0.10, 0], [0, -0.37, 0], 0.065),                     # upper arm
             _cyl([0, -0.45, -0.09], [0, -0.45, 0.09], 0.075)]              # elbow housing (J3 axis)
    link3 = [_cyl([0, -0.07, 0], [0, -0.22, 0], 0.065)]                     # elbow piece
    link4 = [_box([0.11, 0.10, 0.20], [0, 0, -0.165]),                      # forearm (along z)
             _box([0.05, 0.07, 0.12], [0.075, 0, -0.17]),                   # motor housing, off axis
             _cyl([0, -0.07, 0], [0, 0.07, 0], 0.055)]                      # wrist housing (J5 axis)
    link5 = [_cyl([0, 0, 0], [0, -0.05, 0], 0.045)]                         # wrist
    link6 = [_cyl([0, 0, -0.015], [0, 0, 0.0], 0.04),                       # flange
             _box([0.10, 0.06, 0.12], [0.02, 0, 0.06])]                     # tool block, off axis
    parts = (base, link1, link2, link3, link4, link5, link6)
    marker_parts = ((0,), (0,), (0,), (0,), (0, 1), (), (1,))
    return ArmGeometry(names=("base", "link1", "link2", "link3", "link4", "link5", "link6"),
                       parts=tuple(tuple(p) for p in parts), marker_parts=marker_parts)


def posed_meshes(geometry: ArmGeometry, T_world_link) -> list[trimesh.Trimesh]:
    """The link meshes of one frame in the world frame.

    Parameters
    ----------
    geometry : ArmGeometry
    T_world_link : (L, 4, 4) float
        Link poses of one frame (a slice of `forward_kinematics`).

    Returns
    -------
    list of L trimesh.Trimesh, world frame (new meshes; `geometry` is not modified).
    """
    T = np.asarray(T_world_link, dtype=np.float64)
    if T.shape != (geometry.n_links, 4, 4):
        raise InputError(None, "T_world_link", f"shape ({geometry.n_links}, 4, 4)", f"shape {T.shape}")
    return [geometry.mesh(i).apply_transform(T[i]) for i in range(geometry.n_links)]
