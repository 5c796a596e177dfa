"""Joint calibration files (mocapfj.io.geometry)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj import InputError, JointGeometry
from mocapfj.io.geometry import read_joint_geometry, write_joint_geometry


def geometry() -> JointGeometry:
    rng = np.random.default_rng(0)
    n = rng.normal(size=3)
    return JointGeometry(axis=n / np.linalg.norm(n), point=rng.normal(size=3), template=rng.normal(size=(4, 3)) * 0.1,
                         labels=("a", "b", "c", "d"), radii=rng.uniform(0.05, 0.2, 4), radius_rms=rng.uniform(0, 1e-4, 4),
                         marker_rms=2.1e-4, cov_axis=np.eye(3) * 1e-8, cov_point=np.eye(3) * 1e-9, sigma_m=2e-4,
                         method="ml", n_frames=1500)


def test_round_trip_is_exact(tmp_path):
    g = geometry()
    tmpl = np.arange(9.0).reshape(3, 3) * 0.01
    write_joint_geometry(tmp_path / "j2.joint.toml", "j2", g, ("L1_1", "L1_2", "L1_3"), tmpl, extra={"q_offset_rad": 0.01})
    name, back, parent = read_joint_geometry(tmp_path / "j2.joint.toml")
    assert name == "j2" and back.labels == g.labels and back.method == "ml" and back.n_frames == 1500
    for k in ("axis", "point", "template", "radii", "radius_rms", "cov_axis", "cov_point"):
        np.testing.assert_array_equal(getattr(back, k), getattr(g, k))
    assert parent["labels"] == ["L1_1", "L1_2", "L1_3"] and np.array_equal(parent["template_m"], tmpl)


def test_not_a_unit_axis(tmp_path):
    write_joint_geometry(tmp_path / "j.toml", "j", geometry())
    text = (tmp_path / "j.toml").read_text()
    import re

    text = re.sub(r"axis = \[[^\]]*\]", "axis = [0.0, 0.0, 2.0]", text, count=1)
    (tmp_path / "j.toml").write_text(text)
    with pytest.raises(InputError, match=r"j\.toml: axis: expected a unit vector, got norm 2"):
        read_joint_geometry(tmp_path / "j.toml")
