"""Frequency-domain identification (mocapfj.ident.multisine, .frf, .frf_fit): accuracy and calibration.

1. Grid: three joints (ASSIST-like j1 K 1150 and j2 K 220 N m/rad of Makarov et al. 2012, a stiff joint with
   a light motor) x three process-noise levels x seeds, closed loop (motor PD), odd random-phase multisines,
   simulated by the independent state-space simulation of tests/ident/frf_sim.py. Per cell: the largest
   stiffness error, the RMS z-score of k, I, J and of the modes' frequencies and damping ratios (1 when the
   SDs are right), the reduced chi-square.
2. H1 against the indirect / harmonic-mean estimators under closed-loop process noise: the FRF's RMS relative
   error, mean |G - G0|^2 / var (the estimator's own variance; 1 when unbiased) and the stiffness fitted.
3. Periods and realisations: z-score calibration of the fit against M (P - 1), the variance's degrees of freedom.
4. ASSIST reproduction with mocapfj's own simulator (mocapfj.dynamics.simulate, a PD motor loop playing the
   multisine as q_ref through mocapfj.synth.scenario.reference_trajectory, a link-side torque disturbance,
   the controller log with resolver quantisation and torque noise): Ts = 3 ms, N_p = 4096, odd multisine
   0.5-12 Hz, 5 realisations, harmonic-mean estimator (Makarov et al. 2012, §5.2); the paper's K1 = 1150 and
   K2 = 220 N m/rad and modes between 4.5 and 8.5 Hz. The inertias are ours (the paper gives none).
5. A motor-side controller log only (no reference column, no period given) through `mocapfj frf`'s pipeline.
6. datasets/pa10_joint2.toml unchanged (Coulomb friction, gravity) playing a multisine: the linear fit's limits;
   6b. the same over 12 multisine seeds, the fit weighed by the noise alone and by noise and nonlinear distortion
   (simulations cached in benchmarks/.cache/frf_pa10).
7. The grid's joints with gravity planted (g = share x k): g fitted against the model without it.

    .venv/bin/python benchmarks/bench_frf.py [--quick] [--no-assist]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "ident"))

from frf_sim import plant_frf, simulate_multisine  # noqa: E402

from mocapfj.errors import InputError  # noqa: E402
from mocapfj.ident.frf import estimate_frf  # noqa: E402
from mocapfj.ident.frf_fit import TWO_INERTIA_PARAMS, fit_two_inertia, two_inertia_modes  # noqa: E402
from mocapfj.ident.multisine import design_multisine, multisine_realisations  # noqa: E402

FS = 1 / 0.003
JOINTS = {
    "assist_j1": (dict(J=0.75, I=1.165, k=1150.0, d=1.0, b=0.8, v=0.3), 12.0, 300.0, 30.0),
    "assist_j2": (dict(J=0.1938, I=0.2752, k=220.0, d=0.15, b=0.1, v=0.05), 12.0, 60.0, 6.0),
    "stiff": (dict(J=0.02, I=0.3, k=3000.0, d=0.5, b=0.05, v=0.2), 100.0, 100.0, 3.0),
}
NOISE = {"assist_j1": (0.5, 2.0, 5.0), "assist_j2": (0.1, 0.4, 1.0), "stiff": (0.2, 1.0, 3.0)}


def _fit_row(p, fit):
    truth = two_inertia_modes(**p)
    z = [(fit.params[n].value - p[n]) / fit.params[n].std for n in ("k", "I", "J")]
    z += [(m.f_hz - t[1]) / m.f_hz_std for m, t in zip(fit.modes, truth)]
    z += [(m.zeta - t[2]) / m.zeta_std for m, t in zip(fit.modes, truth)]
    return abs(fit.value("k") / p["k"] - 1) * 100, z, fit.chi2_red


def grid(seeds, periods=5, m=2):
    print("\n## 1. Grid: closed loop, process noise, indirect estimator, "
          f"{m} realisations x {periods - 1} periods of 2048 samples at 333 Hz\n")
    print("| joint | noise SD (N m) | runs | max k err % | z RMS k | z RMS I | z RMS J | z RMS f_a | z RMS f_r "
          "| z RMS zeta_a | z RMS zeta_r | chi2/dof |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, (p, fmax, kp, kd) in JOINTS.items():
        for noise in NOISE[name]:
            errs, zs, chis = [], [], []
            for seed in seeds:
                ms = design_multisine(FS, 2048, 0.5, fmax, rms=0.01, seed=seed)
                u, y, r = simulate_multisine(p, multisine_realisations(ms, m, seed=1000 + seed), periods, kp=kp, kd=kd,
                                             noise_sd=noise, seed=seed)
                e, z, c = _fit_row(p, fit_two_inertia(estimate_frf(u, y, FS, 2048, r=r)))
                errs.append(e)
                zs.append(z)
                chis.append(c)
            zr = np.sqrt(np.mean(np.square(zs), axis=0))
            print(f"| {name} | {noise:g} | {len(seeds)} | {max(errs):.2f} | " + " | ".join(f"{x:.2f}" for x in zr)
                  + f" | {np.mean(chis):.2f} |")


def gravity_grid(seeds, periods=5, m=2):
    """Section 7: the grid's joints under gravity (g = share x k planted in the independent
    simulator, the middle noise level): the default fit (g fitted) against the model without
    gravity (g held at 0)."""
    print("\n## 7. Gravity planted: the grid's joints with g = share x k (middle noise level), g fitted against g "
          "held at 0\n")
    print("| joint | g / k | runs | g fitted: max k err % | z RMS k | z RMS g | g held at 0: max k err % | z RMS k |")
    print("|---|---|---|---|---|---|---|---|")
    for name, (p, fmax, kp, kd) in JOINTS.items():
        noise = NOISE[name][1]
        for share in (-0.05, -0.009, 0.02):
            g = share * p["k"]
            hold = kp * p["k"] / (kp + p["k"]) + g          # the static stiffness the PD loop holds the link with
            if hold <= 0:
                print(f"| {name} | {share:+.3f} | 0 | - (not simulated: the PD loop cannot hold the link against "
                      f"gravity, kp k / (kp + k) + g = {hold:.4g} N m/rad; the recording would diverge) | | | | |",
                      flush=True)
                continue
            e1, z1, zg, e0, z0 = [], [], [], [], []
            for seed in seeds:
                ms = design_multisine(FS, 2048, 0.5, fmax, rms=0.01, seed=seed)
                u, y, r = simulate_multisine({**p, "g": g}, multisine_realisations(ms, m, seed=1000 + seed), periods,
                                             kp=kp, kd=kd, noise_sd=noise, seed=seed)
                F = estimate_frf(u, y, FS, 2048, r=r)
                for gs, errs, zs in ((None, e1, z1), (0.0, e0, z0)):
                    try:
                        fit = fit_two_inertia(F, gravity_stiffness=gs)
                    except InputError:
                        errs.append(np.nan)               # counted as a failed fit
                        continue
                    kk = fit.params["k"]
                    if not kk.determined:                  # said not determined: counted with the failures
                        errs.append(np.nan)
                        continue
                    errs.append(100 * abs(kk.value / p["k"] - 1))
                    zs.append((kk.value - p["k"]) / kk.std)
                    if fit.gravity_fitted:
                        zg.append((fit.gravity_stiffness - g) / fit.gravity_stiffness_std)
            rms = lambda z: float(np.sqrt(np.mean(np.square(z)))) if len(z) else float("nan")  # noqa: E731

            def worst(e):
                failed = int(np.isnan(e).sum())
                ok = [x for x in e if np.isfinite(x)]
                return (f"{max(ok):.2f}" if ok else "-") + (f" ({failed} failed or not determined)" if failed else "")
            print(f"| {name} | {share:+.3f} | {len(seeds)} | {worst(e1)} | {rms(z1):.2f} | {rms(zg):.2f} | "
                  f"{worst(e0)} | {rms(z0):.2f} |", flush=True)


def h1_bias(seeds):
    print("\n## 2. H1 against indirect and harmonic mean under closed-loop process noise (assist_j1, 1 realisation "
          "x 64 periods of 512 samples)\n")
    print("| noise SD (N m) | estimator | FRF RMS rel. error | mean abs(G - G0)^2 / var | k err % (fit) |")
    print("|---|---|---|---|---|")
    p, _, kp, kd = JOINTS["assist_j1"]
    ms = design_multisine(FS, 512, 0.5, 12.0, rms=0.01, detection_group=0, seed=1)
    for noise in (2.0, 5.0, 10.0):
        res = {e: ([], [], []) for e in ("h1", "indirect", "harmonic")}
        for seed in seeds:
            u, y, r = simulate_multisine(p, [ms], 65, kp=kp, kd=kd, noise_sd=noise, seed=seed)
            for est in res:
                F = estimate_frf(u, y, FS, 512, r=r, estimator=est)
                G0 = plant_frf(F.f_hz, p)
                res[est][0].append(np.sqrt(np.mean(np.abs(F.G / G0 - 1) ** 2)))
                res[est][1].append(np.mean(np.abs(F.G - G0) ** 2 / F.var))
                try:
                    res[est][2].append(abs(fit_two_inertia(F).value("k") / p["k"] - 1) * 100)
                except InputError:
                    res[est][2].append(np.nan)
        for est, (e, z, k) in res.items():
            kt = "fit failed (no anti-resonance left)" if np.all(np.isnan(k)) else f"{np.nanmean(k):.2f}" + (
                f" ({np.isnan(k).sum()} failed)" if np.isnan(k).any() else "")
            print(f"| {noise:g} | {est} | {np.mean(e):.4f} | {np.mean(z):.2f} | {kt} |")


def calibration(seeds):
    print("\n## 3. SD calibration against the variance's degrees of freedom (assist_j1, noise 2 N m)\n")
    print("| periods P | realisations M | M (P - 1) | max k err % | z RMS k | z RMS f_a | z RMS f_r | chi2/dof |")
    print("|---|---|---|---|---|---|---|---|")
    p, fmax, kp, kd = JOINTS["assist_j1"]
    for P, M in ((2, 1), (3, 1), (4, 2), (8, 1), (4, 5)):
        errs, zs, chis = [], [], []
        for seed in seeds:
            ms = design_multisine(FS, 2048, 0.5, fmax, rms=0.01, seed=seed)
            u, y, r = simulate_multisine(p, multisine_realisations(ms, M, seed=2000 + seed), P + 1, kp=kp, kd=kd,
                                         noise_sd=2.0, seed=seed)
            e, z, c = _fit_row(p, fit_two_inertia(estimate_frf(u, y, FS, 2048, r=r)))
            errs.append(e)
            zs.append(z)
            chis.append(c)
        zr = np.sqrt(np.mean(np.square(zs), axis=0))
        print(f"| {P} | {M} | {M * (P - 1)} | {max(errs):.2f} | {zr[0]:.2f} | {zr[3]:.2f} | {zr[4]:.2f} | "
              f"{np.mean(chis):.2f} |")


def assist(n_real=5, periods=3, joints=(("assist_j1", 0.5), ("assist_j2", 0.1))):
    from mocapfj.dynamics import CoulombViscous, LinearSpring, SingleJoint
    from mocapfj.dynamics.simulate import PID, controller_log, simulate
    from mocapfj.synth.scenario import reference_trajectory

    print(f"\n## 4. ASSIST (Makarov et al. 2012) with mocapfj.dynamics.simulate: Ts 3 ms, N_p 4096, odd multisine "
          f"0.5-12 Hz, {n_real} realisations x {periods} periods (first dropped)\n")
    print("| joint | K paper (N m/rad) | estimator | K fitted | K err % | K SD % | anti-resonance (Hz) | resonance (Hz) "
          "| zeta_a | zeta_r | true modes (Hz) | sim s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    N = 4096
    for name, noise in joints:
        p, fmax, kp, kd = JOINTS[name]
        model = SingleJoint(I=p["I"], J=p["J"], spring=LinearSpring(p["k"]), b=p["b"], d=p["d"],
                            friction=CoulombViscous(0.0, p["v"]))
        ms = design_multisine(FS, N, 0.5, fmax, rms=0.01, seed=3)
        U, Y, R = [], [], []
        t0 = time.time()
        for i, real in enumerate(multisine_realisations(ms, n_real, seed=40)):
            ref = reference_trajectory(real.to_reference())
            t = np.arange(periods * N) / FS
            rng = np.random.default_rng(50 + i)
            w = rng.normal(0.0, noise, t.size)
            res = simulate(model, t, PID(ref, kp=kp, kd=kd), tau_ext=lambda tt, w=w: np.interp(tt, t, w),
                           rtol=1e-6, atol=1e-9)
            log = controller_log(res, FS, rng=rng, quantum_rad=2 * np.pi / 2 ** 20, current_noise_sd=0.01 * noise)
            n = min(log.t.size, t.size)
            U.append(log.tau[:n, 0])
            Y.append(log.q_m[:n, 0])
            R.append(ref(log.t[:n])[0])
        sim_s = time.time() - t0
        true = ", ".join(f"{f:.4f}" for _, f, _ in two_inertia_modes(**p))
        for est in ("harmonic", "indirect"):
            F = estimate_frf(np.array(U), np.array(Y), FS, N, r=np.array(R), estimator=est)
            fit = fit_two_inertia(F)
            k = fit.params["k"]
            fa, fr = fit.modes
            print(f"| {name} | {p['k']:g} | {est} | {k.value:.1f} | {100 * (k.value / p['k'] - 1):+.2f} | "
                  f"{100 * k.std / k.value:.2f} | {fa.f_hz:.4f} +- {fa.f_hz_std:.2g} | {fr.f_hz:.4f} +- {fr.f_hz_std:.2g} "
                  f"| {fa.zeta:.4f} | {fr.zeta:.4f} | {true} | {sim_s:.0f} |")


def motor_only():
    """A log as a robot controller writes it (mocapfj.dynamics.controller_log: resolver quantisation,
    torque noise), closed loop, a 2 s ramp, no reference column, no period given: `mocapfj frf`
    finds the period from the input and the transient from the data (pipeline.frf.run_frf)."""
    import tempfile

    from mocapfj.dynamics import CoulombViscous, LinearSpring, SingleJoint
    from mocapfj.dynamics.simulate import PID, controller_log, simulate
    from mocapfj.io.csvio import write_csv_columns
    from mocapfj.pipeline.frf import run_frf
    from mocapfj.synth.scenario import reference_trajectory

    print("\n## 5. Motor-side controller log only (mocapfj.dynamics.simulate, 200 Hz, period 5.12 s, 5 periods, "
          "no reference, no period given)\n")
    print("| joint | k err % | k SD % | anti-resonance err % | resonance err % | periods used | sim s |")
    print("|---|---|---|---|---|---|---|")
    p, _, kp, kd = JOINTS["assist_j2"]
    model = SingleJoint(I=p["I"], J=p["J"], spring=LinearSpring(p["k"]), b=p["b"], d=p["d"],
                        friction=CoulombViscous(0.0, p["v"]))
    fs, N, P = 200.0, 1024, 5
    ms = design_multisine(fs, N, 0.5, 20.0, rms=0.02, seed=2)
    ref = reference_trajectory(ms.to_reference(ramp_s=2.0))
    t = np.arange(P * N) / fs
    w = np.random.default_rng(1).normal(0, 0.2, t.size)
    t0 = time.time()
    res = simulate(model, t, PID(ref, kp=kp, kd=kd), tau_ext=lambda tt: np.interp(tt, t, w), rtol=1e-6, atol=1e-9)
    sim_s = time.time() - t0
    log = controller_log(res, fs, rng=np.random.default_rng(2), resolver_bits=18, gear_ratio=100.0, current_noise_sd=0.02)
    with tempfile.TemporaryDirectory() as d:
        write_csv_columns(Path(d) / "log.csv", {"time": log.t, "qm_j1": log.q_m[:, 0], "tau_j1": log.tau[:, 0]})
        s = run_frf(Path(d) / "log.csv", Path(d) / "out", input="tau_j1", output="qm_j1")
    truth = two_inertia_modes(**p)
    k = s["model"]["params"]["k"]
    fa, fr = s["modes"]
    print(f"| assist_j2 | {100 * (k['value'] / p['k'] - 1):+.2f} | {100 * k['std'] / k['value']:.2f} | "
          f"{100 * (fa['f_hz'] / truth[0][1] - 1):+.2f} | {100 * (fr['f_hz'] / truth[1][1] - 1):+.2f} | "
          f"{s['frf']['n_periods']} | {sim_s:.0f} |")


def pa10_joint2():
    """datasets/pa10_joint2.toml as it is (Coulomb friction, gravity about q0 = 0.3 rad, the scenario's PD
    loop) playing an odd multisine 0.5-20 Hz at 200 Hz, through `mocapfj frf`'s pipeline with the reference."""
    import tempfile

    from mocapfj.io.csvio import write_csv_columns
    from mocapfj.pipeline.frf import run_frf

    print("\n## 6. PA-10 joint 2 scenario (Coulomb friction 9.28 N m, gravity), multisine reference, 200 Hz\n")
    print("| gravity stiffness (N m/rad) | k err % | k SD % | anti-resonance err % | resonance err % | "
          "odd distortion dB | chi2/dof |")
    print("|---|---|---|---|---|---|---|")
    log, p, g = _pa10_log(2)
    # the truth's modes include gravity's stiffness about the record's mean angle (the physical joint)
    truth = two_inertia_modes(**p, g=g)
    for g_held in (0.0, g, None):            # without the gravity term, the rigid part known, g fitted
        with tempfile.TemporaryDirectory() as d:
            write_csv_columns(Path(d) / "log.csv", {"time": log["t"], "qm_j2": log["qm"], "tau_j2": log["tau"],
                                                    "qref": log["ref"]})
            s = run_frf(Path(d) / "log.csv", Path(d) / "out", input="tau_j2", output="qm_j2", reference="qref",
                        gravity_stiffness=g_held)
        k = s["model"]["params"]["k"]
        fa, fr = s["modes"]
        gs = (f"fitted {s['gravity']['g_Nm_per_rad']:.1f} +- {s['gravity']['g_std_Nm_per_rad']:.1f} (true {g:.1f})"
              if g_held is None else f"{g_held:.1f}")
        print(f"| {gs} | {100 * (k['value'] / p['k'] - 1):+.2f} | {100 * k['std'] / k['value']:.2f} | "
              f"{100 * (fa['f_hz'] / truth[0][1] - 1):+.2f} | {100 * (fr['f_hz'] / truth[1][1] - 1):+.2f} | "
              f"{s['frf']['distortion']['odd']['db']:.1f} | {s['model']['chi2_red']:.2f} |")


def _pa10_log(seed, rms=0.01):
    """Section 6's recording with multisine seed `seed` (also the noise's), cached in benchmarks/.cache/frf_pa10."""
    from mocapfj.dynamics.simulate import PID, controller_log, simulate
    from mocapfj.synth.scenario import joint_models, load_scenario, reference_trajectory

    path = ROOT / "benchmarks" / ".cache" / "frf_pa10" / f"rms{rms}_seed{seed}.npz"
    scn = load_scenario(ROOT / "datasets" / "pa10_joint2.toml")
    model = list(joint_models(scn).values())[0]
    if not path.exists():
        fs, N, P = 200.0, 1024, 5
        ms = design_multisine(fs, N, 0.5, 20.0, rms=rms, seed=seed)
        ref = reference_trajectory(ms.to_reference(q0_rad=0.3, ramp_s=2.0))
        res = simulate(model, np.arange(P * N) / fs, PID(ref, kp=2.0e4, kd=800.0), rtol=1e-6, atol=1e-9)
        log = controller_log(res, fs, rng=np.random.default_rng(seed), resolver_bits=16, gear_ratio=50.0,
                             current_noise_sd=0.3)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, t=log.t, qm=log.q_m[:, 0], tau=log.tau[:, 0], ref=ref(log.t)[0])
        tmp.replace(path)
    q0 = float(np.mean(np.load(path)["qm"]))
    g = -model.mglx * np.cos(q0) - model.mgly * np.sin(q0)
    p = dict(J=model.J, I=model.I, k=model.spring.k, d=model.d, b=model.b, v=model.friction.v)
    return np.load(path), p, g


def pa10_distortion(seeds):
    """Section 6's joint over multisine seeds, the fit weighed by the noise alone and by noise and distortion."""
    from dataclasses import replace

    print("\n## 6b. PA-10 joint 2 (Coulomb friction), one realisation per multisine seed: the fit weighed by the "
          "noise alone, and by the noise and the nonlinear distortion the detection lines show (g fitted)\n")
    print("| multisine seed | noise: k err % (SD %) | z | noise + distortion: k err % (SD %) | z | "
          "anti-resonance err % | resonance err % | chi2/dof | no reference (harmonic): k err % (SD %), modes err % |")
    print("|---|---|---|---|---|---|---|---|---|")
    err = {0: [], 1: [], 2: []}
    for seed in seeds:
        z, p, g = _pa10_log(seed)
        truth = two_inertia_modes(**p, g=g)
        frf = estimate_frf(z["tau"][None], z["qm"][None], 200.0, 1024, r=z["ref"][None], transient_periods="auto")
        row = [str(seed)]
        for i, F in enumerate((replace(frf, var_nl=None), frf)):
            fit = fit_two_inertia(F)
            k = fit.params["k"]
            err[i].append(100 * (k.value / p["k"] - 1))
            row += [f"{err[i][-1]:+.2f} ({100 * k.std / k.value:.2f})", f"{(k.value - p['k']) / k.std:+.1f}"]
        fa, fr = fit.modes
        row += [f"{100 * (fa.f_hz / truth[0][1] - 1):+.2f}", f"{100 * (fr.f_hz / truth[1][1] - 1):+.2f}",
                f"{fit.chi2_red:.2f}"]
        # the motor-side log alone: no reference column, the harmonic-mean estimator
        fit = fit_two_inertia(estimate_frf(z["tau"][None], z["qm"][None], 200.0, 1024, transient_periods="auto"))
        k, (fa, fr) = fit.params["k"], fit.modes
        err[2].append(100 * (k.value / p["k"] - 1))
        row.append(f"{err[2][-1]:+.2f} ({100 * k.std / k.value:.2f}), {100 * (fa.f_hz / truth[0][1] - 1):+.2f} / "
                   f"{100 * (fr.f_hz / truth[1][1] - 1):+.2f}")
        print("| " + " | ".join(row) + " |", flush=True)
    for i, name in ((0, "noise"), (1, "noise + distortion"), (2, "no reference, noise + distortion")):
        e = np.array(err[i])
        print(f"\n{name}: max |k err| {np.abs(e).max():.2f} %, RMS {np.sqrt(np.mean(e ** 2)):.2f} %, "
              f"{np.sum(np.abs(e) > 3)} of {e.size} beyond 3 %")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer seeds")
    ap.add_argument("--no-assist", action="store_true", help="skip the (slow) simulations with mocapfj.dynamics")
    ap.add_argument("--only-pa10", action="store_true", help="section 6 only")
    ap.add_argument("--only-gravity", action="store_true", help="section 7 only")
    args = ap.parse_args()
    if args.only_pa10:
        pa10_joint2()
        pa10_distortion(range(1, 5 if args.quick else 13))
        return
    if args.only_gravity:
        gravity_grid(list(range(4) if args.quick else range(8)))
        return
    seeds = range(4) if args.quick else range(12)
    t0 = time.time()
    grid(list(seeds))
    h1_bias(list(seeds)[:4])
    calibration(list(seeds) if not args.quick else range(6))
    if not args.no_assist:
        assist()
        motor_only()
        pa10_joint2()
        pa10_distortion(range(1, 5 if args.quick else 13))
    gravity_grid(list(range(4) if args.quick else range(8)))
    print(f"\n(total {time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
