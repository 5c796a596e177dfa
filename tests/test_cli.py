"""The command line (mocapfj.cli): commands listed, JSON on stdout, one-line errors with exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from mocapfj.cli import main

DESIGN_COMMANDS = ["demo", "simulate", "calibrate-camera", "calibrate-rig", "triangulate", "joints", "identify",
                   "frf", "discover", "run", "report", "view", "batch"]


def test_help_lists_every_command_of_the_design(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for cmd in DESIGN_COMMANDS + ["inspect"]:
        assert f"\n    {cmd} " in out or f"\n    {cmd}\n" in out, cmd


def test_simulate_reports_concealment(tmp_path, capsys):
    from pathlib import Path

    scn = Path(__file__).resolve().parents[1] / "datasets" / "suite" / "backlash_ident.toml"
    assert main(["simulate", str(scn), "--out", str(tmp_path / "b"), "--duration", "4"]) == 0
    out = capsys.readouterr().out
    assert "effect backlash on j2: deflection RMS" in out and "(concealed)" in out
    truth = json.loads((tmp_path / "b" / "truth.json").read_text())
    assert truth["effects"][0]["name"] == "backlash" and truth["effects"][0]["ratio"] < 1


def test_simulate_bad_scenario_exits_2(tmp_path, capsys):
    p = tmp_path / "bad.toml"
    p.write_text('format = "mocapfj.scenario/1"\nduration_s = 1.0\n')
    assert main(["simulate", str(p), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.toml: joints: expected a value of type array" in err
    assert not (tmp_path / "o").exists()


def test_inspect_real_c3d(realdata, capsys):
    assert main(["inspect", str(realdata / "c3d_samples" / "c3d_org_sample01" / "Eb015pr.c3d"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["markers"]["n_markers"] == 26 and s["markers"]["n_frames"] == 450 and s["markers"]["rate_hz"] == 50.0
    assert s["joints"] == []


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    from mocapfj.io import write_recording
    from mocapfj.synth import toy_recording

    toml = write_recording(toy_recording(duration_s=0.5), tmp_path / "d")
    toml.write_text(toml.read_text().replace('"mocapfj.recording/1"', '"mocapfj.recording/9"'))
    assert main(["inspect", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("mocapfj: error: ") and "format: expected version 1 or older, got version 9" in err


def test_inspect_of_a_cut_c3d_is_one_line_and_exit_2(tmp_path):
    """A half-cut C3D once read as half its frames with exit 0; cut inside its parameter section it
    segfaulted ezc3d. Both are one line naming the file and the field, exit 2, as a user runs it."""
    from mocapfj.io import write_recording
    from mocapfj.synth import toy_recording

    write_recording(toy_recording(duration_s=2.0), tmp_path / "d")
    c3d = next((tmp_path / "d").glob("*.c3d"))
    raw = c3d.read_bytes()
    for keep, says in ((len(raw) // 2, "POINT:FRAMES: expected"), (700, "parameter section: expected")):
        c3d.write_bytes(raw[:keep])
        r = subprocess.run([sys.executable, "-m", "mocapfj.cli", "inspect", str(tmp_path / "d")],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1, r.stderr
        assert f"{c3d.name}: {says}" in r.stderr and "cut" in r.stderr


def test_console_script_runs(tmp_path):
    r = subprocess.run([sys.executable, "-m", "mocapfj.cli", "inspect", str(tmp_path / "missing")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().endswith("got no such path") and r.stderr.count("\n") == 1


def test_discover_prints_each_parameter_with_its_sd():
    """The discover command's text gives each found effect's parameters with their SDs, a list's
    items one by one, and leaves out the parameters without one."""
    from mocapfj.cli import _with_sds_text

    text = _with_sds_text({"amplitudes_rad": [2.612e-4, 1.868e-4], "gear_ratio": 50.0, "vs": 0.0194},
                          {"amplitudes_rad": [5.4e-6, 5.6e-6], "vs": 2.2e-4})
    assert text == "amplitudes_rad 0.0002612 +- 5.4e-06, 0.0001868 +- 5.6e-06; vs 0.0194 +- 0.00022"
