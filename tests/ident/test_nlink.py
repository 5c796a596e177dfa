"""n-link flexible-joint identification (mocapfj.ident.nlink) on pa10_joints23: joints 2 and 3
moving together through Pinocchio, Lightcap and Banks (2007), Table I motor, friction and spring parameters."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mocapfj import InputError
from mocapfj.ident.nlink import identify_nlink_motor_first
from mocapfj.ident.regressor import base_from_standard, standard_parameters

ROOT = Path(__file__).resolve().parents[2]
FC, FV = np.array([9.28, 5.81]), np.array([18.38, 5.79])        # Lightcap and Banks (2007), Table I, joints 2 and 3
MOTOR = {"j2": dict(J=12.57, b=23.28, k=1.19e4), "j3": dict(J=2.48, b=6.35, k=4.60e3)}


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    from mocapfj.synth.record import record_scenario, scenario_urdf, write_scenario_bundle
    from mocapfj.synth.scenario import load_scenario

    scn = load_scenario(ROOT / "datasets" / "pa10_joints23.toml").with_duration(30.0)
    sr = record_scenario(scn, with_concealment=False)
    d = tmp_path_factory.mktemp("nlink")
    write_scenario_bundle(sr, d / "bundle")
    urdf = scenario_urdf(scn)
    phi, _ = standard_parameters(urdf, coulomb=FC, viscous=FV, armature=False)
    return sr, d, urdf, phi


def _errors(res, phi):
    beta = base_from_standard(phi, res.base_idx, res.Kd)
    return {n: (v, b) for n, v, b in zip(res.base.names, res.base.values, beta)}


def test_true_signals_give_the_base_parameters_and_motors(recorded):
    """No measurement noise: the method has no bias of its own (measured: every base parameter
    within 0.25 % or 6e-4 kg m, every motor parameter within 0.01 %)."""
    sr, _, urdf, phi = recorded
    r = sr.sim["j2"]
    s = slice(0, None, 4)
    res = identify_nlink_motor_first(urdf, r.t[s], r.q[s], r.q_m[s], r.u[s], fs_hz=250.0)
    errs = _errors(res, phi)
    print({n: (round(v, 5), round(b, 5)) for n, (v, b) in errs.items()}, [m.motor.values for m in res.motors])
    for name, (v, b) in errs.items():
        assert v == pytest.approx(b, rel=0.005, abs=1e-3), name
    for m, name in zip(res.motors, ("j2", "j3")):
        for p, v in MOTOR[name].items():
            assert m.motor[p] == pytest.approx(v, rel=0.002), (name, p)


def test_through_the_mocap_chain(recorded, capsys):
    """`mocapfj identify` on the bundle (markers -> angles -> deflection), 30 s. Measured: the
    gravity base parameters within 0.05 % (mx_j3 +2.2 %, a 0.08 kg m term), friction within
    0.8 %, joint 2's motor within 1.2 %, both stiffnesses within 0.6 %. Joint 3's motor inertia
    is +15 % (and with it Izz_j3 -5 %, Izz_j2 + 0.2025 m_j3 +7 %): its link angle is measured
    against a moving parent cluster with 3 markers, 1.6 mrad noise partly shared with joint 2's,
    which the bias compensation (white noise) cannot take out."""
    from mocapfj.cli import main

    _, d, _, phi = recorded
    assert main(["identify", str(d / "bundle"), "--out", str(d / "out"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    nl = s["nlink"]
    assert nl["n_trials"] == 1 and len(nl["base_params"]) == 10
    joints = {j["name"]: j for j in s["joints"]}
    assert {j["method"] for j in joints.values()} == {"nlink_motor_first"}
    assert all(j["spring"]["model"] == "linear" for j in joints.values())
    # truth in the same base (the regrouping does not depend on the trajectory)
    from mocapfj.ident.regressor import base_parameters, nlink_regressor
    from mocapfj.synth.record import scenario_urdf
    from mocapfj.synth.scenario import load_scenario

    urdf = scenario_urdf(load_scenario(ROOT / "datasets" / "pa10_joints23.toml"))
    rng = np.random.default_rng(0)
    W, names = nlink_regressor(urdf, rng.uniform(-2, 2, (200, 2)), rng.uniform(-2, 2, (200, 2)),
                               rng.uniform(-5, 5, (200, 2)), armature=False)
    base_idx, Kd, base_names = base_parameters(W, names)
    truth = dict(zip(base_names, base_from_standard(phi, base_idx, Kd)))
    got = {n: v["value"] for n, v in nl["base_params"].items()}
    assert set(got) == set(truth)
    err = {n: 100 * (got[n] / truth[n] - 1) for n in truth if abs(truth[n]) > 1e-6}
    print({n: round(e, 2) for n, e in err.items()}, "mx_j2:", got["mx_j2"])
    for n in ("my_j2 - 0.45 m_j3", "my_j3", "fc_j2", "fv_j2", "fc_j3", "fv_j3"):
        assert abs(err[n]) < 1.5, (n, err[n])
    assert abs(err["mx_j3"]) < 5.0 and abs(got["mx_j2"]) < 0.005
    for n in ("Izz_j2 + 0.2025 m_j3", "Izz_j3"):
        assert abs(err[n]) < 10.0, (n, err[n])
    for name, p in (("j2", "J"), ("j2", "b"), ("j2", "k"), ("j3", "k"), ("j3", "b")):
        v = joints[name]["params"][p]["value"]
        assert v == pytest.approx(MOTOR[name][p], rel=0.05 if name == "j3" else 0.02), (name, p)


def test_bad_shapes_are_named(recorded):
    _, _, urdf, _ = recorded
    t = np.arange(2000) / 250.0
    Q = np.zeros((2000, 2))
    with pytest.raises(InputError, match=r"Q_m: expected shape \(2000, 2\)"):
        identify_nlink_motor_first(urdf, t, Q, Q[:, :1], Q, fs_hz=250.0)
