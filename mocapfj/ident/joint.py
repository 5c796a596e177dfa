"""Identification of one flexible joint from its signals on one clock: the method chosen, its
spring model selected, and the result as an :class:`~.result.IdentifiedJoint`.

Methods (docs/identification.md):

- ``"output_error"``: the link simulated on the recorded motor motion and compared with the mocap
  angle and the motor torque (:mod:`.output_error`); each parameter judged determined or not
  (:mod:`.determinacy`).
- ``"motor_first"``: the motor equation first, then the link equation on a rebuilt link angle
  (:mod:`.motorfirst`).
- ``"two_step"``: Lightcap and Banks (2007) §II.A, eq. (5)-(7) (:mod:`.twostep`).

Lightcap and Banks' two-step and one-step formulations always run too: their condition numbers
(``cond_two_step``, ``cond_one_step``) and the one-step k are reported whatever the method.
"""

from __future__ import annotations


import numpy as np

from ..dynamics import CoulombViscous, CubicSpring, JointModel, LinearSpring
from ..errors import InputError
from ..types import JointSignals
from .conditioning import derivatives, lowpass, white_noise_sd
from .determinacy import flag_imprecise, flag_nonphysical
from .result import PARAMETER_NAMES, IdentifiedJoint, Parameter, SpringResult
from .springs import HYSTERETIC, SPRING_FITTERS, bouc_wen_states, select_spring_model

__all__ = ["IDENTIFY_METHODS", "identify_joint", "identify_signals", "spring_pairs"]

IDENTIFY_METHODS = ("output_error", "motor_first", "two_step")


def spring_pairs(delta, tau_s, t, fs_hz: float, cutoff_hz: float = 10.0, rate_hz: float = 50.0):
    """(delta, tau_s, t) for spring selection: both low-passed at `cutoff_hz` (mocap noise in
    delta would otherwise hide a 10 % nonlinearity) and kept at `rate_hz` (nearly independent
    samples; the hysteresis fits are 5x cheaper)."""
    stride = max(1, int(round(fs_hz / rate_hz)))
    return lowpass(delta, fs_hz, cutoff_hz)[::stride], lowpass(tau_s, fs_hz, cutoff_hz)[::stride], t[::stride]


def _selected(sel) -> SpringResult:
    c = sel.chosen
    return SpringResult(model=c.model, params={k: float(v) for k, v in c.params.items()}, element=c.element,
                        r2=sel.r2, holdout_rms_Nm=sel.holdout_rms)


def _hysteretic_spring(h: dict, delta, tau_s, t, fs_hz: float) -> SpringResult:
    """The Bouc-Wen spring a motor equation found, with its r2 on the spring pairs."""
    from ..dynamics import BoucWen

    d, tau, _ = spring_pairs(delta, tau_s, t, fs_hz)
    pred = h["alpha"] * h["k"] * d + (1 - h["alpha"]) * h["k"] * bouc_wen_states(d, 1.0, h["beta"], h["gamma"])
    r = tau - pred
    r -= r.mean()                                             # the torque offset
    dev = tau - tau.mean()
    params = {n: h[n] for n in ("k", "alpha", "beta", "gamma")}
    return SpringResult(model="bouc_wen", params=params, element=BoucWen(**params), r2=float(1 - (r @ r) / (dev @ dev)),
                        motor_rms_gain_pct=h["rms_gain_pct"])


def _model(name: str, gear_ratio: float, p: dict, spring: SpringResult, smoothing: float = 0.0) -> JointModel:
    """The identified JointModel: the chosen spring when it is an element the simulator runs,
    else the linear spring of the same stiffness."""
    element = spring.element if spring.element is not None else LinearSpring(k=p["k"])
    if spring.model == "linear":
        element = LinearSpring(k=p["k"])
    return JointModel(name=name or "joint", gear_ratio=gear_ratio, I=p["I"], J=p["J"], mglx=p["mglx"], mgly=p["mgly"],
                      b=p["b"], friction=CoulombViscous(c=p["c"], v=p["v"], smoothing=smoothing), spring=element)


def _motor_first_spring(t, q, q_m, u, fs_hz, decimate, models):
    """Motor-first identification with its spring model chosen: a linear pass (which also tests
    the motor equation for a hysteretic spring); without hysteresis the model is selected on the
    (deflection, spring torque) pairs and, when it is not linear, the motor equation is solved
    again with that shape and the spring refitted on the new pairs. (result, SpringResult)."""
    from .motorfirst import identify_motor_first

    mf = identify_motor_first(t, q, q_m, u, fs_hz=fs_hz, decimate=decimate)
    if mf.hysteresis is not None and any(m in models for m in HYSTERETIC):
        return mf, _hysteretic_spring(mf.hysteresis, mf.delta, mf.tau_s, mf.t, fs_hz)
    elastic = tuple(m for m in models if m not in HYSTERETIC)
    sel = select_spring_model(*spring_pairs(mf.delta, mf.tau_s, mf.t, fs_hz), models=elastic)
    if sel.chosen.model != "linear":
        mf = identify_motor_first(t, q, q_m, u, fs_hz=fs_hz, decimate=decimate, spring=sel.chosen.predict,
                                  q_zero_rad=mf.q_zero_rad)
        sel = select_spring_model(*spring_pairs(mf.delta, mf.tau_s, mf.t, fs_hz),
                                  models=(sel.chosen.model, "linear"))
    return mf, _selected(sel)


def _motor_first_values(mf):
    """(parameters, stages, torque RMS, q zero) of a motor-first result."""
    values = {}
    for n in PARAMETER_NAMES:
        part = mf.link if n in mf.link.names else mf.motor
        values[n] = Parameter(n, part[n], part.std_of(n))
    return values, {"motor": mf.motor, "link": mf.link}, mf.motor.residual_rms, mf.q_zero_rad


def _clock_reasons(clock: dict | None, values: dict) -> dict[str, str]:
    """{name: reason} for the parameters an undeclared clock offset moves (output error's test)."""
    if not clock or not clock["found"] or clock["applied"]:
        return {}
    ms, sd = 1e3 * clock["offset_s"], 1e3 * clock["sd_s"]
    out = {}
    for n, shift in clock["moves"].items():
        v = values.get(n)
        per = clock.get("per_ms", {}).get(n, 0.0)
        how = (f"{100 * shift / abs(v):+.3g} % ({100 * per / abs(v):+.3g} % per millisecond of offset)" if v
               else f"{shift:+.3g}")
        out[n] = (f"the recording fits far better (chi-square {clock['chi2']:.0f}) with the mocap {abs(ms):.3g} +- "
                  f"{sd:.2g} ms {'behind' if ms > 0 else 'ahead of'} the controller log than with the declared "
                  f"synchronisation; that offset moves {n} by {how}: a clock offset between the streams (or a "
                  "delay in the log) shows like this; declare it ([markers] clock_offset_s) or identify it with the "
                  "dynamics (--fit-clock-offset)")
    return out


def _output_error_joint(t, q, q_m, u, fs_hz, decimate, models, measured, controller, cond, fit_clock_offset=False,
                        link_context=None):
    """The output-error branch of :func:`identify_joint`: (parameters, spring, stages, torque RMS,
    q zero, extra JSON, friction smoothing); adds its condition number to `cond`.

    The spring: linear; cubic when the output error's own test keeps k3; hysteretic when its
    score test finds a loop in the deflection (:func:`.output_error._hysteresis_test`). Motor-first
    then fits the Bouc-Wen spring inside the motor equation, and when it finds it too its
    parameters (spring shape included) are reported, since the output-error model has no such
    spring; otherwise the linear fit's parameters stand and the spring is the test's. A robot's
    joint (`link_context`, :func:`.output_error.identify_output_error`'s `context`) keeps the
    output error's parameters: motor-first's link equation has no robot in it.
    """
    from ..dynamics import BoucWen
    from .determinacy import combinations, judge_parameters
    from .motorfirst import identify_motor_first
    from .output_error import identify_output_error

    hysteretic = any(m in models for m in HYSTERETIC)
    oe = identify_output_error(t, q, q_m, u, fs_hz=fs_hz, measured=measured, controller=controller,
                               test_cubic="cubic" in models, test_hysteresis=hysteretic,
                               fit_clock_offset=fit_clock_offset, context=link_context)
    f = oe.fit
    if oe.hysteresis is not None and hysteretic and link_context is None:
        try:
            mf = identify_motor_first(t, q, q_m, u, fs_hz=fs_hz, decimate=decimate)
        except InputError:
            mf = None
        spring = None
        if mf is not None and mf.hysteresis is not None:
            try:
                spring = _hysteretic_spring(mf.hysteresis, mf.delta, mf.tau_s, mf.t, fs_hz)
            except InputError:
                # not a spring (alpha < 0: a loop stiffer than the whole spring): motor-first could
                # not fit it, and the output error's test stands, as below
                pass
        if spring is not None:
            values, stages, torque_rms, q_zero = _motor_first_values(mf)
            cond.update(cond_motor=mf.motor.cond, cond_link=mf.link.cond)
            extra = {"parameters_from": "motor_first: a hysteretic spring, found by the output error's score "
                                        "test and fitted in the motor equation, which the output-error model lacks"}
            return values, spring, stages, torque_rms, q_zero, extra, 0.0
    qd, qdd = derivatives(lowpass(np.asarray(q_m, float), fs_hz, min(oe.band_hz, 0.4 * fs_hz)), fs_hz)
    context = {"sigma_q_rad": white_noise_sd(np.asarray(q, float), fs_hz), "band_hz": oe.band_hz,
               "deflection_viscous_rad": float(np.std(f["v"] * qd) / f["k"]),
               "deflection_inertial_rad": float(np.std(f["I"] * qdd) / f["k"]),
               "motor_noise_rad": oe.motor_noise_rad, "split_noise_chi2": oe.split_noise_chi2}
    values = judge_parameters(f.names, f.values, f.std, f.cov, duration_s=float(t[-1] - t[0]), context=context,
                              at_bound=oe.at_bound, suspect=_clock_reasons(oe.clock, dict(zip(f.names, f.values))))
    extra = {"combinations": {k: {"value": v, "std": sd} for k, (v, sd) in
                              combinations(f.names, f.values, f.cov).items()},
             "friction_law": {"law": "tanh" if oe.friction_scale > 0 else "sign", "eps_rad_s": oe.friction_scale},
             "band_hz": oe.band_hz, "residual_sd": {"q_rad": oe.sigma_q, "u_Nm": oe.sigma_u}}
    if oe.clock is not None:
        extra["clock_offset"] = {"offset_s": oe.clock["offset_s"], "sd_s": oe.clock["sd_s"],
                                 "sd_fit_s": oe.clock["sd_fit_s"], "chi2": oe.clock["chi2"],
                                 "found": oe.clock["found"], "applied": oe.clock["applied"],
                                 "moves": oe.clock["moves"], "per_ms": oe.clock.get("per_ms", {})}
    if oe.hysteresis is not None and hysteretic:
        h = oe.hysteresis
        spring = SpringResult(model="bouc_wen", params={"k": f["k"], "alpha": h["alpha"], "beta": h["beta"],
                                                        "gamma": h["gamma"], "chi2": h["chi2"]},
                              element=BoucWen(k=f["k"], alpha=h["alpha"], beta=h["beta"], gamma=h["gamma"]),
                              r2=oe.spring_r2)
        extra["spring_note"] = ("hysteretic by the output error's score test (motor-first could not fit it): the "
                                "other parameters are the linear-spring fit's, k its small-deflection stiffness")
    elif f["k3"] != 0.0:
        spring = SpringResult(model="cubic", params={"k1": f["k"], "k3": f["k3"], "k3_std": f.std_of("k3")},
                              element=CubicSpring(k1=f["k"], k3=f["k3"]), r2=oe.spring_r2)
    else:
        spring = SpringResult(model="linear", params={"k": f["k"], "tau0": f["k"] * f["z"]},
                              element=LinearSpring(k=f["k"]), r2=oe.spring_r2)
    cond["cond_output_error"] = f.cond
    return values, spring, {"output_error": f}, f.residual_rms, f["z"], extra, oe.friction_scale


MIN_DECIMATED = 200
"""Samples a decimation must leave for the two-step and motor-first regressions."""


def identify_joint(t, q, q_m, u, *, fs_hz: float, method: str = "output_error", cutoff_hz: float | None = None,
                   decimate: int = 2, spring_models=None, name: str = "", gear_ratio: float = 1.0,
                   frames_filled: int = 0, recording: str = "", measured=None, controller=None,
                   fit_clock_offset: bool = False, link_context=None) -> IdentifiedJoint:
    """Identify one joint from its signals on one clock (docs/identification.md).

    Parameters
    ----------
    t, q, q_m, u : (T,) float
        Times (s, uniform at fs_hz), link angle from mocap (rad), motor angle / gear ratio (rad),
        motor torque x gear ratio (N m): the link side (docs/conventions.md).
    fs_hz : float
    method : one of IDENTIFY_METHODS.
    cutoff_hz : float, optional
        The two-step method's low-pass on the angles (default 10 Hz); the other methods use their
        documented defaults.
    decimate : int
        Parallel decimation factor.
    spring_models : sequence of str, optional
        Spring models to select among (:data:`.springs.SPRING_FITTERS`; default all).
    name, gear_ratio, frames_filled, recording : carried into the result.
    measured : (T,) bool, optional
        True where q was measured, False where a gap was filled (output error leaves those out).
    controller : (t_c, q_m_c, u_c, fs_c_hz), optional
        The controller's own samples over the same span (output error compares the torque there).
    fit_clock_offset : output error: identify an offset between the mocap and controller clocks
        with the dynamics and apply it (by default it is only tested and reported).
    link_context : (I_t, mglx_t, mgly_t, tau_t) (T,) each, output error only: a joint of a robot in
        the recorded motion of the others (:func:`.output_error.identify_output_error`'s `context`);
        its I, mglx, mgly are then its own terms added to the robot's, and a negative I is a
        correction to the robot's model, not a finding.
    """
    from .twostep import identify_two_step

    if method not in IDENTIFY_METHODS:
        raise InputError(None, "method", f"one of {list(IDENTIFY_METHODS)}", repr(method))
    if link_context is not None and method != "output_error":
        raise InputError(None, "method", "output_error for a robot's joint in its context", repr(method))
    n_t = int(np.size(t))
    if isinstance(decimate, bool) or not isinstance(decimate, (int, np.integer)) or decimate < 1:
        raise InputError(None, "decimate", "an integer decimation factor >= 1", repr(decimate))
    if n_t // decimate < MIN_DECIMATED:
        raise InputError(None, "decimate", f"a factor that leaves at least {MIN_DECIMATED} of the recording's {n_t} samples "
                         f"(at most {max(1, n_t // MIN_DECIMATED)})", decimate)
    extra, smoothing = {}, 0.0
    try:
        two = identify_two_step(t, q, q_m, u, fs_hz=fs_hz, cutoff_hz=10.0 if cutoff_hz is None else cutoff_hz,
                                decimate=decimate)
        cond = {"cond_two_step": two.cond_two_step, "cond_one_step": two.cond_one_step}
    except InputError:
        if method == "two_step":
            raise
        two, cond = None, {}            # reported for comparison only; this recording cannot run it
    if method != "output_error" and measured is not None:
        from .conditioning import MAX_GAP_S, gap_error, longest_gap

        gap, t_gap = longest_gap(t, measured)
        if gap > MAX_GAP_S:
            raise gap_error(recording or None, name, gap, t_gap, MAX_GAP_S,
                            f" for {method}, which differentiates the filled angle (output error accepts longer ones)")
    models = tuple(spring_models or SPRING_FITTERS)
    unknown = [m for m in models if m not in SPRING_FITTERS]
    if unknown:
        raise InputError(None, "spring_models", f"names from {sorted(SPRING_FITTERS)}", unknown)
    if method == "output_error":
        values, spring, stages, torque_rms, q_zero, extra, smoothing = _output_error_joint(
            t, q, q_m, u, fs_hz, decimate, models, measured, controller, cond, fit_clock_offset, link_context)
    elif method == "two_step":
        values = {n: Parameter(n, two.step1[n], two.step1.std_of(n)) for n in PARAMETER_NAMES if n != "k"}
        values["k"] = Parameter("k", two.spring["k"], two.spring.std_of("k"))
        spring = _selected(select_spring_model(two.delta, two.tau_s, two.t, models=models))
        stages = {"step1": two.step1, "spring": two.spring, "one_step": two.one_step}
        torque_rms, q_zero = two.torque_rms, two.q_zero_rad
    else:
        mf, spring = _motor_first_spring(t, q, q_m, u, fs_hz, decimate, models)
        values, stages, torque_rms, q_zero = _motor_first_values(mf)
        cond.update(cond_motor=mf.motor.cond, cond_link=mf.link.cond)
    if link_context is None:
        values = flag_imprecise(flag_nonphysical(values))
    else:                               # the joint's own inertia beside the robot's: any sign
        flagged = flag_nonphysical({n: v for n, v in values.items() if n != "I"})
        values = flag_imprecise({**flagged, "I": values["I"]} if "I" in values else flagged)
    p = {n: v.value for n, v in values.items()}
    return IdentifiedJoint(name=name, method=method, params=values, model=_model(name, gear_ratio, p, spring, smoothing),
                           spring=spring, stages=stages, cond=cond, torque_rms=float(torque_rms),
                           q_zero_rad=float(q_zero), k_one_step=None if two is None else float(two.one_step["k"]),
                           frames_filled=int(frames_filled), recording=recording, extra=extra)


def identify_signals(signals: JointSignals, *, gear_ratio: float = 1.0, recording: str = "", **kw) -> IdentifiedJoint:
    """:func:`identify_joint` on a :class:`~mocapfj.types.JointSignals` (the joints stage's output)."""
    ctrl = ((signals.t_c, signals.q_m_c, signals.u_c, signals.fs_c_hz) if signals.has_controller_rate else None)
    return identify_joint(signals.t, signals.q, signals.q_m, signals.u, fs_hz=signals.fs_hz, name=signals.name,
                          gear_ratio=gear_ratio, frames_filled=signals.n_filled, recording=recording,
                          measured=signals.measured, controller=ctrl, **kw)


