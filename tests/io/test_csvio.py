"""Numeric CSV tables (mocapfj.io.csvio)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from mocapfj import InputError
from mocapfj.io import read_csv_columns, write_csv_columns

finite_or_nan = st.floats(allow_infinity=False, allow_nan=True, width=64)


@settings(max_examples=50, deadline=None)
@given(data=arrays(np.float64, st.tuples(st.integers(0, 30), st.integers(1, 5)), elements=finite_or_nan))
def test_round_trip_is_bit_identical(tmp_path_factory, data):
    cols = {f"c{i}": data[:, i] for i in range(data.shape[1])}
    p = tmp_path_factory.mktemp("csv") / "t.csv"
    write_csv_columns(p, cols)
    back = read_csv_columns(p)
    assert list(back) == list(cols)
    for k in cols:
        np.testing.assert_array_equal(back[k], cols[k])  # NaN == NaN here


def test_integer_columns_print_as_integers(tmp_path):
    write_csv_columns(tmp_path / "i.csv", {"frame": np.array([0, 1, 2]), "x": np.array([0.1, 0.25, 1.0])})
    assert (tmp_path / "i.csv").read_text().splitlines() == ["frame,x", "0,0.1", "1,0.25", "2,1.0"]


def test_bad_cell_is_named(tmp_path):
    p = tmp_path / "b.csv"
    p.write_text("time,x\n0,1\n0.1,oops\n")
    with pytest.raises(InputError, match=r"b\.csv: row 3 column 'x': expected a number, got 4 characters of text"):
        read_csv_columns(p)


def test_ragged_row_is_named(tmp_path):
    p = tmp_path / "r.csv"
    p.write_text("time,x\n0,1\n0.1,,3\n")
    with pytest.raises(InputError, match=r"r\.csv: row 3: expected 2 comma-separated values, got 3"):
        read_csv_columns(p)


def test_duplicate_header(tmp_path):
    p = tmp_path / "d.csv"
    p.write_text("time,x,x\n0,1,2\n")
    with pytest.raises(InputError, match=r"d\.csv: header: expected unique column names, got duplicates \['x'\]"):
        read_csv_columns(p)


def test_unequal_columns_refused_before_writing(tmp_path):
    with pytest.raises(InputError, match="columns of equal length"):
        write_csv_columns(tmp_path / "u.csv", {"a": [1.0, 2.0], "b": [1.0]})
    assert not (tmp_path / "u.csv").exists()
