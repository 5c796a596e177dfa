"""Synthetic hinge recordings (mocapfj.synth.hinge): the signals obey the model, the markers the
stated geometry, the noise the stated SDs, and one case gives one bundle, byte for byte."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocapfj.io import load_recording, read_json
from mocapfj.rotations import rotate
from mocapfj.synth.hinge import (FAMILY_NAMES, HingeCase, dropout_mask, logged_torque, first_row_case, sample_cases,
                                 simulate_hinge, small_grid, write_hinge_bundle)


@pytest.fixture(scope="module")
def pa10():
    """PA-10 joint 2, 6 s (2 s ramp), sign friction, white torque noise."""
    case = replace(first_row_case(3), duration_s=6.0, motor_noise_rad=3e-5)
    return (case,) + simulate_hinge(case)


@pytest.fixture(scope="module")
def cobot():
    """A light joint with tanh friction and coloured torque noise, 5 s."""
    case = replace(small_grid(0)[1], duration_s=5.0)
    assert case.family == "cobot" and case.friction_law == "tanh" and case.torque_noise_kind == "coloured"
    return (case,) + simulate_hinge(case)


def _model_residuals(case, truth):
    """Spring, motor and link equation residuals from the true controller-rate signals, with the
    derivatives taken numerically (a check of the integration, not of the model's own algebra)."""
    s = truth["signals"]["controller"]
    t = s["t"]
    qd_m_num = np.gradient(s["q_m"], t)
    qdd_m_num = np.gradient(s["qd_m"], t)
    qd_num = np.gradient(s["q"], t)
    qdd_num = np.gradient(s["qd"], t)
    eps = case.eps_rad_s if case.friction_law == "tanh" else case.sim_smoothing_rad_s
    spring = s["tau_s"] - case.k * (s["q_m"] - s["q"])
    motor = case.J * qdd_m_num + case.b * s["qd_m"] + s["tau_s"] - s["u"]
    link = (case.I * qdd_num - case.mglx * np.sin(s["q"]) + case.mgly * np.cos(s["q"])
            + case.c * np.tanh(s["qd"] / eps) + case.v * s["qd"] - s["tau_s"])
    return dict(spring=spring, motor=motor, link=link, qd_m=qd_m_num - s["qd_m"], qd=qd_num - s["qd"])


@pytest.mark.parametrize("which", ["pa10", "cobot"])
def test_true_signals_satisfy_the_flexible_joint_equations(which, request):
    case, _rec, truth = request.getfixturevalue(which)
    r = _model_residuals(case, truth)
    s = truth["signals"]["controller"]
    u_rms = np.sqrt(np.mean(s["u"] ** 2))
    assert np.max(np.abs(r["spring"])) < 1e-9 * case.k
    interior = slice(5, -5)
    assert np.sqrt(np.mean(r["motor"][interior] ** 2)) < 2e-3 * u_rms
    # link: Coulomb switching at velocity reversals makes the numerical q'' rough there
    slow = np.abs(s["qd"]) > 50 * (case.eps_rad_s or case.sim_smoothing_rad_s)
    assert np.sqrt(np.mean(r["link"][interior][slow[interior]] ** 2)) < 2e-3 * u_rms
    assert np.sqrt(np.mean(r["qd_m"][interior] ** 2)) < 1e-3 * np.sqrt(np.mean(s["qd_m"] ** 2))
    # a real deflection, and a motor that does not follow the reference exactly
    assert truth["stats"]["deflection_std_rad"] > 1e-4
    assert truth["stats"]["tracking_error_rms_rad"] > 1e-5


def test_the_run_starts_at_rest_in_equilibrium(pa10):
    case, _rec, truth = pa10
    s = truth["signals"]["controller"]
    first = slice(0, 50)   # 50 ms: the reference's ramp has barely begun
    assert np.max(np.abs(s["qd"][first])) < 1e-3
    assert np.max(np.abs(s["tau_s"][first] - (-case.mglx * np.sin(s["q"][first]) + case.mgly * np.cos(s["q"][first])))) \
        < 1e-2 * case.gravity_magnitude


@pytest.mark.parametrize("which", ["pa10", "cobot"])
def test_markers_lie_on_the_stated_cluster_about_the_stated_axis(which, request):
    case, rec, truth = request.getfixturevalue(which)
    m = rec.markers
    assert m.labels == rec.joints[0].link_markers and rec.joints[0].parent_is_world
    n, p0 = np.asarray(case.axis), np.asarray(case.point_m)
    d = m.xyz - p0
    along = d @ n
    radial = np.linalg.norm(d - along[..., None] * n, axis=-1)
    np.testing.assert_allclose(np.nanmean(radial, axis=0), case.marker_radii_m, atol=3e-5)
    np.testing.assert_allclose(np.nanmean(along, axis=0), case.marker_heights_m, atol=3e-5)
    assert 0.05 <= min(case.marker_radii_m) and max(case.marker_radii_m) <= 0.8
    # the noise-free markers at the true link angle plus the mocap zero: residual = the marker noise
    q = truth["signals"]["mocap"]["q"]
    clean = p0 + rotate(n, (q + case.mocap_zero_rad)[:, None], case.template_m()[None])
    err = (m.xyz - clean)[np.isfinite(m.xyz[..., 0])]
    assert abs(np.std(err) / case.marker_noise_m - 1) < 0.05
    assert abs(np.mean(err)) < 3 * case.marker_noise_m / np.sqrt(err.size)


def test_controller_log_noise_is_as_asked(pa10, cobot):
    for case, rec, truth in (pa10, cobot):
        s = truth["signals"]["controller"]
        log = rec.controller
        np.testing.assert_array_equal(log.t, s["t"])
        quantum = truth["noise"]["q_m_quantum_rad"]
        assert math.isclose(quantum, 2 * np.pi / (2.0 ** case.resolver_bits * case.gear_ratio))
        q_quant = quantum * np.round(s["q_m"] / quantum)
        motor_err = log.q_m[:, 0] - q_quant
        if case.motor_noise_rad == 0:
            np.testing.assert_array_equal(motor_err, 0.0)
        else:
            assert abs(np.std(motor_err) / case.motor_noise_rad - 1) < 0.05
        torque_err = log.tau[:, 0] - s["u"]
        tol = 0.05 if case.torque_noise_kind == "white" else 0.3    # coloured: fewer independent samples
        assert abs(np.std(torque_err) / case.torque_noise_Nm - 1) < tol


@pytest.mark.parametrize("kind", ["white", "coloured", "quantised"])
def testlogged_torque_kinds_have_the_asked_sd(kind):
    sd = 0.7
    base = first_row_case(0)
    case = replace(base, torque_noise_Nm=sd, torque_noise_kind=kind, torque_corr_time_s=0.01,
                   torque_quantum_Nm=sd * math.sqrt(12 * 0.6) if kind == "quantised" else 0.0)
    u = np.linspace(-40.0, 40.0, 400_000)
    e = logged_torque(case, u, np.random.default_rng(1)) - u
    assert abs(np.std(e) / sd - 1) < 0.02 and abs(np.mean(e)) < 0.02
    lag1 = np.corrcoef(e[:-1], e[1:])[0, 1]
    if kind == "coloured":
        assert abs(lag1 - math.exp(-1 / (case.controller_hz * 0.01))) < 0.01
    elif kind == "white":
        assert abs(lag1) < 0.01
    if kind == "quantised":
        y = u + e
        np.testing.assert_allclose(y / case.torque_quantum_Nm, np.round(y / case.torque_quantum_Nm), atol=1e-9)


def testdropout_mask_lose_the_asked_share_in_bursts():
    lost = dropout_mask((200_000, 4), 0.02, 8.0, np.random.default_rng(2))
    assert abs(lost.mean() / 0.02 - 1) < 0.1
    starts = (lost[1:] & ~lost[:-1]).sum()
    assert 6.0 < lost.sum() / starts < 10.0


def test_same_case_same_bytes(tmp_path: Path):
    case = replace(small_grid(4)[2], duration_s=2.0, dropout_fraction=0.02)
    a, b = tmp_path / "a", tmp_path / "b"
    write_hinge_bundle(case, a)
    write_hinge_bundle(case, b)
    files = sorted(p.name for p in a.iterdir())
    assert {"recording.toml", "truth.json", "truth_mocap.csv", "controller.csv", "markers.c3d"} <= set(files)
    assert files == sorted(p.name for p in b.iterdir())
    for name in files:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    rec = load_recording(a)
    truth = read_json(a / "truth.json")
    assert rec.joints[0].name == truth["joint"] == "j1"
    assert truth["params"]["k"] == case.k and truth["family"] == "heavy"
    assert HingeCase(**truth["case"]) == case                     # truth.json rebuilds the case
    assert np.isnan(rec.markers.xyz).any() and rec.controller.n_samples == int(2.0 * case.controller_hz) + 1


def test_sampling_rules():
    cases = sample_cases(26, 5000)
    again = sample_cases(5, 5000)
    assert [c.to_dict() for c in again] == [c.to_dict() for c in cases[:5]]    # case i depends on (seed, i) only
    fams = [c.family for c in cases]
    assert set(fams) <= set(FAMILY_NAMES) and fams.count("vertical") == 2       # 1 in 13
    for c in cases:
        assert 0.05 <= c.f0_hz <= 0.3 and 3 <= c.n_harmonics <= 10
        assert 20 - 0.05 <= c.duration_s <= 120.05 and c.duration_s * c.f0_hz >= 2 - 1e-2
        assert math.radians(10) <= c.peak_rad <= math.radians(60)
        r = np.asarray(c.marker_radii_m)
        assert 3 <= r.size <= 5 and r.max() / r.min() <= 3 + 1e-9 and 0.05 <= r.min() and r.max() <= 0.8
        assert np.linalg.norm(c.point_m) <= 2.0 and abs(np.linalg.norm(c.axis) - 1) < 1e-12
        assert c.mocap_hz in (100, 120, 200, 250) and c.controller_hz in (500, 1000)
        assert 1e-4 <= c.marker_noise_m <= 5e-4 and 0 <= c.dropout_fraction <= 0.03
        assert c.motor_noise_rad == 0 or 1e-5 <= c.motor_noise_rad <= 1e-4
        assert (c.friction_law == "sign" and c.eps_rad_s == 0) or 0.002 <= c.eps_rad_s <= 0.05
        if c.family == "vertical":
            assert c.mglx == c.mgly == 0
        else:
            assert c.gravity_magnitude > 0
        # the reference's harmonics reproduce the stated peak
        tt = np.linspace(0, 1 / c.f0_hz, 4001)
        a, ph = np.asarray(c.amplitudes_rad), np.asarray(c.phases_rad)
        w = 2 * np.pi * c.f0_hz * np.arange(1, a.size + 1)
        f = (a * (np.sin(tt[:, None] * w + ph) - np.sin(ph))).sum(-1)
        assert abs(np.max(np.abs(f)) / c.peak_rad - 1) < 1e-3
    one = sample_cases(3, 7, family="cobot")
    assert all(c.family == "cobot" for c in one)
    grid = small_grid(0)
    assert [c.family for c in grid][:4] == ["pa10", "cobot", "heavy", "vertical"]
    assert all(20 - 0.05 <= c.duration_s <= 30.05 for c in grid)
    row = first_row_case(0)
    assert (row.I, row.k, row.mglx, row.duration_s, row.torque_noise_Nm) == (6.15, 1.19e4, 111.64, 40.0, 0.5)


@pytest.mark.parametrize("effect", ["stribeck", "asymmetric", "backlash", "transmission_error"])
def test_planted_effects_obey_their_own_equations(effect):
    """Each further effect, written out here from its definition (not the dynamics library), holds
    on the true signals; an effect left at its default leaves the case's digest as before."""
    base = replace(first_row_case(5), duration_s=3.0, ramp_s=0.5)
    kw = {"stribeck": dict(friction_kind="stribeck", friction_params=(3.0, 0.05, 1.0)),
          "asymmetric": dict(friction_kind="asymmetric", friction_params=(2.0, -4.0)),
          "backlash": dict(backlash_rad=4e-4),
          "transmission_error": dict(te_amplitudes_rad=(6e-5, 3e-5), te_phases_rad=(0.4, 2.0),
                                     te_orders=(1.0, 2.0))}[effect]
    case = replace(base, **kw)
    assert set(kw) <= set(case.to_dict()) and not set(kw) & set(base.to_dict())
    _rec, truth = simulate_hinge(case)
    s = truth["signals"]["controller"]
    q, qd, q_m, tau = s["q"], s["qd"], s["q_m"], s["tau_s"]
    eps = case.sim_smoothing_rad_s
    sg = np.tanh(qd / eps)
    delta = q_m - q
    if effect == "transmission_error":
        (a1, a2), (p1, p2) = case.te_amplitudes_rad, case.te_phases_rad
        th = case.gear_ratio * q_m
        delta = delta + a1 * np.sin(th + p1) + a2 * np.sin(2 * th + p2)
    if effect == "backlash":
        delta = np.sign(delta) * np.maximum(np.abs(delta) - 2e-4, 0.0)
        assert np.mean(np.abs(q_m - q) < 2e-4) > 0.005           # the free play is crossed
    assert np.max(np.abs(tau - case.k * delta)) < 1e-9 * case.k
    extra = np.zeros_like(qd)
    if effect == "stribeck":
        extra = 3.0 * np.exp(-np.abs(qd / 0.05)) * sg
    if effect == "asymmetric":
        extra = np.where(qd >= 0, 1.0, -1.0) * (2.0 * sg - 4.0 * qd)
    link = (case.I * np.gradient(qd, s["t"]) - case.mglx * np.sin(q) + case.mgly * np.cos(q) + case.c * sg
            + case.v * qd - tau)
    ok = (np.abs(qd) > 50 * eps) & (np.arange(qd.size) > 5) & (np.arange(qd.size) < qd.size - 5)
    rms = np.sqrt(np.mean((link + extra)[ok] ** 2))
    assert rms < 5e-3 * np.sqrt(np.mean(s["u"] ** 2))
    if effect in ("stribeck", "asymmetric"):                       # and the effect is there
        assert np.sqrt(np.mean(link[ok] ** 2)) > 3 * rms
