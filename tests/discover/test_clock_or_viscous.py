"""A clock offset against a nominal model identified on the trial is reported as the viscous split
it stands for (engine.clock_or_viscous): the two are one model to first order."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from mocapfj.discover import engine
from mocapfj.discover.model import simulate_joint


def _found(model, delay_s):
    return {"candidate": SimpleNamespace(name="time_delay", params={"delay_s": delay_s}), "before": model,
            "score": {"parameter_sds": {"delay_s": 1e-5}}}


def test_a_clock_offset_and_the_viscous_split_it_stands_for_simulate_alike(pa10_hinge):
    """A mocap angle dt late reads as the link's viscous lag q' dt, and the motor's b q_m' lowered
    by k dt: on a PA-10 joint of the small grid, 0.5 ms of offset lowers the true model's fit by
    3.07 points, and the split (v - k dt, b + k dt) in its place by 3.28 when written: the two
    differ by 7 % of what either changes (the link sticking at its reversals, where v does
    nothing, and its resonance above the band are what tell them apart)."""
    case, sig, model = pa10_hinge
    s = sig["j1"]
    d = 5e-4
    k = model.spring.k
    alias = engine.clock_or_viscous(_found(model, d), None)
    assert alias is not None
    assert np.isclose(alias["v"], model.friction.v - k * d) and np.isclose(alias["b"], model.b + k * d)
    split = model.with_(b=alias["b"], friction=replace(model.friction, v=alias["v"]))
    base, late, other = (simulate_joint(m, s.t, s.q, s.q_m, s.u, period_s=None).fit
                         for m in (model, model.with_(delay_s=d), split))
    assert base - late > 1.0, (base, late)
    assert abs(other - late) < 0.15 * (base - late), (base, late, other)


def test_the_split_is_reported_only_where_the_trial_did_not_determine_it(pa10_hinge):
    """Not when the split would make v or b negative (then it is a clock offset: a -2 ms offset on
    this joint would need b < 0), nor when it moves v by more than CLOCK_SPLIT_SDS of the
    identification's SD of v; only a time_delay is read this way."""
    _, _, model = pa10_hinge
    k, v, b = model.spring.k, model.friction.v, model.b
    d_neg_b = -1.01 * b / k                                          # b + k d just below zero
    assert engine.clock_or_viscous(_found(model, d_neg_b), None) is None
    d_neg_v = 1.01 * v / k                                           # v - k d just below zero
    assert engine.clock_or_viscous(_found(model, d_neg_v), None) is None
    d = 0.2 * v / k
    assert engine.clock_or_viscous(_found(model, d), {"v": k * d / (engine.CLOCK_SPLIT_SDS + 0.1)}) is None
    assert engine.clock_or_viscous(_found(model, d), {"v": k * d / (engine.CLOCK_SPLIT_SDS - 0.1)}) is not None
    other = _found(model, d)
    other["candidate"] = SimpleNamespace(name="hysteresis", params={"alpha": 0.7})
    assert engine.clock_or_viscous(other, None) is None


def test_an_offset_named_against_an_undetermined_split_is_given_the_range_the_split_allows(pa10_hinge):
    """Named (its split would make b negative), an offset d against a model whose v the trial did
    not determine is known only within d - v / k to d + b / k, where each offset has a physical
    split that fits alike: reported as not determined there, with d's RMS error for an offset
    uniform over that range.
    With v determined at SD s_v, its SD takes s_v / k."""
    _, _, model = pa10_hinge
    k, v, b = model.spring.k, model.friction.v, model.b
    d = -1.5 * b / k                                                   # b + k d < 0: named
    f = _found(model, d)
    assert engine.clock_or_viscous(f, None) is None
    engine.offset_with_split(f, None, model)
    lo, hi = d - v / k, d + b / k
    rms = np.sqrt(np.mean((d - np.linspace(lo, hi, 100001)) ** 2))     # d against offsets over the range
    assert np.isclose(f["score"]["parameter_sds"]["delay_s"], np.hypot(1e-5, rms), rtol=1e-4)
    assert "between" in f["score"]["not_determined"]["delay_s"]
    g = _found(model, d)
    engine.offset_with_split(g, {"v": 0.1 * v}, model)
    assert np.isclose(g["score"]["parameter_sds"]["delay_s"], np.hypot(1e-5, 0.1 * v / k))
    assert "not_determined" not in g["score"]
