"""Angles with the geometry estimated from the same trial (issue acceptance; methods.md:
20 deg range: GL 0.189 deg, bias-compensated 0.131, ML 0.130 against a 0.128 deg bound)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj.joints import fit_gamage_lasenby, fit_halvorsen, fit_hinge_ml, joint_angles
from mocapfj.rotations import matrix_from_axis_angle as rotate

SIGMA = 0.5e-3
RADII = np.array([0.08, 0.10, 0.12, 0.14])


def trial(rng, range_deg, n=200):
    axis = np.array([0.0, 0.0, 1.0])
    phase = np.radians([0.0, 12.0, 27.0, 40.0])
    a = np.column_stack([RADII * np.cos(phase), RADII * np.sin(phase), [0.02, -0.01, 0.015, -0.02]])
    q = np.radians(range_deg) * rng.random(n) - np.radians(range_deg) / 2
    c = np.array([0.3, -0.1, 0.9])
    v = c + np.einsum("tij,pj->tpi", rotate(axis, q), a) + rng.normal(0, SIGMA, (n, 4, 3))
    return v, q


def angle_rms(fit, range_deg, trials=60, seed=0):
    rng = np.random.default_rng(seed)
    errs = []
    for _ in range(trials):
        v, q = trial(rng, range_deg)
        g = fit(v)
        est = joint_angles(v, g, outlier_sigma=np.inf).q
        e = est * np.sign(g.axis[2]) - q
        errs.append(e - e.mean())  # the angle's zero is the fit's gauge
    return float(np.sqrt(np.mean(np.concatenate(errs) ** 2)))


CRLB = SIGMA / np.sqrt(np.sum(RADII**2))


def ml(v):
    return fit_hinge_ml(v, init=fit_halvorsen(v))[0]


@pytest.mark.parametrize("range_deg", [20, 45])
def test_ml_geometry_gives_angles_within_5_percent_of_the_bound(range_deg):
    rms = angle_rms(ml, range_deg)
    assert rms <= 1.05 * CRLB, (np.degrees(rms), np.degrees(CRLB))


def test_bias_compensated_geometry_is_close_and_plain_algebraic_is_not():
    hal = angle_rms(fit_halvorsen, 20)
    gl = angle_rms(fit_gamage_lasenby, 20)
    assert hal <= 1.08 * CRLB
    assert gl > 1.2 * CRLB  # the biased centre leaves an angle-dependent error (methods.md: 0.189 vs 0.128 deg)
