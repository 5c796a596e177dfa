"""mocapfj.synth.markers: clusters on link surfaces (Lightcap and Banks (2007), §III-IV) and their motion."""

import numpy as np
import pytest
import trimesh

from mocapfj.errors import InputError
from mocapfj.synth.markers import DEFAULT_CLUSTERS, marker_positions, place_markers
from mocapfj.synth.robot_mesh import forward_kinematics, pa10_geometry


@pytest.fixture(scope="module")
def geometry():
    return pa10_geometry()


@pytest.fixture(scope="module")
def layout(geometry):
    return place_markers(geometry, np.random.default_rng(0))


def test_default_layout_labels_and_cluster_sizes(layout):
    assert len(layout.labels) == sum(DEFAULT_CLUSTERS.values()) == 20
    assert layout.labels[:3] == ("B_1", "B_2", "B_3")
    assert layout.labels[6:10] == ("L2_1", "L2_2", "L2_3", "L2_4")
    for link, n in DEFAULT_CLUSTERS.items():
        assert len(layout.cluster(link)) == n and 3 <= n <= 4
    assert layout.radius_m == 0.007


def test_markers_sit_one_radius_above_their_link_and_clear_of_the_rest(geometry, layout):
    T = forward_kinematics(np.zeros(6))
    p = marker_positions(layout, T)
    for link in np.unique(layout.link):
        i = layout.cluster(link)
        _, d, _ = trimesh.proximity.closest_point(geometry.mesh(link).apply_transform(T[link]), p[i])
        np.testing.assert_allclose(d, 0.007, atol=1e-6)
    for link in range(geometry.n_links):
        for part in geometry.parts[link]:
            _, d, _ = trimesh.proximity.closest_point(part.copy().apply_transform(T[link]), p)
            assert d.min() >= 0.98 * 0.007
    np.testing.assert_allclose(np.linalg.norm(layout.normal_link, axis=1), 1.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_axis_radii_differ_and_markers_spread_within_clusters(geometry, seed):
    layout = place_markers(geometry, np.random.default_rng(seed))
    r = layout.axis_radius()
    for link in (1, 2, 3, 4, 6):
        i = layout.cluster(link)
        iu = np.triu_indices(len(i), 1)
        assert np.abs(r[i][:, None] - r[i][None])[iu].min() >= 0.015        # min_radius_gap_m
        assert np.linalg.norm(layout.p_link[i][:, None] - layout.p_link[i][None], axis=2)[iu].min() > 0.05


def test_same_seed_same_layout_other_seed_other_layout(geometry, layout):
    again = place_markers(geometry, np.random.default_rng(0))
    assert again.labels == layout.labels
    assert again.p_link.tobytes() == layout.p_link.tobytes()
    other = place_markers(geometry, np.random.default_rng(1))
    assert np.abs(other.p_link - layout.p_link).max() > 0.01


def test_positions_move_rigidly_with_their_links(layout):
    rng = np.random.default_rng(4)
    q = rng.uniform(-2, 2, (30, 6))
    T = forward_kinematics(q)
    p = marker_positions(layout, T)
    assert p.shape == (30, 20, 3)
    m = 7
    R, t = T[11, layout.link[m], :3, :3], T[11, layout.link[m], :3, 3]
    np.testing.assert_allclose(p[11, m], R @ layout.p_link[m] + t, atol=1e-15)
    for link in DEFAULT_CLUSTERS:
        i = layout.cluster(link)
        d = np.linalg.norm(p[:, i, None] - p[:, None, i], axis=-1)
        d0 = np.linalg.norm(layout.p_link[i][:, None] - layout.p_link[i][None], axis=-1)
        np.testing.assert_allclose(d, np.broadcast_to(d0, d.shape), atol=1e-12)


def test_link_without_marker_surface_raises(geometry):
    with pytest.raises(InputError, match="clusters"):
        place_markers(geometry, np.random.default_rng(0), clusters={5: 3})
    with pytest.raises(InputError, match="T_world_link"):
        marker_positions(place_markers(geometry, np.random.default_rng(0), clusters={0: 3}), np.zeros((4, 4)))
