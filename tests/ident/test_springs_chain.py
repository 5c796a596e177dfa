"""Nonlinear springs through the whole chain: pa10_joint2 with a cubic and with a Bouc-Wen spring
(markers -> angles -> deflection -> mocapfj.pipeline.identify_signals), 30 s each."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapfj.ident.springs import bouc_wen_states

ROOT = Path(__file__).resolve().parents[2]
LINEAR = 'spring = { model = "linear", k = 1.19e4 }'
SPRINGS = {
    # +14 % torque at the largest deflection (6 mrad)
    "cubic": 'spring = { model = "cubic", k1 = 1.19e4, k3 = 4.6e7 }',
    # a loop of (1 - alpha) k / (beta + gamma) = 6 N m half-height
    "bouc_wen": 'spring = { model = "bouc_wen", k = 1.19e4, alpha = 0.7, beta = 300.0, gamma = 300.0 }',
}
RIGID = dict(I=6.15, mglx=111.64, mgly=-7.80, c=9.28, v=18.38, J=12.57, b=23.28)


@pytest.fixture(scope="module", params=sorted(SPRINGS))
def identified(request, tmp_path_factory):
    import mocapfj
    from mocapfj.synth.record import record_scenario, write_scenario_bundle
    from mocapfj.synth.scenario import load_scenario

    d = tmp_path_factory.mktemp(request.param)
    text = (ROOT / "datasets" / "pa10_joint2.toml").read_text()
    assert LINEAR in text
    (d / "scenario.toml").write_text(text.replace(LINEAR, SPRINGS[request.param]))
    sr = record_scenario(load_scenario(d / "scenario.toml").with_duration(30.0), with_concealment=False)
    write_scenario_bundle(sr, d / "bundle")
    s = mocapfj.signals(d / "bundle")["j2"]
    from mocapfj.ident.joint import identify_signals

    res = identify_signals(s)                  # output error at the controller's rate
    print(request.param, res.spring.to_dict(), {n: round(100 * (res[n] / v - 1), 2) for n, v in RIGID.items()})
    return request.param, res, s.q_m - s.q, s


def test_the_planted_spring_is_selected_and_its_coefficients_recovered(identified):
    """Output error (the default) keeps the cubic term by its own likelihood-ratio test; its
    score test finds the loop, which motor-first then fits in the motor equation. Measured:
    cubic k1 +1.7 %, k3 +22 % with a reported SD of 7.4 %; Bouc-Wen k -0.04 %, alpha 0.702,
    beta 280, gamma 332 (beta + gamma, which sets the loop's saturation, +2.0 %)."""
    name, res, _, _ = identified
    s = res.spring
    assert s.model == name
    p = s.params
    if name == "cubic":
        assert p["k1"] == pytest.approx(1.19e4, rel=0.02)
        assert abs(p["k3"] - 4.6e7) < min(3 * p["k3_std"], 0.3 * 4.6e7), (p["k3"], p["k3_std"])
    else:
        assert p["k"] == pytest.approx(1.19e4, rel=0.03)
        assert p["alpha"] == pytest.approx(0.7, abs=0.03)
        assert p["beta"] + p["gamma"] == pytest.approx(600.0, rel=0.10)


@pytest.mark.parametrize("identified", ["bouc_wen"], indirect=True)
def test_the_hysteresis_loop_dissipates_the_true_energy(identified):
    """The fitted Bouc-Wen element along the measured deflection dissipates what the true one
    does along the same path, within 10 % (measured 0.318 J vs 0.329 J; the Lightcap and Banks (2007) step-2 route through the link-side spring
    torque cannot see the loop at all: the motor's viscous b absorbs it)."""
    name, res, delta, _ = identified
    from mocapfj.ident.conditioning import lowpass

    d = lowpass(delta, 250.0, 10.0)[::5]
    d = d - d.mean()

    def energy(k, alpha, beta, gamma):
        tau = alpha * k * d + (1 - alpha) * k * bouc_wen_states(d, 1.0, beta, gamma)
        return float(np.sum(0.5 * (tau[1:] + tau[:-1]) * np.diff(d)))

    fit = energy(**res.spring.params)
    true = energy(1.19e4, 0.7, 300.0, 300.0)
    print("dissipated energy, fit vs true (J):", fit, true)
    assert true > 0 and fit == pytest.approx(true, rel=0.10)


def test_rigid_parameters_stay_close_with_a_nonlinear_spring(identified):
    """The spring's shape goes back into the motor equation, so the rigid-body parameters do not
    absorb it. Measured: cubic I -5.0, J +1.9, b -1.6 %; Bouc-Wen I -1.4, J +2.9, b -1.0 %;
    gravity and Coulomb within 0.7 %. (30 s each; the 60 s linear trial is within 2 %.) A parameter
    flagged not determined must instead lie within 3 of its SDs: the cubic case's v / b split is
    near the 5 % line (v +3.6 % or +8.7 % with an SD of 5.8 %, depending on the last bits of the
    marker data), and is then flagged."""
    _, res, _, _ = identified
    err = {n: 100 * (res[n] / v - 1) for n, v in RIGID.items()}
    for n in ("mglx", "mgly", "c", "v", "J", "b"):
        p = res.params[n]
        if p.determined:
            assert abs(err[n]) < 4.0, (n, err[n])
        else:                       # flagged (relative SD above 5 %): its SD must cover the error
            assert abs(res[n] - RIGID[n]) < 3 * p.std, (n, err[n], p.std)
    assert abs(err["I"]) < 7.0, err["I"]


@pytest.mark.parametrize("identified", ["bouc_wen"], indirect=True)
def test_a_motor_first_loop_that_is_not_a_spring_leaves_the_output_errors(identified, monkeypatch):
    """Motor-first's Bouc-Wen fit can put more stiffness in the loop than in the whole spring
    (alpha -0.076 on a heavy joint of the discovery grid, seed 21000): that is not a spring, and
    the output error's own loop stands (alpha within [0, 1]) instead of the identification failing
    with the element's error, which took discovery's re-identification down with it."""
    import dataclasses

    import mocapfj.ident.motorfirst as mf
    from mocapfj.ident.joint import identify_signals

    s = identified[3]
    real = mf.identify_motor_first

    def loop_too_stiff(*a, **kw):
        r = real(*a, **kw)
        return dataclasses.replace(r, hysteresis={**r.hysteresis, "alpha": -0.076})

    monkeypatch.setattr(mf, "identify_motor_first", loop_too_stiff)
    out = identify_signals(s)
    assert out.spring.model == "bouc_wen" and 0.0 <= out.spring.params["alpha"] <= 1.0
    assert "motor-first could not fit it" in out.extra["spring_note"]
