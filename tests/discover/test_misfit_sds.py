"""The SDs discovery reports for a fitted model's parameters carry the model's own error where it
misses a channel by more than that channel's noise (mocapfj.discover.tournament.Judge.parameter_sds)."""

from __future__ import annotations

import numpy as np

from mocapfj.discover.effects import nominal_parameters
from mocapfj.discover.refit import refit
from mocapfj.discover.tournament import Judge
from mocapfj.dynamics import CoulombViscous


def _fitted(pa10_hinge, model):
    case, sig, true = pa10_hinge
    judge = Judge(sig, None, {"j1": np.zeros_like(sig["j1"].t)}, {}, {"j1": true}, 0.3, {"j1": 4.0}, 3.0, 0.1, 1e-10)
    c1, _, _ = refit(nominal_parameters(model), model, judge.evidence("j1", "trial"))
    sds, _ = judge.parameter_sds("j1", c1, model)
    truth = {"I": true.I, "J": true.J, "b": true.b, "k": true.spring.k}
    return {k: (c1.params[k] - truth[k]) / sds[k] for k in truth}


def test_sds_of_a_model_that_misses_its_coulomb_friction_cover_the_error_it_makes(pa10_hinge):
    """A PA-10 joint (small_grid(6)[0], 22 s): its model without the Coulomb friction, the link's
    inertia, the motor's inertia and viscous friction and the stiffness refitted by output error on
    the trial, take up the missing friction: I -13 %, J +12 %, b +42 %, k -19 %. With the noise
    alone their SDs were 10-21 times short of those errors; with each channel taken at the
    residual the model leaves, each error is within 2 SDs (1.0-1.9). The true model, at its noise
    floor, keeps SDs its errors are within 1 of (0.7-1.0), as before."""
    z = _fitted(pa10_hinge, pa10_hinge[2].with_(friction=CoulombViscous(c=1e-9, v=pa10_hinge[2].friction.v,
                                                                         smoothing=pa10_hinge[2].friction.smoothing)))
    assert max(abs(v) for v in z.values()) < 3.0, z
    z = _fitted(pa10_hinge, pa10_hinge[2])
    assert max(abs(v) for v in z.values()) < 2.0, z


def test_parameters_fitted_beside_a_mismatch_far_below_the_floor_are_not_determined():
    """A smooth Stribeck law named on a light cobot that sticks (fresh hinge grid seed 41000, case
    000, the true nominal given): the torque was left 12.1 points below its noise floor and the
    excess came out 0.21 N m for the planted 0.75, 18 of its SDs off. Beyond MISFIT_POINTS below
    the floor the joint's effects' parameters are listed as not determined, with the channel and
    the points; a reason already given (the exponent the recordings do not decide) is kept. At the
    3.8 points of the grids' worst discovery that named its effect rightly, nothing changes."""
    from mocapfj.discover.engine import MISFIT_POINTS, _misfit_undetermined

    def effects():
        return [{"name": "stribeck", "joint": "j1", "parameters": {"fs": 0.96, "fc": 0.75, "vs": 0.070},
                 "parameter_sds": {"fs": 0.029, "vs": 0.0089},
                 "not_determined": {"exponent": "exponent 1 fits as well"}},
                {"name": "backlash", "joint": "j2", "parameters": {"gap_rad": 1e-3}, "parameter_sds": {"gap_rad": 1e-4}}]

    out = effects()
    _misfit_undetermined(out, "j1", {"torque": 12.1, "deflection": 1.2})
    nd = out[0]["not_determined"]
    assert set(nd) == {"fs", "vs", "exponent"} and nd["exponent"] == "exponent 1 fits as well"
    assert "torque 12.1 points below its noise floor" in nd["fs"]
    assert "not_determined" not in out[1]
    assert 3.8 < MISFIT_POINTS < 8.1
    kept = effects()
    _misfit_undetermined(kept, "j1", {"torque": 3.8})
    assert kept == effects()
