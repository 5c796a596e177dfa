"""Rig and board TOML (mocapfj.io.calib)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mocapfj import Board, Camera, InputError, Rig
from mocapfj.io import read_board, read_rig, write_board, write_rig

ANIPOSE = """
[cam_0]
name = "A"
size = [1280, 1024]
matrix = [[1000.0, 0.0, 640.0], [0.0, 1000.0, 512.0], [0.0, 0.0, 1.0]]
distortions = [-0.1, 0.01, 0.0, 0.0, 0.0]
rotation = [0.1, -0.2, 0.3]
translation = [100.0, -50.0, 2000.0]

[cam_10]
name = "K"
size = [1280, 1024]
matrix = [[1000.0, 0.0, 640.0], [0.0, 1000.0, 512.0], [0.0, 0.0, 1.0]]
distortions = [0.0, 0.0, 0.0, 0.0, 0.0]
rotation = [0.0, 0.0, 0.0]
translation = [0.0, 0.0, 1500.0]

[cam_2]
name = "C"
size = [640, 480]
matrix = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
distortions = [0.0, 0.0, 0.0, 0.0, 0.0]
rotation = [0.0, 1.0, 0.0]
translation = [0.0, 0.0, 1000.0]

[metadata]
adjusted = true
"""


def test_anipose_file_needs_units_then_reads_in_metres_ordered_by_number(tmp_path):
    p = tmp_path / "calibration.toml"
    p.write_text(ANIPOSE)
    with pytest.raises(InputError, match=r"calibration\.toml: metadata\.units: expected the unit of the camera translations.*"
                                         r"add \[metadata\] units = \"mm\""):
        read_rig(p)
    rig = read_rig(p, units="mm")
    assert [c.name for c in rig.cameras] == ["A", "C", "K"]  # cam_2 before cam_10
    np.testing.assert_allclose(rig.cameras[0].t_cam_world, [0.1, -0.05, 2.0])
    np.testing.assert_allclose(rig.cameras[0].R_cam_world, Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix())
    assert rig.metadata["adjusted"] is True


@settings(max_examples=20, deadline=None)
@given(n=st.integers(1, 8), seed=st.integers(0, 2**16))
def test_rig_round_trip(tmp_path_factory, n, seed):
    rng = np.random.default_rng(seed)
    cams = tuple(Camera(f"cam{i}", (1280, 1024), np.array([[rng.uniform(500, 2000), 0, 640], [0, rng.uniform(500, 2000), 512], [0, 0, 1]]),
                        rng.normal(0, 0.05, 5), Rotation.from_rotvec(rng.normal(0, 1, 3)).as_matrix(), rng.normal(0, 2, 3))
                 for i in range(n))
    p = tmp_path_factory.mktemp("rig") / "rig.toml"
    write_rig(p, Rig(cams, {"rms_px": 0.21}))
    back = read_rig(p)
    assert back.metadata == {"rms_px": 0.21, "units": "m"}
    for a, b in zip(cams, back.cameras):
        assert a.name == b.name and a.size == b.size
        np.testing.assert_array_equal(a.K, b.K)
        np.testing.assert_array_equal(a.dist, b.dist)
        np.testing.assert_array_equal(a.t_cam_world, b.t_cam_world)
        np.testing.assert_allclose(a.R_cam_world, b.R_cam_world, atol=1e-14)


def test_bad_matrix_shape(tmp_path):
    p = tmp_path / "r.toml"
    p.write_text(ANIPOSE.replace("matrix = [[1000.0, 0.0, 640.0], [0.0, 1000.0, 512.0], [0.0, 0.0, 1.0]]\ndistortions = [-0.1",
                                 "matrix = [[1000.0, 0.0, 640.0], [0.0, 1000.0, 512.0]]\ndistortions = [-0.1"))
    with pytest.raises(InputError, match=r"r\.toml: cam_0\.matrix: expected numbers in shape \(3, 3\), got shape \(2, 3\)"):
        read_rig(p, units="mm")


@pytest.mark.parametrize("board", [
    Board("chessboard", 9, 6, square_m=0.03),
    Board("charuco", 4, 5, square_m=0.054, marker_m=0.0405, dictionary="DICT_4X4_1000", inverted=True),
    Board("aprilgrid", 6, 6, tag_m=0.088, spacing_m=0.0264, family="tag36h11"),
])
def test_board_round_trip(tmp_path, board):
    write_board(tmp_path / "b.toml", board)
    back = read_board(tmp_path / "b.toml")
    assert vars(back) == vars(board)


def test_board_missing_required_key(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text('[board]\ntype = "charuco"\ncolumns = 4\nrows = 5\nsquare_m = 0.05\ndictionary = "DICT_4X4_50"\n')
    with pytest.raises(InputError, match=r"c\.toml: board\.marker_m: expected a value \(required for a charuco\), got nothing"):
        read_board(p)


def test_board_unknown_type(tmp_path):
    p = tmp_path / "t.toml"
    p.write_text('[board]\ntype = "circles"\ncolumns = 4\nrows = 5\n')
    with pytest.raises(InputError, match=r"t\.toml: board\.type: expected one of \['chessboard', 'charuco', 'aprilgrid'\], got 'circles'"):
        read_board(p)


def test_shipped_boards_load():
    from pathlib import Path

    boards = sorted((Path(__file__).resolve().parents[2] / "calibration" / "boards").glob("*.toml"))
    assert len(boards) >= 3
    for b in boards:
        read_board(b)


def test_newer_board_and_rig_versions_are_refused(tmp_path):
    (tmp_path / "b.toml").write_text('format = "mocapfj.board/2"\n[board]\ntype = "chessboard"\ncolumns = 9\nrows = 6\nsquare_m = 0.03\n')
    with pytest.raises(InputError, match=r"b\.toml: format: expected version 1 or older, got version 2"):
        read_board(tmp_path / "b.toml")
    (tmp_path / "r.toml").write_text('format = "mocapfj.rig/3"\n' + ANIPOSE)
    with pytest.raises(InputError, match=r"r\.toml: format: expected version 1 or older, got version 3"):
        read_rig(tmp_path / "r.toml", units="mm")
