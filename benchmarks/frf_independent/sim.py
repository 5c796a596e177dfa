"""Independent two-inertia flexible-joint simulator under motor-position PD control,
excited by a multisine reference. numpy/scipy only (nothing from mocapfj). Written by a helper
trying `mocapfj frf` as a new user on 26 November 2026, kept as it was (only where it writes):
benchmarks/bench_frf_independent.py runs it.

usage: python sim.py [CASE ...]     (default: all cases)  -> OUT/<name>/rec.csv, truth.json
(OUT: the environment's FRF_INDEPENDENT_OUT, else benchmarks/.cache/frf_independent)
"""
import json
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.environ.get("FRF_INDEPENDENT_OUT", os.path.join(HERE, "..", ".cache", "frf_independent"))

# --------------------------------------------------------------------------- cases
# friction given as a fraction of the torque RMS (measured on a friction-free pass)
CASES = {
    # name: plant, controller, excitation, noise
    "A_small_odd": dict(J=0.05, I=0.5, k=200.0, d=0.15, b=0.01, v=0.02,
                        fcm=0.0, fcl=0.0, fc_ctrl=2.0, fs=500.0, T=10.0, P=5, R=1,
                        kind="odd", r_rms=0.05, u_noise=0.01, q_noise=2e-5, q_res=0.0,
                        w_noise=0.01, seed=101),
    "B_mid_odd_motorCoulomb": dict(J=2.0, I=20.0, k=5000.0, d=3.0, b=0.5, v=1.0,
                        fcm=0.03, fcl=0.0, fc_ctrl=1.0, fs=500.0, T=10.0, P=5, R=1,
                        kind="odd", r_rms=0.05, u_noise=0.01, q_noise=1e-5, q_res=0.0,
                        w_noise=0.01, seed=202),
    "C_big_odd_linkCoulomb_2real": dict(J=20.0, I=300.0, k=1.0e5, d=60.0, b=5.0, v=20.0,
                        fcm=0.0, fcl=0.04, fc_ctrl=1.0, fs=500.0, T=8.0, P=5, R=2,
                        kind="odd", r_rms=0.02, u_noise=0.01, q_noise=5e-6, q_res=0.0,
                        w_noise=0.01, seed=303),
    "D_full_bothCoulomb_encoder": dict(J=0.5, I=2.0, k=2000.0, d=0.8, b=0.05, v=0.1,
                        fcm=0.02, fcl=0.02, fc_ctrl=1.5, fs=1000.0, T=5.0, P=6, R=1,
                        kind="full", r_rms=0.05, u_noise=0.01, q_noise=0.0,
                        q_res=2 * math.pi / 2**18, w_noise=0.005, seed=404),
    "E_lowres_noisy_3real": dict(J=0.2, I=5.0, k=800.0, d=0.3, b=0.02, v=0.05,
                        fcm=0.0, fcl=0.0, fc_ctrl=1.0, fs=500.0, T=10.0, P=4, R=3,
                        kind="odd", r_rms=0.05, u_noise=0.05, q_noise=1e-4, q_res=0.0,
                        w_noise=0.03, seed=505),
    "F_stiff_fast_full_motorCoulomb_2real": dict(J=1.0, I=3.0, k=3.0e4, d=1.0, b=0.2, v=0.3,
                        fcm=0.05, fcl=0.0, fc_ctrl=3.0, fs=1000.0, T=4.0, P=6, R=2,
                        kind="full", r_rms=0.01, u_noise=0.01, q_noise=0.0,
                        q_res=2 * math.pi / 2**20, w_noise=0.01, seed=606),
    # controls for case F: the same plant without friction, and with an odd multisine
    "F0_stiff_fast_full_nofriction_2real": dict(J=1.0, I=3.0, k=3.0e4, d=1.0, b=0.2, v=0.3,
                        fcm=0.0, fcl=0.0, fc_ctrl=3.0, fs=1000.0, T=4.0, P=6, R=2,
                        kind="full", r_rms=0.01, u_noise=0.01, q_noise=0.0,
                        q_res=2 * math.pi / 2**20, w_noise=0.01, seed=606),
    "G_stiff_fast_odd_motorCoulomb_2real": dict(J=1.0, I=3.0, k=3.0e4, d=1.0, b=0.2, v=0.3,
                        fcm=0.05, fcl=0.0, fc_ctrl=3.0, fs=1000.0, T=4.0, P=6, R=2,
                        kind="odd", r_rms=0.01, u_noise=0.01, q_noise=0.0,
                        q_res=2 * math.pi / 2**20, w_noise=0.01, seed=707),
}


# --------------------------------------------------------------------------- truth
def truth(p):
    J, I, k, d, b, v = (p[x] for x in "J I k d b v".split())
    num = np.roots([I, v + d, k])
    char = np.roots([J * I, J * (v + d) + (b + d) * I, J * k + I * k + b * (v + d) + d * v,
                     k * (b + v)])
    cpx = [r for r in char if abs(r.imag) > 1e-9 and r.imag > 0][0]
    a = num[np.argmax(num.imag)]
    return dict(
        f_res_hz=abs(cpx) / (2 * math.pi), zeta_res=-cpx.real / abs(cpx),
        f_res_damped_hz=cpx.imag / (2 * math.pi),
        f_anti_hz=abs(a) / (2 * math.pi), zeta_anti=-a.real / abs(a),
        f_anti_undamped_hz=math.sqrt(k / I) / (2 * math.pi),
    )


# --------------------------------------------------------------------------- multisine
def multisine(T, fs, f_lo, f_hi, kind, rng):
    """lines (harmonic numbers), phases; amplitudes flat. odd: odd lines with one in
    every 4 left out at random (detection lines); full: every line."""
    f0 = 1.0 / T
    n_lo, n_hi = int(math.ceil(f_lo / f0)), int(math.floor(f_hi / f0))
    lines = np.arange(n_lo, n_hi + 1)
    if kind == "odd":
        lines = lines[lines % 2 == 1]
        keep = []
        for g in range(0, len(lines), 4):
            grp = list(lines[g:g + 4])
            if len(grp) == 4:
                grp.pop(rng.integers(4))
            keep += grp
        lines = np.array(keep)
    phases = rng.uniform(0, 2 * math.pi, len(lines))
    return lines, phases


# --------------------------------------------------------------------------- simulation
def simulate(p, fcm_abs, fcl_abs, rng_seed, write=True):
    rng = np.random.default_rng(rng_seed)
    J, I, k, d, b, v = (p[x] for x in "J I k d b v".split())
    tr = truth(p)
    fs, T, P, R = p["fs"], p["T"], p["P"], p["R"]
    wc = 2 * math.pi * p["fc_ctrl"]
    kp = (J + I) * wc ** 2
    kd = 2 * 0.7 * (J + I) * wc
    n_per = int(round(T * fs))
    N = n_per * P * R
    f0 = 1.0 / T
    # reference: R realisations, each P periods of its own random-phase multisine
    real = []
    for _ in range(R):
        lines, ph = multisine(T, fs, 0.5, 1.5 * tr["f_res_hz"], p["kind"], rng)
        real.append((lines, ph))
    amp = p["r_rms"] * math.sqrt(2.0 / len(real[0][0]))

    # substeps: 10x the log rate, more if the friction tanh or the plant is stiff
    eps = 1e-3
    stiff = max(fcm_abs / (eps * J), fcl_abs / (eps * I), kd / J,
                math.sqrt(k * (1 / J + 1 / I)), (d * (1 / J + 1 / I)))
    sub = 10
    while stiff * (1.0 / (fs * sub)) > 1.5:
        sub += 1
    h = 1.0 / (fs * sub)

    u_rms_guess = None
    x = [0.0, 0.0, 0.0, 0.0]  # qm, qm', q, q'
    t_log = np.arange(N) / fs
    u_log = np.empty(N)
    qm_log = np.empty(N)
    r_log = np.empty(N)
    w = rng.normal(0.0, 1.0, N)  # process torque disturbance, scaled below

    def ref(t, lines, ph, tshift):
        a = 2 * math.pi * f0 * lines
        arg = a * (t - tshift) + ph
        return amp * np.sum(np.cos(arg)), -amp * np.sum(a * np.sin(arg))

    # pre-compute the reference on the substep grid (vectorised), per realisation
    w_scale = p["w_noise_abs"]
    for ri, (lines, ph) in enumerate(real):
        i0 = ri * n_per * P
        nloc = n_per * P
        tt = np.arange(nloc * sub + 1) * h  # local time, realisation starts at a period boundary
        a = 2 * math.pi * f0 * lines
        rr = np.zeros_like(tt)
        rd = np.zeros_like(tt)
        for aj, pj in zip(a, ph):
            arg = aj * tt + pj
            rr += amp * np.cos(arg)
            rd -= amp * aj * np.sin(arg)
        # also mid points for RK4
        tm = tt[:-1] + h / 2
        rrm = np.zeros_like(tm)
        rdm = np.zeros_like(tm)
        for aj, pj in zip(a, ph):
            arg = aj * tm + pj
            rrm += amp * np.cos(arg)
            rdm -= amp * aj * np.sin(arg)
        rr, rd, rrm, rdm = rr.tolist(), rd.tolist(), rrm.tolist(), rdm.tolist()
        th = math.tanh

        def f(x0, x1, x2, x3, r, rdot, wd):
            u = kp * (r - x0) + kd * (rdot - x1) + wd
            spring = k * (x0 - x2) + d * (x1 - x3)
            a_m = (u - b * x1 - spring - fcm_abs * th(x1 / eps)) / J
            a_l = (spring - v * x3 - fcl_abs * th(x3 / eps)) / I
            return x1, a_m, x3, a_l

        x0, x1, x2, x3 = x
        for n in range(nloc):
            wd = w_scale * w[i0 + n]
            j = n * sub
            # log at the sample instant (u as applied by the controller, without disturbance)
            u_log[i0 + n] = kp * (rr[j] - x0) + kd * (rd[j] - x1)
            qm_log[i0 + n] = x0
            r_log[i0 + n] = rr[j]
            for s in range(sub):
                js = j + s
                k1 = f(x0, x1, x2, x3, rr[js], rd[js], wd)
                k2 = f(x0 + h / 2 * k1[0], x1 + h / 2 * k1[1], x2 + h / 2 * k1[2], x3 + h / 2 * k1[3],
                       rrm[js], rdm[js], wd)
                k3 = f(x0 + h / 2 * k2[0], x1 + h / 2 * k2[1], x2 + h / 2 * k2[2], x3 + h / 2 * k2[3],
                       rrm[js], rdm[js], wd)
                k4 = f(x0 + h * k3[0], x1 + h * k3[1], x2 + h * k3[2], x3 + h * k3[3],
                       rr[js + 1], rd[js + 1], wd)
                x0 += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
                x1 += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
                x2 += h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
                x3 += h / 6 * (k1[3] + 2 * k2[3] + 2 * k3[3] + k4[3])
        x = [x0, x1, x2, x3]
    # NB: the torque that acts is u + disturbance (an unmeasured torque disturbance on the
    # motor, which the loop feeds back: the closed-loop case the indirect estimator is for).
    u_act = u_log  # the disturbance is NOT measured: it acts, the drive logs only its command
    return dict(t=t_log, u=u_act, qm=qm_log, r=r_log, kp=kp, kd=kd, sub=sub, amp=amp,
                n_lines=len(real[0][0]), lines0=real[0][0].tolist(), tr=tr)


def run_case(name):
    p = dict(CASES[name])
    tr = truth(p)
    # pass 1: friction-free, no disturbance, to get the torque RMS (short: 1 period)
    q = dict(p, P=2, R=1, w_noise_abs=0.0)
    s0 = simulate(q, 0.0, 0.0, p["seed"])
    n_per = int(round(p["T"] * p["fs"]))
    u_rms = float(np.std(s0["u"][n_per:]))
    fcm = p["fcm"] * u_rms
    fcl = p["fcl"] * u_rms
    p["w_noise_abs"] = p["w_noise"] * u_rms
    s = simulate(p, fcm, fcl, p["seed"])
    rng = np.random.default_rng(p["seed"] + 7)
    u_meas = s["u"] + p["u_noise"] * u_rms * rng.normal(size=len(s["u"]))
    qm_meas = s["qm"] + p["q_noise"] * rng.normal(size=len(s["qm"]))
    if p["q_res"] > 0:
        qm_meas = np.round(qm_meas / p["q_res"]) * p["q_res"]
    out = os.path.join(OUT, name)
    os.makedirs(out, exist_ok=True)
    np.savetxt(os.path.join(out, "rec.csv"),
               np.column_stack([s["t"], u_meas, qm_meas, s["r"]]),
               delimiter=",", header="time,tau,qm,qref", comments="", fmt="%.10g")
    info = dict(name=name, params={kk: p[kk] for kk in p}, truth=tr, u_rms=u_rms,
                fc_motor_abs=fcm, fc_link_abs=fcl, kp=s["kp"], kd=s["kd"], substeps=s["sub"],
                r_amp_per_line=s["amp"], n_lines=s["n_lines"], qm_rms=float(np.std(s["qm"])),
                u_rms_final=float(np.std(s["u"])), n_samples=len(s["t"]))
    with open(os.path.join(out, "truth.json"), "w") as fh:
        json.dump(info, fh, indent=1)
    print(name, json.dumps(tr), "u_rms", round(u_rms, 4), "sub", s["sub"], "lines", s["n_lines"],
          flush=True)


if __name__ == "__main__":
    names = sys.argv[1:] or list(CASES)
    for nm in names:
        run_case(nm)
