"""Marker clusters on the link surfaces of an arm, and their world positions over time.

Lightcap and Banks (2007), §III-IV: clusters of three or four reflective markers on the exterior surface of the
links (Fig. 2). Each marker centre sits one marker radius (default 7 mm, a 14 mm sphere) above
the link surface along the surface normal, so that the sphere touches the link. Within a
cluster the markers are spread apart and their radii from the link's joint axis (the z axis of
the link frame, Bompos et al. (2007), eq. (1)) differ, which the axis fits of Lightcap and Banks (2007), eqs. (11)-(12) need.
Labels are ``B_1..`` on the base and ``L<k>_1..`` on link k.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import trimesh

from ..errors import InputError
from .robot_mesh import ArmGeometry, forward_kinematics

__all__ = ["DEFAULT_CLUSTERS", "MarkerLayout", "place_markers", "marker_positions", "cluster_label", "vendor_smoothed"]

DEFAULT_CLUSTERS: Mapping[int, int] = {0: 3, 1: 3, 2: 4, 3: 3, 4: 4, 6: 3}
"""Markers per link (link index: count) of the default 20-marker layout."""


def cluster_label(link: int) -> str:
    """Label prefix of the cluster on `link`: "B" for the base (0), "L<k>" otherwise."""
    return "B" if link == 0 else f"L{link}"


@dataclass(frozen=True, eq=False)
class MarkerLayout:
    """Where the markers sit on the arm.

    Attributes
    ----------
    labels : tuple of M str
        "B_1", ..., "L2_1", ... in link order.
    link : (M,) int
        Link that carries each marker (0 = base).
    p_link : (M, 3) float
        Marker centre in the frame of its link, metres.
    normal_link : (M, 3) float
        Unit outward surface normal under the marker, link frame.
    radius_m : float
        Marker sphere radius, metres (the centre is this far above the surface).
    """

    labels: tuple[str, ...]
    link: np.ndarray
    p_link: np.ndarray
    normal_link: np.ndarray
    radius_m: float

    def cluster(self, link: int) -> np.ndarray:
        """Marker indices on `link`, (n,) int."""
        return np.flatnonzero(self.link == link)

    def axis_radius(self) -> np.ndarray:
        """Distance of each marker from its link's z axis (joint axis), (M,) metres."""
        return np.hypot(self.p_link[:, 0], self.p_link[:, 1])


def _sample_surface(mesh: trimesh.Trimesh, n: int, rng: np.random.Generator):
    """Area-weighted uniform points on `mesh`, with their face normals: (n, 3), (n, 3)."""
    area = mesh.area_faces
    face = rng.choice(len(area), size=n, p=area / area.sum())
    uv = rng.random((n, 2))
    flip = uv.sum(axis=1) > 1.0
    uv[flip] = 1.0 - uv[flip]
    tri = mesh.triangles[face]
    p = tri[:, 0] + uv[:, :1] * (tri[:, 1] - tri[:, 0]) + uv[:, 1:] * (tri[:, 2] - tri[:, 0])
    return p, mesh.face_normals[face]


def _clear(points_world: np.ndarray, parts_world: list[trimesh.Trimesh], radius: float) -> np.ndarray:
    """True where a marker sphere at each point touches no primitive (outside all, distance >= r)."""
    ok = np.ones(len(points_world), dtype=bool)
    for part in parts_world:
        lo, hi = part.bounds
        near = np.flatnonzero(np.all((points_world > lo - radius) & (points_world < hi + radius), axis=1) & ok)
        if near.size:
            _, dist, _ = trimesh.proximity.closest_point(part, points_world[near])
            ok[near] = (dist >= 0.98 * radius) & ~part.contains(points_world[near])
    return ok


def _spread(p: np.ndarray, r_axis: np.ndarray, n: int, gap: float, first: int) -> list[int]:
    """Greedy farthest-point choice of n rows of p whose axis radii differ by >= gap (halved as
    needed when no candidate satisfies it)."""
    chosen = [first]
    while len(chosen) < n:
        dmin = np.min(np.linalg.norm(p[:, None] - p[chosen][None], axis=2), axis=1)
        rgap = np.min(np.abs(r_axis[:, None] - r_axis[chosen][None]), axis=1)
        g = gap
        while True:
            score = np.where(rgap >= g, dmin, -np.inf)
            score[chosen] = -np.inf
            if np.isfinite(score).any() or g < 1e-6:
                break
            g /= 2.0
        chosen.append(int(np.argmax(score)))
    return chosen


def place_markers(geometry: ArmGeometry, rng: np.random.Generator, *,
                  clusters: Mapping[int, int] = DEFAULT_CLUSTERS, radius_m: float = 0.007,
                  min_radius_gap_m: float = 0.015, n_candidates: int = 400,
                  T_world_link_check=None) -> MarkerLayout:
    """Place marker clusters on the marker-bearing surfaces of `geometry`.

    For each link, `n_candidates` points are drawn uniformly on its marker surface (from `rng`),
    pushed out along the face normal by `radius_m`, and kept only where the marker sphere is
    clear of every primitive of the arm in the pose `T_world_link_check`. From those a greedy farthest-point
    choice (first point drawn from `rng`) picks the cluster so that the markers' radii from the
    link's joint axis differ pairwise by at least `min_radius_gap_m` (relaxed by halves when the
    surface cannot provide it).

    Parameters
    ----------
    geometry : ArmGeometry
    rng : numpy.random.Generator
        The only source of randomness: the same seed gives the same layout.
    clusters : mapping link -> count
        Markers per link; 3-4 as in Lightcap and Banks (2007).
    radius_m : float
        Marker sphere radius, metres.
    min_radius_gap_m : float
        Wanted minimum difference of axis radii within a cluster, metres.
    n_candidates : int
        Surface samples per link.
    T_world_link_check : (L, 4, 4) float, optional
        Link poses for the clearance check; default the PA-10 zero pose on its table
        (`forward_kinematics(zeros(6))`).

    Returns
    -------
    MarkerLayout
    """
    if not radius_m > 0:
        raise InputError(None, "radius_m", "a positive marker radius in metres", radius_m)
    if T_world_link_check is None:
        T = forward_kinematics(np.zeros(geometry.n_links - 1))
    else:
        T = np.asarray(T_world_link_check, dtype=np.float64)
    if T.shape != (geometry.n_links, 4, 4):
        raise InputError(None, "T_world_link_check", f"shape ({geometry.n_links}, 4, 4)", f"shape {T.shape}")
    world_parts = [p.copy().apply_transform(T[i]) for i in range(geometry.n_links) for p in geometry.parts[i]]
    labels, links, pts, nrms = [], [], [], []
    for link in sorted(int(k) for k in clusters):
        n = int(clusters[link])
        surface = geometry.marker_surface(link) if 0 <= link < geometry.n_links else None
        if surface is None or n < 1:
            raise InputError(None, f"clusters[{link}]", "a link with a marker surface and a count >= 1",
                             f"link {link}, count {n}")
        p, nrm = _sample_surface(surface, n_candidates, rng)
        p = p + radius_m * nrm
        ok = _clear(p @ T[link, :3, :3].T + T[link, :3, 3], world_parts, radius_m)
        if ok.sum() < n:
            raise InputError(None, f"clusters[{link}]", f"room for {n} markers on {geometry.names[link]}",
                             f"{int(ok.sum())} clear candidates")
        p, nrm = p[ok], nrm[ok]
        first = int(rng.integers(len(p)))
        idx = _spread(p, np.hypot(p[:, 0], p[:, 1]), n, min_radius_gap_m, first)
        labels += [f"{cluster_label(link)}_{j + 1}" for j in range(n)]
        links += [link] * n
        pts.append(p[idx])
        nrms.append(nrm[idx])
    return MarkerLayout(labels=tuple(labels), link=np.asarray(links, dtype=np.int64),
                        p_link=np.concatenate(pts), normal_link=np.concatenate(nrms), radius_m=float(radius_m))


def marker_positions(layout: MarkerLayout, T_world_link) -> np.ndarray:
    """World positions of the markers for link poses over time.

    Parameters
    ----------
    layout : MarkerLayout
    T_world_link : (..., L, 4, 4) float
        Link poses, e.g. (T, L, 4, 4) from `forward_kinematics`.

    Returns
    -------
    p_world : (..., M, 3) float
        Marker centres in the world frame, metres: p_world = R_world_link p_link + t_world_link.
    """
    T = np.asarray(T_world_link, dtype=np.float64)
    if T.ndim < 3 or T.shape[-2:] != (4, 4) or T.shape[-3] <= int(layout.link.max()):
        raise InputError(None, "T_world_link", "an array of shape (..., L, 4, 4) covering every marker's link",
                         f"shape {T.shape}")
    Tm = T[..., layout.link, :, :]
    return np.einsum("...mij,mj->...mi", Tm[..., :3, :3], layout.p_link) + Tm[..., :3, 3]


def vendor_smoothed(markers, fc_hz: float, order: int = 4):
    """`markers` (:class:`mocapfj.types.MarkerTrajectories`) through a zero-phase Butterworth low-pass
    of `order` at `fc_hz`, as mocap software smooths trajectories before export: each marker's
    lost samples filled linearly for the filter and lost again after it (a marker never seen
    stays lost)."""
    from dataclasses import replace

    from scipy.signal import butter, filtfilt

    x = np.array(markers.xyz, dtype=np.float64)
    T, M, _ = x.shape
    ok = np.isfinite(x[:, :, 0])
    t = np.arange(T)
    flat = x.reshape(T, M * 3)
    for j in np.flatnonzero(ok.any(axis=0)):          # per marker: np.interp is one-dimensional
        for c in range(3):
            flat[:, 3 * j + c] = np.interp(t, t[ok[:, j]], x[ok[:, j], j, c])
    b, a = butter(order, fc_hz / (markers.rate_hz / 2))
    seen = np.repeat(ok.any(axis=0), 3)
    flat[:, seen] = filtfilt(b, a, flat[:, seen], axis=0)
    y = np.where(ok[:, :, None], flat.reshape(T, M, 3), np.nan)
    return replace(markers, xyz=y)
