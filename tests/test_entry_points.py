"""What users bring, each through the command line: markers only (a passive hinge, a human joint),
and a rigid robot's controller log with its URDF (no markers)."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocapfj.cli import main
from mocapfj.io import write_recording
from mocapfj.synth import toy_recording
from mocapfj.synth.toy import TOY_TRUTH


def test_markers_only_bundle_gives_axis_centre_and_angles(tmp_path, capsys):
    """A hinge without a motor: no [controller] in recording.toml. joints gives the axis and the
    centre, in the world too (the parent cluster is static), and says there is no deflection;
    identify refuses with what it needs."""
    write_recording(replace(toy_recording(duration_s=4.0), controller=None), tmp_path / "hinge")
    toml = (tmp_path / "hinge" / "recording.toml").read_text()
    assert "[controller]" not in toml and "motor_position" not in toml
    assert main(["inspect", str(tmp_path / "hinge")]) == 0
    assert "controller none (markers only" in capsys.readouterr().out
    assert main(["joints", str(tmp_path / "hinge"), "--out", str(tmp_path / "out"), "--json"]) == 0
    (j,) = json.loads(capsys.readouterr().out)["joints"]
    assert "no deflection" in j["note"] and j["deflection_rms_rad"] is None and j["q_offset_rad"] is None
    axis = np.asarray(j["axis_world"])
    assert abs(abs(axis @ TOY_TRUTH["axis"]) - 1) < 1e-5
    centre = np.asarray(TOY_TRUTH["centre_m"])
    p = np.asarray(j["point_world_m"])
    off = (p - centre) - ((p - centre) @ axis) * axis            # the point anywhere along the axis
    assert np.linalg.norm(off) < 1e-3
    assert j["q_range_deg"] == pytest.approx(np.degrees(2 * 0.6 * 0.96), rel=0.1)
    cols = (tmp_path / "out" / "j1.angles.csv").read_text().splitlines()[0].split(",")
    assert "q" in cols and "delta" not in cols
    assert main(["identify", str(tmp_path / "hinge"), "--out", str(tmp_path / "id")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "expected a controller log with the joint's motor columns, got markers only" in err


def test_real_elbow_as_a_markers_only_bundle(realdata, tmp_path, capsys):
    """The Kinetics Toolkit wheelchair-propulsion elbow (real optical mocap, both segments moving):
    a bundle of the C3D and a recording.toml naming the clusters, no controller log. The elbow's
    range is the clusters' relative rotation between the extreme frames, 111.0 deg (its excursion
    from the first frame is the published 88 deg: tests/joints/test_pipeline.py); the upper arm
    moves, so the axis is given in its frame only (axis_world null)."""
    (tmp_path / "elbow").mkdir()
    shutil.copy(realdata / "c3d_samples" / "kinematics_racing_propulsion.c3d", tmp_path / "elbow" / "markers.c3d")
    (tmp_path / "elbow" / "recording.toml").write_text(
        'format = "mocapfj.recording/1"\nname = "elbow"\n[markers]\nfile = "markers.c3d"\n'
        '[[joints]]\nname = "elbow"\nlink_markers = ["ForearmR1", "ForearmR2", "ForearmR3"]\n'
        'parent_markers = ["ArmR1", "ArmR2", "ArmR3"]\n')
    assert main(["joints", str(tmp_path / "elbow"), "--out", str(tmp_path / "out"), "--json"]) == 0
    (j,) = json.loads(capsys.readouterr().out)["joints"]
    assert j["method"] == "sara" and j["axis_world"] is None and j["parent_static"] is False
    assert abs(j["q_range_deg"] - 111.0) < 1.0 and "no deflection" in j["note"]


ROBOT = 3


@pytest.fixture(scope="module")
def rigid(tmp_path_factory):
    """A 3-joint spatial arm (joint origins rotated by rpy = +-pi/2) following a Fourier trajectory,
    its torques from Pinocchio's inverse dynamics with armature, Coulomb and viscous friction and
    0.05 N m noise, logged at 500 Hz with jittered time stamps; a second trajectory for validation."""
    from mocapfj.ident.regressor import load_pin_model
    from mocapfj.synth.rigid import arm_urdf, rigid_recording, rigid_truth

    d = tmp_path_factory.mktemp("rigid")
    urdf = arm_urdf(ROBOT, seed=1)
    (d / "robot.urdf").write_text(urdf)
    write_recording(replace(rigid_recording(urdf, duration_s=60, seed=2, jitter_s=2e-4, amplitude_rad=1.5,
                                            harmonics=8), urdf=d / "robot.urdf"), d / "trial")
    write_recording(replace(rigid_recording(urdf, duration_s=20, seed=3, f0_hz=0.13), urdf=d / "robot.urdf"),
                    d / "validation")
    pm = load_pin_model(urdf)
    tr = rigid_truth(urdf)
    truth = dict(zip([f"{p}_{j}" for j in ("j1", "j2", "j3") for p in ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz",
                                                                       "Iyz", "Izz")],
                     np.concatenate([pm.inertias[j].toDynamicParameters() for j in range(1, pm.njoints)])))
    for i, j in enumerate(("j1", "j2", "j3")):
        truth.update({f"Ia_{j}": tr["armature"][i], f"fc_{j}": tr["coulomb"][i], f"fv_{j}": tr["viscous"][i]})
    return d, truth


def test_rigid_robot_bundle_identified_from_its_log(rigid, capsys):
    """Base parameters with statistics, against the truth in the same regrouping: every one within
    3.5 of its SDs (Newey-West: the filtered residual is correlated), every one whose relative SD
    is below 0.3 % within 1 % (measured: 17 of 22, the others being the distal link's products of
    inertia, below 0.01 kg m2, whose torque is at the noise: relative SD 1-54 %, and flagged not
    determined above 5 %); the jittered time stamps resampled and counted; each joint's torque RMS
    on the validation recording reported, near the noise left after the same filtering."""
    from mocapfj import identify
    from mocapfj.ident import base_from_standard

    d, named = rigid
    assert main(["identify", str(d / "trial"), "--out", str(d / "out"), "--validation", str(d / "validation"),
                 "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    r = s["rigid"]
    assert r["n_resampled"] > 0 and r["friction"] in ("coulomb_viscous", "tanh_coulomb_viscous", "stribeck")
    assert set(s["validation"]) == {"j1", "j2", "j3"} and [j["name"] for j in s["joints"]] == ["j1", "j2", "j3"]
    fit = identify(str(d / "trial")).rigid[0]
    print(r["friction"], r["friction_holdout_rms_Nm"])
    phi = np.array([named.get(n, 0.0) for n in fit.standard_names])     # a friction law's extra terms are 0
    truth = base_from_standard(phi, fit.base_idx, fit.Kd)
    params = fit.params
    within = 0
    for (name, p), b in zip(params.items(), truth):
        assert abs(p.value - b) < 3.5 * p.std, (name, p.value, b, p.std)
        assert p.determined == (p.rel_std_pct <= 5.0)
        if p.rel_std_pct < 0.3:
            assert p.value == pytest.approx(b, rel=0.01), (name, p.value, b)
        within += abs(p.value / b - 1) < 0.01
    assert within >= 0.7 * len(params), (within, len(params))
    assert all(v < 0.02 and v < 3 * j["torque_rms"] for v, j in zip(s["validation"].values(), s["joints"]))
    assert not any(abs(n) < 1e-10 for n in truth)          # no rounding-level column kept as a parameter
