"""Model elements to and from tables (mocapfj.dynamics.spec)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj import InputError
from mocapfj.dynamics import (AsymmetricCoulombViscous, AsymmetricStribeck, Backlash, BoucWen, CoulombViscous, CubicSpring,
                              Dahl, ExtendedStribeck, LinearSpring, MaxwellSlip, PiecewiseSpring, PositionDependent,
                              Stribeck, element_from_table, element_to_table)

ELEMENTS = [
    CoulombViscous(9.28, 18.38),
    AsymmetricCoulombViscous(9.0, 18.0, 10.0, 19.0),
    Stribeck(fc=9.0, fs=12.0, vs=0.05, fv=18.0),
    AsymmetricStribeck(9.0, 12.0, 0.05, 18.0, 10.0, 13.0, 0.04, 19.0),
    ExtendedStribeck(f=(1.0, 2.0, 3.0, 0.1, 0.5, 1.5)),
    PositionDependent(CoulombViscous(9.0, 18.0), orders=(1.0, 2.0), amplitudes=(0.5, 0.2), phases=(0.0, 1.0)),
    LinearSpring(1.19e4, 1e-4),
    CubicSpring(1.0e4, 2.0e9),
    PiecewiseSpring(k1=5e3, k2=1e4, k3=1.5e4, tau1=20.0, tau2=60.0),
    Backlash(1e-3, LinearSpring(1e4)),
    BoucWen(k=1.2e4, alpha=0.8, beta=0.5, gamma=0.5),
    Dahl(sigma=1e5, fc=5.0, k0=1e4),
    MaxwellSlip(k=(2e3, 3e3), f=(1.0, 3.0), k0=1e4),
]


@pytest.mark.parametrize("element", ELEMENTS, ids=lambda e: type(e).__name__)
def test_round_trip_gives_the_same_element(element):
    table = element_to_table(element)
    back = element_from_table(table)
    assert type(back) is type(element) and element_to_table(back) == table
    x = np.linspace(-2e-3, 2e-3, 7)
    if hasattr(element, "torque") and hasattr(element, "n_states") and element.n_states == 0:
        np.testing.assert_array_equal(back.torque(x), element.torque(x))


def test_unknown_model_and_key_are_named():
    with pytest.raises(InputError, match=r"s\.toml: joints\[j2\]\.spring\.model: expected one of \[.*'linear'.*\], got 'lineer'"):
        element_from_table({"model": "lineer", "k": 1.0}, source="s.toml", where="joints[j2].spring")
    with pytest.raises(InputError, match=r"joints\[j2\]\.friction: expected parameters of coulomb_viscous: \['c', 'v', 'smoothing'\], got unknown \['mu'\]"):
        element_from_table({"model": "coulomb_viscous", "c": 1.0, "v": 1.0, "mu": 2}, where="joints[j2].friction")
