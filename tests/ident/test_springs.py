"""Step-2 spring models and their selection (mocapfj.ident.springs; Lightcap and Banks (2007), eq. 7)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapfj import InputError
from mocapfj.dynamics import Backlash, BoucWen, CubicSpring, Dahl, LinearSpring, MaxwellSlip, PiecewiseSpring
from mocapfj.ident.springs import bouc_wen_states, select_spring_model

ROOT = Path(__file__).resolve().parents[2]
NOISE_NM = 0.3          # N m, the scenarios' torque noise


def _path(seed=0, T=30.0, fs=200.0):
    """A deflection history like the pa10 joint 2 trial's (multi-sine, about +-6 mrad), rad."""
    t = np.arange(int(T * fs)) / fs
    rng = np.random.default_rng(seed)
    f = np.array([0.1, 0.2, 0.3, 0.5, 0.7])
    ph = rng.uniform(0, 2 * np.pi, f.size)
    a = np.array([2.0, 1.2, 0.8, 0.5, 0.3]) * 1e-3
    return t, -0.3e-3 + 1.4 * (a * np.sin(2 * np.pi * f * t[:, None] + ph)).sum(1)


def _data(element, seed):
    t, d = _path(seed)
    tau = element.run(d, t) + np.random.default_rng(seed + 100).normal(0, NOISE_NM, t.size)
    return t, d, tau


def test_exact_bouc_wen_path_matches_the_element_ode():
    t, d = _path(1)
    bw = BoucWen(k=11900.0, alpha=0.93, beta=300.0, gamma=300.0)
    z = bouc_wen_states(d, 1.0, 300.0, 300.0)
    np.testing.assert_allclose(bw.torque(d, z[:, None]), bw.run(d, t), atol=0.01)   # N m
    bw2 = BoucWen(k=5000.0, alpha=0.5, beta=800.0, gamma=-200.0)                    # softening loop shape
    np.testing.assert_allclose(bw2.torque(d, bouc_wen_states(d, 1.0, 800.0, -200.0)[:, None]), bw2.run(d, t),
                               atol=0.01)


def test_linear_spring_is_recovered_and_selected():
    t, d, tau = _data(LinearSpring(k=1.19e4, offset=-0.4e-3), 2)
    s = select_spring_model(d, tau, t)
    print({k: round(v, 4) for k, v in s.holdout_rms.items()})
    assert s.chosen.model == "linear"
    assert s.chosen.params["k"] == pytest.approx(1.19e4, rel=0.01)
    assert s.chosen.params["tau0"] == pytest.approx(1.19e4 * 0.4e-3, abs=0.1)
    assert s.r2 > 0.99


def test_cubic_spring_is_recovered_and_selected():
    t, d, tau = _data(CubicSpring(k1=1.0e4, k3=8.0e7), 3)
    s = select_spring_model(d, tau, t)
    assert s.chosen.model == "cubic"
    assert s.chosen.params["k1"] == pytest.approx(1.0e4, rel=0.01)
    assert s.chosen.params["k3"] == pytest.approx(8.0e7, rel=0.05)
    assert s.holdout_rms["cubic"] < 1.1 * NOISE_NM < s.holdout_rms["linear"]


def test_piecewise_spring_is_recovered_and_selected():
    true = PiecewiseSpring(k1=9500.0, k2=11500.0, k3=12500.0, tau1=8.0, tau2=35.0)
    t, d, tau = _data(true, 4)
    s = select_spring_model(d, tau, t)
    assert s.chosen.model == "piecewise"
    p = s.chosen.params
    for name, tol in (("k1", 0.03), ("k2", 0.03), ("k3", 0.03), ("tau1", 0.1), ("tau2", 0.05)):
        assert p[name] == pytest.approx(true.params[name], rel=tol), name
    assert abs(p["d0"]) < 2e-5


def test_backlash_is_recovered_and_selected():
    t, d, tau = _data(Backlash(gap=1.0e-3, spring=LinearSpring(k=1.19e4)), 5)
    s = select_spring_model(d, tau, t)
    assert s.chosen.model == "backlash"
    assert s.chosen.params["gap"] == pytest.approx(1.0e-3, rel=0.03)
    assert s.chosen.params["k"] == pytest.approx(1.19e4, rel=0.01)


def test_bouc_wen_is_recovered_and_selected():
    t, d, tau = _data(BoucWen(k=11900.0, alpha=0.93, beta=300.0, gamma=300.0), 6)
    s = select_spring_model(d, tau, t)
    assert s.chosen.model == "bouc_wen"
    p = s.chosen.params
    assert p["k"] == pytest.approx(11900.0, rel=0.02)
    assert p["alpha"] == pytest.approx(0.93, abs=0.01)
    assert p["beta"] + p["gamma"] == pytest.approx(600.0, rel=0.15)     # the loop half-width 1/(beta+gamma)
    assert s.holdout_rms["bouc_wen"] < 1.1 * NOISE_NM < s.holdout_rms["linear"]


def _loop_energy(tau, d):
    """Closed integral of tau d(delta) along the path, J."""
    return float(np.sum(0.5 * (tau[1:] + tau[:-1]) * np.diff(d)))


def test_dahl_is_recovered_and_selected():
    true = Dahl(sigma=4.0e4, fc=6.0, k0=9000.0)
    t, d, tau = _data(true, 7)
    s = select_spring_model(d, tau, t)
    print({k: round(v, 4) for k, v in s.holdout_rms.items()}, s.chosen.params)
    assert s.chosen.model == "dahl"
    p = s.chosen.params
    assert p["sigma"] == pytest.approx(4.0e4, rel=0.10)
    assert p["fc"] == pytest.approx(6.0, rel=0.05)
    assert p["k0"] == pytest.approx(9000.0, rel=0.02)
    assert s.holdout_rms["dahl"] < 1.1 * NOISE_NM < s.holdout_rms["linear"]


def test_maxwell_slip_is_recovered_and_selected():
    """Three elements, thresholds by variable projection: measured k0 6002, (k, f) pairs
    (2998, 1.007), (1998, 2.992), (1499, 5.996), prediction within 0.006 N m of the truth."""
    true = MaxwellSlip(k=(3000.0, 2000.0, 1500.0), f=(1.0, 3.0, 6.0), k0=6000.0)
    t, d, tau = _data(true, 8)
    s = select_spring_model(d, tau, t)
    print({k: round(v, 4) for k, v in s.holdout_rms.items()}, s.chosen.params)
    assert s.chosen.model == "maxwell_slip"
    p = s.chosen.params
    assert p["k0"] == pytest.approx(6000.0, rel=0.02)
    pairs = sorted((p[f"f{i}"], p[f"k{i}"]) for i in (1, 2, 3))
    for (f, k), (ft, kt) in zip(pairs, [(1.0, 3000.0), (3.0, 2000.0), (6.0, 1500.0)]):
        assert f == pytest.approx(ft, rel=0.05) and k == pytest.approx(kt, rel=0.05)
    assert s.holdout_rms["maxwell_slip"] < 1.1 * NOISE_NM < s.holdout_rms["linear"]
    clean = true.run(d, t)
    assert _loop_energy(s.chosen.predict(d, t), d) == pytest.approx(_loop_energy(clean, d), rel=0.02)


def _scenario_truth(name):
    from mocapfj.synth.record import simulate_scenario
    from mocapfj.synth.scenario import load_scenario

    r = simulate_scenario(load_scenario(ROOT / "datasets" / "suite" / f"{name}.toml").with_duration(20.0))["j2"]
    keep = r.t >= 2.0                                      # after the reference ramp-in
    return r.t[keep][::5], r.delta[keep, 0][::5], r.tau_s[keep, 0][::5]


def test_suite_hysteresis_scenario_selects_bouc_wen():
    t, d, tau = _scenario_truth("hysteresis_ident")
    s = select_spring_model(d, tau, t)
    print({k: round(v, 4) for k, v in s.holdout_rms.items()}, s.chosen.params)
    assert s.chosen.model == "bouc_wen"
    assert s.chosen.params["alpha"] == pytest.approx(0.93, abs=0.01)
    assert s.chosen.params["k"] == pytest.approx(11900.0, rel=0.01)
    assert s.holdout_rms["bouc_wen"] < 0.1 * s.holdout_rms["linear"]


def test_suite_stiffening_scenario_selects_a_stiffening_spring_over_linear():
    t, d, tau = _scenario_truth("stiffening_ident")
    s = select_spring_model(d, tau, t, models=("linear", "cubic", "piecewise", "bouc_wen"))
    print({k: round(v, 4) for k, v in s.holdout_rms.items()})
    assert s.chosen.model == "piecewise"
    assert s.criterion["cubic"] < s.criterion["linear"]
    for name, v in (("k1", 9500.0), ("k2", 11500.0), ("k3", 12500.0), ("tau1", 8.0), ("tau2", 35.0)):
        assert s.chosen.params[name] == pytest.approx(v, rel=0.01), name


def test_bad_input_is_refused():
    t, d = _path(0)
    with pytest.raises(InputError, match="models"):
        select_spring_model(d, d, t, models=("quadratic",))
    with pytest.raises(InputError, match="holdout"):
        select_spring_model(d, d, t, holdout=1.5)
    with pytest.raises(InputError, match="strictly increasing"):
        select_spring_model(d, d, t[::-1])
