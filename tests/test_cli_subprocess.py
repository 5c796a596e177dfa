"""Every ``mocapfj`` command as a user's shell runs it: a subprocess, its exit code, its stdout and
stderr. Per command one bad input (exit 2, one line on stderr, no traceback, nothing written) and,
where the work is cheap, one real run whose numbers are checked against what built the input.

Commands whose real run is expensive have it elsewhere (in process or as a subprocess); see
ELSEWHERE. `test_every_command_is_run_as_a_subprocess_here` fails when a command is added to the
CLI without a case here.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocapfj.cli import build_parser
from mocapfj.io import read_c3d, write_csv_columns, write_recording
from mocapfj.synth import toy_recording

ROOT = Path(__file__).resolve().parents[1]
PA10 = ROOT / "datasets" / "pa10_joint2.toml"


def _cli(*args, timeout=180):
    return subprocess.run([sys.executable, "-m", "mocapfj.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def _ok(r):
    assert r.returncode == 0, (r.returncode, r.stderr[-3000:])
    return r


def _bad(r, *needles, out=None):
    """Exit 2, one line on stderr naming what is wrong, nothing on stdout, --out not created."""
    assert r.returncode == 2, (r.returncode, r.stdout[-500:], r.stderr[-3000:])
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("mocapfj: error: "), r.stderr
    assert "Traceback" not in r.stderr and r.stdout == ""
    for n in needles:
        assert n in r.stderr, r.stderr
    if out is not None:
        assert not Path(out).exists()


# -- inputs made once per module (cheap: a toy bundle, a few CSVs) ------------------------------

W0, ZETA = math.sqrt(1.0794e6 / 290.39), 0.163


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    write_recording(toy_recording(duration_s=3.0), d / "toy")
    (d / "broken.toml").write_text("name = \n")                 # not TOML
    (d / "notes.csv").write_text("time,a\n0,1\n0.1,oops\n")
    # a free vibration after a stop at 0.2 s (Staubli axis 2 numbers, 4 ms)
    t = np.arange(0, 0.6, 0.004)
    y = np.where(t < 0.2, 0.0, 1e-4 + 1.5e-4 * np.exp(-ZETA * W0 * (t - 0.2))
                 * np.cos(W0 * math.sqrt(1 - ZETA ** 2) * (t - 0.2)))
    y = y + 1e-7 * np.random.default_rng(0).standard_normal(t.size)
    write_csv_columns(d / "stop.csv", {"time": t, "delta": y, "ref": 0.1 * np.clip(t - 0.1, 0, 0.3) ** 2})
    return d


def test_every_command_is_run_as_a_subprocess_here():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.choices and "inspect" in a.choices)
    here = Path(__file__).read_text()
    for name in sub.choices:
        assert f'_cli("{name}"' in here, f"mocapfj {name} has no subprocess test in {Path(__file__).name}"


def test_help_and_version():
    r = _ok(_cli("--help"))
    assert "inspect" in r.stdout and "identify" in r.stdout
    r = _cli("no-such-command")
    assert r.returncode == 2 and "invalid choice" in r.stderr


# -- recordings ------------------------------------------------------------------------------

def test_inspect(files):
    s = json.loads(_ok(_cli("inspect", files / "toy", "--json")).stdout)
    assert s["markers"]["rate_hz"] == 250.0 and s["markers"]["n_frames"] == 751 and s["joints"][0]["name"] == "j1"
    _bad(_cli("inspect", files / "missing"), "missing", "got no such path")


def test_simulate_bad_input(files, tmp_path):
    """Its real run as a subprocess: tests/test_bad_input.py (the 20 s PA-10 recording)."""
    _bad(_cli("simulate", files / "broken.toml", "--out", tmp_path / "o"), "broken.toml", out=tmp_path / "o")


def test_joints(files, tmp_path):
    from mocapfj.synth.toy import TOY_TRUTH

    s = json.loads(_ok(_cli("joints", files / "toy", "--out", tmp_path / "j", "--json")).stdout)
    (j,) = s["joints"]
    assert abs(abs(np.dot(j["axis_world"], TOY_TRUTH["axis"])) - 1) < 1e-5
    assert (tmp_path / "j" / "j1.angles.csv").is_file()
    _bad(_cli("joints", files / "broken.toml", "--out", tmp_path / "o"), "broken.toml", out=tmp_path / "o")


def test_identify_and_discover_bad_input(files, tmp_path):
    """Their real runs as subprocesses: identify in tests/test_bad_input.py (a 20 s PA-10 recording);
    discover in process in tests/discover/test_chain.py (a run takes tens of seconds)."""
    _bad(_cli("identify", files / "toy", files / "broken.toml", "--out", tmp_path / "o"), "broken.toml",
         out=tmp_path / "o")
    _bad(_cli("discover", files / "toy", "--model", tmp_path / "none.toml", "--out", tmp_path / "o"), "none.toml",
         out=tmp_path / "o")


def test_demo_bad_input(files, tmp_path):
    """Its real run is `make demo` (minutes); in process in tests/test_cli.py."""
    _bad(_cli("demo", "--out", files / "toy" / "recording.toml"), "--out")


# -- cameras ---------------------------------------------------------------------------------

def test_calibrate_camera_bad_input(tmp_path):
    """Its real run: in process in tests/vision/test_calibrate_camera_cli.py (rendered board views)."""
    from mocapfj.io.calib import write_board
    from mocapfj.types import Board

    write_board(tmp_path / "board.toml", Board("chessboard", 9, 6, square_m=0.03))
    (tmp_path / "broken.png").write_bytes(b"not an image")
    _bad(_cli("calibrate-camera", tmp_path / "broken.png", "--board", tmp_path / "board.toml", "--out", tmp_path / "o"),
         "broken.png", out=tmp_path / "o")


def test_calibrate_rig_bad_input(files, tmp_path):
    """Its real runs as subprocesses (board views, a wand wave) are in tests/vision/test_calibrate_rig_cli.py."""
    _bad(_cli("calibrate-rig", "--out", tmp_path / "o", "--wand", ROOT / "calibration" / "wands" /
              "wand_3marker_500mm.toml", "--detections", files / "notes.csv", "--intrinsics", files / "broken.toml"),
         out=tmp_path / "o")


def test_triangulate(files, tmp_path):
    """Three markers over 30 frames seen by a ring of 4 cameras, 0.1 px noise: back within a millimetre."""
    import cv2

    from mocapfj.io import write_detections
    from mocapfj.io.calib import write_rig
    from mocapfj.synth.cameras import ring_rig
    from mocapfj.types import Detections, Rig

    rng = np.random.default_rng(4)
    rig = ring_rig(4, rng=rng)
    n, m = 30, 3
    t = np.arange(n) / 100.0
    xyz = np.array([0.0, 0.0, 1.2]) + 0.1 * np.stack([np.c_[np.cos(2 * t + k), np.sin(3 * t + k), 0.5 * np.sin(t + k)]
                                                      for k in range(m)], axis=1)            # (n, m, 3)
    frame, camera, xy, pid = [], [], [], []
    for ci, c in enumerate(rig.cameras):
        uv, _ = cv2.projectPoints(xyz.reshape(-1, 3), cv2.Rodrigues(c.R_cam_world)[0], c.t_cam_world, c.K, c.dist)
        frame.append(np.repeat(np.arange(n), m))
        camera.append(np.full(n * m, ci))
        xy.append(uv.reshape(-1, 2) + 0.1 * rng.standard_normal((n * m, 2)))
        pid.append(np.tile(np.arange(m), n))
    write_rig(tmp_path / "rig.toml", Rig(rig.cameras, {"units": "m", "sigma_px": 0.1}))
    write_detections(tmp_path / "det.csv", Detections(np.concatenate(frame), np.concatenate(camera),
                                                     np.concatenate(xy), np.concatenate(pid)))
    _ok(_cli("triangulate", tmp_path / "det.csv", "--rig", tmp_path / "rig.toml", "--rate", "100", "--out",
             tmp_path / "o", "--json"))
    c3d = read_c3d(tmp_path / "o" / "markers.c3d")
    assert c3d.labels == ("P0", "P1", "P2") and c3d.n_frames == n
    assert np.sqrt(np.mean(np.sum((c3d.xyz - xyz) ** 2, axis=2))) < 1e-3
    _bad(_cli("triangulate", tmp_path / "det.csv", "--rig", files / "broken.toml", "--rate", "100", "--out",
              tmp_path / "x"), "broken.toml", out=tmp_path / "x")


# -- joint dynamics from CSV logs --------------------------------------------------------------

def test_algebraic_and_precompensate_bad_input(files, tmp_path):
    """Their real runs (omega0 and zeta against the analytic ringing, eq. 17 against the model's
    response): in process in tests/ident/test_algebraic_cli.py."""
    _bad(_cli("algebraic", files / "stop.csv", "--output", "nope", "--out", tmp_path / "o"), "column 'nope'",
         out=tmp_path / "o")
    _bad(_cli("precompensate", files / "stop.csv", "--reference", "ref", "--out", tmp_path / "o"), "--omega0",
         out=tmp_path / "o")


def test_control_check(files):
    s = json.loads(_ok(_cli("control-check", PA10, "--duration", "1.5", "--json")).stdout)
    flexible, rigid = (next(r for r in s["runs"] if r["name"] == n) for n in ("flexible", "rigid"))
    assert s["joint"] == "j2" and flexible["rms_rad"] * 5 < rigid["rms_rad"]          # Bompos et al. 2007
    _bad(_cli("control-check", PA10, "--joint", "j9"), "j9")


def test_clamped_and_frf_bad_input(files, tmp_path):
    """Their real runs (the KR500's stiffness, a closed-loop multisine's two-inertia model): in
    process in tests/ident/test_algebraic_cli.py and tests/ident/test_frf_cli.py."""
    _bad(_cli("clamped", files / "stop.csv", "--positions", "delta", "--torques", "tau1", "--out", tmp_path / "x"),
         "tau1", out=tmp_path / "x")
    _bad(_cli("frf", files / "stop.csv", "--input", "torque", "--output", "delta", "--out", tmp_path / "x"), "torque",
         out=tmp_path / "x")


def test_view_bad_input(tmp_path):
    """The recording read back and the viewer command: tests/viz/test_rrd.py (no viewer is started here)."""
    _bad(_cli("view", tmp_path / "missing", "--no-open"), "missing", "run directory", "no such directory")
    (tmp_path / "empty").mkdir()
    _bad(_cli("view", tmp_path / "empty"), "empty", "results")


def test_report(tmp_path):
    """Its real runs (a run directory's report, HTML and figures checked): tests/viz/test_report.py."""
    _bad(_cli("report", tmp_path / "missing"), "missing", "no such directory")
    (tmp_path / "empty").mkdir()
    _bad(_cli("report", tmp_path / "empty"), "empty", "none of them")


def test_run_bad_input(files, tmp_path):
    """Its real runs (every stage, resuming, a failing stage): in process in tests/pipeline/test_run.py."""
    _bad(_cli("run", files / "toy", "--out", tmp_path / "o", "--stages", "nonsense"), "--stages", "nonsense",
         out=tmp_path / "o")


def test_batch_bad_input(files, tmp_path):
    """Its real runs on a two-worker Dask cluster (and the CLI's exit 1 for a failed recording):
    tests/pipeline/test_batch.py."""
    _bad(_cli("batch", files / "toy", tmp_path / "missing", "--out", tmp_path / "o"), "missing", "RECORDING",
         out=tmp_path / "o")
