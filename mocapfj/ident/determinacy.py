"""Which identified parameters the recording determines, and why not the others.

A parameter is reported *not determined* (``determined: false`` with a reason) when

- its standard deviation exceeds :data:`~.result.UNDETERMINED_REL_STD_PCT` (5 %) of its value (the
  gravity moments: of the gravity magnitude sqrt(mglx^2 + mgly^2));
- the joint shows no gravity torque at all: the magnitude is within three SDs of zero (a vertical
  axis or a balanced link; mglx and mgly are then 0 within their SDs, not measured);
- (the inertia split) the motor angle's noise, not the motion, can set it (output error:
  :func:`.output_error.split_noise_chi2` above 25);
- the data push it against a physical bound (a friction, damping, inertia or stiffness of zero):
  a non-physical value is a finding, and its likely causes (an undeclared clock offset between
  mocap and controller, a sign or scale error) are named.

The reason says what the data lack and what would give it. For the two splits that rest on the
mocap deflection (link and motor inertia I + J, link and motor viscous friction b + v) the sum is
reported with its SD (:func:`combinations`), which the torque alone determines. The recording
length that would bring an SD to 1 % at the same excitation follows from SD ~ 1 / sqrt(duration).
"""

from __future__ import annotations

import math

import numpy as np

from .result import PARAMETER_NAMES, UNDETERMINED_REL_STD_PCT, Parameter

SPLIT_NOISE_CHI2 = 25.0
"""Output error: when the motor angle's noise changes its expected share of the cost by more than
this over the inertia splits (:func:`.output_error.split_noise_chi2`), the split is not determined."""

__all__ = ["judge_parameters", "combinations"]

_PAIRS = {"I": ("I", "J"), "J": ("I", "J"), "v": ("b", "v"), "b": ("b", "v")}


def combinations(names, values, cov) -> dict:
    """{"I+J": (value, SD), "b+v": (value, SD)} from the estimates and their covariance."""
    idx = {n: i for i, n in enumerate(names)}
    out = {}
    for a, b in (("I", "J"), ("b", "v")):
        i, j = idx[a], idx[b]
        var = cov[i, i] + cov[j, j] + 2 * cov[i, j]
        out[f"{a}+{b}"] = (float(values[i] + values[j]), float(math.sqrt(var)) if var >= 0 else float("nan"))
    return out


def _longer(rel_pct: float, duration_s: float) -> str:
    need = duration_s * (rel_pct / 1.0) ** 2
    if not math.isfinite(need) or need > 100 * duration_s:
        return "a recording over a hundred times longer (not a practical way)"
    return f"about {need:.0f} s of the same motion for a 1 % SD"


def judge_parameters(names, values, std, cov, *, duration_s: float, context: dict | None = None,
                     at_bound=(), suspect: dict[str, str] | None = None) -> dict[str, Parameter]:
    """Parameters (name -> :class:`~.result.Parameter`) of the eight of Lightcap and Banks (2007),
    eq. (4), each determined or not with its reason (module docstring).

    names, values, std, cov : the estimator's parameter names, values, SDs and covariance (SI).
    duration_s : the recording's length (for what a longer one would give).
    context : facts for the reasons: ``sigma_q_rad`` (mocap angle noise per sample), ``band_hz``
        (comparison band), ``deflection_viscous_rad`` and ``deflection_inertial_rad`` (RMS of
        v q' / k and I q'' / k along the motion), ``motor_noise_rad`` and ``split_noise_chi2``
        (output error: the motor angle's noise and how strongly it pulls on the inertia split).
    at_bound : names held at a bound of zero by the estimator.
    suspect : {name: reason} of parameters a finding outside the fit puts in doubt (an undeclared
        clock offset that moves them): not determined, with that reason.
    """
    ctx = context or {}
    idx = {n: i for i, n in enumerate(names)}
    val = {n: float(values[idx[n]]) for n in PARAMETER_NAMES}
    sd = {n: float(std[idx[n]]) for n in PARAMETER_NAMES}
    combos = combinations(names, values, cov)
    g = math.hypot(val["mglx"], val["mgly"])
    i1, i2 = idx["mglx"], idx["mgly"]
    # the SD of the gravity magnitude along its direction
    if g > 0:
        u = np.array([val["mglx"], val["mgly"]]) / g
        C = np.asarray(cov)[np.ix_([i1, i2], [i1, i2])]
        sd_g = float(math.sqrt(max(u @ C @ u, 0.0))) if np.isfinite(C).all() else float("nan")
    else:
        sd_g = float(math.hypot(sd["mglx"], sd["mgly"]))
    out = {}
    partner_at_bound = {n for n in ("b", "v") if ({"b", "v"} - {n}) & set(at_bound)}
    for n in PARAMETER_NAMES:
        v, s = val[n], sd[n]
        reason = None
        if n in partner_at_bound and n not in at_bound:
            other = "b" if n == "v" else "v"
            tot, tot_sd = combos["b+v"]
            reason = (f"{other} is held at zero, so {n} carries all of b + v = {tot:.4g} +- {tot_sd:.2g}: the split is "
                      f"not determined (see {other})")
        elif n in at_bound:
            reason = (f"held at its bound of zero: the data push {n} below zero, which no joint does; likely causes: "
                      "an undeclared clock offset between mocap and controller (the link then seems to lead or lag "
                      "the motor), a sign or scale error in q_m, q or u (docs/conventions.md), or a friction law the "
                      "model lacks")
        elif n in ("mglx", "mgly"):
            if not (g > 3 * sd_g):
                reason = (f"no gravity torque: |(mglx, mgly)| = {g:.3g} N m with an SD of {sd_g:.2g} N m is not "
                          "distinguishable from zero (a vertical axis or a balanced link); nothing to identify")
            elif not math.isfinite(s) or 100 * s / g > UNDETERMINED_REL_STD_PCT:
                reason = (f"SD {s:.3g} N m is {100 * s / g:.3g} % of the gravity magnitude {g:.3g} N m: the motion "
                          f"covers too little of the joint's range; a wider angle range or {_longer(100 * s / g, duration_s)}")
        else:
            rel = 100 * s / abs(v) if v and math.isfinite(s) else math.inf
            if rel > UNDETERMINED_REL_STD_PCT:
                if n in _PAIRS:
                    a, b = _PAIRS[n]
                    tot, tot_sd = combos[f"{a}+{b}"]
                    what = "inertial deflection I q''/k" if a == "I" else "viscous deflection v q'/k"
                    key = "deflection_inertial_rad" if a == "I" else "deflection_viscous_rad"
                    facts = ""
                    if key in ctx and "sigma_q_rad" in ctx:
                        facts = (f" ({ctx[key]:.2g} rad RMS against a mocap angle noise of {ctx['sigma_q_rad']:.2g} rad "
                                 "per sample)")
                    how = ("a faster motion (more harmonics or higher frequency)" if a == "I"
                           else "faster motion (higher velocities)")
                    reason = (f"relative SD {rel:.3g} %: only {a} + {b} = {tot:.4g} +- {tot_sd:.2g} is determined; "
                              f"the split rests on the link's {what}{facts}; {how}, a larger marker cluster or "
                              f"{_longer(rel, duration_s)} would determine it")
                    chi2 = ctx.get("split_noise_chi2", 0.0)
                    if a == "I" and chi2 > SPLIT_NOISE_CHI2:
                        reason = (f"relative SD {rel:.3g} %: only I + J = {tot:.4g} +- {tot_sd:.2g} is determined; the "
                                  f"motor angle's noise ({ctx['motor_noise_rad']:.2g} rad per sample) drives the "
                                  f"simulated link, and how the inertia splits changes that noise's share of the "
                                  f"torque residual by {chi2:.0f} (chi-square), so the noise, not the "
                                  f"motion, can set the split; a quieter motor angle (a finer encoder, or "
                                  "its noise filtered before logging) or a faster motion would determine it")
                else:
                    reason = (f"relative SD {rel:.3g} % above {UNDETERMINED_REL_STD_PCT:g} %: its torque is near the "
                              f"noise along this motion; {_longer(rel, duration_s)}")
        if reason is None and suspect and n in suspect:
            reason = suspect[n]
        out[n] = Parameter(n, v, s, determined=reason is None, reason=reason)
    return out


_NON_NEGATIVE = {"I": "link inertia", "J": "motor inertia", "k": "stiffness", "c": "Coulomb friction",
                 "v": "link viscous friction", "b": "motor viscous friction"}
_PARTNER = {"I": "J", "J": "I", "v": "b", "b": "v"}
NONPHYSICAL_CAUSES = ("an undeclared clock offset between mocap and controller (the link then seems to lead or lag "
                      "the motor; output error, the default method, fits and reports it), a sign or scale error in "
                      "q_m, q or u (docs/conventions.md), or a friction law the model lacks")


def flag_nonphysical(values: dict) -> dict:
    """Parameters (name -> Parameter) with every negative inertia, stiffness or friction reported
    not determined, as a finding with its likely causes, and its split partner (I / J, v / b) with
    it; the others unchanged."""
    from dataclasses import replace

    neg = [n for n, what in _NON_NEGATIVE.items() if n in values and values[n].value < 0]
    if not neg:
        return values
    out = dict(values)
    for n in neg:
        out[n] = replace(values[n], determined=False,
                         reason=f"{n} = {values[n].value:.4g} is negative, which no joint's {_NON_NEGATIVE[n]} is: "
                                f"not a result but a finding; likely causes: {NONPHYSICAL_CAUSES}")
        m = _PARTNER.get(n)
        if m in values and m not in neg:
            out[m] = replace(values[m], determined=False,
                             reason=f"its partner {n} came out negative ({values[n].value:.4g}), so their split is not "
                                    f"physical; likely causes: {NONPHYSICAL_CAUSES}")
    return out


def flag_imprecise(values: dict) -> dict:
    """Parameters (name -> Parameter) with every one still reported determined whose relative SD
    is above UNDETERMINED_REL_STD_PCT (mglx, mgly: of the gravity magnitude) reported not
    determined: the rule of :func:`judge_parameters`, for the estimators that do not apply it."""
    from dataclasses import replace

    g = math.hypot(values["mglx"].value, values["mgly"].value) if "mglx" in values and "mgly" in values else 0.0
    out = dict(values)
    for n, p in values.items():
        if not p.determined:
            continue
        ref = g if n in ("mglx", "mgly") else abs(p.value)
        rel = 100 * p.std / ref if ref > 0 and math.isfinite(p.std) else math.inf
        if rel > UNDETERMINED_REL_STD_PCT:
            out[n] = replace(p, determined=False,
                             reason=f"relative SD {rel:.3g} % above {UNDETERMINED_REL_STD_PCT:g} %: the recording does not "
                                    "determine it with this method")
    return out
