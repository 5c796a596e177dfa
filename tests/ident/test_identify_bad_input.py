"""Identification's bad-input list (issue 5): gaps in the link angle, NaN in the controller log,
a recording too short for the filters, signals of different lengths, no excitation."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocapfj import InputError, identify_joint
from mocapfj.ident import identify_signals, joint_signals

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """A 6 s pa10_joint2 bundle, loaded, and its joints stage (in memory)."""
    import mocapfj
    from mocapfj.synth.record import record_scenario, write_scenario_bundle
    from mocapfj.synth.scenario import load_scenario

    d = tmp_path_factory.mktemp("bad")
    sr = record_scenario(load_scenario(ROOT / "datasets" / "pa10_joint2.toml").with_duration(6.0), with_concealment=False)
    write_scenario_bundle(sr, d / "bundle")
    rec = mocapfj.load(d / "bundle")
    return rec, mocapfj.joints(rec).joint("j2").deflection


def _with_gap(d, start: int, n: int):
    q = d.q.copy()
    q[start:start + n] = np.nan
    return replace(d, q=q)


def test_a_short_gap_is_filled_and_counted(short):
    rec, d = short
    s = joint_signals(_with_gap(d, 500, 10), rec.controller, "j2")
    full = joint_signals(d, rec.controller, "j2")
    assert s.n_filled == 10 + full.n_filled
    assert np.isfinite(s.q).all()
    # linear interpolation over 44 ms of a smooth motion: within the angle noise (0.43 mrad) of the
    # angles it replaced, and every other sample untouched
    assert np.abs(s.q - full.q)[500:510].max() < 4 * 0.43e-3
    assert np.array_equal(np.delete(s.q, np.s_[500:510]), np.delete(full.q, np.s_[500:510]))


def test_a_gap_where_the_motion_bends_follows_the_motor(short):
    """A 0.1 s gap in a fast motion (a 3 Hz, 50 mrad swing added to the link and to the logged
    motor angle alike, so the deflection is the recording's): the fill follows the logged motor
    angle (the deflection interpolated, not the angle), within the angle noise (0.43 mrad RMS) of
    the angles it replaced; a linear fill of the angle itself misses them by the swing's curvature
    (about 20 mrad)."""
    rec, d = short
    j = rec.controller.joint_names.index("j2")
    swing = lambda t: 0.05 * np.sin(2 * np.pi * 3.0 * t)       # noqa: E731
    q_m = rec.controller.q_m.copy()
    q_m[:, j] += swing(rec.controller.t)
    ctrl = replace(rec.controller, q_m=q_m)
    fast = replace(d, q=d.q + swing(d.t))
    full = joint_signals(fast, ctrl, "j2")
    i = int(np.argmin(np.abs(full.t - 3.0 - 1.0 / 12.0))) - 12    # around a crest of the swing
    s = joint_signals(_with_gap(fast, i, 25), ctrl, "j2")
    gap = np.s_[i:i + 25]
    err = np.abs(s.q - full.q)[gap].max()
    lin = np.interp(full.t[gap], full.t[[i - 1, i + 25]], full.q[[i - 1, i + 25]])
    assert err < 4 * 0.43e-3
    assert np.abs(lin - full.q[gap]).max() > 10e-3


def test_a_long_gap_is_refused_with_where_it_is(short):
    """A 0.2 s gap: output error takes it (the link is simulated through it, its samples left
    out); motor-first, which differentiates the filled angle, refuses it with where it is; a gap
    over 2 s is refused by all."""
    rec, d = short
    s = joint_signals(_with_gap(d, 500, 50), rec.controller, "j2", source="bundle")   # 50 frames at 250 Hz: 0.204 s
    assert (~s.measured).sum() >= 50
    with pytest.raises(InputError, match=r"^bundle: joints\[j2\] link angle: expected gaps in the link angle of at "
                                         r"most 0\.1 s for motor_first, .*got 0\.204 s without an angle from "
                                         r"t = 2\.000 s"):
        identify_signals(s, method="motor_first", recording="bundle")
    with pytest.raises(InputError, match=r"^bundle: joints\[j2\] link angle: expected gaps in the link angle of at "
                                         r"most 2 s, got 2\.404 s without an angle from t = 2\.000 s"):
        joint_signals(_with_gap(d, 500, 600), rec.controller, "j2", source="bundle", min_valid=0.5)


def test_nan_in_the_controller_log_is_refused_with_its_time(short):
    rec, d = short
    tau = rec.controller.tau.copy()
    tau[3000:3005, 0] = np.nan
    with pytest.raises(InputError, match=r"controller log tau \(joint j2\): expected finite samples, got 5 NaN, the "
                                         r"first at t = 3\.0000 s"):
        joint_signals(d, replace(rec.controller, tau=tau), "j2")


def test_a_recording_too_short_for_the_filters_is_named(short):
    """3 s: output error needs its 1 s trims and 5 s to compare (7 s at 250 Hz); motor-first
    needs the trims and its 2 Hz split filter (4 s)."""
    rec, d = short
    s = joint_signals(d, rec.controller, "j2")
    n = int(3.0 * 250)
    with pytest.raises(InputError, match=r"t: expected at least 1750 samples \(7\.0 s\) for output error .*"
                                         r"got 750 samples \(3\.00 s\)"):
        identify_joint(s.t[:n], s.q[:n], s.q_m[:n], s.u[:n], fs_hz=250.0)
    with pytest.raises(InputError, match=r"t: expected at least 1000 samples \(4\.0 s\) for the filters and the trim, "
                                         r"got 750 samples \(3\.00 s\)"):
        identify_joint(s.t[:n], s.q[:n], s.q_m[:n], s.u[:n], fs_hz=250.0, method="motor_first")


def test_signals_of_different_lengths_and_no_excitation_are_named():
    t = np.arange(5000) / 250.0
    q = 0.3 * np.sin(2 * np.pi * 0.2 * t)
    with pytest.raises(InputError, match=r"t, q, q_m, u: expected four \(T,\) arrays"):
        identify_joint(t, q[:-3], q, q, fs_hz=250.0)
    # the motor stands still: nothing moves the joint's inertia (output error), the motor equation
    # cannot see J and b (motor-first)
    with pytest.raises(InputError, match=r"no independent excitation of \[.*'I \+ J'.*\]"):
        identify_joint(t, q, np.zeros_like(q), np.zeros_like(q), fs_hz=250.0)
    with pytest.raises(InputError, match=r"no independent excitation of \[.*'J'.*\]"):
        identify_joint(t, q, np.zeros_like(q), np.zeros_like(q), fs_hz=250.0, method="motor_first")


def _slow_joint(extra_inertia: float):
    """A slow heavy joint's rigid torque (60 s at 200 Hz, 0.05 and 0.15 Hz): 500 q_m' + 176 sgn(q_m')
    N m plus `extra_inertia` q_m'' (a negative one standing for what a joint that sticks puts in
    phase against the acceleration), its link 1e-6 rad/(N m) behind."""
    from mocapfj.ident.output_error import _initial

    fs = 200.0
    t = np.arange(0.0, 60.0, 1.0 / fs)
    q_m = 0.4 * np.sin(2 * np.pi * 0.05 * t) + 0.1 * np.sin(2 * np.pi * 0.15 * t + 1.0)
    qd = np.gradient(q_m, 1.0 / fs)
    u = extra_inertia * np.gradient(qd, 1.0 / fs) + 500.0 * qd + 176.0 * np.sign(qd)
    return (lambda uu: _initial(q_m - 1e-6 * u, q_m, uu, fs, 2.0, 100)), u


def test_a_negative_start_inertia_with_power_in_is_a_missing_friction_not_a_sign_error():
    """The start's rigid regression u = A q_m'' + B q_m' + c s + G gives A = I + J < 0 both for a
    sign error and for a friction its law lacks (a heavy joint whose breakaway friction equals its
    Coulomb level sticks at each reversal: A = -50.8 kg m^2 for 202 on the hinge grid, seed 39000,
    case 004, and the discovery without a model file exited with an error). The mean power the
    torque puts in tells them apart: positive, the start goes on with the inertia's torque held at
    5 % of the torque's RMS (it came out at 159 kg m^2, the Coulomb level within 4 %); negative (a
    joint of 200 kg m^2 with its torque's sign flipped), it is the sign error it names."""
    start, u = _slow_joint(-200.0)
    x = start(u)
    assert x[0] + x[5] > 0 and abs(x[3] - 176.0) < 0.1 * 176.0, x
    start, u = _slow_joint(200.0)
    with pytest.raises(InputError, match="puts power into it.*mean power -"):
        start(-u)
