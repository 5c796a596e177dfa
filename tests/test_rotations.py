"""The one rotation helper (mocapfj.rotations) against scipy's Rotation and analytic cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapfj import InputError
from mocapfj.rotations import (matrix_from_axis_angle, matrix_from_rotvec, rotate, rotvec_from_matrix, skew,
                               twist_angle)


def test_matrices_match_scipy_and_broadcast():
    rng = np.random.default_rng(1)
    axes = rng.normal(size=(40, 3))
    q = rng.uniform(-4, 4, 40)
    unit = axes / np.linalg.norm(axes, axis=1)[:, None]
    expect = Rotation.from_rotvec(unit * q[:, None]).as_matrix()
    assert np.abs(matrix_from_axis_angle(axes, q) - expect).max() < 1e-14
    assert matrix_from_axis_angle(unit[0], 0.3).shape == (3, 3) and matrix_from_axis_angle(unit[0], q).shape == (40, 3, 3)
    assert np.abs(matrix_from_rotvec(unit * q[:, None]) - expect).max() < 1e-14
    back = rotvec_from_matrix(expect)
    assert np.abs(matrix_from_rotvec(back) - expect).max() < 1e-13
    assert np.allclose(skew([1.0, 2.0, 3.0]) @ [4.0, 5.0, 6.0], np.cross([1, 2, 3], [4, 5, 6]))
    with pytest.raises(InputError, match="axis: expected a non-zero direction"):
        matrix_from_axis_angle([0, 0, 0], 1.0)


def test_rotate_vectors_equals_matrix_product():
    rng = np.random.default_rng(2)
    n = rng.normal(size=3)
    q = rng.uniform(-3, 3, 25)
    a = rng.normal(size=(4, 3))
    R = matrix_from_axis_angle(n, q)
    assert np.abs(rotate(n, q[:, None], a[None]) - np.einsum("tij,pj->tpi", R, a)).max() < 1e-14
    # a quarter turn about z takes x to y (right hand)
    assert np.allclose(rotate([0, 0, 1], np.pi / 2, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0])


def test_twist_angle_recovers_the_rotation_about_the_axis():
    rng = np.random.default_rng(3)
    n = np.array([0.3, -0.2, 0.93])
    n /= np.linalg.norm(n)
    q = np.linspace(-2.5 * np.pi, 2.5 * np.pi, 400)              # beyond one turn: unwrapped
    R = matrix_from_axis_angle(n, q)
    assert np.abs(twist_angle(R, n) - (q - q[0] + np.angle(np.exp(1j * q[0])))).max() < 1e-9
    # a swing about a perpendicular axis leaves the twist unchanged
    perp = np.cross(n, rng.normal(size=3))
    swing = matrix_from_axis_angle(perp, 0.2)
    assert np.abs(twist_angle(swing @ R[:50], n) - twist_angle(R[:50], n)).max() < 1e-9
    R_nan = R.copy()
    R_nan[3] = np.nan
    assert np.isnan(twist_angle(R_nan, n)[3]) and np.isfinite(twist_angle(R_nan, n)[4])
