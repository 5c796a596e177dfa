"""Scenario to bundle (mocapfj.synth.record): the chain agrees with its truth."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from mocapfj.io import load_recording, read_csv_columns
from mocapfj.synth.record import marker_layout, scenario_rngs, measure_concealment, record_scenario, write_scenario_bundle
from mocapfj.synth.markers import marker_positions
from mocapfj.synth.robot_mesh import base_pose, forward_kinematics, pa10_geometry
from mocapfj.synth.scenario import load_scenario

DATASETS = Path(__file__).resolve().parents[2] / "datasets"


@pytest.fixture(scope="module")
def joint2():
    """pa10_joint2 for 6 s (the first 2 s are the reference's ramp from rest)."""
    return record_scenario(load_scenario(DATASETS / "pa10_joint2.toml").with_duration(6.0))


def _marker_error(sr, scn, t_ctrl) -> np.ndarray:
    """Rendered markers minus the noise-free markers of the arm posed from truth at t_ctrl."""
    r = sr.sim["j2"]
    q = np.interp(t_ctrl, r.t, r.q[:, 0])
    q_full = np.tile(np.asarray(scn.pose_rad), (q.size, 1))
    q_full[:, 1] = q
    layout = marker_layout(scn, pa10_geometry(), scenario_rngs(scn)[0])
    p = marker_positions(layout, forward_kinematics(q_full, T_world_base=base_pose()))
    return sr.recording.markers.xyz - p


def test_markers_follow_the_true_link_angle_within_the_marker_noise(joint2):
    scn = load_scenario(DATASETS / "pa10_joint2.toml").with_duration(6.0)
    err = _marker_error(joint2, scn, joint2.t_true_mocap)
    sd = np.nanstd(err)
    assert abs(sd - 2e-4) < 0.1 * 2e-4  # 0.2 mm per coordinate, nothing else
    assert abs(np.nanmean(err)) < 1e-5


def test_a_planted_clock_delay_is_in_the_markers_not_in_the_declared_clock():
    scn = load_scenario(DATASETS / "suite" / "time_delay_ident.toml").with_duration(6.0)
    sr = record_scenario(scn, with_concealment=False)
    assert sr.truth["clock"] == {"declared_offset_s": 0.0, "true_offset_s": 1e-3, "delay_s": 1e-3}
    t_declared = sr.recording.markers_t_controller()
    np.testing.assert_allclose(sr.t_true_mocap - t_declared, 1e-3, atol=1e-12)
    candidates = np.array([-1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 3.0]) * 1e-3
    rms = [np.sqrt(np.nanmean(_marker_error(sr, scn, t_declared + d) ** 2)) for d in candidates]
    assert candidates[int(np.argmin(rms))] == 1e-3  # the markers were taken 1 ms later than declared
    assert rms[1] > rms[3] * 1.02


def test_truth_files_and_the_controller_log_agree(joint2, tmp_path):
    write_scenario_bundle(joint2, tmp_path / "b", DATASETS / "pa10_joint2.toml")
    rec = load_recording(tmp_path / "b")
    truth = read_csv_columns(tmp_path / "b" / "truth.csv")
    np.testing.assert_array_equal(truth["time"], rec.controller.t)
    quantum = json.loads((tmp_path / "b" / "truth.json").read_text())["joints"][0]["q_m_quantum_rad"]
    assert quantum == pytest.approx(2 * np.pi / (2**16 * 50))
    assert np.max(np.abs(rec.controller.q_m[:, 0] - truth["q_m_j2"])) <= quantum / 2 + 1e-12  # resolver
    noise = rec.controller.tau[:, 0] - truth["u_j2"]
    assert abs(np.std(noise) - 0.3) < 0.03  # current noise, N m
    np.testing.assert_allclose(truth["tau_s_j2"], 1.19e4 * truth["delta_j2"], rtol=1e-12)  # linear spring, eq. 7
    assert (tmp_path / "b" / "scenario.toml").read_text() == (DATASETS / "pa10_joint2.toml").read_text()
    assert rec.rig is not None and len(rec.rig.cameras) == 8
    assert rec.detections.frame.max() < 2.0 * 250  # 2D detections of the first 2 s


def test_same_scenario_and_seed_give_byte_identical_bundles(tmp_path):
    scn = load_scenario(DATASETS / "suite" / "hysteresis_ident.toml").with_duration(3.0)
    digests = []
    for d in ("a", "b"):
        write_scenario_bundle(record_scenario(scn, with_concealment=False), tmp_path / d)
        digests.append({p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted((tmp_path / d).iterdir())})
    assert digests[0] == digests[1] and len(digests[0]) == 8
    scn2 = load_scenario(DATASETS / "suite" / "hysteresis_valid.toml").with_duration(3.0)
    write_scenario_bundle(record_scenario(scn2, with_concealment=False), tmp_path / "c")
    assert hashlib.sha256((tmp_path / "c" / "markers.c3d").read_bytes()).hexdigest() != digests[0]["markers.c3d"]


SUITE = sorted(p for p in (DATASETS / "suite").glob("*.toml") if not p.name.startswith("control"))


@pytest.mark.parametrize("path", SUITE, ids=lambda p: p.stem)
def test_every_planted_effect_is_concealed_in_the_deflection(path):
    """Contribution to the measured deflection below its per-sample noise SD, over the ramp
    and one full period of the excitation (the whole range of motion)."""
    scn = load_scenario(path)
    ref = scn.joint("j2").reference
    scn = scn.with_duration(ref["ramp_s"] + 1.0 / ref["f0_hz"])
    (c,) = measure_concealment(scn)
    assert c["name"] == path.stem.rsplit("_", 1)[0]
    assert c["ratio"] < 1.0 and c["concealed"]
    if c["name"] != "drive_gain":  # a drive-gain error shows in torque, not in deflection
        assert c["ratio"] > 0.1, "the effect should be there to find"
