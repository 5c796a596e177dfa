"""Validation by model-based control (Bompos et al. 2007): computed-torque tracking on the true
flexible joint with the flexible (identified) model against the rigid one."""

import numpy as np
import pytest

from mocapfj.dynamics import CoulombViscous, JointModel, LinearSpring
from mocapfj.errors import InputError
from mocapfj.ident.control_validation import (ComputedTorque, WindowedSines, control_check, lab_gains,
                                              perturbed)

# Lightcap and Banks (2007), Table I, joint 2 (datasets/pa10_joint2.toml)
PA10 = JointModel(name="j2", gear_ratio=50, I=6.15, J=12.57, mglx=111.64, mgly=-7.80, b=23.28,
                  friction=CoulombViscous(9.28, 18.38), spring=LinearSpring(1.19e4))
# the central values of the cobot and heavy families of mocapfj.synth.hinge
COBOT = JointModel(name="cobot", gear_ratio=120, I=0.35, J=0.2, mglx=5.5, mgly=0.4, b=0.8,
                   friction=CoulombViscous(0.6, 0.5), spring=LinearSpring(4.5e3))
HEAVY = JointModel(name="heavy", gear_ratio=200, I=180.0, J=60.0, mglx=4000.0, mgly=-300.0, b=300.0,
                   friction=CoulombViscous(150.0, 400.0), spring=LinearSpring(1.08e6))
FAST = WindowedSines(0.3, (0.3, 0.06), (0.5, 1.5), 1.0)
SLOW = WindowedSines(-0.2, (0.4, 0.1), (0.2, 0.6), 0.8)


def test_trajectory_derivatives_match_finite_differences():
    t = np.linspace(0.0, 3.0, 30001)
    d = FAST.derivatives(t)
    assert np.allclose(d[:, 0], [0.3, 0, 0, 0, 0], atol=1e-12)           # at rest at q0
    for k in range(4):
        num = np.gradient(d[k], t)
        assert np.max(np.abs(num[5:-5] - d[k + 1][5:-5])) < 2e-3 * np.max(np.abs(d[k + 1]))


def test_flexible_feedforward_is_the_plant_inverse():
    # the feedforward's own formulas against the dynamics package's inverse model (link_torque,
    # motor_torque) with the motor acceleration by a spline derivative
    from scipy.interpolate import CubicSpline
    eps = 0.05
    c = ComputedTorque("id", PA10, friction_smoothing=eps)
    t = np.linspace(0.0, 3.0, 30001)                       # 0.1 ms: the spline resolves the friction reversals
    qm, qmd, uff = c.reference(FAST, t)
    sj = PA10.single_joint(eps)
    q, qd, qdd = FAST.derivatives(t)[:3]
    tau = sj.link_torque(q[:, None], qd[:, None], qdd[:, None])
    assert np.allclose(qm, q + tau[:, 0] / 1.19e4, atol=1e-12)
    sp = CubicSpline(t, qm)
    assert np.max(np.abs(sp(t, 1) - qmd)[10:-10]) < 1e-5
    u = sj.motor_torque(qm[:, None], qmd[:, None], sp(t, 2)[:, None], tau)[:, 0]
    assert np.max(np.abs(u - uff)[10:-10]) < 1e-3 * np.max(np.abs(uff))
    # the rigid feedforward: lumped inertia, no deflection
    qm_r, _, u_r = ComputedTorque("r", PA10, flexible=False, friction_smoothing=eps).reference(FAST, t)
    assert np.array_equal(qm_r, q)
    assert np.allclose(u_r, (6.15 + 12.57) * qdd + 23.28 * qd + sj.gravity(q) + sj.friction_torque(q[:, None], qd[:, None])[:, 0])


def test_step_convergence():
    kp, kd = lab_gains(PA10, 5.0)
    ctrls = [ComputedTorque("flexible", PA10), ComputedTorque("rigid", PA10, flexible=False)]
    a = control_check(PA10, ctrls, FAST, 1.2, kp=kp, kd=kd, substeps=2)
    b = control_check(PA10, ctrls, FAST, 1.2, kp=kp, kd=kd)            # the default, 4
    # RK4: halving the step divides the error by 16, so the default's error is ~|b - a| / 15.
    # measured |b - a| 4.6e-6 rad max (the errors are 1e-4 to 1e-2 rad), RMS errors within 4.5e-4
    assert np.max(np.abs(a.q - b.q)) < 1e-5
    for n in ("flexible", "rigid"):
        assert a.run(n).rms_rad == pytest.approx(b.run(n).rms_rad, rel=1e-3)


def test_pa10_identified_tracks_better_than_rigid():
    kp, kd = lab_gains(PA10, 5.0)
    rng = np.random.default_rng(7)
    ctrls = [ComputedTorque("flexible", PA10), ComputedTorque("rigid", PA10, flexible=False),
             ComputedTorque("sd2_a", perturbed(PA10, 0.02, rng)), ComputedTorque("sd2_b", perturbed(PA10, 0.02, rng))]
    r = control_check(PA10, ctrls, FAST, 2.0, kp=kp, kd=kd)
    # measured: RMS ratio 35, max ratio 16; the rigid error is the spring's deflection (G/k ~ 9 mrad)
    assert r.ratio("rigid", "flexible") > 15
    assert r.ratio("rigid", "flexible", "max") > 7
    assert r.run("rigid").rms_rad > 3e-3
    for n in ("sd2_a", "sd2_b"):
        assert r.ratio("rigid", n) > 5
    # Bompos et al. (2007): with a good model the feedback is a small share of the torque
    assert r.run("flexible").feedback_share < 0.05 < r.run("rigid").feedback_share
    d = r.to_dict()
    assert [x["name"] for x in d["runs"]] == ["flexible", "rigid", "sd2_a", "sd2_b"]
    assert d["rate_hz"] == 400.0 and d["trajectory"]["kind"] == "windowed_sines"


@pytest.mark.parametrize("plant, traj, floor", [(COBOT, FAST, 4.0), (HEAVY, SLOW, 5.0)])
def test_other_joints(plant, traj, floor):
    kp, kd = lab_gains(plant, 5.0)
    ctrls = [ComputedTorque("flexible", plant), ComputedTorque("rigid", plant, flexible=False),
             ComputedTorque("sd2", perturbed(plant, 0.02, np.random.default_rng(3)))]
    r = control_check(plant, ctrls, traj, 2.0, kp=kp, kd=kd)
    assert r.ratio("rigid", "flexible") > floor
    assert r.ratio("rigid", "sd2") > 1.5


def test_bad_input():
    kp, kd = lab_gains(PA10, 5.0)
    c = ComputedTorque("a", PA10)
    with pytest.raises(InputError, match="plant"):
        control_check("pa10.toml", [c], FAST, 1.0, kp=kp, kd=kd)
    with pytest.raises(InputError, match="distinct"):
        control_check(PA10, [c, c], FAST, 1.0, kp=kp, kd=kd)
    with pytest.raises(InputError, match="duration_s"):
        control_check(PA10, [c], FAST, 0.01, kp=kp, kd=kd)
    with pytest.raises(InputError, match="frequencies_hz"):
        WindowedSines(0.0, (0.1,), (-1.0,))
    with pytest.raises(InputError, match="model"):
        ComputedTorque("a", object())
    with pytest.raises(InputError, match="name"):
        control_check(PA10, [c], FAST, 0.1, kp=kp, kd=kd).run("nope")
    kp, kd = lab_gains(PA10, 80.0)                   # a loop far beyond what 400 Hz holds
    with pytest.raises(InputError, match="diverging"):
        control_check(PA10, [c], FAST, 0.5, kp=kp, kd=kd)


def test_perturbed_draws_have_the_stated_sd():
    rng = np.random.default_rng(11)
    ms = [perturbed(PA10, 0.05, rng) for _ in range(400)]
    for n in ("I", "J", "mglx", "b"):
        r = np.array([getattr(m, n) for m in ms]) / getattr(PA10, n) - 1
        assert abs(r.std() - 0.05) < 0.006 and abs(r.mean()) < 0.008
    k = perturbed(PA10, {"k": 0.1}, rng)
    assert k.spring.k != 1.19e4 and (k.I, k.J, k.mglx, k.b, k.friction) == (6.15, 12.57, 111.64, 23.28, PA10.friction)
    with pytest.raises(InputError, match="rel_sd"):
        perturbed(PA10, -0.1, rng)


def test_cli_control_check(capsys):
    import json
    from pathlib import Path

    from mocapfj.cli import main

    toml = Path(__file__).resolve().parents[2] / "datasets" / "pa10_joint2.toml"
    assert main(["control-check", str(toml), "--duration", "1.5", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["joint"] == "j2" and s["ratio_rms"] > 10 and [r["name"] for r in s["runs"]] == ["flexible", "rigid"]
    assert main(["control-check", str(toml), "--frequencies", "0.5,x"]) == 2
    assert "--frequencies" in capsys.readouterr().err
    assert main(["control-check", str(toml), "--joint", "j9"]) == 2
    assert "j9" in capsys.readouterr().err
