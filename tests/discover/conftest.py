"""Recordings several discovery test modules share, simulated once per test process."""

from __future__ import annotations

import pytest

import mocapfj
from mocapfj.dynamics import CoulombViscous, JointModel, LinearSpring
from mocapfj.synth.hinge import simulate_hinge, small_grid


def nominal_of(case) -> JointModel:
    """The hinge case's true joint model with a linear spring and its own friction law."""
    return JointModel(name="j1", gear_ratio=case.gear_ratio, I=case.I, J=case.J, mglx=case.mglx, mgly=case.mgly,
                      b=case.b, friction=CoulombViscous(c=case.c, v=case.v, smoothing=case.eps_rad_s),
                      spring=LinearSpring(k=case.k))


@pytest.fixture(scope="session")
def pa10_hinge():
    """A PA-10 joint of the hinge grid (small_grid(6)[0]: 22 s, sign friction, white torque noise):
    (case, its signals, its true model)."""
    case = small_grid(6)[0]
    rec, _ = simulate_hinge(case)
    return case, mocapfj.signals(rec), nominal_of(case)
