"""``mocapfj calibrate-camera``: rendered board images in, the camera, its summary and figure out;
bad input exits 2 with one line and writes nothing."""

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapfj.cli import main
from mocapfj.io.calib import read_rig, write_board
from mocapfj.synth.images import render_board_view
from mocapfj.types import Board, Camera
from mocapfj.vision.boards import board_points

BOARD = Board("chessboard", 9, 6, square_m=0.03)
K = np.array([[540.0, 0.0, 321.7], [0.0, 541.0, 237.2], [0.0, 0.0, 1.0]])
DIST = np.array([-0.2, 0.05, 0.0005, -0.0003, 0.0])
CAM = Camera("c", (640, 480), K, DIST, np.eye(3), np.zeros(3))


def _render(path, tilt_deg, n, seed):
    rng = np.random.default_rng(seed)
    _, p = board_points(BOARD)
    files = []
    while len(files) < n:
        rv = rng.normal(0, 1, 3)
        R = Rotation.from_rotvec(rv / np.linalg.norm(rv) * np.radians(rng.uniform(*tilt_deg))).as_matrix()
        z = rng.uniform(0.34, 0.45)
        c = np.array([rng.uniform(-0.12, 0.12) * z, rng.uniform(-0.1, 0.1) * z, z])
        v = render_board_view(CAM, BOARD, R, c - R @ p.mean(0), supersample=3, blur_sigma_px=0.8, noise_sd=2.0, rng=rng)
        if v.in_view.all():
            files.append(path / f"view{len(files):02d}.png")
            cv2.imwrite(str(files[-1]), v.image)
    return files


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("cc")
    (root / "tilted").mkdir()
    (root / "parallel").mkdir()
    write_board(root / "board.toml", BOARD)
    write_board(root / "wrong.toml", Board("chessboard", 8, 6, square_m=0.03))
    cv2.imwrite(str(root / "blank.png"), np.full((480, 640), 120, np.uint8))
    (root / "broken.png").write_bytes(b"not an image")
    return {"root": root, "tilted": _render(root / "tilted", (15, 40), 7, 1),
            "parallel": _render(root / "parallel", (0.0, 0.4), 4, 2)}


def test_calibrates_and_writes_the_camera(data, tmp_path, capsys):
    root = data["root"]
    out = tmp_path / "out"
    code = main(["calibrate-camera", *map(str, data["tilted"]), str(root / "blank.png"), "--board",
                 str(root / "board.toml"), "--out", str(out), "--json"])
    stdout, stderr = capsys.readouterr()
    assert code == 0, stderr
    s = json.loads(stdout)
    for key in ("fx", "fy", "cx", "cy", "dist", "rms_px", "n_views_used", "n_views", "std", "views"):
        assert key in s
    assert s["n_views"] == 8 and s["n_views_used"] == 7 and len(s["dist"]) == 5
    assert s["views"][-1]["status"] == "no board" and "blank.png" in " ".join(s["warnings"])
    for name, truth in (("fx", K[0, 0]), ("fy", K[1, 1]), ("cx", K[0, 2]), ("cy", K[1, 2])):
        assert abs(s[name] - truth) < 4 * s["std"][name] + 1e-9, name
    cam = read_rig(out / "camera.toml").cameras[0]
    np.testing.assert_allclose(cam.K, [[s["fx"], 0, s["cx"]], [0, s["fy"], s["cy"]], [0, 0, 1]])
    assert cam.size == (640, 480) and np.isfinite(cam.dist).all()
    figure = cv2.imread(str(out / "coverage.png"))
    assert figure is not None and figure.shape[1] > 1000
    full = json.loads((out / "intrinsics.json").read_text())
    assert len(full["covariance"]) == 9 and len(full["poses"]) == 7
    assert len(json.loads((out / "detections.json").read_text())["views"]) == 8


def test_bad_input_exits_2_as_a_subprocess(data, tmp_path):
    root = data["root"]
    r = subprocess.run([sys.executable, "-m", "mocapfj.cli", "calibrate-camera", str(root / "broken.png"),
                        str(data["tilted"][0]), "--board", str(root / "board.toml"), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and "broken.png" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("case, expect", [
    ("blank", "at least 3 views"),
    ("one", "at least 3 views"),
    ("parallel", "focal length"),
    ("wrong", "9 x 6"),
    ("missing", "no such file"),
])
def test_bad_input_is_one_line_and_nothing_written(data, tmp_path, capsys, case, expect):
    root = data["root"]
    board = root / ("wrong.toml" if case == "wrong" else "board.toml")
    images = {"blank": [root / "blank.png"] * 3, "one": data["tilted"][:1], "parallel": data["parallel"],
              "wrong": data["tilted"][:4], "missing": [root / "nothere.png"]}[case]
    out = tmp_path / "o"
    code = main(["calibrate-camera", *map(str, images), "--board", str(board), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and expect in err and err.count("\n") == 1, err
    assert not out.exists()
    if case == "parallel":
        assert "view00.png" in err
