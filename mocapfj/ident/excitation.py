"""Excitation design for the identification of one flexible joint (Lightcap and Banks (2007), §II.B, eq. 8-10).

The motor reference is the finite Fourier series of Lightcap and Banks (2007), eq. (9) in exactly the
parameterisation the simulator plays (:func:`mocapfj.synth.scenario.reference_trajectory`),

    q_m(t) = q0 + s(t) sum_{l=1..N} a_l [sin(2 pi l f0 t + phi_l) - sin(phi_l)],

with the smoothstep ramp s(t) = x^2 (3 - 2 x), x = clip(t / ramp_s, 0, 1). The amplitudes a_l
(rad) and phases phi_l (rad) minimise the condition number of the step-1 regressor
(:func:`mocapfj.ident.twostep.step1_regressor`, Lightcap and Banks (2007), eq. 6, columns for I, mglx, mgly, c,
v, J, b) subject to motor position, velocity and acceleration limits (Lightcap and Banks (2007), eq. 8).

Link motion (Lightcap and Banks (2007), eq. 10). For the optimisation the link follows the motor through a
quasi-static spring: delta = tau_s / k with tau_s = I q'' - mglx sin q + mgly cos q + v q'
+ c tanh(q' / eps) (docs/conventions.md signs), two fixed-point passes, derivatives of delta by
periodic central differences. This holds while the harmonics stay well below the joint's
natural frequency sqrt(k / I) (about 7 Hz for Lightcap and Banks (2007), Table I joint 2); the final design can be
checked by one full simulation, :func:`simulated_condition`.

The condition number is evaluated over one period 1 / f0 of the steady motion (after the ramp):
the played trial repeats that period, so its W^T W is a multiple of that period's. The limits are
checked on a dense grid over the ramp and one period (everything the trial plays), and met by
construction: each candidate shape is scaled to the largest amplitude the limits allow (times
`margin`), so the optimiser (Nelder-Mead from seeded starts) works without constraints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from ..errors import InputError
from .equations import link_torque
from .twostep import step1_regressor

__all__ = ["ExcitationDesign", "design_excitation", "reference_condition", "reference_motion",
           "simulated_condition", "write_reference"]

_LIMIT_KEYS = ("q_min_rad", "q_max_rad", "qd_max_rad_s", "qdd_max_rad_s2")


@dataclass(frozen=True)
class ExcitationDesign:
    """An optimised motor reference and what it reaches.

    reference : dict
        f0_hz, q0_rad, amplitudes_rad (N,), phases_rad (N,), ramp_s — the `[joints.reference]`
        table of a scenario file (Lightcap and Banks (2007), eq. 9).
    cond : float
        Condition number of the step-1 regressor (quasi-static link model) over one period.
    q_range_rad : (float, float)
        Smallest and largest motor angle reached, rad.
    max_abs_q_rad, max_abs_qd_rad_s, max_abs_qdd_rad_s2 : float
        Largest |q_m|, |q_m'|, |q_m''| reached over the ramp and the steady motion.
    cond_single_sine : float
        The same condition number for the best single sine (N = 1) under the same limits.
    """

    reference: dict
    cond: float
    q_range_rad: tuple[float, float]
    max_abs_q_rad: float
    max_abs_qd_rad_s: float
    max_abs_qdd_rad_s2: float
    cond_single_sine: float


def _fourier(t, f0, a, ph):
    """F, F', F'' of sum_l a_l [sin(w_l t + phi_l) - sin phi_l]; t (T,), returns three (T,) arrays."""
    w = 2 * np.pi * f0 * np.arange(1, a.size + 1)
    arg = t[:, None] * w + ph
    s, c = np.sin(arg), np.cos(arg)
    return (s - np.sin(ph)) @ a, c @ (a * w), -(s @ (a * w * w))


def reference_motion(ref: dict, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Motor reference q_m, q_m', q_m'' (rad, rad/s, rad/s^2) at times t (T,) s; Lightcap and Banks (2007), eq. (9).

    The same function as :func:`mocapfj.synth.scenario.reference_trajectory` (ramp included),
    with the acceleration added (s'' of the smoothstep is 6 (1 - 2x) / ramp_s^2 on the ramp).
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    a = np.asarray(ref["amplitudes_rad"], float)
    ph = np.asarray(ref["phases_rad"], float)
    F, Fd, Fdd = _fourier(t, float(ref["f0_hz"]), a, ph)
    ramp = float(ref.get("ramp_s", 2.0))
    if ramp > 0:
        x = np.clip(t / ramp, 0.0, 1.0)
        on = (t > 0) & (t < ramp)
        s, sd, sdd = x * x * (3 - 2 * x), np.where(on, 6 * x * (1 - x) / ramp, 0.0), np.where(on, 6 * (1 - 2 * x) / ramp**2, 0.0)
    else:
        s, sd, sdd = np.ones_like(t), np.zeros_like(t), np.zeros_like(t)
    return ref["q0_rad"] + s * F, s * Fd + sd * F, s * Fdd + 2 * sd * Fd + sdd * F


def _check_params(p: dict) -> dict:
    if not isinstance(p, dict):
        raise InputError(None, "model_params", "a dict with I, k, mglx, mgly (c, v optional)", type(p).__name__)
    out = {}
    for key, default in (("I", None), ("k", None), ("mglx", None), ("mgly", None), ("c", 0.0), ("v", 0.0)):
        v = p.get(key, default)
        if v is None:
            raise InputError(None, f"model_params.{key}", "a number (Lightcap and Banks (2007), Table I names)", "missing")
        v = float(v)
        if not np.isfinite(v) or (key in ("I", "k") and not v > 0) or (key in ("c", "v") and v < 0):
            raise InputError(None, f"model_params.{key}", "positive" if key in ("I", "k") else "a finite number", v)
        out[key] = v
    return out


def _check_limits(lim: dict) -> dict:
    if not isinstance(lim, dict) or any(k not in lim for k in _LIMIT_KEYS):
        raise InputError(None, "limits", f"a dict with keys {list(_LIMIT_KEYS)}",
                         sorted(lim) if isinstance(lim, dict) else type(lim).__name__)
    out = {k: float(lim[k]) for k in _LIMIT_KEYS}
    if not all(np.isfinite(v) for v in out.values()) or not out["q_min_rad"] < out["q_max_rad"]:
        raise InputError(None, "limits", "finite values with q_min_rad < q_max_rad", out)
    for k in ("qd_max_rad_s", "qdd_max_rad_s2"):
        if not out[k] > 0:
            raise InputError(None, f"limits.{k}", "a positive number", out[k])
    return out


class _Problem:
    """Grids and the quasi-static link model shared by every evaluation of one design problem."""

    def __init__(self, params, limits, f0, q0, ramp_s, n_period=1024, eps=0.02):
        self.p, self.lim, self.f0, self.q0, self.ramp = params, limits, f0, q0, ramp_s
        T0 = 1.0 / f0
        self.h = T0 / n_period
        self.t_per = ramp_s + np.arange(n_period) * self.h
        t_ramp = np.arange(0.0, ramp_s, self.h / 2) if ramp_s > 0 else np.zeros(0)
        self.t_lim = np.concatenate([t_ramp, self.t_per])
        self.eps = eps

    def ref(self, a, ph) -> dict:
        return {"f0_hz": self.f0, "q0_rad": self.q0, "amplitudes_rad": [float(x) for x in a],
                "phases_rad": [float(x) for x in np.mod(ph, 2 * np.pi)], "ramp_s": self.ramp}

    def motion(self, a, ph, t):
        return reference_motion(self.ref(a, ph), t)

    def feasible_scale(self, a, ph, margin) -> float:
        """Largest alpha with alpha * a inside the limits (the reference is linear in a)."""
        q, qd, qdd = self.motion(a, ph, self.t_lim)
        dq, L = q - self.q0, self.lim
        with np.errstate(divide="ignore"):
            bounds = [(L["q_max_rad"] - self.q0) / max(dq.max(), 0.0), (self.q0 - L["q_min_rad"]) / max(-dq.min(), 0.0),
                      L["qd_max_rad_s"] / np.abs(qd).max(), L["qdd_max_rad_s2"] / np.abs(qdd).max()]
        return margin * float(min(bounds))

    def _d(self, x):
        h = self.h
        xp, xm = np.roll(x, -1), np.roll(x, 1)
        return (xp - xm) / (2 * h), (xp - 2 * x + xm) / h**2

    def link(self, q_m, qd_m, qdd_m):
        """Quasi-static link q, q', q'' from the periodic motor motion (two fixed-point passes)."""
        p = self.p
        q, qd, qdd = q_m, qd_m, qdd_m
        for _ in range(2):
            tau = link_torque(p, q, qd, qdd, sgn=np.tanh(qd / self.eps))
            delta = tau / p["k"]
            dd, ddd = self._d(delta)
            q, qd, qdd = q_m - delta, qd_m - dd, qdd_m - ddd
        return q, qd, qdd

    def cond(self, a, ph) -> float:
        q_m, qd_m, qdd_m = self.motion(a, ph, self.t_per)
        q, qd, qdd = self.link(q_m, qd_m, qdd_m)
        return float(np.linalg.cond(step1_regressor(q, qd, qdd, qd_m, qdd_m)))


def reference_condition(ref: dict, model_params: dict) -> float:
    """Condition number of the step-1 regressor (Lightcap and Banks (2007), eq. 6) for any reference `ref`.

    Same quasi-static link model and one-period window as :func:`design_excitation`, so a
    hand-made reference and an optimised design are compared on equal terms.
    """
    pb = _Problem(_check_params(model_params), {}, float(ref["f0_hz"]), float(ref["q0_rad"]), float(ref.get("ramp_s", 2.0)))
    return pb.cond(np.asarray(ref["amplitudes_rad"], float), np.asarray(ref["phases_rad"], float))


def _optimise(pb, n, rng, n_starts, margin, maxfev):
    def scaled(x):
        a, ph = x[:n], x[n:]
        if not np.any(a):
            return None
        alpha = pb.feasible_scale(a, ph, margin)
        return (alpha * a, ph) if np.isfinite(alpha) and alpha > 0 else None

    def cost(x):
        s = scaled(x)
        return 1e3 if s is None else float(np.log(pb.cond(*s)))

    best = None
    for _ in range(n_starts):
        # amplitudes falling with the harmonic number (a smooth start), random phases
        x0 = np.concatenate([rng.uniform(0.3, 1.0, n) / np.arange(1, n + 1), rng.uniform(0, 2 * np.pi, n)])
        res = minimize(cost, x0, method="Nelder-Mead",
                       options={"maxfev": maxfev, "xatol": 1e-4, "fatol": 1e-6, "adaptive": n > 2})
        if best is None or res.fun < best.fun:
            best = res
    return scaled(best.x)


def design_excitation(model_params: dict, limits: dict, *, f0_hz: float, n_harmonics: int = 5,
                      duration_s: float = 60.0, ramp_s: float = 2.0, q0_rad: float | None = None,
                      seed: int = 0, n_starts: int = 4, margin: float = 0.99, maxfev: int = 1500) -> ExcitationDesign:
    """Optimal motor reference of Lightcap and Banks (2007), eq. (8)-(9) for one joint.

    Parameters
    ----------
    model_params : dict
        Approximate parameters (Lightcap and Banks (2007), Table I names, docs/conventions.md signs): I (kg m^2),
        k (N m/rad), mglx, mgly (N m), optional c (N m), v (N m s/rad). J and b are not needed
        (the motor motion is prescribed) and are ignored.
    limits : dict
        q_min_rad < q_m(t) < q_max_rad, |q_m'| < qd_max_rad_s, |q_m''| < qdd_max_rad_s2 (motor,
        link side).
    f0_hz : float
        Fundamental frequency; Lightcap and Banks (2007), §II.B: near the natural frequency when the sampling allows.
    n_harmonics : int
        N, the number of terms (fundamental and N - 1 harmonics).
    duration_s : float
        Length of the trial the reference is for; it must hold the ramp and one period 1 / f0.
    ramp_s, q0_rad : float
        Ramp length (s) and start angle (rad; default the middle of the position range).
    seed, n_starts, maxfev : seeded Nelder-Mead starts and evaluations per start (deterministic).
    margin : float
        Fraction of the largest feasible scale that is used (room for the grid, < 1).

    Returns
    -------
    ExcitationDesign
    """
    p, lim = _check_params(model_params), _check_limits(limits)
    if not (np.isfinite(f0_hz) and f0_hz > 0):
        raise InputError(None, "f0_hz", "a positive frequency in Hz", f0_hz)
    if not (isinstance(n_harmonics, (int, np.integer)) and n_harmonics >= 1):
        raise InputError(None, "n_harmonics", "an integer >= 1", n_harmonics)
    if not ramp_s >= 0:
        raise InputError(None, "ramp_s", "a non-negative time in s", ramp_s)
    if not duration_s >= ramp_s + 1.0 / f0_hz:
        raise InputError(None, "duration_s", f">= ramp_s + 1/f0_hz = {ramp_s + 1.0 / f0_hz:g} s", duration_s,
                         hint="the regressor is evaluated over one steady period")
    if not 0 < margin <= 1:
        raise InputError(None, "margin", "a fraction in (0, 1]", margin)
    q0 = 0.5 * (lim["q_min_rad"] + lim["q_max_rad"]) if q0_rad is None else float(q0_rad)
    if not lim["q_min_rad"] < q0 < lim["q_max_rad"]:
        raise InputError(None, "q0_rad", f"inside ({lim['q_min_rad']}, {lim['q_max_rad']})", q0)

    pb = _Problem(p, lim, float(f0_hz), q0, float(ramp_s))
    rng = np.random.default_rng(seed)
    a, ph = _optimise(pb, int(n_harmonics), rng, n_starts, margin, maxfev)
    a1, ph1 = _optimise(pb, 1, np.random.default_rng(seed), 2, margin, 200)
    q, qd, qdd = pb.motion(a, ph, pb.t_lim)
    return ExcitationDesign(reference=pb.ref(a, ph), cond=pb.cond(a, ph), q_range_rad=(float(q.min()), float(q.max())),
                            max_abs_q_rad=float(np.abs(q).max()), max_abs_qd_rad_s=float(np.abs(qd).max()),
                            max_abs_qdd_rad_s2=float(np.abs(qdd).max()), cond_single_sine=pb.cond(a1, ph1))


def simulated_condition(ref: dict, model, *, duration_s: float, fs_hz: float = 200.0):
    """Check of a reference by forward simulation of Lightcap and Banks (2007), eq. (10) (motor prescribed).

    model : mocapfj.dynamics.SingleJoint (friction smoothed for the stiff integrator).
    Returns (cond, SimulationResult): the step-1 regressor (Lightcap and Banks (2007), eq. 6) condition number
    over the steady part t >= ramp_s of a `duration_s` run sampled at `fs_hz`.
    """
    from ..dynamics.simulate import PrescribedMotor, simulate

    t = np.arange(int(np.floor(duration_s * fs_hz + 1e-9)) + 1) / fs_hz
    res = simulate(model, t, PrescribedMotor(lambda tt: reference_motion(ref, tt) if np.ndim(tt)
                                             else tuple(x[0] for x in reference_motion(ref, tt))),
                   method="LSODA", rtol=1e-7, atol=1e-9)
    keep = t >= float(ref.get("ramp_s", 2.0))
    W = step1_regressor(res.q[keep, 0], res.qd[keep, 0], res.qdd[keep, 0], res.qd_m[keep, 0], res.qdd_m[keep, 0])
    return float(np.linalg.cond(W)), res


def write_reference(path, design: ExcitationDesign) -> None:
    """Write ``[joints.reference]`` (TOML) for a scenario file's joint; mocapfj.io.tomlio.write_toml.

    The snippet replaces the `[joints.reference]` table of a one-joint scenario file
    (format mocapfj.scenario/1); `load_scenario` reads it back unchanged.
    """
    from ..io.tomlio import write_toml

    r = design.reference
    write_toml(path, {"joints": {"reference": {
        "f0_hz": float(r["f0_hz"]), "q0_rad": float(r["q0_rad"]), "amplitudes_rad": [float(x) for x in r["amplitudes_rad"]],
        "phases_rad": [float(x) for x in r["phases_rad"]], "ramp_s": float(r["ramp_s"])}}})
