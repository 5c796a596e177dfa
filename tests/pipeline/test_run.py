"""mocapfj run (mocapfj.pipeline.run): a camera bundle through triangulation, joints and
identification into a run directory; resumable; a failing stage leaves the finished ones."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from mocapfj.cli import main
from mocapfj.io import read_csv_columns, read_json
from mocapfj.pipeline import default_scenario, run_pipeline
from mocapfj.pipeline import run as run_module
from mocapfj.pipeline.demo import _camera_bundle
from mocapfj.synth.record import record_scenario, write_scenario_bundle
from mocapfj.synth.scenario import load_scenario

FAST = ("triangulate", "joints", "identify")


@pytest.fixture(scope="module")
def camera_bundle(tmp_path_factory):
    """8 s of PA-10 joint 2 as 8 cameras' labelled blobs and a controller log (the simulator's
    own rig as the calibrated rig), with the simulator's truth beside it."""
    d = tmp_path_factory.mktemp("run")
    scn = load_scenario(default_scenario("pa10_joint2")).with_duration(8.0)
    scn = replace(scn, measurement=replace(scn.measurement, detections_s=scn.duration_s))
    sr = record_scenario(scn, with_concealment=False)
    write_scenario_bundle(sr, d / "sim")
    bundle = _camera_bundle(sr, scn, sr.recording.rig, d / "cams")
    return bundle, d / "sim", sr


@pytest.fixture(scope="module")
def first_run(camera_bundle, tmp_path_factory):
    bundle, _, _ = camera_bundle
    out = tmp_path_factory.mktemp("out") / "run"
    return run_pipeline(bundle, out, stages=FAST), out


def test_camera_bundle_runs_to_identification_with_the_deflection_at_its_bound(camera_bundle, first_run):
    _, sim, sr = camera_bundle
    r, out = first_run
    assert [s.status for s in r.stages] == ["done", "done", "done", "not_applicable", "not_applicable",
                                            "not_applicable"]
    assert r.stage("discover").reason == "not requested (--stages)"
    tri = read_json(out / "triangulate" / "triangulate.json")
    assert tri["n_frames"] == 2000 and tri["nan_share"] < 0.01
    # the deflection from triangulated markers against the truth: at its Cramer-Rao bound
    a = read_csv_columns(out / "joints" / "j2.angles.csv")
    truth = read_csv_columns(sim / "truth.csv")
    err = a["delta"] - np.interp(a["t_controller"], truth["time"], truth["delta_j2"])
    ok = np.isfinite(err)
    err = err[ok] - err[ok].mean()
    bound = np.sqrt(np.mean(a["sigma_delta"][ok] ** 2))
    assert np.sqrt(np.mean(err**2)) < 1.15 * bound
    # the identified stiffness: its SD covers its error against Table I's k
    (j,) = read_json(out / "identify" / "identify.json")["joints"]
    k = j["params"]["k"]
    k_true = sr.truth["joints"][0]["nominal"]["spring"]["k"]
    assert abs(k["value"] - k_true) < 4 * k["std"] and k["std"] < 0.05 * k_true
    manifest = read_json(out / "run.json")
    assert manifest["format"] == "mocapfj.run/1" and [s["status"] for s in manifest["stages"]][:3] == ["done"] * 3


def test_a_rerun_keeps_unchanged_stages_and_redoes_changed_inputs(camera_bundle, first_run, tmp_path):
    bundle, _, _ = camera_bundle
    _, out = first_run
    again = run_pipeline(bundle, out, stages=FAST)
    assert [s.status for s in again.stages[:3]] == ["skipped"] * 3
    copy = tmp_path / "cams"
    shutil.copytree(bundle, copy)
    text = (copy / "controller.csv").read_text().splitlines()
    row = text[100].split(",")
    row[-1] = repr(float(row[-1]) + 1e-3)            # one torque sample moved: every stage's input changed
    text[100] = ",".join(row)
    (copy / "controller.csv").write_text("\n".join(text) + "\n")
    out2 = tmp_path / "run"
    shutil.copytree(out, out2)
    manifest = json.loads((out2 / "run.json").read_text())
    manifest["recording"] = str(copy)
    (out2 / "run.json").write_text(json.dumps(manifest))
    redo = run_pipeline(copy, out2, stages=("triangulate", "joints"))
    assert [s.status for s in redo.stages[:2]] == ["done", "done"]


def test_a_failing_stage_leaves_the_finished_ones_and_says_why(camera_bundle, first_run, tmp_path, monkeypatch):
    bundle, _, _ = camera_bundle
    _, out = first_run
    out2 = tmp_path / "run"
    shutil.copytree(out, out2)
    before = (out2 / "joints" / "j2.angles.csv").read_bytes()

    def broken(ctx, d):
        (d / "half.json").write_text("{")
        raise ValueError("the identification could not start")

    monkeypatch.setitem(run_module._RUNNERS, "identify", broken)
    r = run_pipeline(bundle, out2, stages=FAST, force=True)
    assert [s.status for s in r.stages[:3]] == ["done", "done", "failed"]
    assert r.failed.name == "identify" and "could not start" in r.failed.error
    assert (out2 / "joints" / "j2.angles.csv").read_bytes() == before
    assert (out2 / "identify" / "identify.json").is_file()        # the last good identification stays
    assert not (out2 / "identify" / "half.json").exists() and not (out2 / ".identify.tmp").exists()
    m = read_json(out2 / "run.json")
    assert m["stages"][2]["status"] == "failed" and "could not start" in m["stages"][2]["error"]


def test_single_stage_commands_ask_for_the_markers_to_be_triangulated(camera_bundle, tmp_path, capsys):
    bundle, _, _ = camera_bundle
    assert main(["joints", str(bundle), "--out", str(tmp_path / "j")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "mocapfj run" in err and "2D detections" in err


@pytest.mark.parametrize("args, needle", [
    (["--stages", "joints,fly"], "--stages"),
    (["--validation", "/nonexistent/bundle"], "recording.toml"),
])
def test_run_bad_input_exits_2(camera_bundle, tmp_path, capsys, args, needle):
    bundle, _, _ = camera_bundle
    assert main(["run", str(bundle), "--out", str(tmp_path / "o"), *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err
    assert not (tmp_path / "o" / "run.json").exists()


def test_inspect_says_the_markers_come_from_the_cameras(camera_bundle, capsys):
    bundle, _, _ = camera_bundle
    assert main(["inspect", str(bundle)]) == 0
    out = capsys.readouterr().out
    assert "markers    from 8 cameras:" in out and "2D detections, triangulated by 'mocapfj run'" in out
    assert main(["inspect", str(bundle), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["markers"] is None and s["markers_from_cameras"] is True and s["rig_cameras"] == 8
