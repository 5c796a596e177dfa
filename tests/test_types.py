"""Shape checks of the shared data types (mocapfj.types)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj import Camera, ControllerLog, InputError, MarkerTrajectories


def test_marker_shapes_are_checked_and_arrays_frozen():
    m = MarkerTrajectories(t=np.arange(3) / 10, xyz=np.zeros((3, 2, 3)), labels=("a", "b"), rate_hz=10)
    assert not m.xyz.flags.writeable
    assert m.select(["b"]).shape == (3, 1, 3)
    with pytest.raises(InputError, match=r"xyz: expected shape \(T=3, M=3, 3\), got shape \(3, 2, 3\)"):
        MarkerTrajectories(t=np.arange(3), xyz=np.zeros((3, 2, 3)), labels=("a", "b", "c"), rate_hz=10)
    with pytest.raises(InputError, match=r"labels: expected unique marker labels, got duplicates \['a'\]"):
        MarkerTrajectories(t=np.arange(3), xyz=np.zeros((3, 2, 3)), labels=("a", "a"), rate_hz=10)
    with pytest.raises(InputError, match=r"marker label: expected one of \['a', 'b'\], got 'z'"):
        m.index("z")


def test_controller_shapes():
    with pytest.raises(InputError, match=r"tau: expected shape \(4, 1\), got shape \(4,\)"):
        ControllerLog(t=np.arange(4.0), q_m=np.zeros((4, 1)), tau=np.zeros(4), joint_names=("j",))


def test_camera_shapes():
    with pytest.raises(InputError, match=r"camera 'c' K: expected shape \(3, 3\), got shape \(2, 2\)"):
        Camera("c", (10, 10), np.eye(2), np.zeros(5), np.eye(3), np.zeros(3))
