"""``mocapfj calibrate-rig`` through the command line (subprocess): board views, a wand wave, bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocapfj.io import read_rig, write_detections, write_rig
from mocapfj.io.calib import read_wand
from mocapfj.synth.cameras import ring_rig
from mocapfj.synth.wand import lframe_detections, wand_wave
from mocapfj.types import Camera, Detections, Rig

ROOT = Path(__file__).resolve().parents[2]
WAND_FILE = ROOT / "calibration" / "wands" / "wand_3marker_500mm.toml"


def run(*args, capsys=None):
    """calibrate-rig as a subprocess, or in this process when `capsys` is given (no interpreter and
    import start-up per call)."""
    if capsys is None:
        return subprocess.run([sys.executable, "-m", "mocapfj.cli", "calibrate-rig", *map(str, args)],
                              capture_output=True, text=True, cwd=ROOT)
    from types import SimpleNamespace

    from mocapfj.cli import main

    code = main(["calibrate-rig", *map(str, args)])
    out, err = capsys.readouterr()
    return SimpleNamespace(returncode=code, stdout=out, stderr=err)


@pytest.fixture(scope="module")
def wand_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("wand")
    rng = np.random.default_rng(77)
    rig = ring_rig(4, rng=rng)
    wand = read_wand(WAND_FILE)
    write_detections(d / "blobs.csv", wand_wave(rig, wand, 300, rng, noise_px=0.2).detections)
    write_detections(d / "lframe.csv", lframe_detections(rig, wand, 5, rng, noise_px=0.2))
    write_rig(d / "intrinsics.toml", Rig(tuple(Camera(c.name, c.size, c.K, c.dist, np.eye(3), np.zeros(3))
                                               for c in rig.cameras)))
    return d, rig


def test_wand_wave_to_rig_file_and_json(wand_files, tmp_path, capsys):
    d, rig = wand_files
    out = tmp_path / "out"
    r = run("--wand", WAND_FILE, "--detections", d / "blobs.csv", "--lframe", d / "lframe.csv",
            "--intrinsics", d / "intrinsics.toml", "--out", out, "--json", capsys=capsys)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["method"] == "wand" and s["world"] == "lframe" and s["wand_length_sd_mm"] < 0.8
    assert abs(s["wand_length_mean_mm"] - 500.0) < 0.2
    assert [c["name"] for c in s["cameras"]] == [f"cam_{i}" for i in range(4)]
    for c in s["cameras"]:
        assert c["rms_px"] < 0.3 and c["rms_mm"] < 1.5 and set(c["std"]) >= {"rx", "tx"} or c["name"] == "cam_0"
        assert len(c["position_std_m"]) == 3 and len(c["rotation_std_deg"]) == 3
    back = read_rig(out / "rig.toml")
    for a, b in zip(rig.cameras, back.cameras):
        assert np.linalg.norm(a.R_cam_world.T @ a.t_cam_world - b.R_cam_world.T @ b.t_cam_world) < 0.01
    full = json.loads((out / "calibrate_rig.json").read_text())
    P = np.array(full["covariance"])
    assert P.shape == (len(full["parameter_names"]),) * 2 and np.allclose(P, P.T)


def test_board_videos_of_caliscopes_four_webcams(realdata, tmp_path, capsys):
    """caliscope's four webcams (its mp4 files, every 4th frame; the inverted 4 x 5 ChArUco) with
    caliscope's intrinsics as the intrinsics source: every camera centre, in camera 0's frame,
    within 2 cm of caliscope's post-optimisation rig (D. Prible, github.com/mprib/caliscope, BSD-2).
    All 57 frames give 0.31, 0.59 and 0.78 cm (docs/calibration.md)."""
    import tomllib

    root = realdata / "caliscope" / "post_optimization"
    ref = tomllib.loads((root / "camera_array.toml").read_text())["cameras"]
    write_rig(tmp_path / "intrinsics.toml", Rig(tuple(
        Camera(f"cam_{c}", (1280, 720), np.array(ref[str(c)]["matrix"]), np.array(ref[str(c)]["distortions"]),
               np.eye(3), np.zeros(3)) for c in range(4))))
    videos = [root / "calibration" / "extrinsic" / f"cam_{c}.mp4" for c in range(4)]
    args = ["--board", ROOT / "calibration" / "boards" / "charuco_4x5_caliscope.toml"]
    for v in videos:
        args += ["--camera", v]
    r = run(*args, "--intrinsics", tmp_path / "intrinsics.toml", "--refine-intrinsics", "fixed", "--every", "4",
            "--out", tmp_path / "rig", "--json", capsys=capsys)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert s["method"] == "board" and s["refined_intrinsics"] == [] and s["rms_px"] < 1.0

    def centres_in_cam0(R, t):
        return np.array([R[0] @ (-Rc.T @ tc) + t[0] for Rc, tc in zip(R, t)])

    rig = read_rig(tmp_path / "rig" / "rig.toml")
    ours = centres_in_cam0([c.R_cam_world for c in rig.cameras], [c.t_cam_world for c in rig.cameras])
    theirs = centres_in_cam0([np.array(ref[str(c)]["rotation"]) for c in range(4)],
                             [np.array(ref[str(c)]["translation"]) for c in range(4)])
    assert np.linalg.norm(ours - theirs, axis=1).max() < 0.02
    assert (tmp_path / "rig" / "detections.csv").is_file()


def test_bad_input_exits_2_with_one_line_and_writes_nothing(wand_files, tmp_path, capsys):
    """The first case as a subprocess (the exit code a shell sees), the others in this process."""
    d, _ = wand_files
    text = (d / "blobs.csv").read_text().splitlines()
    head, first = text[0], text[1].split(",")
    cols = head.split(",")
    first[cols.index("x_px")] = "nan"
    (tmp_path / "nan.csv").write_text("\n".join([head, ",".join(first)] + text[2:]) + "\n")
    many = [head] + [line for line in text[1:]] + [",".join(["0", "9", "100.0", "100.0"] + ([] if len(cols) == 4 else ["-1"]))]
    (tmp_path / "nine.csv").write_text("\n".join(many) + "\n")
    cases = [
        (("--wand", WAND_FILE, "--detections", tmp_path / "nan.csv", "--intrinsics", d / "intrinsics.toml"),
         r"nan\.csv: row 0 \(frame 0, camera \d\) x_px/y_px: expected finite pixel coordinates"),
        (("--wand", WAND_FILE, "--detections", tmp_path / "nine.csv", "--intrinsics", d / "intrinsics.toml"),
         r"nine\.csv: camera: expected camera numbers below 4 \(the rig has 4 cameras\), got camera 9"),
        (("--wand", WAND_FILE, "--board", ROOT / "calibration" / "boards" / "chessboard_9x6_30mm.toml"),
         r"--board/--wand: expected exactly one of --board"),
    ]
    for i, (args, pattern) in enumerate(cases):
        out = tmp_path / "never"
        r = run(*args, "--out", out, capsys=capsys if i else None)
        assert r.returncode == 2, (args, r.stderr)
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("mocapfj: error: "), r.stderr
        import re

        assert re.search(pattern, lines[0]), lines[0]
        assert not out.exists()


def test_one_board_view_per_camera_is_refused(realdata, tmp_path, capsys):
    images = realdata / "bouguet_stereo" / "images"
    r = run("--board", ROOT / "calibration" / "boards" / "chessboard_9x6_30mm.toml", "--camera", images / "left01.jpg",
            "--camera", images / "right01.jpg", "--out", tmp_path / "one", capsys=capsys)
    assert r.returncode == 2
    assert "camera 0 (cam_0): expected at least 3 board views to estimate its intrinsics, got 1 view" in r.stderr
    assert not (tmp_path / "one").exists()
