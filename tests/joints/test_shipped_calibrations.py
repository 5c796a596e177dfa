"""The cluster calibrations shipped in calibration/ agree with their scenarios' true layouts."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapfj.io.geometry import read_joint_geometry
from mocapfj.synth.record import marker_layout, scenario_rngs
from mocapfj.synth.robot_mesh import pa10_geometry
from mocapfj.synth.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
FILES = sorted((ROOT / "calibration").glob("pa10_*/*.joint.toml"))


@pytest.mark.parametrize("path", FILES, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_radii_match_the_true_marker_layout(path):
    scn = load_scenario(ROOT / "datasets" / f"{path.parent.name}.toml")
    name, g, parent = read_joint_geometry(path)
    layout = marker_layout(scn, pa10_geometry(), scenario_rngs(scn)[0])
    true = layout.axis_radius()[[layout.labels.index(s) for s in g.labels]]
    np.testing.assert_allclose(g.radii, true, atol=1e-3)
    assert list(g.labels) == list(scn.joint(name).link_markers)
    assert g.method == "ml" and g.n_frames == 15001


def test_every_shipped_scenario_joint_has_a_calibration():
    names = {(p.parent.name, p.name.split(".")[0]) for p in FILES}
    assert names == {("pa10_joint1", "j1"), ("pa10_joint2", "j2"), ("pa10_joints23", "j2"), ("pa10_joints23", "j3")}
