"""Board views and blob clips written for a rig (mocapfj.synth.views)."""

from __future__ import annotations

import json

import cv2
import numpy as np

from mocapfj.synth.cameras import ring_rig
from mocapfj.synth.views import DEFAULT_BOARD, write_board_views


def test_written_board_views_are_detected_where_the_truth_says(tmp_path):
    rig = ring_rig(8, rng=np.random.default_rng(0))
    truth = write_board_views(tmp_path, rig, DEFAULT_BOARD, 2, np.random.default_rng(1))
    assert len(truth["images"]) >= 2
    saved = json.loads((tmp_path / "board_truth.json").read_text())
    assert saved["board"]["type"] == "charuco" and len(saved["images"]) == len(truth["images"])
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_100)
    board = cv2.aruco.CharucoBoard((7, 5), 0.06, 0.042, d)
    item = saved["images"][0]
    grey = cv2.imread(str(tmp_path / item["file"]), cv2.IMREAD_GRAYSCALE)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(grey)
    assert ids is not None and len(ids) >= 0.8 * len(item["ids"])
    want = dict(zip(item["ids"], map(np.asarray, item["corners_px"])))
    err = [np.linalg.norm(c.ravel() - want[int(i)]) for c, i in zip(corners, ids.ravel())]
    assert np.median(err) < 0.3  # px, a small distant board with sensor noise and blur
