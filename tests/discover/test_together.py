"""Effects refitted from more than one start, and together: a transmission error refitted by output
error, a breakaway friction's rough fit, a second effect judged with the first refitted beside it,
and the SDs a found effect's parameters carry."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import mocapfj
from mocapfj.discover import engine
from mocapfj.dynamics import shift_signal
from mocapfj.synth.hinge import first_row_case, sample_cases, simulate_hinge, small_grid

from .conftest import nominal_of


def _recordings(case, offset_s: float = 0.0):
    """(trial, validation recording with new noise) of `case`, the link on a clock offset_s late."""
    out = []
    for c in (case, replace(case, seed=case.seed + 7)):
        sj = mocapfj.signals(simulate_hinge(c)[0])["j1"]
        if offset_s:
            q = shift_signal(sj.t, sj.q, -offset_s)
            sj = replace(sj, q=np.where(np.isfinite(q), q, sj.q))
        out.append({"j1": sj})
    return out


def test_a_transmission_error_the_equation_error_cannot_show_is_refitted_and_named():
    """A light cobot of the hinge grid (seed 26000, case 4: 27 s, deflection noise 3x the error's
    first order) with a transmission error of 93 and 431 urad at orders 1 and 2. Its
    equation-error test came out at p = 0.028 after the Bonferroni correction, above the 0.01
    screen, so it was never judged and nothing was found (validation fit 43.2 % against the true
    model's 57.4 %). Refitted by output error like the other effects, it is named, with both
    amplitudes within 3 of the SDs discovery reports for them."""
    amps = (9.2532e-05, 4.30595e-04)
    case = replace(sample_cases(6, 26000)[4], te_amplitudes_rad=amps, te_phases_rad=(3.47951, 4.79465),
                   te_orders=(1.0, 2.0))
    s, v = _recordings(case)
    d = engine.discover(s, {"j1": nominal_of(case)}, fs_hz=s["j1"].fs_hz, reidentify=False, validation=v)
    assert [e["name"] for e in d.effects][:1] == ["transmission_error"], (d.stopped, d.rejected)
    e = d.effects[0]
    for a, est, sd in zip(amps, e["parameters"]["amplitudes_rad"], e["parameter_sds"]["amplitudes_rad"]):
        assert abs(est - a) < 3.0 * sd, (a, est, sd)


def test_a_breakaway_friction_is_refitted_from_a_grid_of_starts():
    """The PA-10 reference joint, 30 s, with a breakaway friction of 9.28 N m over its Coulomb
    (vs 0.019 rad/s, exponent 2). Its simulated fit is rough in vs (sticking moves where it
    slips): refitted from the equation error's start alone it stayed at 3.6 N m and 0.029 rad/s,
    2 points below the truth on the trial. From the grid the excess and vs come back within 5 %."""
    excess, vs = 9.28, 0.018854
    case = replace(first_row_case(11), duration_s=30.0, friction_kind="stribeck", friction_params=(excess, vs, 2.0))
    s, v = _recordings(case)
    d = engine.discover(s, {"j1": nominal_of(case)}, fs_hz=s["j1"].fs_hz, reidentify=False, validation=v)
    assert [e["name"] for e in d.effects][:1] == ["stribeck"], (d.stopped, d.rejected)
    p = d.effects[0]["parameters"]
    assert p["fs"] - p["fc"] == pytest.approx(excess, rel=0.05) and p["vs"] == pytest.approx(vs, rel=0.05), p


def test_a_second_effect_is_judged_with_the_first_refitted_beside_it():
    """A PA-10 joint of the hinge grid (seed 26000, case 5, cut to 40 s) with a Bouc-Wen spring
    (alpha 0.7, beta = gamma = 232 rad^-1) and a -1.70 ms clock offset. The hysteresis found first
    takes part of the offset's lag (alpha 0.25), and the offset fitted with it held came out
    -0.33 ms. The second effect is now judged with the first refitted beside it, and the pair
    refitted together once both are found: the offset comes back within 0.5 ms and alpha within
    0.25."""
    c0 = sample_cases(6, 26000)[5]
    beta, offset = 231.788, -1.6997e-3
    case = replace(c0, duration_s=40.0, spring="bouc_wen", spring_params=(0.7, beta, beta))
    s, v = _recordings(case, offset)
    d = engine.discover(s, {"j1": nominal_of(c0)}, fs_hz=s["j1"].fs_hz, reidentify=False, validation=v)
    names = [e["name"] for e in d.effects]
    assert names[:2] == ["hysteresis", "time_delay"], (names, d.rejected)
    assert abs(d.effects[1]["parameters"]["delay_s"] - offset) < 0.5e-3, d.effects[1]["parameters"]
    assert abs(d.effects[0]["parameters"]["alpha"] - 0.7) < 0.25, d.effects[0]["parameters"]
    assert "refitted_with" in d.effects[0]["location"]


def test_the_sds_of_a_found_effects_parameters_cover_their_errors():
    """A transmission error of 300 and 210 urad on four 12 s PA-10 recordings that differ in their
    noise only: the amplitudes' and phases' errors over the SDs discovery reports for them have an
    RMS between 0.4 and 2 (0.9 when written; SDs from the trial's noise projected on each
    parameter's change of the prediction, tournament.Judge.parameter_sds)."""
    case = replace(small_grid(6)[0], duration_s=12.0)
    amps, phases = (3.0e-4, 2.1e-4), (0.4, 2.0)
    zs = []
    for k in range(4):
        c = replace(case, seed=case.seed + 2000 + k, te_amplitudes_rad=amps, te_phases_rad=phases, te_orders=(1.0, 2.0))
        s = {"j1": mocapfj.signals(simulate_hinge(c)[0])["j1"]}
        d = engine.discover(s, {"j1": nominal_of(case)}, fs_hz=s["j1"].fs_hz, effects=("transmission_error",),
                            reidentify=False)
        e = d.effects[0]
        p, sd = e["parameters"], e["parameter_sds"]
        zs += [(a - b) / c_ for a, b, c_ in zip(p["amplitudes_rad"], amps, sd["amplitudes_rad"])]
        zs += [math.remainder(a - b, 2 * math.pi) / c_ for a, b, c_ in zip(p["phases_rad"], phases, sd["phases_rad"])]
    rms = math.sqrt(float(np.mean(np.square(zs))))
    assert 0.4 < rms < 2.0, zs


def test_each_residual_familys_leaders_are_judged_when_the_other_family_crowds_the_pool():
    """tournament.pool: the equation error's criteria of the spring and the link residuals are not
    one scale. Beside a large transmission error fitted a little off, five spring effects ranked
    ahead of a Coulomb asymmetry of 111 noise SDs, which was never judged (hinge grid seed 38000,
    case 002; judged, it is named within 1 SD of its planted levels). The pool takes POOL_SIZE by
    the criterion and each family's FAMILY_LEADERS best besides; the order stays the criterion's."""
    from mocapfj.discover.effects import Candidate
    from mocapfj.discover.tournament import FAMILY_LEADERS, POOL_SIZE, pool

    def cand(name, family, crit):
        c = Candidate(name, family, {}, 1, np.zeros(0), lambda m: m, {}, lambda g: "", rebuild=lambda th: None)
        return ("j1", c, {"criterion": crit, "explained_Nm": 0.0, "p_value": 1.0})

    spring = [cand(n, "spring", c) for n, c in (("stiffening", -90.1), ("hysteresis", -72.0), ("backlash", -71.6),
                                                ("drive_gain", 6.1), ("time_delay", 6.6))]
    link = [cand(n, "link", c) for n, c in (("stribeck", 12.0), ("friction_asymmetry", 12.4), ("gravity_mismatch", 24.4),
                                            ("position_dependent_friction", 32.0))]
    got = [c.name for _, c, _ in pool(spring + link, 9, {"j1": 0.0}, 0.01)]
    assert (POOL_SIZE, FAMILY_LEADERS) == (5, 2)
    assert got == ["stiffening", "hysteresis", "backlash", "drive_gain", "time_delay", "stribeck", "friction_asymmetry"]
    # a family already among the first POOL_SIZE adds nothing
    mixed = spring[:4] + [cand(n, "link", c) for n, c in (("stribeck", -80.0), ("friction_asymmetry", -60.0),
                                                          ("gravity_mismatch", 24.4))]
    assert [c.name for _, c, _ in pool(mixed, 7, {"j1": 0.0}, 0.01)] == [
        "stiffening", "stribeck", "hysteresis", "backlash", "friction_asymmetry"]
