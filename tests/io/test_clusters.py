"""Clusters files (mocapfj.clusters/1) and joint calibrations as clusters (mocapfj.io.clusters)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.io.clusters import read_clusters, tag_template, write_clusters
from mocapfj.types import MarkerCluster

ROOT = Path(__file__).resolve().parents[2]


def test_round_trip_with_a_tag(tmp_path):
    c = MarkerCluster("link2", ["L2_1", "L2_2", "L2_3"], [[0.1, 0, 0.02], [0, 0.08, 0], [-0.05, 0, 0.03]])
    t = MarkerCluster("tag3", [f"tag3_{i}" for i in range(4)], tag_template(0.05), tag_id=3, tag_family="tag36h11")
    write_clusters(tmp_path / "c.toml", [c, t])
    back = read_clusters(tmp_path / "c.toml")
    assert [x.name for x in back] == ["link2", "tag3"]
    assert np.array_equal(back[0].template_m, c.template_m) and back[0].labels == c.labels
    assert back[1].tag_id == 3 and np.allclose(back[1].template_m, t.template_m)
    assert np.isclose(np.linalg.norm(tag_template(0.05)[1] - tag_template(0.05)[0]), 0.05)


def test_a_joint_calibration_serves_as_clusters():
    cl = read_clusters(ROOT / "calibration" / "pa10_joint2" / "j2.joint.toml")
    assert [c.name for c in cl] == ["j2.link", "j2.parent"]
    assert cl[0].labels == ("L2_1", "L2_2", "L2_3", "L2_4") and cl[1].template_m.shape == (3, 3)


@pytest.mark.parametrize("text, field", [
    ('format = "mocapfj.clusters/1"\n', "clusters"),
    ('format = "mocapfj.clusters/2"\n[[clusters]]\nname="a"\n', "format"),
    ('format = "mocapfj.clusters/1"\n[[clusters]]\nname = "a"\nlabels = ["x", "y", "z"]\n'
     'template_m = [[0, 0, 0], [1, 0, 0]]\n', "clusters[0].template_m"),
    ('format = "mocapfj.clusters/1"\n[[clusters]]\nname = "a"\nlabels = ["x", "y", "z"]\n'
     'template_m = [[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]]\n', "template_m"),
    ('format = "mocapfj.clusters/1"\n[[clusters]]\nname = "a"\nlabels = ["x", "y", "z"]\n'
     'template_m = [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]]\n[[clusters]]\nname = "b"\nlabels = ["x", "v", "w"]\n'
     'template_m = [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]]\n', "label 'x'"),
    ('format = "mocapfj.clusters/1"\n[[tags]]\nname = "t"\nid = 1\nsize_m = -1\n', "tags[0].size_m"),
])
def test_bad_clusters_files_name_the_field(tmp_path, text, field):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(InputError) as e:
        read_clusters(f)
    assert str(f) in str(e.value) and field in str(e.value)
