"""Fast and clamped identification on grids: the algebraic estimator and the logarithmic decrement
(Oueslati, Bearee, Gibaru and Moraru 2012), their pre-compensation, and the clamped end-effector
stiffness (Jubien, Abba and Gautier 2014).

1. Algebraic estimator on damped oscillations drawn independently of it (f0 3-20 Hz, zeta
   0.02-0.3, random phase, start in the decay, rest offset), windows of 0.6 to 2 periods, noise
   SD / amplitude 0.07 % (the Staubli tracker's resolution) to 3 %, sampled 25 or 100 times per
   period: error RMS and maximum of omega0 and zeta, share within 2 % / 5 %, z RMS (error / SD);
   the same windows fitted by nonlinear least squares (scipy curve_fit, damped cosine + offset,
   started 10 % off the truth) as the peer; the logarithmic decrement on 3-period records.
2. Staubli RX-170B axis 2 (their section 3.C-4.B) from 80 and 100 ms at Ts = 4 ms.
3. Pre-compensation (their eq. 17) on the project's simulator: plants with the model's form, with
   Coulomb friction it leaves out, with the damping on the spring instead of the link, the model
   identified from noisy data; peak and RMS of the link's tracking error before and after.
4. Clamped stiffness: the KR500 of their Tables 1-2 and random configurations and stiffnesses of
   the same robot, both methods, error, relative SD, z RMS with the Newey-West and classic SDs.
5. Against `identify` (output error, 16 s) on the same simulated Staubli joint, with and without
   Coulomb friction: the algebraic estimate after each stop (the link rings and turns back) and
   after each velocity step (it keeps its direction).

    python benchmarks/bench_algebraic.py            # ~1-2 min on one core
    python benchmarks/bench_algebraic.py --quick
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import curve_fit

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mocapfj.errors import InputError  # noqa: E402
from mocapfj.ident.algebraic import algebraic_estimate  # noqa: E402
from mocapfj.ident.decrement import log_decrement  # noqa: E402


def oscillation(rng, f0, zeta, fs_per_period, periods, rel_noise):
    w0 = 2 * math.pi * f0
    h = 1 / (f0 * fs_per_period)
    t = np.arange(0, periods / f0 + 1e-12, h)
    amp, t0, ph, rest = 1.5e-4, rng.uniform(0, 0.5 / f0), rng.uniform(0, 2 * math.pi), rng.uniform(-2e-4, 2e-4)
    wd = w0 * math.sqrt(1 - zeta ** 2)
    clean = rest + amp * np.exp(-zeta * w0 * (t + t0)) * np.cos(wd * (t + t0) + ph)
    return t, clean + rel_noise * amp * rng.standard_normal(t.size), w0


def peer_fit(t, y, w0, zeta):
    """Nonlinear least squares of c + e^(-zeta w0 t) (a cos wd t + b sin wd t), started 10 % off."""
    def f(t, w, z, a, b, c):
        wd = w * np.sqrt(max(1 - z ** 2, 1e-6))
        return c + np.exp(-z * w * t) * (a * np.cos(wd * t) + b * np.sin(wd * t))
    p0 = [1.1 * w0, 0.9 * zeta, y[0] - y.mean(), 0.0, y.mean()]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p, _ = curve_fit(f, t, y, p0=p0, maxfev=4000)
    return p[0], p[1]


def grid_algebraic(n_cases, seed0):
    print("\n## 1. Algebraic estimator (window in periods of f0; noise SD / initial amplitude)\n")
    print("| samples/period | window | noise | n | omega0 err RMS % | max % | <=2 % | zeta err RMS % | max % | <=5 % "
          "| z RMS omega0 / zeta | refused | median abs err omega0 / zeta %: algebraic | peer NLS | peer diverged |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for spp in (25, 100):
        for periods in (0.6, 0.8, 1.0, 2.0):
            for rel in (7e-4, 3e-3, 1e-2, 3e-2):
                rng = np.random.default_rng(seed0 + int(1e4 * rel) + 7 * spp + int(10 * periods))
                ew, ez, zw, zz, pw, pz, bad = [], [], [], [], [], [], 0
                for _ in range(n_cases):
                    f0, zeta = rng.uniform(3, 20), rng.uniform(0.02, 0.3)
                    t, y, w0 = oscillation(rng, f0, zeta, spp, periods, rel)
                    try:
                        e = algebraic_estimate(t, y)
                    except InputError:
                        bad += 1
                        continue
                    ew.append(e.omega0 / w0 - 1)
                    ez.append(e.zeta / zeta - 1)
                    zw.append((e.omega0 - w0) / e.omega0_std)
                    zz.append((e.zeta - zeta) / e.zeta_std)
                    try:
                        a, b = peer_fit(t, y, w0, zeta)
                        pw.append(a / w0 - 1)
                        pz.append(b / zeta - 1)
                    except RuntimeError:
                        pass
                ew, ez = 100 * np.array(ew), 100 * np.array(ez)
                rms = lambda x: float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")  # noqa: E731
                pw, pz = 100 * np.array(pw), 100 * np.array(pz)
                div = (np.abs(pw) > 20) | (np.abs(pz) > 50)
                med = lambda x: float(np.median(np.abs(x)))  # noqa: E731
                print(f"| {spp} | {periods:g} | {100 * rel:.2g} % | {len(ew)} | {rms(ew):.3g} | {np.abs(ew).max():.3g} | "
                      f"{100 * np.mean(np.abs(ew) <= 2):.0f} % | {rms(ez):.3g} | {np.abs(ez).max():.3g} | "
                      f"{100 * np.mean(np.abs(ez) <= 5):.0f} % | {rms(zw):.2f} / {rms(zz):.2f} | {bad} | "
                      f"{med(ew):.3g} / {med(ez):.3g} | {med(pw[~div]):.3g} / {med(pz[~div]):.3g} | {int(div.sum())} |")
    print("\n### Logarithmic decrement (3-period records)\n")
    print("| samples/period | noise | n | omega0 err RMS % | zeta err RMS % | z RMS omega0 / zeta | refused |")
    print("|---|---|---|---|---|---|---|")
    for spp in (25, 100):
        for rel in (7e-4, 3e-3, 1e-2, 3e-2):
            rng = np.random.default_rng(seed0 + 99 + int(1e4 * rel) + spp)
            ew, ez, zw, zz, bad = [], [], [], [], 0
            for _ in range(n_cases):
                f0, zeta = rng.uniform(3, 20), rng.uniform(0.02, 0.2)
                t, y, w0 = oscillation(rng, f0, zeta, spp, 3.0, rel)
                try:
                    e = log_decrement(t, y)
                except InputError:
                    bad += 1
                    continue
                ew.append(100 * (e.omega0 / w0 - 1))
                ez.append(100 * (e.zeta / zeta - 1))
                zw.append((e.omega0 - w0) / e.omega0_std)
                zz.append((e.zeta - zeta) / e.zeta_std)
            rms = lambda x: float(np.sqrt(np.mean(np.square(x)))) if len(x) else float("nan")  # noqa: E731
            print(f"| {spp} | {100 * rel:.2g} % | {len(ew)} | {rms(ew):.3g} | {rms(ez):.3g} | {rms(zw):.2f} / "
                  f"{rms(zz):.2f} | {bad} |")


def crlb(t, w0, zeta, a, b, c, sd):
    """Cramer-Rao SDs of (omega0, zeta) for c + e^(-zeta w0 t)(a cos wd t + b sin wd t) in white noise sd."""
    def f(p):
        w, z, a_, b_, c_ = p
        wd = w * math.sqrt(1 - z ** 2)
        return c_ + np.exp(-z * w * t) * (a_ * np.cos(wd * t) + b_ * np.sin(wd * t))
    p = np.array([w0, zeta, a, b, c])
    J = np.column_stack([(f(p + dp) - f(p - dp)) / (2 * dp[i]) for i, dp in
                         enumerate(np.diag(np.maximum(np.abs(p), 1e-6) * 1e-6))])
    C = sd ** 2 * np.linalg.inv(J.T @ J)
    return math.sqrt(C[0, 0]), math.sqrt(C[1, 1])


def staubli(n):
    print("\n## 2. Staubli RX-170B axis 2 (J 290.39 kg m^2, K 1.0794e6 N m/rad, zeta 0.163: f0 9.703 Hz)\n")
    J, K, Z = 290.39, 1.0794e6, 0.163
    w0 = math.sqrt(K / J)
    print("| window | noise SD (rad) | n | f0 mean (Hz) | f0 SD | zeta mean | zeta SD | max omega0 err % | "
          "max zeta err % | K mean (N m/rad) | mean reported SD f0 / zeta | Cramer-Rao SD f0 / zeta (RMS) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for dur in (0.08, 0.1):
        for sd in (1e-7, 1e-6):
            rng = np.random.default_rng(1601 + int(dur * 1e3) + int(sd * 1e8))
            t = np.arange(0, dur + 1e-12, 0.004)
            r = []
            for _ in range(n):
                wd = w0 * math.sqrt(1 - Z ** 2)
                t0, ph = rng.uniform(0, 0.1), rng.uniform(0, 2 * math.pi)
                y = 1e-4 + 1.5e-4 * np.exp(-Z * w0 * (t + t0)) * np.cos(wd * (t + t0) + ph) + sd * rng.standard_normal(t.size)
                try:
                    e = algebraic_estimate(t, y)
                except InputError:
                    continue
                amp = 1.5e-4 * math.exp(-Z * w0 * t0)
                cw, cz = crlb(t, w0, Z, amp * math.cos(wd * t0 + ph), -amp * math.sin(wd * t0 + ph), 1e-4, sd)
                r.append((e.f0_hz, e.zeta, e.stiffness(J)[0], e.f0_hz_std, e.zeta_std, cw / (2 * math.pi), cz))
            r = np.array(r)
            f0 = w0 / (2 * math.pi)
            print(f"| {dur * 1e3:.0f} ms | {sd:.0e} | {len(r)} | {r[:, 0].mean():.4f} | {r[:, 0].std():.3g} | "
                  f"{r[:, 1].mean():.4f} | {r[:, 1].std():.3g} | {100 * np.abs(r[:, 0] / f0 - 1).max():.3g} | "
                  f"{100 * np.abs(r[:, 1] / Z - 1).max():.3g} | {r[:, 2].mean():.5g} | {r[:, 3].mean():.3g} / "
                  f"{r[:, 4].mean():.3g} | {np.sqrt(np.mean(r[:, 5] ** 2)):.3g} / {np.sqrt(np.mean(r[:, 6] ** 2)):.3g} |")
    print("\nTheir discretisation, noise-free, 80 ms at 4 ms, their two equations (motor angle known, no offset), "
          "200 start phases:\n")
    print("| integrals | f0 median (Hz) | f0 10-90 % | zeta median | zeta 10-90 % |")
    print("|---|---|---|---|---|")
    rng = np.random.default_rng(80)
    t = np.arange(0, 0.08 + 1e-12, 0.004)
    wd = w0 * math.sqrt(1 - Z ** 2)
    starts = [(rng.uniform(0, 2 * math.pi), rng.uniform(0, 0.1)) for _ in range(200)]
    for rule in ("trapezoid", "spline"):
        r = []
        for ph, t0 in starts:
            y = 1.5e-4 * np.exp(-Z * w0 * (t + t0)) * np.cos(wd * (t + t0) + ph)
            try:
                e = algebraic_estimate(t, y, np.zeros(t.size), offset=False, damping="link", quadrature=rule)
            except InputError:
                continue
            r.append((e.f0_hz, e.zeta))
        r = np.array(r)
        lo, hi = np.percentile(r, [10, 90], axis=0)
        print(f"| {rule} | {np.median(r[:, 0]):.3f} | {lo[0]:.3f}-{hi[0]:.3f} | {np.median(r[:, 1]):.4f} | "
              f"{lo[1]:.4f}-{hi[1]:.4f} |")
    print("\nTheir numbers: eq. 8 (logarithmic decrement) zeta 0.1626, omega0 60.968 rad/s (f0 9.703 Hz); the "
          "algebraic estimator after 80 ms f0 8.972 Hz, zeta 0.1722 (7.35 % and 5.57 % from eq. 8, their words).")


def precomp(quick):
    from mocapfj.dynamics import CoulombViscous, LinearSpring, PrescribedMotor, SingleJoint, simulate
    from mocapfj.ident.precompensation import deflection_amplitude, jerk_limited_profile, precompensate

    print("\n## 3. Pre-compensation on the project's simulator (Staubli axis 2, jerk-limited moves of their Fig. 13)\n")
    J, K, Z = 290.39, 1.0794e6, 0.163
    D = 2 * Z * math.sqrt(K * J)
    deg = math.pi / 180
    plants = {
        "model's form (link viscous D)": SingleJoint(I=J, J=1.0, spring=LinearSpring(k=K), friction=CoulombViscous(0, D)),
        "+ Coulomb 120 N m": SingleJoint(I=J, J=1.0, spring=LinearSpring(k=K),
                                         friction=CoulombViscous(120.0, D, smoothing=1e-3)),
        "damping on the spring (d), not the link": SingleJoint(I=J, J=1.0, spring=LinearSpring(k=K), d=D),
    }
    moves = {"30 deg": (-20, 10), "120 deg (their Fig. 3 range)": (-70, 50)}
    if quick:
        moves = {"30 deg": (-20, 10)}
    print("| plant | move | model | peak before (mrad) | peak after | ratio | RMS before (mrad) | RMS after | ratio |")
    print("|---|---|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(17)
    for pname, plant in plants.items():
        for mname, (a, b) in moves.items():
            dur = abs(b - a) / 15 + 1.5
            t = np.arange(0, dur, 0.004)
            ref = jerk_limited_profile(t, a * deg, b * deg, 15 * deg, 50 * deg, 500 * deg, t0=0.2)[0]
            run = simulate(plant, t, PrescribedMotor.from_samples(t, ref))
            # identification run: a velocity step 5 -> 10 deg/s in 20 ms, 0.1 s window, u = motor
            ti = np.arange(0, 0.8, 0.004)
            pos = lambda x: 5 * deg * x + 5 * deg * (np.clip(x - 0.3, 0, 0.02) ** 2 / 0.04 + np.clip(x - 0.32, 0, None))  # noqa: E731
            vel = lambda x: 5 * deg + 5 * deg * np.clip((x - 0.3) / 0.02, 0, 1)                 # noqa: E731
            acc = lambda x: 250 * deg * ((x > 0.3) & (x < 0.32))                                 # noqa: E731
            idr = simulate(plant, ti, PrescribedMotor(lambda x: (pos(x), vel(x), acc(x) + 0 * x)))
            seg = slice(75, 101)
            for label, sd, form, method in (("eq. 17, noise 1e-7, damping auto", 1e-7, "auto", "eq17"),
                                            ("eq. 17, noise 1e-6, damping auto", 1e-6, "auto", "eq17"),
                                            ("eq. 17, noise 1e-7, damping link (their eq. 9)", 1e-7, "link", "eq17"),
                                            ("model inverse, noise 1e-7, damping auto", 1e-7, "auto", "inverse")):
                q = idr.q[:, 0] + sd * rng.standard_normal(ti.size)
                e = algebraic_estimate(ti[seg], q[seg], idr.q_m[seg, 0], damping=form)
                pc = precompensate(t, ref, e.omega0, e.zeta, damping=e.damping, method=method)
                after = simulate(plant, t, PrescribedMotor.from_samples(t, pc.command))
                b0, b1 = deflection_amplitude(run.q[:, 0] - ref), deflection_amplitude(after.q[:, 0] - ref)
                print(f"| {pname} | {mname} | {label} -> {e.damping} (f0 {e.f0_hz:.3f} Hz, zeta {e.zeta:.3f}) | "
                      f"{1e3 * b0['peak']:.3g} | "
                      f"{1e3 * b1['peak']:.3g} | {b0['peak'] / b1['peak']:.1f} | {1e3 * b0['rms']:.3g} | "
                      f"{1e3 * b1['rms']:.3g} | {b0['rms'] / b1['rms']:.1f} |")


def clamped(n):
    import pinocchio as pin

    from mocapfj.ident.clamped import KR500_CONFIGURATIONS, KR500_MDH, identify_clamped, mdh_model, simulate_clamped

    print("\n## 4. Clamped end-effector stiffness (KR500 MDH of Jubien et al. 2014, Table 1)\n")
    m = mdh_model(KR500_MDH, masses=(1200, 600, 450, 100, 60, 30))
    data = m.createData()
    noise = dict(torque_sd=100.0, force_sd=20.0, torque_drift_sd=150.0, force_drift_sd=45.0, offm=300.0,
                 wrench_gaps=[(20.0, 30.0)])
    print("| case | axis | method | n | k err RMS % | max % | rel. SD % (mean) | z RMS (Newey-West) | z RMS (eq. 16) | "
          "|W chi - Y| / |Y| % | motor vs wrench diff % (mean) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    cases = [("Table 2 conf. 1", 1, 0, None), ("Table 2 conf. 2", 2, 1, None)]
    cases += [("random q0 and k", None, ax, None) for ax in (0, 1, 2)]
    cases += [("conf. 1, noise x3", 1, 0, 3.0)]
    for name, conf, ax, scale in cases:
        rng = np.random.default_rng(4242 + ax + (conf or 0) * 10 + int(scale or 0))
        rows = {"motor": [], "wrench": []}
        diffs = []
        for _ in range(n):
            if conf is None:
                while True:
                    q0 = rng.uniform(-1.5, 1.5, 6)
                    q0[4] = rng.choice([-1, 1]) * rng.uniform(0.5, 1.5)
                    Jm = pin.computeFrameJacobian(m, data, q0, m.getFrameId("tool"), pin.LOCAL)
                    if np.linalg.cond(Jm) < 50 and abs(Jm[2, ax]) > 0.8:
                        break
                k = rng.uniform(2e6, 1e7, 6)
            else:
                q0, k = np.array(KR500_CONFIGURATIONS[conf]), np.array([6.93e6, 7.81e6, 5e6, 1e6, 1e6, 5e5])
            nz = dict(noise)
            if scale:
                for key in ("torque_sd", "force_sd", "torque_drift_sd", "force_drift_sd"):
                    nz[key] *= scale
            ex = simulate_clamped(m, q0, k, rng, **nz)
            res = {}
            for cov in ("hac", "classic"):
                (res[cov],) = identify_clamped(ex.t, ex.q_m, tau_m=ex.tau_m, wrench=ex.wrench, t_wrench=ex.t_wrench,
                                               model=m, joints=[ax], cov=cov)
            for key in ("motor", "wrench"):
                f, fc = getattr(res["hac"], key), getattr(res["classic"], key)
                rows[key].append((100 * (f.k / k[ax] - 1), f.k_rel_std_pct, (f.k - k[ax]) / f.k_std,
                                  (fc.k - k[ax]) / fc.k_std, f.rel_error_pct))
            diffs.append(res["hac"].rel_diff_pct)
        for key, r in rows.items():
            r = np.array(r)
            print(f"| {name} | {ax + 1} | {key} | {n} | {np.sqrt(np.mean(r[:, 0] ** 2)):.3g} | {np.abs(r[:, 0]).max():.3g} | "
                  f"{r[:, 1].mean():.3g} | {np.sqrt(np.mean(r[:, 2] ** 2)):.2f} | {np.sqrt(np.mean(r[:, 3] ** 2)):.2f} | "
                  f"{r[:, 4].mean():.3g} | {np.mean(diffs):.3g} |")
    print("\nTheir Tables 3-7: k1 6.09e6 (2.1 %) / 6.93e6 (0.77 %), k2 8.00e6 (2.0 %) / 7.81e6 (0.98 %), "
          "|W chi - Y| / |Y| 2.82 / 1.44 % and 2.67 / 2.13 %, differences 12.1 % and 2.43 %.")


def against_identify(quick):
    from mocapfj.dynamics import CoulombViscous, LinearSpring, PrescribedMotor, SingleJoint, simulate
    from mocapfj.ident.joint import identify_joint

    print("\n## 5. Against identify (output error) on the same simulated joint (Staubli axis 2, 250 Hz)\n")
    J, K, Z = 290.39, 1.0794e6, 0.163
    D = 2 * Z * math.sqrt(K * J)
    deg = math.pi / 180
    fs = 250.0
    # motor velocity: steps of +-5 deg/s in 20 ms without reversal, then stops (a smooth-step profile)
    knots = [(0.5, 5), (2.0, 5), (3.5, -5), (5.0, -5), (6.5, -5), (8.0, 5), (9.5, -10), (11.0, -5), (12.5, 5), (14.0, 5)]
    tf = np.arange(0, 16, 1e-3)
    v = np.zeros_like(tf)
    for t0, dv in knots:
        v += dv * deg * np.clip((tf - t0) / 0.02, 0, 1) ** 2 * (3 - 2 * np.clip((tf - t0) / 0.02, 0, 1))
    pos = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * 1e-3)])
    t = np.arange(0, 16, 1 / fs)
    cases = [("no Coulomb friction", 0.0), ("Coulomb 60 N m", 60.0)] + ([] if quick else [("Coulomb 120 N m", 120.0)])
    print("| plant | method | omega0 (rad/s) | zeta | k = J omega0^2 (N m/rad) | link reversals |")
    print("|---|---|---|---|---|---|")
    rng = np.random.default_rng(5)
    for name, fc in cases:
        plant = SingleJoint(I=J, J=30.0, b=50.0, spring=LinearSpring(k=K), friction=CoulombViscous(fc, D, smoothing=1e-3))
        r = simulate(plant, t, PrescribedMotor.from_samples(tf, pos))
        q = r.q[:, 0] + 2e-6 * rng.standard_normal(t.size)
        qm = r.q_m[:, 0] + 1e-7 * rng.standard_normal(t.size)
        u = r.u[:, 0] + 5.0 * rng.standard_normal(t.size)
        p = identify_joint(t, q, qm, u, fs_hz=fs).to_dict()["params"]
        I_, k_, v_ = p["I"]["value"], p["k"]["value"], p["v"]["value"]
        print(f"| {name} | truth | {math.sqrt(K / J):.3f} | {Z:.4f} | {K:.5g} | |")
        print(f"| {name} | identify (output error, 16 s) | {math.sqrt(k_ / I_):.3f} | {v_ / (2 * math.sqrt(k_ * I_)):.4f} | "
              f"{k_:.5g} +- {p['k']['std']:.2g} | |")
        for kind, sel in (("velocity step", [1, 2, 7, 8, 9]), ("stop", [3, 5])):   # velocities: knots' cumulative sums
            res = []
            for i in sel:
                t0 = knots[i][0]
                seg = slice(int(round(t0 * fs)), int(round(t0 * fs)) + 26)
                e = algebraic_estimate(t[seg], q[seg], qm[seg])
                res.append((e.omega0, e.zeta, e.stiffness(J)[0], e.link_reversals))
            res = np.array(res)
            print(f"| {name} | algebraic, 0.1 s after each {kind} ({len(sel)}) | {res[:, 0].mean():.3f} +- {res[:, 0].std():.2g} | "
                  f"{res[:, 1].mean():.4f} +- {res[:, 1].std():.2g} | {res[:, 2].mean():.5g} | "
                  f"{', '.join(str(int(x)) for x in res[:, 3])} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer cases")
    ap.add_argument("--seed", type=int, default=2012)
    a = ap.parse_args()
    t0 = time.time()
    grid_algebraic(20 if a.quick else 100, a.seed)
    staubli(50 if a.quick else 200)
    precomp(a.quick)
    clamped(5 if a.quick else 20)
    against_identify(a.quick)
    print(f"\n({time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
