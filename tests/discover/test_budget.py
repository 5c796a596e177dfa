"""The output-error refit's cost is bounded by a count of simulations, its Jacobian's included
(mocapfj.discover.refit.simulation_budget), and a refit that spends it keeps the best parameters
it simulated."""

from __future__ import annotations

import math

import numpy as np

from mocapfj.discover.effects import Candidate
from mocapfj.discover.refit import MAX_EVALS_PER_PARAMETER, refit, simulation_budget


class _Rosenbrock:
    """A stand-in for a recording: the 'fit' of theta is a chained Rosenbrock valley's residual,
    which trust-region steps cross slowly (a simulation each call, counted)."""

    def __init__(self, a: float = 100.0):
        self.calls, self.a = 0, a

    def residual(self, model, size=None):
        self.calls += 1
        th = model
        return np.concatenate([self.a * (th[1:] - th[:-1] ** 2), 1.0 - th[:-1]]) / self.a

    def fit(self, model):
        r = self.residual(model)
        self.calls -= 1                  # the fits before and after are not the refit's
        return 100.0 * (1.0 - math.sqrt(float(r @ r)))


def _candidate(th):
    th = np.asarray(th, float)
    return Candidate("valley", "link", {"theta": th.tolist()}, th.size, np.zeros(1), lambda m, th=th: th.copy(), {},
                     lambda g: "", th, np.ones(th.size), _candidate)


def test_a_refit_of_many_parameters_stops_at_its_simulation_budget_with_the_best_it_found():
    """13 parameters from -1.2 each (the classic start): scipy's own limit (MAX_EVALS_PER_PARAMETER
    steps, each with a finite-difference Jacobian of 13 more simulations) allows 8 x 13 x 14 = 1456
    simulations; the budget is 32 x 14 = 448. Without it this refit runs 1379 simulations (as a
    spot model's refits with the nominal parameters free ran to 1456 each, for 15 minutes on a 40 s
    recording). It returns the best point it simulated, which fits better than the start."""
    p = 13
    ev = _Rosenbrock()
    c1, f0, f1 = refit(_candidate(np.full(p, -1.2)), None, ev)
    assert simulation_budget(p) == 448 < MAX_EVALS_PER_PARAMETER * p * (p + 1) == 1456
    assert ev.calls <= simulation_budget(p), ev.calls
    assert f1 > f0 + 1.0, (f0, f1)
    assert abs(ev.fit(np.asarray(c1.theta)) - f1) < 1e-12


def test_a_small_refit_keeps_scipys_own_limit():
    """For up to 4 parameters the budget is scipy's own limit, 8 p (p + 1): the refits of one
    effect are not cut. Two parameters in a wide valley converge to its minimum (1, 1) within it."""
    assert [simulation_budget(p) for p in (1, 2, 3, 4)] == [16, 48, 96, 160]
    ev = _Rosenbrock(a=3.0)
    c1, f0, f1 = refit(_candidate(np.array([0.5, 0.5])), None, ev)
    assert ev.calls <= 48 and np.allclose(c1.theta, [1.0, 1.0], atol=0.05), (ev.calls, c1.theta)
