"""TRC reading and writing (mocapfj.io.trc)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocapfj import InputError, MarkerTrajectories
from mocapfj.io import read_c3d, read_trc, write_trc

HEADER = (
    "PathFileType\t4\t(X/Y/Z)\tx.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
    "100\t100\t3\t2\t{units}\t100\t1\t3\n"
    "Frame#\tTime\tA\t\t\tB\t\t\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
    "\n"
)


def test_hand_written_trc_in_mm_with_a_gap(tmp_path):
    p = tmp_path / "x.trc"
    p.write_text(HEADER.format(units="mm") + "1\t0.00\t1\t2\t3\t4\t5\t6\n2\t0.01\t\t\t\t7\t8\t9\n3\t0.02\t10\t11\t12\n")
    m = read_trc(p)
    assert m.labels == ("A", "B") and m.rate_hz == 100.0
    np.testing.assert_allclose(m.t, [0.0, 0.01, 0.02])
    np.testing.assert_allclose(m.xyz[0], [[1e-3, 2e-3, 3e-3], [4e-3, 5e-3, 6e-3]])
    assert np.isnan(m.xyz[1, 0]).all() and np.isnan(m.xyz[2, 1]).all()  # empty and absent trailing cells
    np.testing.assert_allclose(m.xyz[1, 1], [7e-3, 8e-3, 9e-3])


@settings(max_examples=25, deadline=None)
@given(n_frames=st.integers(1, 20), n_markers=st.integers(1, 8), seed=st.integers(0, 2**16),
       units=st.sampled_from(["mm", "m"]))
def test_trc_round_trip_property(tmp_path_factory, n_frames, n_markers, seed, units):
    rng = np.random.default_rng(seed)
    xyz = rng.normal(0, 1.0, (n_frames, n_markers, 3))
    xyz[rng.random((n_frames, n_markers)) < 0.2] = np.nan
    m = MarkerTrajectories(t=np.arange(n_frames) / 120.0, xyz=xyz, labels=tuple(f"K{i}" for i in range(n_markers)), rate_hz=120.0)
    p = tmp_path_factory.mktemp("trc") / "r.trc"
    write_trc(p, m, units=units)
    back = read_trc(p)
    assert back.labels == m.labels and back.rate_hz == 120.0
    np.testing.assert_array_equal(back.t, m.t)
    if units == "m":
        np.testing.assert_array_equal(back.xyz, m.xyz)
    else:
        np.testing.assert_allclose(back.xyz, m.xyz, rtol=1e-15, atol=1e-18, equal_nan=True)


def test_real_c3d_through_trc_is_unchanged(realdata, tmp_path):
    m = read_c3d(realdata / "c3d_samples" / "kinematics_racing_propulsion.c3d")
    write_trc(tmp_path / "p.trc", m, units="m")
    back = read_trc(tmp_path / "p.trc")
    np.testing.assert_array_equal(back.xyz, m.xyz)
    assert back.labels == m.labels


def test_missing_units(tmp_path):
    p = tmp_path / "nounits.trc"
    p.write_text(HEADER.format(units="") + "1\t0.0\t1\t2\t3\t4\t5\t6\n")
    with pytest.raises(InputError, match=r"nounits\.trc: Units: expected a length unit.*got nothing"):
        read_trc(p)


def test_non_monotonic_time(tmp_path):
    p = tmp_path / "t.trc"
    p.write_text(HEADER.format(units="mm") + "1\t0.00\t1\t2\t3\t4\t5\t6\n2\t0.02\t1\t2\t3\t4\t5\t6\n3\t0.01\t1\t2\t3\t4\t5\t6\n")
    with pytest.raises(InputError, match=r"t\.trc: Time: expected strictly increasing times, got 0\.01 after 0\.02"):
        read_trc(p)


def test_not_a_number(tmp_path):
    p = tmp_path / "n.trc"
    p.write_text(HEADER.format(units="mm") + "1\t0.00\t1\tabc\t3\t4\t5\t6\n")
    with pytest.raises(InputError, match=r"n\.trc: row 6 column 4: expected a number, got 3 characters of text"):
        read_trc(p)
