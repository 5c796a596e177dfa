"""Discovery's prepared comparisons (mocapfj.discover.evidence), the output-error refit of an effect
(mocapfj.discover.refit) and the judgement of candidates on held-out evidence
(mocapfj.discover.tournament)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import mocapfj
from mocapfj.discover import engine
from mocapfj.discover.effects import FITTERS
from mocapfj.discover.evidence import Evidence
from mocapfj.discover.model import simulate_joint
from mocapfj.discover.refit import refit
from mocapfj.dynamics import Backlash, BoucWen, CubicSpring
from mocapfj.synth.hinge import deflection_noise_sd, simulate_hinge, small_grid

from .conftest import nominal_of


@pytest.fixture(scope="module")
def backlash_case():
    """A PA-10 hinge case of the small grid with free play of 1.5 x the deflection noise (total
    width) in front of its spring."""
    case = small_grid(6)[0]
    planted = replace(case, backlash_rad=1.5 * deflection_noise_sd(case))
    return planted, mocapfj.signals(simulate_hinge(planted)[0]), nominal_of(case)


def test_a_prepared_comparison_equals_the_full_one(backlash_case):
    """Evidence.fit and Evidence.change_sd are simulate_joint's fit and OutputError.change_sd for
    models of every kind the kernels run (the comparison is linear in the prediction)."""
    _, s, nominal = backlash_case
    sj = s["j1"]
    ref = simulate_joint(nominal, sj.t, sj.q, sj.q_m, sj.u)
    ev = Evidence(sj, {}, ref.band_hz, noise_from=ref)
    k = nominal.spring.k
    for m in (nominal, nominal.with_(spring=CubicSpring(k1=k, k3=50 * k)),
              nominal.with_(spring=BoucWen(k=k, alpha=0.7, beta=3e3, gamma=3e3)),
              nominal.with_(spring=Backlash(2e-4, nominal.spring)), nominal.with_(delay_s=0.002)):
        full = simulate_joint(m, sj.t, sj.q, sj.q_m, sj.u, band_hz=ref.band_hz)
        sc = ev.score(m)
        assert sc.fit == pytest.approx(full.fit, abs=1e-9)
        assert ev.change_sd(ev.score(nominal), sc) == pytest.approx(ref.change_sd(full), rel=1e-9, abs=1e-12)
        r = ev.residual(m)
        assert 100.0 * (1.0 - np.linalg.norm(r)) == pytest.approx(full.fit, abs=1e-9)


def test_an_effect_refitted_by_output_error_moves_to_the_truth(backlash_case):
    """The free play's equation-error candidate restarted from three times the planted width and
    refitted by output error on the trial with the nominal parameters held comes back to within
    30 % of the planted width, and its trial fit rises to within 0.3 points of the true model's."""
    planted, s, nominal = backlash_case
    sj = s["j1"]
    fams, _ = engine._families_all({"j1": nominal}, s, sj.fs_hz)
    cand = FITTERS["backlash"](fams["j1"], fams["j1"].keep_s, {})
    start = cand.rebuild(cand.theta + np.array([np.log(3.0 * planted.backlash_rad / cand.params["gap_rad"]), 0.0]))
    ev = Evidence(sj, {}, simulate_joint(nominal, sj.t, sj.q, sj.q_m, sj.u).band_hz, model=nominal)
    refined, f0, f1 = refit(start, nominal, ev)
    true_fit = ev.fit(nominal.with_(spring=Backlash(planted.backlash_rad, nominal.spring)))
    assert abs(refined.params["gap_rad"] / planted.backlash_rad - 1.0) < 0.3, refined.params
    assert f1 > f0 and f1 > true_fit - 0.3, (f0, f1, true_fit)


def test_the_held_out_simulation_picks_the_planted_effect_over_the_equation_errors_favourite(backlash_case,
                                                                                           monkeypatch):
    """The equation error's criterion rigged to rank a clock delay first: the candidates are judged
    by their refitted simulations on the trial's held-out part, so the free play is named and the
    delay, which fits it less well, is not."""
    _, s, nominal = backlash_case
    real = engine._score

    def rigged(cand, fam, test):
        out = real(cand, fam, test)
        if cand.name == "time_delay":
            out["criterion"] = -1e9
        return out

    monkeypatch.setattr(engine, "_score", rigged)
    d = engine.discover(s, {"j1": nominal}, fs_hz=s["j1"].fs_hz, effects=("time_delay", "backlash"), reidentify=False)
    assert [e["name"] for e in d.effects][:1] == ["backlash"], (d.verdict, d.rejected)
    cands = {c["name"]: c for c in d.effects[0]["location"]["candidates"]}
    assert cands["backlash"]["held_out_gain_points"] > cands["time_delay"]["held_out_gain_points"]


def test_a_validation_recording_that_shows_the_gain_admits_it():
    """The sum of the held-out gains is judged against the SD of the sum, which the noisier part
    sets. A candidate is also admissible when the validation recording alone shows its gain beyond
    3 of its noise SDs and 0.1 points, and the trial's held-out part does not lose it (the numbers of
    a hysteresis against a re-identified elbow, benchmarks/bench_discover_nlink.py --bias)."""
    from mocapfj.discover.tournament import Judge, Judged

    judge = Judge({}, None, {}, {}, {}, 0.3, {}, engine.GAIN_SDS, engine.WEAK_MIN_POINTS, 0.01)

    def judged(tail, val):
        return Judged("j3", None, {}, None, gains={"trial's held-out part": tail, "validation recording": val})

    assert judge._by_validation(judged((1.06, 7.84), (5.10, 0.36)))
    assert not judge._by_validation(judged((-0.2, 7.84), (5.10, 0.36)))     # the trial's part loses it
    assert not judge._by_validation(judged((1.06, 7.84), (0.50, 0.20)))     # 2.5 SDs on the validation
    assert not judge._by_validation(judged((0.02, 0.04), (0.09, 0.01)))     # 9 SDs, but under 0.1 points
    assert not judge._by_validation(Judged("j3", None, {}, None, gains={"trial's held-out part": (1.06, 0.1)}))
