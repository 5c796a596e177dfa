"""Results JSON and 2D detections (mocapfj.io.results), and atomic writes (mocapfj.io.atomic)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np
import pytest

from mocapfj import Detections, InputError
from mocapfj.io import atomic_path, read_detections, read_json, write_detections, write_json


@dataclass(frozen=True)
class Result:
    values: np.ndarray
    cond: float


def test_json_converts_numpy_dataclasses_and_nan(tmp_path):
    write_json(tmp_path / "r.json", {"joints": [Result(np.array([1.5, np.nan]), np.float64(12.0))], "n": np.int64(3)})
    assert json.loads((tmp_path / "r.json").read_text()) == {"joints": [{"values": [1.5, None], "cond": 12.0}], "n": 3}
    assert read_json(tmp_path / "r.json")["n"] == 3


def test_bad_json_names_the_line(tmp_path):
    (tmp_path / "b.json").write_text('{\n"a": 1,\n}\n')
    with pytest.raises(InputError, match=r"b\.json: line 3: expected valid JSON"):
        read_json(tmp_path / "b.json")


def test_detections_round_trip_and_missing_column(tmp_path):
    det = Detections(frame=np.array([0, 0, 3]), camera=np.array([1, 2, 1]), xy_px=np.array([[0.25, 1.5], [640.125, 10.0], [3.0, 4.0]]),
                     point_id=np.array([-1, 7, 0]))
    write_detections(tmp_path / "d.csv", det)
    back = read_detections(tmp_path / "d.csv")
    for k in ("frame", "camera", "xy_px", "point_id"):
        np.testing.assert_array_equal(getattr(back, k), getattr(det, k))
    (tmp_path / "e.csv").write_text("frame,cam,x_px,y_px\n0,0,1,2\n")
    with pytest.raises(InputError, match=r"e\.csv: camera: expected a column named 'camera'"):
        read_detections(tmp_path / "e.csv")


def test_atomic_path_keeps_the_old_file_when_writing_fails(tmp_path):
    target = tmp_path / "keep.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


def test_atomic_files_have_ordinary_permissions(tmp_path):
    write_json(tmp_path / "p.json", {})
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "p.json").stat().st_mode & 0o777 == 0o666 & ~umask
