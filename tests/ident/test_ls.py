"""Least squares with statistics (mocapfj.ident.ls; Jubien, Abba and Gautier (2014), eq. 15-17)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj import InputError
from mocapfj.ident.ls import cv_pct, ls_fit


def test_reported_std_matches_the_monte_carlo_scatter():
    rng = np.random.default_rng(1)
    W = np.column_stack([rng.normal(size=400), np.sin(np.linspace(0, 20, 400)), np.ones(400)])
    x = np.array([2.0, -0.5, 10.0])
    ys = [W @ x + rng.normal(0, 0.3, 400) for _ in range(2000)]
    fits = [ls_fit(W, y, ["a", "b", "c"]) for y in ys]
    values = np.array([f.values for f in fits])
    np.testing.assert_allclose(values.mean(0), x, atol=4 * 0.3 / np.sqrt(400 * 2000) * 10)
    np.testing.assert_allclose(values.std(0, ddof=1), np.mean([f.std for f in fits], 0), rtol=0.05)
    f = fits[0]
    np.testing.assert_allclose(f.rel_std_pct, 100 * f.std / np.abs(f.values))
    res = ys[0] - W @ f.values
    assert f.cond == pytest.approx(np.linalg.cond(W))
    assert f.r2 == pytest.approx(1 - res @ res / np.sum((ys[0] - ys[0].mean()) ** 2), rel=1e-12)
    assert f.residual_rms == pytest.approx(np.sqrt(np.mean(res**2)), rel=1e-12)
    assert f["c"] == f.values[2]
    cv = cv_pct(fits[:10])
    assert cv.shape == (3,) and (cv > 0).all()


def test_weighted_and_nan_rows():
    rng = np.random.default_rng(2)
    W = rng.normal(size=(300, 2))
    sd = np.where(np.arange(300) < 150, 0.1, 1.0)
    y = W @ [1.0, 2.0] + rng.normal(0, sd)
    y[5] = np.nan
    f = ls_fit(W, y, ["a", "b"], weights=1 / sd**2)
    assert f.n_samples == 299
    np.testing.assert_allclose(f.values, [1.0, 2.0], atol=5 * f.std.max())


def test_unexcited_parameters_are_named():
    W = np.column_stack([np.ones(50), np.arange(50.0), np.zeros(50)])
    with pytest.raises(InputError, match=r"no independent excitation of \['fc'\]"):
        ls_fit(W, np.arange(50.0), ["offset", "fv", "fc"])
    with pytest.raises(InputError, match=r"more rows \(2\) than parameters \(3\)"):
        ls_fit(np.ones((2, 3)), np.ones(2), ["a", "b", "c"])
