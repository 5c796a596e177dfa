"""An independent linear simulation of a two-inertia joint under a motor-position PD loop, for the
FRF tests and benchmarks/bench_frf.py (no code shared with mocapfj.ident.frf or frf_fit).

State x = (q_m, q_m', q, q'); plant
    J q_m'' = u + w - b q_m' - k (q_m - q) - d (q_m' - q'),   I q'' = -v q' - g q + k (q_m - q) + d (q_m' - q'),
controller u = kp (r - q_m) + kd (r' - q_m') (continuous, like mocapfj.dynamics.simulate.PID), or
open loop u = the multisine itself. The multisine's part of the response is the exact periodic
steady state from the state-space matrices at each line; the process noise w (a torque on the motor,
held over each sample) is integrated exactly (zero-order-hold discretisation of the closed loop).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm


def plant_matrices(J, I, k, d, b, v, g=0.0):
    """g: the link's gravity stiffness about the operating point (I q'' = ... - g q)."""
    A = np.array([[0, 1, 0, 0],
                  [-k / J, -(b + d) / J, k / J, d / J],
                  [0, 0, 0, 1],
                  [k / I, d / I, -(k + g) / I, -(v + d) / I]], float)
    B = np.array([0, 1 / J, 0, 0], float)
    return A, B


def plant_frf(f_hz, p, output="motor"):
    """q_m/u (or q/u) of the state-space plant at f_hz (K,)."""
    A, B = plant_matrices(**p)
    c = 0 if output == "motor" else 2
    return np.array([np.linalg.solve(2j * np.pi * f * np.eye(4) - A, B)[c] for f in f_hz])


def simulate_multisine(p, ms_list, n_periods, *, kp=None, kd=None, noise_sd=0.0, y_noise_sd=0.0, u_noise_sd=0.0,
                       seed=0, output="motor", distortion=None):
    """Realisations (one per Multisine of `ms_list`) of n_periods periods each.

    Closed loop when kp is given (the multisine is the position reference r, rad), else open loop
    (the multisine is the torque u, N m). noise_sd: SD of the held motor-torque disturbance w, N m;
    y_noise_sd, u_noise_sd: white measurement noise on the logged q_m and u (not fed back).
    distortion: callable (lines (L,), rng) -> complex amplitudes (L,), N m, of a periodic torque on the
    motor at every odd line of the multisine's band, excited or not, with the same phase in every
    period: the stochastic nonlinear distortion of Pintelon and Schoukens (2012, §3.4) as a random-phase
    multisine meets it (uncorrelated with the excitation, periodic with it, also at the detection lines).
    Returns (u, y, r) each (M, n_periods N), y = q_m (output "motor") or q (output "link").
    """
    A, B = plant_matrices(**p)
    c = 0 if output == "motor" else 2
    closed = kp is not None
    K = np.array([kp, kd, 0, 0]) if closed else np.zeros(4)
    Acl = A - np.outer(B, K)
    rng = np.random.default_rng(seed)
    U, Y, R = [], [], []
    for ms in ms_list:
        fs, n = ms.fs_hz, ms.n_samples
        t = np.arange(n * n_periods) / fs
        f = ms.lines * fs / n
        cphase = ms.amplitudes * np.exp(1j * ms.phases)          # r or u = Re(c e^{jwt})
        Xc = np.empty((f.size, 4), complex)
        Uc = np.empty(f.size, complex)
        for i, fi in enumerate(f):
            s = 2j * np.pi * fi
            drive = B * (kp + kd * s) if closed else B
            Xc[i] = np.linalg.solve(s * np.eye(4) - Acl, drive)
            Uc[i] = (kp + kd * s) - K @ Xc[i] if closed else 1.0
        E = np.exp(1j * np.outer(t, 2 * np.pi * f)) * cphase
        y = np.real(E @ Xc[:, c])
        u = np.real(E @ Uc)
        r = np.real(E.sum(axis=1))
        if distortion is not None:
            ld = np.arange(ms.lines.min() | 1, ms.lines.max() + 1, 2)
            a = distortion(ld, rng)
            Xd = np.array([np.linalg.solve(2j * np.pi * li * fs / n * np.eye(4) - Acl, B) for li in ld])
            Ed = np.exp(1j * np.outer(t, 2 * np.pi * ld * fs / n)) * a
            y = y + np.real(Ed @ Xd[:, c])
            u = u - np.real(Ed @ (Xd @ K))
        if noise_sd > 0:
            dt = 1 / fs
            Mx = expm(np.block([[Acl, B[:, None]], [np.zeros((1, 5))]]) * dt)
            Ad, Bd = Mx[:4, :4], Mx[:4, 4]
            w = rng.normal(0, noise_sd, t.size)
            x = np.zeros(4)
            xs = np.empty((t.size, 4))
            for i in range(t.size):
                xs[i] = x
                x = Ad @ x + Bd * w[i]
            y = y + xs[:, c]
            u = u - xs @ K
        U.append(u + (rng.normal(0, u_noise_sd, t.size) if u_noise_sd else 0))
        Y.append(y + (rng.normal(0, y_noise_sd, t.size) if y_noise_sd else 0))
        R.append(r)
    return np.array(U), np.array(Y), np.array(R)
