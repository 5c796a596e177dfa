"""The check_* validators (mocapfj.validate): clean values out, one-line InputError naming what
was expected and what came."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj import InputError
from mocapfj.validate import check_array, check_int, check_scalar, check_unit_vector, freeze


def test_check_scalar():
    assert check_scalar(3, "k", positive=True) == 3.0 and isinstance(check_scalar(np.float32(2), "k"), float)
    assert np.isnan(check_scalar(np.nan, "x", allow_nan=True))
    for bad, kw, msg in ((0.0, {"positive": True}, "k: expected a positive number, got 0.0"),
                         (-1.0, {"nonneg": True}, "k: expected a non-negative number, got -1.0"),
                         (np.inf, {}, "k: expected a finite number, got inf"),
                         (np.nan, {}, "k: expected a finite number, got nan"),
                         ("abc", {}, "k: expected a finite number, got 'abc'"),
                         (2.0, {"lo": 0.0, "hi": 1.0}, r"k: expected a finite number in \[0, 1\], got 2.0")):
        with pytest.raises(InputError, match=msg):
            check_scalar(bad, "k", **kw)
    with pytest.raises(InputError, match=r"^f.toml: gear_ratio: expected a positive number, got inf$"):
        check_scalar(float("inf"), "gear_ratio", positive=True, file="f.toml")


def test_check_int():
    assert check_int(3.0, "n") == 3 and check_int(np.int64(2), "n", lo=1) == 2
    for bad in (2.5, True, "3", np.nan):
        with pytest.raises(InputError, match="n: expected a whole number"):
            check_int(bad, "n")
    with pytest.raises(InputError, match=r"n: expected a whole number >= 1, got 0"):
        check_int(0, "n", lo=1)


def test_check_array_named_sizes_agree():
    dims = {}
    t = check_array([0, 1, 2], "t", ("T",), dims=dims)
    assert t.dtype == np.float64 and dims == {"T": 3}
    assert check_array(np.zeros((3, 5, 3)), "xyz", ("T", None, 3), dims=dims).shape == (3, 5, 3)
    with pytest.raises(InputError, match=r"xyz: expected an array of shape \(T=3, any, 3\), got shape \(4, 5, 3\)"):
        check_array(np.zeros((4, 5, 3)), "xyz", ("T", None, 3), dims=dims)
    with pytest.raises(InputError, match=r"v: expected finite values, got 1 NaN or infinite of 3"):
        check_array([1.0, np.inf, 2.0], "v", (3,), finite=True)
    with pytest.raises(InputError, match="w: expected an array of numbers"):
        check_array(["a", "b"], "w")


def test_unit_vector_and_freeze():
    assert np.allclose(check_unit_vector([0, 0, 1], "axis"), [0, 0, 1])
    with pytest.raises(InputError, match="axis: expected a unit vector, got norm 2"):
        check_unit_vector([0, 0, 2], "axis")
    a = np.arange(3.0)
    f = freeze(a)
    a[0] = 9.0
    assert f[0] == 0.0 and not f.flags.writeable
