"""Output-error identification (mocapfj.ident.output_error) and the judgement of what a recording
determines (mocapfj.ident.determinacy), on recordings of the hinge generator (mocapfj.synth.hinge),
whose simulator (LSODA on the whole joint under its PD loop) is not the estimator's kernel.

The full grid (at least 60 cases per family mix, seeds never used while developing) is
benchmarks/bench_identify_grid.py; these are its fast subset: the issue's reference row through
the whole chain, and one joint of each other family from plain arrays."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import mocapfj
from mocapfj.ident.conditioning import noise_floor_sd
from mocapfj.ident.determinacy import judge_parameters
from mocapfj.ident.output_error import burg_ar
from mocapfj.synth.hinge import first_row_case, sample_cases, simulate_hinge, small_grid, write_hinge_bundle

NAMES = ("I", "mglx", "mgly", "c", "v", "J", "b", "k")
TOL = {n: (5.0 if n == "c" else 2.0) for n in NAMES}


def _errors(params, truth):
    """{name: (error %, |error| / SD)}, gravity relative to its magnitude."""
    g = math.hypot(truth["mglx"], truth["mgly"])
    out = {}
    for n in NAMES:
        p = params[n]
        scale = (g or 1.0) if n in ("mglx", "mgly") else abs(truth[n])
        out[n] = (100 * (p.value - truth[n]) / scale, abs(p.value - truth[n]) / p.std)
    return out


def test_first_row_through_the_whole_chain(tmp_path):
    """The reference row of the issue (PA-10 joint 2 of Lightcap and Banks (2007), Table I; 40 s,
    a 0.1 Hz x 5 Fourier motor reference to +-50 deg, torque noise 0.5 N m, markers 0.2 mm),
    written as a bundle and identified by `mocapfj.identify`: every parameter within 2 % (c 5 %),
    none flagged, each error within 3 reported SDs. Measured: |error| <= 0.2 %."""
    case = first_row_case(7)
    write_hinge_bundle(case, tmp_path / "row")
    ident = mocapfj.identify(str(tmp_path / "row"), method="output_error")
    p = ident.joint("j1").params
    for n, (err, z) in _errors(p, case.params).items():
        assert p[n].determined, (n, p[n].reason)
        assert abs(err) < TOL[n] and z < 3.0, (n, err, z)


@pytest.fixture(scope="module")
def family_signals():
    """A cobot, a heavy joint and a vertical joint of the grid's rules, 25-30 s, as plain arrays
    through the joints stage (mocapfj.signals): {family: (case, JointSignals)}."""
    out = {}
    for case in small_grid(3)[1:4]:
        rec, truth = simulate_hinge(case)
        out[case.family] = (case, mocapfj.signals(rec)["j1"])
    return out


@pytest.fixture(scope="module")
def families(family_signals):
    """Those joints identified by output error."""
    out = {}
    for case, s in family_signals.values():
        out[case.family] = (case, mocapfj.identify_joint(s.t, s.q, s.q_m, s.u, fs_hz=s.fs_hz, method="output_error",
                                                         measured=s.measured,
                                                         controller=(s.t_c, s.q_m_c, s.u_c, s.fs_c_hz)))
    return out


@pytest.mark.parametrize("family", ["cobot", "heavy", "vertical"])
def test_each_parameter_within_tolerance_or_flagged_with_an_honest_sd(families, family):
    case, res = families[family]
    for n, (err, z) in _errors(res.params, case.params).items():
        if n in ("mglx", "mgly") and family == "vertical":
            continue
        p = res.params[n]
        if p.determined:
            assert abs(err) < max(TOL[n], 3 * 100 * p.std / abs(case.params[n])), (n, err, p.std)
            assert z < 4.0, (n, err, z)
        else:
            assert p.reason and 100 * p.std / abs(p.value) > 5 or "zero" in p.reason, (n, p.reason)


def test_vertical_joint_reports_no_gravity(families):
    case, res = families["vertical"]
    for n in ("mglx", "mgly"):
        p = res.params[n]
        assert not p.determined and "no gravity torque" in p.reason
        assert abs(p.value) < 4 * p.std                      # zero within its SD, not a confident number


def test_split_reasons_name_what_is_determined(families):
    """Where the link's deflection is below the mocap noise, v and b (or I and J) are flagged and
    their sum, which the torque determines, is given with its SD."""
    case, res = families["cobot"]
    flagged = [n for n in ("v", "b", "I", "J") if not res.params[n].determined]
    for n in flagged:
        assert ("b + v" in res.params[n].reason) or ("I + J" in res.params[n].reason)
    comb = res.extra["combinations"]
    total = case.params["b"] + case.params["v"]
    assert abs(comb["b+v"]["value"] - total) < max(0.02 * total, 3 * comb["b+v"]["std"])


def test_burg_whitens_an_ar1_process():
    rng = np.random.default_rng(4)
    e = rng.standard_normal(40_000)
    x = np.zeros_like(e)
    for i in range(1, x.size):                                 # AR(1), a = 0.9
        x[i] = 0.9 * x[i - 1] + e[i]
    a, var = burg_ar(x, 10)
    assert abs(a[1] + 0.9) < 0.01 and abs(var - 1.0) < 0.03
    a_white, _ = burg_ar(e, 10)
    assert a_white.size <= 3                                   # white: AIC keeps (nearly) no lags


def test_noise_floor_of_a_quantised_motor_angle():
    """The encoder's white noise floor under a large slow motion (no leakage into it)."""
    t = np.arange(0, 60, 1e-3)
    q = 0.8 * np.sin(2 * np.pi * 0.1 * t)
    quantum = 2 * np.pi / 2 ** 16 / 50
    rng = np.random.default_rng(1)
    for extra in (0.0, 3e-5):
        y = quantum * np.round(q / quantum) + extra * rng.standard_normal(t.size)
        expect = math.sqrt(quantum ** 2 / 12 + extra ** 2)
        assert abs(noise_floor_sd(y, 1000.0) / expect - 1) < 0.1


def test_judge_parameters_flags_bounds_and_missing_gravity():
    names = ("I", "mglx", "mgly", "c", "v", "J", "b", "k")
    values = np.array([6.0, 0.3, -0.2, 9.0, 0.0, 12.0, 40.0, 1.2e4])
    std = np.array([0.01, 0.5, 0.5, 0.01, 0.0, 0.01, 0.1, 10.0])
    p = judge_parameters(names, values, std, np.diag(std ** 2), duration_s=60.0, at_bound=("v",))
    assert not p["v"].determined and "below zero" in p["v"].reason and "clock offset" in p["v"].reason
    assert not p["b"].determined and "b + v" in p["b"].reason
    assert not p["mglx"].determined and "no gravity torque" in p["mglx"].reason
    assert p["I"].determined and p["k"].determined and p["c"].determined


def test_more_data_gives_a_smaller_sd():
    """The reported SD follows the information: the same joint and excitation over twice the
    duration gives an SD about 1/sqrt(2) as large (here 0.55-0.85 of it)."""
    base = replace(sample_cases(1, 41, family="pa10")[0], duration_s=20.0, marker_noise_m=4e-4)
    sds = []
    for dur in (20.0, 40.0):
        rec, _ = simulate_hinge(replace(base, duration_s=dur))
        s = mocapfj.signals(rec)["j1"]
        r = mocapfj.identify_joint(s.t, s.q, s.q_m, s.u, fs_hz=s.fs_hz, method="output_error")
        sds.append(r.params["k"].std)
    assert 0.5 < sds[1] / sds[0] < 0.9, sds


def test_motor_angle_noise_that_sets_the_inertia_split_is_reported():
    """White noise on the logged motor angle drives the simulated link and, through the link's
    resonance, pulls the inertia split toward the motor (grid cases: I -47 % with 4.4e-5 rad of
    noise, +0.5 % without). A light cobot joint with 5e-5 rad: I and J within 2 % or flagged not
    determined with an SD that covers the error and a reason naming the motor angle's noise; the
    same joint without the noise is not flagged for it (split_noise_chi2 below 25).
    Measured: I -60 %, J +97 %, both flagged (|error| / SD 1.3); without the noise chi2 < 1."""
    from mocapfj.ident.output_error import identify_output_error

    base = replace(sample_cases(1, 43, family="cobot")[0], duration_s=25.0)
    rec, _ = simulate_hinge(replace(base, motor_noise_rad=5e-5))
    s = mocapfj.signals(rec)["j1"]
    r = mocapfj.identify_joint(s.t, s.q, s.q_m, s.u, fs_hz=s.fs_hz, method="output_error", measured=s.measured,
                               controller=(s.t_c, s.q_m_c, s.u_c, s.fs_c_hz))
    errors = _errors(r.params, base.params)
    for n in ("I", "J"):
        err, z = errors[n]
        p = r.params[n]
        assert abs(err) < TOL[n] or (not p.determined and z < 3.0), (n, err, z, p.reason)
        if not p.determined:
            assert "motor angle's noise" in p.reason, p.reason
    rec, _ = simulate_hinge(replace(base, motor_noise_rad=0.0))
    s = mocapfj.signals(rec)["j1"]
    oe = identify_output_error(s.t, s.q, s.q_m, s.u, fs_hz=s.fs_hz, measured=s.measured,
                               controller=(s.t_c, s.q_m_c, s.u_c, s.fs_c_hz))
    assert oe.split_noise_chi2 < 25.0, oe.split_noise_chi2


def test_a_second_identification_of_the_same_signals_reuses_the_linear_fit(family_signals, monkeypatch):
    """The linear-spring fit (steps 1-4) of a recording identified with every spring model is
    reused by its effect-free identification (discovery runs both): the result is the one a fresh
    identification gives, to the bit, and the memo was used."""
    import mocapfj.ident.output_error as oe_mod

    _, s = family_signals["cobot"]
    kw = dict(fs_hz=s.fs_hz, measured=s.measured, controller=(s.t_c, s.q_m_c, s.u_c, s.fs_c_hz))
    oe_mod.LINEAR_FITS._d.clear()
    fresh = oe_mod.identify_output_error(s.t, s.q, s.q_m, s.u, test_cubic=False, test_hysteresis=False, **kw)
    oe_mod.LINEAR_FITS._d.clear()
    oe_mod.identify_output_error(s.t, s.q, s.q_m, s.u, **kw)                   # every spring model
    hits = []
    get = oe_mod.LINEAR_FITS.get
    monkeypatch.setattr(oe_mod.LINEAR_FITS, "get", lambda key: hits.append(get(key) is not None) or get(key))
    again = oe_mod.identify_output_error(s.t, s.q, s.q_m, s.u, test_cubic=False, test_hysteresis=False, **kw)
    assert hits == [True]
    for a, b in ((fresh.fit.values, again.fit.values), (fresh.fit.std, again.fit.std), (fresh.fit.cov, again.fit.cov)):
        np.testing.assert_array_equal(a, b)
    assert (fresh.n_iter, fresh.band_hz, fresh.friction_scale) == (again.n_iter, again.band_hz, again.friction_scale)
    # other signals are not served from it
    hits.clear()
    oe_mod.identify_output_error(s.t, s.q, s.q_m, s.u * 1.01, test_cubic=False, test_hysteresis=False, **kw)
    assert hits == [False]


def test_no_fit_of_an_identification_simulates_a_link_faster_than_its_start_allows(monkeypatch):
    """Each fit of an output-error identification starts where the last stopped, and each problem
    capped the link resonance at 16 x that of its own first simulation: on a light cobot whose
    link inertia its data barely determine (hinge grid seed 23000) the inertia ratcheted down by
    256 x per fit to 2e-10 kg m^2, 178 000 substeps per sample, a re-identification still running
    after 27 minutes. The cap is now the identification's: a later problem whose first simulation
    is already past 16 x the start's resonance is not simulated (NaN, a step the optimiser refuses)."""
    from mocapfj.ident import output_error as oe

    fs = 500.0
    t = np.arange(2000) / fs
    q_m = 0.2 * np.sin(2 * np.pi * 0.3 * t)
    u = 5.0 * np.sin(2 * np.pi * 0.3 * t + 0.2)
    d = oe._Data(t, q_m, u, fs, t, q_m.copy(), np.ones(t.size, bool), 0.2, 5.0)
    x = np.zeros(len(oe.OE_NAMES))
    x[[oe._IDX[n] for n in ("I", "J", "k", "c", "v")]] = (0.3, 0.2, 4000.0, 0.4, 0.7)
    scale = np.ones(len(oe.OE_NAMES))
    omega0 = math.sqrt(4000.0 / 0.3)
    calls = []
    real = oe.link_response
    monkeypatch.setattr(oe, "link_response", lambda *a, **k: calls.append(k["I"]) or real(*a, **k))
    first = oe._Problem(d, "sign", scale)
    first.omega_cap = oe.SUBSTEP_GROWTH * omega0
    assert np.isfinite(first.simulate(x)[0]).all()
    # the next fit starts at a resonance 20 x the identification's start: 400 x less inertia
    x2 = x.copy()
    x2[oe._IDX["I"]] = 0.3 / 400.0
    later = oe._Problem(d, "sign", scale)
    later.omega_cap = first.omega_cap
    assert not np.isfinite(later.simulate(x2)[0]).any()
    assert calls == [0.3]
    # within the cap it simulates
    x3 = x.copy()
    x3[oe._IDX["I"]] = 0.3 / 100.0
    assert np.isfinite(later.simulate(x3)[0]).all()


def test_a_shift_past_the_fits_limits_leaves_a_model_that_simulates(family_signals, monkeypatch):
    """The encoder noise's shift is removed after the fits. On the hinge grid it took a light
    cobot's motor inertia to exactly 0 (seed 35000, case 001, a transmission error: discovery
    against that model stopped with an error) and a heavy joint's link inertia past the fits'
    resonance cap (seed 33000, case 003: every spring sample NaN, an error). A shift that would
    take J below zero and I 10^4 x down (a resonance 100 x the start's, past the cap of 16 x)
    leaves J above zero, and the spring's samples are simulated at the shifted point."""
    import mocapfj.ident.output_error as oe_mod

    _, s = family_signals["cobot"]
    seen = {}

    def shift(*args):
        x = args[10]
        seen["x"] = x.copy()
        out = np.zeros(x.size)
        out[oe_mod._IDX["J"]] = 2.0 * x[oe_mod._IDX["J"]]
        out[oe_mod._IDX["I"]] = (1.0 - 1e-4) * x[oe_mod._IDX["I"]]
        return out

    monkeypatch.setattr(oe_mod, "_encoder_noise_shift", shift)
    monkeypatch.setattr(oe_mod, "_wiener_drive_shift", lambda *a: np.zeros(len(oe_mod.OE_NAMES)))
    r = oe_mod.identify_output_error(s.t, s.q, s.q_m, s.u, fs_hz=s.fs_hz, measured=s.measured,
                                     controller=(s.t_c, s.q_m_c, s.u_c, s.fs_c_hz), test_cubic=False,
                                     test_hysteresis=False, test_clock=False)
    v = dict(zip(oe_mod.OE_NAMES, r.fit.values))
    assert v["I"] == pytest.approx(1e-4 * seen["x"][oe_mod._IDX["I"]], rel=1e-6)
    assert 0.0 < v["J"] < 1e-3 * seen["x"][oe_mod._IDX["J"]]
    assert np.isfinite(r.delta_sim).all() and np.isfinite(r.tau_s).all()


def test_the_excitations_band_is_not_set_by_a_ringing_the_link_puts_on_the_motor():
    """A 0.1 Hz x 5 Fourier motor trajectory: its band is its top harmonic, 0.5 Hz. With a 15 Hz
    ringing carrying 3 % of the motor velocity's power (a transmission error at the link's
    resonance, hinge grid seed 33000, case 003) 99 % of the power lies below 15 Hz; the band is
    held to 3 x the frequency below which 95 % lies (1.5 Hz)."""
    from mocapfj.ident.output_error import excitation_bandwidth_hz

    fs = 1000.0
    t = np.arange(int(40 * fs)) / fs
    rng = np.random.default_rng(5)
    q_m = sum(0.3 / k * np.sin(2 * np.pi * 0.1 * k * t + rng.uniform(0, 2 * np.pi)) for k in range(1, 6))
    assert excitation_bandwidth_hz(q_m, fs) == pytest.approx(0.5, abs=0.03)
    qd = np.gradient(q_m) * fs
    a = math.sqrt(0.03 / 0.97 * np.mean(qd ** 2) * 2) / (2 * np.pi * 15.0)     # 3 % of the power
    ringing = q_m + a * np.sin(2 * np.pi * 15.0 * t)
    assert excitation_bandwidth_hz(ringing, fs, core=0.99) == pytest.approx(15.0, abs=0.03)
    assert excitation_bandwidth_hz(ringing, fs) == pytest.approx(1.5, abs=0.1)


def test_a_joint_without_gravity_whose_transmission_error_reverses_the_deflections_first_slope_is_identified():
    """Without gravity the first stiffness of output error's start rests on the Coulomb column
    alone, which a transmission error's 1 mrad swings reversed (1/k = -4.9e-4 rad/(N m)): a
    30 s version of hinge grid seed 38000, case 005 (a "vertical" light joint) stopped with "k:
    expected a positive stiffness", and `mocapfj discover` without a model file with it. The
    deflection's slope on the whole torque is then the start: identified, k is within 30 % of
    the truth (4212 for 5540 when written; the transmission error, not modelled here, is what
    discovery names)."""
    from mocapfj.ident.joint import identify_signals
    from mocapfj.synth.hinge import HingeCase, simulate_hinge

    case = HingeCase(
        name="vertical_te", seed=159735536, family="vertical", I=0.33907850604033485, J=0.17255066402184802,
        mglx=0.0, mgly=0.0, b=0.998499704390146, c=0.5839200087745845, v=0.5901669899591553, k=5540.438715268298,
        gear_ratio=120.0, friction_law="tanh", eps_rad_s=0.005197946589337662, sim_smoothing_rad_s=1e-05,
        f0_hz=0.17978478890593036,
        amplitudes_rad=(0.15297036744318035, 0.09745541511629487, 0.04403853226851145, 0.0323685489901282,
                        0.04577841150449904),
        phases_rad=(3.654771002762147, 3.535457155350577, 0.6099495738195148, 0.11234767542691353,
                    0.19170110771493548),
        peak_rad=0.3073132019474947, n_harmonics=5, q0_rad=0.35517622988694436, duration_s=30.0,
        ramp_s=1.2347404773834691, kp=10485.910332163503, kd=133.6336236985287, mocap_hz=250.0, controller_hz=1000.0,
        marker_noise_m=0.0003498819920500008, dropout_fraction=0.02338664673494492,
        dropout_burst_frames=7.831720807190056, torque_noise_Nm=0.03616144002431345, torque_noise_kind="quantised",
        torque_corr_time_s=0.0, torque_quantum_Nm=0.09357431362737456, motor_noise_rad=0.0, resolver_bits=18,
        marker_radii_m=(0.14713563952409117, 0.15285505093886223, 0.05717119411030754),
        marker_heights_m=(0.03774426740506818, -0.02430086431055907, -0.020282445246476218),
        marker_azimuths_rad=(3.5715452191639203, 5.837671689057781, 8.032782803569653),
        axis=(0.36600846197697423, 0.32401367480911863, -0.872383484654507),
        point_m=(1.6425054316261678, 0.5793881680027969, -0.6938927258025418), mocap_zero_rad=-0.6037757559476096,
        sim_max_step_s=None, sim_rtol=1e-08, spring="linear", spring_params=(),
        te_amplitudes_rad=(0.0009458308676769602, 0.0010394220473677702),
        te_phases_rad=(5.322595750060128, 4.820024952594175), te_orders=(1.0, 2.0))
    s = mocapfj.signals(simulate_hinge(case)[0])["j1"]
    r = identify_signals(s, gear_ratio=case.gear_ratio, spring_models=("linear",))
    assert abs(r.model.spring.k / case.k - 1.0) < 0.3, r.model.spring.k
