"""The Cramér-Rao bound of one hinge grid case: the smallest SD any unbiased estimator can reach.

Independent of mocapfj's estimators: it uses only the case's truth (its simulated signals) and
its noise model. The observations are the link angle at the mocap instants (white noise of the
case's angle SD, marker noise over the cluster's radii) and the motor torque at the controller
rate, u = J q_m'' + b q_m' + k (q_m - q) (white, AR(1)-whitened for coloured noise, quantised
noise taken as white of the same variance); q is the link's response to the motor angle
(:func:`mocapfj.dynamics.link_response`, the grid's physics) and depends on I, mglx, mgly, c, v, k;
the mocap zero is a nuisance parameter. The bound is computed with more information than any
estimator has (the true motor angle without its encoder noise, no dropouts, the joint's axis and
the tanh law's eps known), so it is a lower bound on every estimator's SD: a parameter whose bound
is above 5 % of its value cannot be reported as determined by an honest estimator on that
recording.

Sensitivities by central differences of the simulated link (step 1e-4 of each parameter).
"""

from __future__ import annotations

import math

import numpy as np

NAMES = ("I", "mglx", "mgly", "c", "v", "J", "b", "k")
_LINK = ("I", "mglx", "mgly", "c", "v", "k")


def hinge_bound(case) -> dict[str, float]:
    """{name: bound on the SD of the estimate / |true value| in %} for the eight parameters
    (mglx, mgly relative to the gravity magnitude; NaN for them on a joint without gravity)."""
    from scipy.signal import lfilter

    from mocapfj.dynamics.link_response import link_response
    from mocapfj.synth.hinge import simulate_hinge

    _, truth = simulate_hinge(case)
    s = truth["signals"]["controller"]
    fs = case.controller_hz
    eps = case.eps_rad_s if case.friction_law == "tanh" else 0.0
    p = {n: getattr(case, n) for n in _LINK}
    g = math.hypot(case.mglx, case.mgly)

    def sim(pp):
        return link_response(s["q_m"], fs, eps=eps, qd_m=s["qd_m"], q0=s["q"][0], w0=s["qd"][0], **pp)[0]

    cols = list(NAMES) + ["z"]
    Sq = np.zeros((s["q_m"].size, len(cols)))
    for n in _LINK:
        h = 1e-4 * (max(g, 1.0) if n in ("mglx", "mgly") else abs(p[n]))
        plus, minus = dict(p), dict(p)
        plus[n] += h
        minus[n] -= h
        if n in ("c", "v") and minus[n] < 0:                   # one-sided at a bound
            minus[n] = p[n]
            Sq[:, cols.index(n)] = (sim(plus) - sim(minus)) / h
        else:
            Sq[:, cols.index(n)] = (sim(plus) - sim(minus)) / (2 * h)
    q_sim = sim(p)
    Sq[:, cols.index("z")] = 1.0
    # the torque u = J q_m'' + b q_m' + k (q_m - q)
    Su = -case.k * Sq
    Su[:, cols.index("z")] = 0.0
    Su[:, cols.index("J")] = s["qdd_m"]
    Su[:, cols.index("b")] = s["qd_m"]
    Su[:, cols.index("k")] += s["q_m"] - q_sim
    t_c = np.arange(s["q_m"].size) / fs
    t_m = np.arange(int(np.floor(case.duration_s * case.mocap_hz + 1e-9)) + 1) / case.mocap_hz
    Sm = np.column_stack([np.interp(t_m, t_c, Sq[:, j]) for j in range(len(cols))])
    sigma_q = truth["noise"]["angle_sigma_rad"]
    sigma_u = case.torque_noise_Nm
    if case.torque_noise_kind == "coloured":
        a = math.exp(-1.0 / (fs * case.torque_corr_time_s))
        Su = lfilter([1.0, -a], [1.0], Su, axis=0)[1:] / math.sqrt(1 - a * a)   # whitened AR(1)
    F = Sm.T @ Sm / sigma_q ** 2 + Su.T @ Su / sigma_u ** 2
    free = np.array([not (n in ("mglx", "mgly") and g == 0) for n in cols])
    sc = np.sqrt(np.diag(F)[free])
    C = np.full((len(cols), len(cols)), np.nan)
    C[np.ix_(free, free)] = np.linalg.pinv(F[np.ix_(free, free)] / np.outer(sc, sc)) / np.outer(sc, sc)
    out = {}
    for i, n in enumerate(NAMES):
        ref = g if n in ("mglx", "mgly") else abs(getattr(case, n))
        out[n] = float(100 * math.sqrt(C[i, i]) / ref) if free[i] and ref > 0 else float("nan")
    return out


def pass_probability(bound_pct: dict[str, float], tol_pct: dict[str, float], flag_above: float = 5.0) -> float:
    """The probability that an efficient unbiased estimator (Gaussian, SD at the bound) passes
    every parameter: within tolerance, or (bound above `flag_above` %) flagged not determined."""
    prob = 1.0
    for n, b in bound_pct.items():
        if not math.isfinite(b) or b > flag_above:
            continue
        prob *= math.erf(tol_pct[n] / (b * math.sqrt(2))) if b > 0 else 1.0
    return prob
