"""Two-step identification (mocapfj.ident.twostep; Lightcap and Banks (2007), §II.A eq. 4-7, Table I joint 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocapfj import InputError
from mocapfj.ident.twostep import identify_two_step

ROOT = Path(__file__).resolve().parents[2]
# Lightcap and Banks (2007), Table I, joint 2 means (the pa10_joint2 scenario's true parameters)
TABLE1_J2 = dict(I=6.15, mglx=111.64, mgly=-7.80, c=9.28, v=18.38, J=12.57, b=23.28)
K_J2 = 1.19e4


@pytest.fixture(scope="module")
def recorded():
    from mocapfj.synth.record import record_scenario
    from mocapfj.synth.scenario import load_scenario

    return record_scenario(load_scenario(ROOT / "datasets" / "pa10_joint2.toml").with_duration(30.0),
                           with_concealment=False)


def _rel_err(result, ref):
    return {n: 100.0 * (result[n] / v - 1.0) for n, v in ref.items()}


def test_true_signals_recover_table1_joint2_and_two_step_is_better_conditioned(recorded):
    r = recorded.sim["j2"]
    res = identify_two_step(r.t, r.q[:, 0], r.q_m[:, 0], r.u[:, 0], fs_hz=1000.0)
    err = _rel_err(res.step1, TABLE1_J2)
    print("step 1 error %:", {k: round(v, 3) for k, v in err.items()}, "k:", res.spring["k"],
          "cond two/one:", res.cond_two_step, res.cond_one_step)
    for name, e in err.items():
        assert abs(e) < 2.0, (name, e)
    assert res.spring["k"] == pytest.approx(K_J2, rel=0.02)
    assert res.one_step["k"] == pytest.approx(K_J2, rel=0.02)
    assert res.cond_two_step < res.cond_one_step
    assert abs(res.q_zero_rad) < 1e-4          # the true q has the true zero
    # the reconstructed spring torque is the simulator's (eq. 7)
    tau_true = np.interp(res.t, r.t, r.tau_s[:, 0])
    assert np.sqrt(np.mean((res.tau_s - tau_true) ** 2)) < 0.01 * np.ptp(tau_true)
    assert res.spring.r2 > 0.999


@pytest.fixture(scope="module")
def chain(recorded, tmp_path_factory):
    import mocapfj
    from mocapfj.synth.record import write_scenario_bundle

    d = tmp_path_factory.mktemp("twostep")
    write_scenario_bundle(recorded, d / "bundle")
    # the 1 kHz log onto the 250 Hz mocap clock, the (rare) occluded frames filled
    s = mocapfj.signals(d / "bundle")["j2"]
    t, q, q_m, u, n_filled = s.t, s.q, s.q_m, s.u, s.n_filled
    res = identify_two_step(t, q, q_m, u, fs_hz=250.0, cutoff_hz=10.0, decimate=2)
    err = _rel_err(res.step1, TABLE1_J2)
    err["k (two-step)"] = 100.0 * (res.spring["k"] / K_J2 - 1.0)
    err["k (one-step)"] = 100.0 * (res.one_step["k"] / K_J2 - 1.0)
    err["I+J"] = 100.0 * ((res.step1["I"] + res.step1["J"]) / (TABLE1_J2["I"] + TABLE1_J2["J"]) - 1.0)
    err["v+b"] = 100.0 * ((res.step1["v"] + res.step1["b"]) / (TABLE1_J2["v"] + TABLE1_J2["b"]) - 1.0)
    print("full chain, error %:", {k: round(v, 2) for k, v in err.items()},
          "rel std %:", dict(zip(res.step1.names, np.round(res.step1.rel_std_pct, 2))), "n missing q:", n_filled)
    return res, err


def test_full_chain_identifies_gravity_coulomb_sums_and_one_step_k(chain):
    """Mocap q (0.43 mrad at 250 Hz) through the pipeline: what the data determine well."""
    res, err = chain
    for name in ("mglx", "mgly", "c", "I+J", "v+b", "k (one-step)"):
        assert abs(err[name]) < 2.0, (name, err[name])
    assert res.cond_two_step < res.cond_one_step
    # the pipeline zeroes the mean deflection; step 2 finds that zero (true mean deflection ~ -1.4 mrad)
    assert -3e-3 < res.q_zero_rad < -0.5e-3


@pytest.mark.xfail(strict=True, reason=(
    "measured: with mocap q the link/motor split is not resolved on this 30 s trajectory: I -88 %, J +42 %, "
    "v -81 %, b +65 %, two-step k -8 % (ls_fit rel std of I 5 %, of v 51 %: it rests on delta'' and delta', "
    "buried in the 0.43 mrad angle noise, and the q'' noise biases I towards 0). Lightcap and Banks' 2 % is not met."))
def test_full_chain_meets_2_percent_for_every_parameter(chain):
    _, err = chain
    for name in (*TABLE1_J2, "k (two-step)"):
        assert abs(err[name]) < 2.0, (name, err[name])


def test_rigid_joint_does_not_excite_the_link_motor_split():
    """q_m == q: the columns q'' and q_m'' (q' and q_m') coincide, so I/J and v/b are not separable."""
    t = np.arange(20000) / 1000.0
    q = 0.3 * np.sin(2 * np.pi * 0.2 * t) + 0.1 * np.sin(2 * np.pi * 0.7 * t + 1.0)
    qd, qdd = np.gradient(q, t), np.gradient(np.gradient(q, t), t)
    u = 18.72 * qdd - 111.64 * np.sin(q) - 7.8 * np.cos(q) + 9.28 * np.tanh(qd / 1e-3) + 41.66 * qd
    with pytest.raises(InputError, match=r"no independent excitation of \['(I|J)', '(v|b)'\]|'(v|b)', '(I|J)'"):
        identify_two_step(t, q, q.copy(), u, fs_hz=1000.0)


def test_bad_input_is_refused():
    t = np.arange(1000) / 1000.0
    q = np.sin(t)
    with pytest.raises(InputError, match="uniform"):
        identify_two_step(t, q, q, q, fs_hz=250.0)
    qn = q.copy()
    qn[5] = np.nan
    with pytest.raises(InputError, match="q: expected finite"):
        identify_two_step(t, qn, q, q, fs_hz=1000.0)
    with pytest.raises(InputError, match="four"):
        identify_two_step(t, q[:-1], q, q, fs_hz=1000.0)


@pytest.fixture(scope="module")
def chain_60s(tmp_path_factory):
    """The full 60 s pa10_joint2 recording through mocapfj joints (the issue's acceptance data)."""
    import mocapfj
    from mocapfj.synth.record import record_scenario, write_scenario_bundle
    from mocapfj.synth.scenario import load_scenario

    d = tmp_path_factory.mktemp("motorfirst")
    sr = record_scenario(load_scenario(ROOT / "datasets" / "pa10_joint2.toml"), with_concealment=False)
    write_scenario_bundle(sr, d / "bundle")
    s = mocapfj.signals(d / "bundle")["j2"]
    return s.t, s.q, s.q_m, s.u


def test_motor_first_identifies_every_parameter_through_the_full_chain(chain_60s):
    """Motor equation first, then the link equation on the rebuilt link angle
    (mocapfj.ident.motorfirst), on the 60 s recording: I, mglx, mgly, c, v, J, b and k within 2 %
    of Lightcap and Banks (2007), Table I joint 2. Measured: I -0.97, mglx +0.02, mgly +0.01, c +0.02, v +1.91,
    J +0.47, b -1.55, k +0.16 %. (On true angles every parameter is within 0.35 %; what is left
    is the mocap angle's noise below 1 Hz, 46 urad RMS, which moves J and b by about 1 % from
    trial to trial and I twice that: benchmarks/bench_identify.py measures ten trials.)"""
    from mocapfj.ident.motorfirst import identify_motor_first

    res = identify_motor_first(*chain_60s, fs_hz=250.0)
    err = {n: 100.0 * (res[n] / v - 1.0) for n, v in {**TABLE1_J2, "k": K_J2}.items()}
    print("motor-first, full chain, error %:", {k: round(v, 2) for k, v in err.items()})
    assert all(abs(v) < 2.0 for v in err.values()), err
    assert res.hysteresis is None                     # a linear spring: the hysteresis test stays quiet
    # the zero found is the one the pipeline's mean-deflection alignment moved (true mean ~ -1.4 mrad)
    assert -3e-3 < res.q_zero_rad < -0.5e-3


def test_motor_first_recovers_the_true_parameters_from_true_signals(recorded):
    """Without measurement noise the method has no bias of its own: every parameter within 0.5 %
    (measured: I +0.32, v -0.11, the rest within 0.06 %)."""
    from mocapfj.ident.motorfirst import identify_motor_first

    r = recorded.sim["j2"]
    t = r.t[::4]
    res = identify_motor_first(t, r.q[::4, 0], r.q_m[::4, 0], r.u[::4, 0], fs_hz=250.0)
    for n, v in {**TABLE1_J2, "k": K_J2}.items():
        assert res[n] == pytest.approx(v, rel=0.005), n


def test_motor_first_refuses_a_recording_too_short_for_its_filters():
    t = np.arange(500) / 250.0
    q = 0.1 * np.sin(t)
    with pytest.raises(InputError, match=r"t: expected at least \d+ samples .* for the filters"):
        from mocapfj.ident.motorfirst import identify_motor_first
        identify_motor_first(t, q, q, q, fs_hz=250.0)
