"""Scenario files (mocapfj.synth.scenario) and the shipped datasets."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from mocapfj import InputError
from mocapfj.dynamics import BoucWen, CoulombViscous, LinearSpring, PositionDependent, Stribeck
from mocapfj.synth.scenario import EFFECTS, joint_models, load_scenario, reference_trajectory

import numpy as np

DATASETS = Path(__file__).resolve().parents[2] / "datasets"
SUITE = sorted((DATASETS / "suite").glob("*.toml"))


def test_every_shipped_scenario_parses():
    files = sorted(DATASETS.glob("*.toml")) + SUITE
    assert {f.stem for f in DATASETS.glob("*.toml")} >= {"pa10_joint1", "pa10_joint2", "pa10_joints23"}
    for f in files:
        s = load_scenario(f)
        assert s.duration_s == 60.0 and s.joints, f


def test_pa10_joint2_carries_lightcap_banks_table1():
    j = load_scenario(DATASETS / "pa10_joint2.toml").joint("j2")
    # Lightcap and Banks (2007), Table I, joint 2 means
    assert (j.I, j.J, j.mglx, j.mgly, j.b) == (6.15, 12.57, 111.64, -7.80, 23.28)
    assert j.friction == {"model": "coulomb_viscous", "c": 9.28, "v": 18.38} and j.spring == {"model": "linear", "k": 1.19e4}
    s = load_scenario(DATASETS / "pa10_joint2.toml")
    assert s.measurement.mocap_hz == 250.0 and s.measurement.controller_hz == 1000.0 and s.measurement.marker_noise_m == 2e-4


def test_suite_plants_each_effect_once_in_an_ident_and_a_valid_trial():
    names = {f.stem for f in SUITE}
    assert names == {f"{e}_{t}" for e in (*EFFECTS, "control") for t in ("ident", "valid")}
    for f in SUITE:
        s = load_scenario(f)
        effect = f.stem.rsplit("_", 1)[0]
        if effect == "control":
            assert s.effects == ()
        else:
            assert [(e.name, e.joint) for e in s.effects] == [(effect, "j2")]
    a, b = load_scenario(DATASETS / "suite" / "stribeck_ident.toml"), load_scenario(DATASETS / "suite" / "stribeck_valid.toml")
    assert a.seed != b.seed and a.joint("j2").reference != b.joint("j2").reference


def test_suite_files_are_what_the_generator_writes(tmp_path):
    spec = importlib.util.spec_from_file_location("make_suite", DATASETS / "make_suite.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    written = mod.main(tmp_path)
    assert len(written) == len(SUITE)
    for p in written:
        assert p.read_text() == (DATASETS / "suite" / p.name).read_text(), p.name


def test_effects_change_the_true_model_only():
    s = load_scenario(DATASETS / "suite" / "hysteresis_ident.toml")
    assert isinstance(joint_models(s)["j2"].spring, BoucWen)
    assert isinstance(joint_models(s, with_effects=False)["j2"].spring, LinearSpring)
    s = load_scenario(DATASETS / "suite" / "position_dependent_friction_ident.toml")
    fr = joint_models(s)["j2"].friction
    assert isinstance(fr, PositionDependent) and isinstance(fr.base, CoulombViscous) and fr.orders == (8.0, 16.0)
    s = load_scenario(DATASETS / "suite" / "stribeck_ident.toml")
    assert isinstance(joint_models(s)["j2"].friction, Stribeck)
    s = load_scenario(DATASETS / "suite" / "drive_gain_ident.toml")
    assert joint_models(s)["j2"].drivetrain.torque_gain == 1.05 and joint_models(s, False)["j2"].drivetrain.torque_gain == 1.0


def test_reference_is_lightcap_banks_eq9_with_a_smooth_start():
    ref = {"f0_hz": 0.1, "q0_rad": 0.3, "amplitudes_rad": [0.3, 0.1], "phases_rad": [0.5, 1.0], "ramp_s": 2.0}
    fn = reference_trajectory(ref)
    q, qd = fn(np.array([0.0, 5.0]))
    assert q[0] == pytest.approx(0.3) and qd[0] == 0.0
    w = 2 * np.pi * 0.1
    want = 0.3 + 0.3 * (np.sin(w * 5 + 0.5) - np.sin(0.5)) + 0.1 * (np.sin(2 * w * 5 + 1.0) - np.sin(1.0))
    assert q[1] == pytest.approx(want, abs=1e-15)
    t = np.linspace(0, 8, 8001)
    q, qd = fn(t)
    np.testing.assert_allclose(np.gradient(q, t)[1:-1], qd[1:-1], atol=2e-5)  # qd is the derivative of q


# -- bad input ------------------------------------------------------------------------------------

def edit(tmp_path, old: str, new: str) -> Path:
    p = tmp_path / "s.toml"
    text = (DATASETS / "pa10_joint2.toml").read_text()
    assert old in text
    p.write_text(text.replace(old, new))
    return p


@pytest.mark.parametrize("old,new,message", [
    ('format = "mocapfj.scenario/1"', 'format = "mocapfj.scenario/2"', r"format: expected version 1 or older, got version 2"),
    ("axis = 2", "axis = 9", r"joints\[j2\]\.axis: expected a PA-10 joint number from 1 to 6, got 9"),
    ('spring = { model = "linear", k = 1.19e4 }', 'spring = { model = "linear", kk = 1.19e4 }',
     r"joints\[j2\]\.spring: expected parameters of linear: \['k', 'offset'\], got unknown \['kk'\]"),
    ("I = 6.15", "I = -6.15", r"joints\[j2\]\.I: expected a positive number, got -6\.15"),
    ("mocap_hz = 250.0", "mocap_rate = 250.0", r"measurement: expected keys among .*got unknown \['mocap_rate'\]"),
])
def test_bad_scenarios_are_named(tmp_path, old, new, message):
    with pytest.raises(InputError, match=r"s\.toml: " + message):
        load_scenario(edit(tmp_path, old, new))


def test_bad_effects_are_named(tmp_path):
    base = (DATASETS / "pa10_joint2.toml").read_text()
    for effect, message in [
        ('[[effects]]\nname = "magic"\njoint = "j2"\n', r"effects\[0\]\.name: expected one of \['hysteresis'"),
        ('[[effects]]\nname = "backlash"\njoint = "j9"\ngap_rad = 1e-3\n', r"effects\[0\]\.joint: expected one of the scenario's joints \['j2'\]"),
        ('[[effects]]\nname = "backlash"\njoint = "j2"\n', r"effects\[0\]: expected backlash keys \['gap_rad'\].*got missing \['gap_rad'\]"),
        ('[[effects]]\nname = "coupling"\njoint = "j2"\nsource = "j5"\ninertia_kgm2 = 1.0\n', r"effects\[0\]\.source: expected one of"),
    ]:
        p = tmp_path / "e.toml"
        p.write_text(base + "\n" + effect)
        with pytest.raises(InputError, match=r"e\.toml: " + message):
            load_scenario(p)
