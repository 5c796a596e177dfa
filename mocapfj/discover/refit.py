"""An effect's parameters refitted by output error: the augmented model simulated on a recording and
its fit in the comparison band maximised over the effect's parameter vector, the nominal
parameters held.

The equation-error fit of :mod:`.effects` starts it: an effect of a fraction of the mocap noise
per sample is lost in an equation-error residual that differentiates that noise, while the
simulation averages it out, so its equation-error parameters can be far off (a free play read at
3x its width) or its shape misread. Least squares (trust-region reflective, scipy
``least_squares``) on the weighted in-band residual of :class:`.evidence.Evidence`, whose norm
the fit is a function of, with forward differences on the candidate's own scales
(``Candidate.steps``), which matches or beats the Nelder-Mead search it replaced on the grid's
cases (tests/discover/test_evidence.py).

Its cost is bounded by a count of simulations, the Jacobian's included (SIMULATIONS_PER_STEP;
scipy's ``max_nfev`` does not count the finite differences of the Jacobian, so MAX_EVALS_PER_PARAMETER
alone allowed 8 p (p + 1) simulations: 1456 for the 13 parameters of an effect refitted with a
spot model's own). A refit that reaches the count keeps the best parameters it simulated. On the
grid's refits of 1-14 parameters the count was 6-15 simulations per parameter (hinge grid seed
39000), below the bound.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

from ..errors import InputError
from .effects import Candidate
from .evidence import Evidence

__all__ = ["refit", "MAX_EVALS_PER_PARAMETER", "SIMULATIONS_PER_STEP", "simulation_budget"]

MAX_EVALS_PER_PARAMETER = 8
"""Steps (scipy's ``max_nfev``, the Jacobian's simulations not counted) per parameter of a refit."""
SIMULATIONS_PER_STEP = 32
"""A refit of p parameters simulates at most this many times p + 1 (a Jacobian and its step), and
never more than MAX_EVALS_PER_PARAMETER allows (:func:`simulation_budget`): with a Jacobian of
p + 1 simulations, 32 steps' worth. A 40 s recording of a joint without gravity whose spot model
had a collapsed inertia (0.019 for 0.34 kg m^2, 10 kernel substeps a sample) took 15 minutes to
discover, its refits with the nominal parameters free running to 1456 simulations each (hinge grid
seed 38000, case 005, transmission error, no model file); with this budget it still takes 8
minutes of CPU, in the number of its refits rather than their length."""

REACH = 10.0
"""A refit moves each parameter at most this many of its steps from the equation-error start (a
stiffness by a factor e, a free play's width by e^5): a stiffness run away by a few hundred times
makes the kernel take thousands of substeps per sample."""


def simulation_budget(p: int) -> int:
    """The most simulations a refit of p parameters runs (module docstring)."""
    return min(MAX_EVALS_PER_PARAMETER * p * (p + 1), SIMULATIONS_PER_STEP * (p + 1))


class _Spent(Exception):
    """The refit's simulation budget is spent."""


def _model_of(cand: Candidate, theta, model):
    try:
        c = cand.rebuild(np.asarray(theta, dtype=np.float64))
        return c, c.apply(model)
    except (InputError, ValueError, FloatingPointError, ArithmeticError):
        return None, None


def refit(cand: Candidate, model, ev: Evidence) -> tuple[Candidate, float, float]:
    """(candidate refitted, fit of `model` with the candidate as given, fit with the refitted one)
    on the evidence `ev`; the candidate unchanged when it has no parameter vector or the refit
    does not raise the fit (module docstring)."""
    if cand.rebuild is None or cand.theta is None:
        return cand, math.nan, math.nan
    th0 = np.asarray(cand.theta, dtype=np.float64)
    steps = np.asarray(cand.steps, dtype=np.float64)
    c0, m0 = _model_of(cand, th0, model)
    f0 = ev.fit(m0) if m0 is not None else -math.inf
    size = [None]
    budget = simulation_budget(th0.size)
    spent = [0]
    best = [math.inf, np.zeros(th0.size)]

    def resid(z):
        if spent[0] >= budget:
            raise _Spent
        spent[0] += 1
        _, m = _model_of(cand, th0 + z * steps, model)
        if m is None:
            return np.full(size[0] or 2, 1e3)
        r = ev.residual(m, size[0])
        if size[0] is None:
            size[0] = r.size
        cost = float(r @ r)
        if cost < best[0]:
            best[0], best[1] = cost, np.array(z, dtype=np.float64)
        return r

    r0 = resid(np.zeros(th0.size))
    if size[0] is None or r0.size != size[0]:
        return cand, f0, f0
    try:
        res = least_squares(resid, np.zeros(th0.size), method="trf", diff_step=0.05, x_scale=1.0,
                            bounds=(-REACH, REACH), max_nfev=MAX_EVALS_PER_PARAMETER * th0.size, xtol=1e-4,
                            ftol=1e-6)
        x = res.x
    except _Spent:
        x = best[1]
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):
        return cand, f0, f0
    c1, m1 = _model_of(cand, th0 + x * steps, model)
    f1 = ev.fit(m1) if m1 is not None else -math.inf
    if not (math.isfinite(f1) and f1 > f0):
        return (c0 or cand), f0, f0
    return c1, f0, f1
