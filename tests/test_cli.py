"""The command line (mocapfj.cli): commands listed, JSON on stdout, one-line errors with exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from mocapfj.cli import PLANNED, main

DESIGN_COMMANDS = ["demo", "simulate", "calibrate-camera", "calibrate-rig", "triangulate", "joints", "identify",
                   "frf", "discover", "run", "report", "view", "batch"]


def test_help_lists_every_command_of_the_design(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for cmd in DESIGN_COMMANDS + ["inspect"]:
        assert f"\n    {cmd} " in out or f"\n    {cmd}\n" in out, cmd


def test_demo_json_reports_a_clean_round_trip(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "d"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["round_trip"]["controller_identical"] is True
    assert s["round_trip"]["marker_max_error_m"] < 1e-7  # float32 millimetres in the C3D
    assert [j["name"] for j in s["joints"]] == ["j1"]
    assert s["markers"]["n_frames"] == 1001 and s["controller"]["n_samples"] == 4001
    assert (tmp_path / "d" / "recording" / "recording.toml").is_file()
    assert json.loads((tmp_path / "d" / "summary.json").read_text())["name"] == "toy_joint1"


def test_inspect_real_c3d(realdata, capsys):
    assert main(["inspect", str(realdata / "c3d_samples" / "c3d_org_sample01" / "Eb015pr.c3d"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["markers"]["n_markers"] == 26 and s["markers"]["n_frames"] == 450 and s["markers"]["rate_hz"] == 50.0
    assert s["joints"] == []


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "d")]) == 0
    capsys.readouterr()
    toml = tmp_path / "d" / "recording" / "recording.toml"
    toml.write_text(toml.read_text().replace('"mocapfj.recording/1"', '"mocapfj.recording/9"'))
    assert main(["inspect", str(tmp_path / "d" / "recording")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("mocapfj: error: ") and "format: expected version 1 or older, got version 9" in err


@pytest.mark.parametrize("name", [n for n, _ in PLANNED])
def test_planned_commands_say_so_and_exit_2(name, capsys):
    assert main([name, "x"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"'{name}' is not available" in err


def test_console_script_runs(tmp_path):
    r = subprocess.run([sys.executable, "-m", "mocapfj.cli", "inspect", str(tmp_path / "missing")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().endswith("got no such path") and r.stderr.count("\n") == 1
