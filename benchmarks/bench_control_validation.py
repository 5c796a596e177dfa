"""Validation by model-based control (Bompos, Artemiadis, Oikonomopoulos and Kyriakopoulos 2007,
§III.C) on a grid: joints x trajectories x model errors.

A computed-torque controller (model feedforward + motor-side PD, 400 Hz zero-order hold as the
PA-10's 2.5 ms cycle) tracks a windowed multi-sine on the true flexible joint
(:mod:`mocapfj.ident.control_validation`). Controllers, all on one plant per row:

- ``flexible``: built from the true parameters (what a perfect identification gives);
- ``flex s%``: every parameter (I, J, mglx, mgly, b, c, v, k) off by (1 + s N(0, 1)), s = 2, 5,
  10 %, `--draws` independent draws each (the size of the SDs identification reports; the worst
  draw and the median are shown);
- ``nominal k``: flexible, true parameters but k 30 % low (a catalogue stiffness);
- ``rigid``: true inertias, gravity and friction, the spring taken as infinitely stiff.

Joints (the families of mocapfj.synth.hinge, their central values): PA-10 joint 2 of Lightcap
and Banks (2007), Table I; a light cobot joint; a heavy industrial joint. Loop bandwidth 5 Hz,
damping 0.8 on I + J. Trajectories: slow (0.2 + 0.6 Hz) and fast (0.5 + 1.5 Hz) with a 1 s ramp.
The table gives link error RMS and maximum (mrad) and the ratio rigid / flexible.

Section 0: the fixed-step RK4 loop against the project's simulator: the torques each controller
commanded, replayed open loop through ``mocapfj.dynamics.simulate`` (LSODA, rtol 1e-10, step
<= 1/4 of the control period) from the same state; the largest link-angle difference.

Section 2 (skipped with --quick): models identified by mocapfj itself (``identify_joint``,
output error) from simulated recordings of the hinge generator (mocapfj.synth.hinge: the PA-10
reference row and the cobot and heavy cases of ``small_grid(3)``; markers, torque noise, resolver),
each used as the controller's model on its true joint; beside it the same model with every
parameter drawn again from its reported SD (x1 and x3, `--draws` draws) and the rigid model built
from the identified parameters (I + J, b, gravity, friction).

    python benchmarks/bench_control_validation.py            # ~1-2 min on one core
    python benchmarks/bench_control_validation.py --quick
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mocapfj.dynamics import CoulombViscous, JointModel, LinearSpring  # noqa: E402
from mocapfj.ident.control_validation import (ComputedTorque, WindowedSines, control_check, lab_gains,  # noqa: E402
                                              perturbed)

JOINTS = {
    "pa10_j2": JointModel(name="pa10_j2", gear_ratio=50, I=6.15, J=12.57, mglx=111.64, mgly=-7.80, b=23.28,
                          friction=CoulombViscous(9.28, 18.38), spring=LinearSpring(1.19e4)),
    "cobot": JointModel(name="cobot", gear_ratio=120, I=0.35, J=0.2, mglx=5.5, mgly=0.4, b=0.8,
                        friction=CoulombViscous(0.6, 0.5), spring=LinearSpring(4.5e3)),
    "heavy": JointModel(name="heavy", gear_ratio=200, I=180.0, J=60.0, mglx=4000.0, mgly=-300.0, b=300.0,
                        friction=CoulombViscous(150.0, 400.0), spring=LinearSpring(1.08e6)),
}
TRAJECTORIES = {
    "slow": WindowedSines(0.3, (0.4, 0.1), (0.2, 0.6), 1.0),
    "fast": WindowedSines(0.3, (0.3, 0.06), (0.5, 1.5), 1.0),
}
LEVELS = (0.02, 0.05, 0.10)


def one(name, plant, tname, traj, duration, draws, seed):
    rng = np.random.default_rng(seed)
    ctrls = [ComputedTorque("flexible", plant), ComputedTorque("rigid", plant, flexible=False),
             ComputedTorque("nominal_k", plant.with_(spring=LinearSpring(0.7 * plant.spring.k)))]
    for s in LEVELS:
        ctrls += [ComputedTorque(f"flex{s:g}_{d}", perturbed(plant, s, rng)) for d in range(draws)]
    kp, kd = lab_gains(plant, 5.0)
    t0 = time.perf_counter()
    r = control_check(plant, ctrls, traj, duration, kp=kp, kd=kd)
    dt = time.perf_counter() - t0
    rig = r.run("rigid")
    rows = []

    def row(label, rms, mx, share):
        rows.append(f"| {name} | {tname} | {label} | {1e3 * rms:.3f} | {1e3 * mx:.3f} | {share:.3f} | "
                    f"{rig.rms_rad / rms:.1f} | {rig.max_rad / mx:.1f} |")
    for n in ("flexible", "nominal_k", "rigid"):
        x = r.run(n)
        row(n, x.rms_rad, x.max_rad, x.feedback_share)
    for s in LEVELS:
        xs = [r.run(f"flex{s:g}_{d}") for d in range(draws)]
        worst = max(xs, key=lambda x: x.rms_rad)
        med = sorted(xs, key=lambda x: x.rms_rad)[len(xs) // 2]
        row(f"flex {100 * s:g}% median", med.rms_rad, med.max_rad, med.feedback_share)
        row(f"flex {100 * s:g}% worst", worst.rms_rad, worst.max_rad, worst.feedback_share)
    return rows, dt


def integrator_check():
    from mocapfj.dynamics import TorqueInput, simulate

    plant = JOINTS["pa10_j2"]
    kp, kd = lab_gains(plant, 5.0)
    r = control_check(plant, [ComputedTorque("flexible", plant), ComputedTorque("rigid", plant, flexible=False)],
                      TRAJECTORIES["fast"], 1.5, kp=kp, kd=kd)
    sj = plant.single_joint(1e-3)
    q0 = float(r.reference[0])
    out = []
    for b, run in enumerate(r.runs):
        u = r.u[b]

        def held(tt, u=u):
            return u[np.clip(np.floor(np.asarray(tt) * r.rate_hz + 1e-9).astype(int), 0, u.size - 1)]
        s = simulate(sj, r.t, TorqueInput(held), q0=[q0], qd0=[0.0], q_m0=sj.static_motor_angle(np.array([q0])),
                     qd_m0=[0.0], rtol=1e-10, atol=1e-12, max_step=1 / (4 * r.rate_hz))
        out.append(f"{run.name} {np.max(np.abs(s.q[:, 0] - r.q[b])):.1e} rad (its RMS error {run.rms_rad:.1e} rad)")
    print("RK4 loop against mocapfj.dynamics.simulate (PA-10 joint 2, fast, 1.5 s), largest |q difference|: "
          + "; ".join(out) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 s runs, 2 draws per error level")
    ap.add_argument("--draws", type=int, default=5)
    ap.add_argument("--duration", type=float, default=6.0)
    ap.add_argument("--seed", type=int, default=20070601)
    a = ap.parse_args()
    duration, draws = (3.0, 2) if a.quick else (a.duration, a.draws)
    integrator_check()
    print(f"## Computed-torque tracking on the true flexible joint ({duration:g} s, 400 Hz, 4 RK4 substeps, "
          f"{draws} draws per error level)\n")
    print("| joint | trajectory | controller model | RMS (mrad) | max (mrad) | feedback share | rigid/this RMS | "
          "rigid/this max |")
    print("|---|---|---|---|---|---|---|---|")
    total = 0.0
    for i, (name, plant) in enumerate(JOINTS.items()):
        for j, (tname, traj) in enumerate(TRAJECTORIES.items()):
            rows, dt = one(name, plant, tname, traj, duration, draws, a.seed + 10 * i + j)
            total += dt
            print("\n".join(rows), flush=True)
    print(f"\nsimulation time {total:.1f} s")
    if not a.quick:
        identified_section(duration, draws, a.seed)


def identified_section(duration, draws, seed):
    import mocapfj
    from mocapfj.synth.hinge import first_row_case, simulate_hinge, small_grid

    print("\n## Models identified by mocapfj (output error) from simulated recordings\n")
    print("| joint | trajectory | controller model | RMS (mrad) | max (mrad) | feedback share | rigid/this RMS | "
          "rigid/this max |")
    print("|---|---|---|---|---|---|---|---|")
    notes = []
    for case in [first_row_case(7)] + small_grid(3)[1:3]:
        t0 = time.perf_counter()
        rec, _ = simulate_hinge(case)
        s = mocapfj.signals(rec)["j1"]
        res = mocapfj.identify_joint(s.t, s.q, s.q_m, s.u, fs_hz=s.fs_hz, method="output_error",
                                     measured=s.measured, controller=(s.t_c, s.q_m_c, s.u_c, s.fs_c_hz))
        t_id = time.perf_counter() - t0
        plant = JointModel(name=case.family, gear_ratio=case.gear_ratio, I=case.I, J=case.J, mglx=case.mglx,
                           mgly=case.mgly, b=case.b, friction=case.friction_element(), spring=case.spring_element())
        ident = res.model
        rel = {n: abs(p.std / p.value) for n, p in res.params.items() if p.value != 0}
        err = {n: 100 * (p.value - getattr(case, n)) / abs(getattr(case, n)) for n, p in res.params.items()}
        notes.append(f"{case.family}: identification {t_id:.0f} s; errors (%) "
                     + ", ".join(f"{n} {e:+.2f}" for n, e in err.items()) + "; reported SDs (%) "
                     + ", ".join(f"{n} {100 * v:.2f}" for n, v in rel.items()))
        rng = np.random.default_rng(seed)
        ctrls = [ComputedTorque("identified", ident), ComputedTorque("true flexible", plant),
                 ComputedTorque("rigid (identified)", ident, flexible=False),
                 ComputedTorque("rigid (true)", plant, flexible=False)]
        for m in (1, 3):
            ctrls += [ComputedTorque(f"sd{m}_{d}", perturbed(ident, {n: m * v for n, v in rel.items()}, rng))
                      for d in range(draws)]
        kp, kd = lab_gains(plant, 5.0)
        for tname, traj in TRAJECTORIES.items():
            r = control_check(plant, ctrls, traj, duration, kp=kp, kd=kd)
            rig = r.run("rigid (identified)")

            def row(label, x):
                print(f"| {case.family} | {tname} | {label} | {1e3 * x.rms_rad:.3f} | {1e3 * x.max_rad:.3f} | "
                      f"{x.feedback_share:.3f} | {rig.rms_rad / x.rms_rad:.1f} | {rig.max_rad / x.max_rad:.1f} |")
            for n in ("identified", "true flexible", "rigid (identified)", "rigid (true)"):
                row(n, r.run(n))
            for m in (1, 3):
                xs = sorted((r.run(f"sd{m}_{d}") for d in range(draws)), key=lambda x: x.rms_rad)
                row(f"identified, redrawn {m} SD, median", xs[len(xs) // 2])
                row(f"identified, redrawn {m} SD, worst", xs[-1])
            sys.stdout.flush()
    print()
    for n in notes:
        print("- " + n)


if __name__ == "__main__":
    main()
