"""The model discovery compares with a recording: one joint's flexible-joint model with its
elements, read from and written to a model file, and its output-error simulation.

The joint model itself is :class:`mocapfj.dynamics.JointModel` (identification produces it).
A model file (TOML, ``format = "mocapfj.model/1"``) has one ``[[joints]]`` table per joint:
``name``, ``gear_ratio``, ``I``, ``J``, ``mglx``, ``mgly``, ``b`` (Lightcap and Banks (2007) names and SI units,
docs/conventions.md), ``friction`` and ``spring`` tables (:mod:`mocapfj.dynamics.spec`), and the
optional drivetrain and measurement terms discovery adds: ``transmission_error``
{amplitudes_rad, phases_rad, orders}, ``position_torque`` {orders, cos_Nm, sin_Nm, chebyshev_Nm,
center_rad, half_range_rad},
``torque_gain``, ``delay_s`` (the mocap samples are this late on the controller clock) and
``coupling`` {source joint: inertia kg m^2, the torque -inertia x q''(source) on this joint}.
A scenario file (``mocapfj.scenario/1``) is read as a model file too, without its effects: the
simulation a lab compares its robot with.

The joints of a URDF robot (:mod:`.context`): a top-level ``urdf`` (the file's path, relative to
the model file) and, per joint, ``urdf_joint`` (its name in the URDF, default the joint's name);
every moving joint of the URDF has a table, I, mglx and mgly are optional there (default 0) and
added to the link's inertia and gravity from the URDF. A scenario with ``robot.model = "urdf"``
is read so, its URDF built from the scenario.

Output-error simulation: the link is driven by the recorded motor angle (the motor's position
loop is stiff: :class:`mocapfj.dynamics.PrescribedMotor`), with `mocapfj.dynamics.simulate`; it
gives the link angle, the deflection and the motor torque the model needs for that motion.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..dynamics import JointModel, PositionTorque, PrescribedMotor, TransmissionError, shift_signal, simulate
from ..dynamics.spec import FRICTION_MODELS, SPRING_MODELS, element_from_table
from ..errors import InputError
from ..io.tomlio import describe, read_toml, require, write_toml
from .memo import by_content, spline_rates, wiener_drive_of

__all__ = ["JointModel", "read_model_file", "write_model_file", "fit_pct", "simulate_joint", "simulate_signals", "OutputError",
           "link_context"]

MODEL_FORMAT = "mocapfj.model/1"


def _joint_from_table(tab: dict, path, i: int, in_robot: bool = False) -> JointModel:
    w = f"joints[{i}]"
    name = require(path, tab, "name", str, w)
    w = f"joints[{name}]"
    # a robot's joint: the URDF gives the link's inertia and gravity, these are added to them
    own = ("I", "mglx", "mgly") if in_robot else ()
    num = {k: float(require(path, tab, k, (int, float), w, **({"default": 0.0} if k in own else {})))
           for k in ("I", "J", "mglx", "mgly", "b")}
    for k, v in num.items():
        ok = np.isfinite(v) and (v > 0 if k in ("I", "J") and k not in own else v >= 0 if k in ("b", "I") else True)
        if not ok:
            what = ("positive" if k in ("I", "J") and k not in own else "non-negative" if k in ("b", "I")
                    else "finite")
            raise InputError(path, f"{w}.{k}", f"a {what}, finite number", v)
    gear = float(require(path, tab, "gear_ratio", (int, float), w, default=1.0))
    if not (np.isfinite(gear) and gear > 0):
        raise InputError(path, f"{w}.gear_ratio", "a positive, finite gear ratio", gear)
    fr = element_from_table(require(path, tab, "friction", dict, w), FRICTION_MODELS, path, f"{w}.friction")
    sp = element_from_table(require(path, tab, "spring", dict, w), SPRING_MODELS, path, f"{w}.spring")
    for key in ("k", "k1", "k0"):
        stiff = getattr(sp, key, None)
        if stiff is not None and not (np.isfinite(stiff) and stiff > 0):
            raise InputError(path, f"{w}.spring.{key}", "a positive, finite stiffness in N m/rad", stiff)
    te = pt = None
    if "transmission_error" in tab:
        t = tab["transmission_error"]
        amps = t.get("amplitudes_rad", [])
        te = TransmissionError(gear, amps, t.get("phases_rad", []), t.get("orders", [1.0, 2.0][: len(amps)]))
    if "position_torque" in tab:
        t = dict(tab["position_torque"])
        try:
            pt = PositionTorque(**t)
        except TypeError as e:
            raise InputError(path, f"{w}.position_torque", "orders, cos_Nm, sin_Nm, chebyshev_Nm, center_rad, "
                             "half_range_rad", str(e)) from None
    coupling = {str(k): float(v) for k, v in dict(tab.get("coupling", {})).items()}
    return JointModel(name=name, gear_ratio=gear, friction=fr, spring=sp, transmission_error=te, position_torque=pt,
                      torque_gain=float(tab.get("torque_gain", 1.0)), delay_s=float(tab.get("delay_s", 0.0)),
                      coupling=coupling, **num)


def _scenario_robot(path: Path, doc: dict):
    """The robot of a scenario file whose ``robot.model`` is "urdf" (its URDF text), else None."""
    robot = doc.get("robot")
    if not (isinstance(robot, dict) and robot.get("model") == "urdf"):
        return None
    from ..synth.record import scenario_urdf
    from ..synth.scenario import load_scenario
    from .context import Robot, urdf_joint_names

    scn = load_scenario(path)
    try:
        urdf = scenario_urdf(scn)
    except ValueError as e:
        raise InputError(path, "joints", "the URDF joints in PA-10 order", str(e)) from None
    names = urdf_joint_names(urdf)
    return Robot(urdf=urdf, joints=names, urdf_joints=names)


def read_model_file(path: str | Path) -> dict[str, JointModel]:
    """Joint models by name from a model file, or from a scenario file without its effects.

    A top-level ``urdf`` (a path relative to the file) makes the joints those of a URDF robot
    (:mod:`.context`): each joint's ``urdf_joint`` (default its name) names its URDF joint, every
    moving joint of the URDF has one table, and I, mglx, mgly are optional (default 0), added to
    the robot's own terms. A scenario whose ``robot.model`` is "urdf" is read the same way."""
    path = Path(path)
    doc = read_toml(path)
    fmt = doc.get("format")
    if fmt not in (MODEL_FORMAT, "mocapfj.scenario/1"):
        raise InputError(path, "format", f'"{MODEL_FORMAT}" (or a "mocapfj.scenario/1" file)', repr(fmt))
    joints = doc.get("joints")
    if not isinstance(joints, list) or not joints:
        raise InputError(path, "joints", "one [[joints]] table per joint", describe(joints))
    robot = None
    if fmt == MODEL_FORMAT and "urdf" in doc:
        from .context import robot_from_table

        if not all(isinstance(t, dict) for t in joints):
            raise InputError(path, "joints", "one [[joints]] table per joint", describe(joints))
        robot = robot_from_table(doc, path, [str(t.get("name", "")) for t in joints], joints)
    elif fmt != MODEL_FORMAT:
        robot = _scenario_robot(path, doc)
    try:
        models = [_joint_from_table(t, path, i, robot is not None) for i, t in enumerate(joints)]
    except InputError as e:
        if e.file == "<argument>":              # a model element's own check: name this file
            raise InputError(path, e.field, e.expected, e.got, e.hint) from None
        raise
    names = [m.name for m in models]
    if len(set(names)) != len(names):
        raise InputError(path, "joints.name", "one table per joint", f"{sorted({n for n in names if names.count(n) > 1})} "
                         "more than once")
    if robot is not None:
        models = [m.with_(robot=robot) for m in models]
    return {m.name: m for m in models}


def write_model_file(path: str | Path, models, effects: list[dict] | None = None) -> None:
    """Write joint models (and, for the record, the effects that made them) atomically. A robot's
    URDF is named by its absolute path, or, given as text, written next to the file
    (``<stem>.urdf``)."""
    from ..io import write_text_atomic

    models = list(models)
    doc = {"format": MODEL_FORMAT, "joints": [m.to_table() for m in models]}
    robots = {m.robot for m in models if m.robot is not None}
    if robots:
        urdf = next(iter(robots)).urdf
        if urdf.lstrip().startswith("<"):
            target = Path(path).with_suffix(".urdf")
            write_text_atomic(target, urdf)
            urdf = target.name
        doc = {"format": MODEL_FORMAT, "urdf": urdf, "joints": doc["joints"]}
    if effects:
        doc["discovered"] = effects
    write_toml(path, doc)


def fit_pct(y: np.ndarray, y_hat: np.ndarray) -> float:
    """100 (1 - ||y - y_hat|| / ||y - mean(y)||) over the samples where both are finite (docs/conventions.md)."""
    ok = np.isfinite(y) & np.isfinite(y_hat)
    y, y_hat = y[ok], y_hat[ok]
    den = np.linalg.norm(y - y.mean())
    return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / den)) if den > 0 else float("nan")


SMOOTHED_BAND = 0.5
"""A recording whose markers were smoothed before export is compared below this share of the
smoothing's corner (:mod:`mocapfj.joints.smoothing`): there a zero-phase Butterworth filter of order
2-4 passes the motion within 1 %, at the corner it halves it; the corner is read at 0.63-0.75 of
the filter's on the hinge grid (the residuals carry the cluster template's error too), never above
it. A causal filter's corner is not read reliably (:mod:`mocapfj.joints.smoothing`)."""


@dataclass(frozen=True, eq=False)
class OutputError:
    """An output-error simulation compared with a recording (one joint, mocap samples).

    t (T,) s; q_sim, delta_sim, u_sim: simulated link angle, deflection q_m - q and logged motor
    torque (rad, rad, N m); r_delta, r_u: recorded minus simulated, full band (the deflection's
    constant, the link-angle zero the joints stage cannot know, removed).

    The comparison (:mod:`.compare`, docs/conventions.md): fit_delta, fit_u, fit: fit % of the
    deflection, of the torque and of the joint, 100 (1 - sqrt((e_delta^2 + e_u^2) / 2)) with e the
    normalised error of each, in the band the model claims (band_hz); floor_delta, floor_u, floor:
    the same for a perfect model (the recording's noise in that band: noise_delta_rad, noise_u_Nm,
    estimated by floor_method "periods" over the excitation's period_s or "white"), floor_sd,
    floor_sd_delta, floor_sd_u the floors' SDs in points (a white floor's: the scatter of the
    noise realised in the band);
    fit_full_delta, fit_full_u: the fits at full rate, noise included; sd_delta, sd_u: the recorded
    deflection's and torque's SDs in the band; smoothing_hz: the corner of the smoothing the
    markers went through before export (the band is below it), None when they were not smoothed.
    """

    t: np.ndarray
    q_sim: np.ndarray
    delta_sim: np.ndarray
    u_sim: np.ndarray
    r_delta: np.ndarray
    r_u: np.ndarray
    fit_delta: float
    fit_u: float
    fit: float
    floor_delta: float = float("nan")
    floor_u: float = float("nan")
    floor: float = float("nan")
    floor_sd: float = float("nan")
    floor_sd_delta: float = float("nan")
    floor_sd_u: float = float("nan")
    band_hz: float = float("nan")
    period_s: float | None = None
    floor_method: str = ""
    noise_delta_rad: float = float("nan")
    noise_u_Nm: float = float("nan")
    fit_full_delta: float = float("nan")
    fit_full_u: float = float("nan")
    sd_delta: float = float("nan")
    sd_u: float = float("nan")
    smoothing_hz: float | None = None

    def change_sd(self, other: "OutputError") -> float:
        """The SD (points) of other.fit - self.fit that this recording's noise alone gives (`other`:
        another model simulated on the same recording, compared in the same band;
        :func:`.compare.fit_change_sd`)."""
        from .compare import fit_change_sd

        keep = np.isfinite(self.r_delta) & np.isfinite(other.r_delta)
        return fit_change_sd(self.t, keep, self.band_hz, self.fit,
                             [(self.sd_delta, self.noise_delta_rad, other.delta_sim - self.delta_sim, True),
                              (self.sd_u, self.noise_u_Nm, other.u_sim - self.u_sim)])

    def summary(self) -> dict:
        """The comparison's numbers (discovery.json)."""
        return {"fit": self.fit, "deflection": self.fit_delta, "torque": self.fit_u, "floor": self.floor,
                "floor_deflection": self.floor_delta, "floor_torque": self.floor_u, "gap_to_floor": self.floor - self.fit,
                "floor_sd": self.floor_sd, "floor_sd_deflection": self.floor_sd_delta, "floor_sd_torque": self.floor_sd_u,
                "band_hz": self.band_hz, "period_s": self.period_s, "floor_method": self.floor_method,
                "noise_deflection_rad": self.noise_delta_rad, "noise_torque_Nm": self.noise_u_Nm,
                "deflection_full_band": self.fit_full_delta, "torque_full_band": self.fit_full_u,
                **({"markers_smoothed_hz": self.smoothing_hz} if self.smoothing_hz is not None else {})}


def _plain_link(model: JointModel, t, drive, d_span: float, ext=None):
    """(q_sim, u_sim) by a compiled link kernel when the model is what one runs, None otherwise:
    :func:`mocapfj.dynamics.link_response.link_response` for the plain joint (Coulomb-viscous
    friction, a linear (no offset) or cubic spring, no drivetrain term), exact in the Coulomb law
    and 100x faster than integrating the general model;
    :func:`mocapfj.dynamics.link_forward.link_forward` for the effects discovery names
    (direction-dependent and Stribeck friction, piecewise, Bouc-Wen and free-play springs, a
    transmission error, a drive gain). The motor's velocity and acceleration are the cubic
    spline's of `drive`, as the general path's; `d_span` rad bounds the deflections met (for the
    kernel's substeps).

    A coupling torque `ext` (T,) N m and a position torque P(q) act on the link through the
    kernel's torque input (linear between samples). P is taken along the simulated link angle by
    fixed point: first at the motor angle, then at the link angle that run gave, then once more;
    each pass shrinks the error by |P'(q)| / k (about 1e-4 for a gravity-model correction), so
    the third run agrees with the general integrator to its own tolerance."""
    from ..dynamics import CoulombViscous, CubicSpring, LinearSpring
    from ..dynamics.link_forward import encode_friction, encode_spring, link_forward
    from ..dynamics.link_response import link_response

    fr, sp = model.friction, model.spring
    fs = 1.0 / float(np.median(np.diff(t)))
    if np.abs(np.diff(t) * fs - 1.0).max() > 1e-6 or not model.I > 0:
        return None
    if (ext is not None) != bool(model.coupling):
        return None
    forced = ext is not None or model.position_torque is not None
    plain = not forced and (type(fr) is CoulombViscous and model.transmission_error is None and model.torque_gain == 1.0
             and ((type(sp) is LinearSpring and sp.offset == 0.0) or (type(sp) is CubicSpring and sp.k3 >= 0.0)))
    if plain:
        k, k3 = (sp.k, 0.0) if type(sp) is LinearSpring else (sp.k1, sp.k3)
        if not (k > 0 and fr.c >= 0 and fr.v >= 0 and fr.smoothing >= 0):
            return None
    elif encode_friction(fr) is None or encode_spring(sp) is None:
        return None
    qd, qdd = spline_rates(t, drive)
    if plain:
        q_sim, _ = link_response(drive, fs, I=model.I, mglx=model.mglx, mgly=model.mgly, c=fr.c, v=fr.v,
                                 k=k, eps=fr.smoothing, k3=k3, qd_m=qd)
        return q_sim, model.J * qdd + model.b * qd + sp.torque(drive - q_sim)
    sj = model.with_(position_torque=None).single_joint(smoothing=1e-6)
    q_start = float(sj.static_link_angle(np.array([drive[0]]))[0])
    ext = np.zeros_like(drive) if ext is None else np.asarray(ext, dtype=np.float64)
    zero = np.zeros_like(drive)
    q_eval = drive
    for _ in range(3 if model.position_torque is not None else 1):
        tau_in = ext if model.position_torque is None else ext + model.position_torque.torque(q_eval)
        # the static state under the first sample's extra torque (a linear spring's slope: the
        # torque is a small correction to the static deflection)
        q0 = q_start + float(tau_in[0]) / model.stiffness() if forced else q_start
        q_sim, _, tau = link_forward(drive, fs, I=model.I, mglx=model.mglx, mgly=model.mgly, friction=fr,
                                     spring=sp, transmission_error=model.transmission_error, qd_m=qd, q0=q0,
                                     d_span=d_span, context=(zero, zero, zero, tau_in) if forced else None)
        q_eval = q_sim
    gain = 1.0 if model.transmission_error is None else 1.0 + model.transmission_error.derivative(drive)
    return q_sim, (model.J * qdd + model.b * qd + gain * tau) / model.torque_gain


@by_content()
def _period_s(q_m, fs):
    from .compare import excitation_period_s

    return excitation_period_s(q_m, fs)


def coupling_input(model: JointModel, others_qdd: dict | None) -> np.ndarray | None:
    """The external torque (T,) N m the model's coupling terms put on its link from the other
    joints' accelerations, -sum inertia x q_other''; None without coupling."""
    if not model.coupling:
        return None
    others_qdd = others_qdd or {}
    missing = [s for s in model.coupling if s not in others_qdd]
    if missing:
        raise InputError(None, f"joints[{model.name}].coupling", "source joints in the recording", missing)
    return -sum(c * np.asarray(others_qdd[s]) for s, c in model.coupling.items())


def link_context(model: JointModel, others: dict | None):
    """The :class:`.context.LinkContext` of a robot's joint from the other joints' map (its
    :data:`.context.ROBOT_KEY` entry), None for a single joint."""
    if model.robot is None:
        return None
    from .context import ROBOT_KEY

    ctx = (others or {}).get(ROBOT_KEY)
    if ctx is None or model.name not in ctx.links:
        raise InputError(None, f"joints[{model.name}].urdf_joint", "the robot's other joints in the recording",
                         "no robot context")
    return ctx.of(model.name)


def _robot_link(model: JointModel, t, q, drive, ext, context, d_span: float):
    """(q_sim, u_sim) (T,) of a robot's joint (:mod:`.context`) by the compiled link kernel, its
    inertia, gravity and the other links' torque from `context` (a LinkContext at the samples of
    t), plus the coupling torque `ext` and a position torque at the recorded link angle q.
    RuntimeError for an element the kernel does not run."""
    from ..dynamics.link_forward import encode_friction, encode_spring, link_forward

    fs = 1.0 / float(np.median(np.diff(t)))
    if np.abs(np.diff(t) * fs - 1.0).max() > 1e-6:
        raise RuntimeError("a robot's joint is simulated on uniform samples only")
    if encode_friction(model.friction) is None or encode_spring(model.spring) is None:
        raise RuntimeError(f"a robot's joint with {type(model.friction).__name__} friction and a "
                           f"{type(model.spring).__name__} spring is not simulated (mocapfj.dynamics.link_forward)")
    I_t, gx, gy, tau = context.arrays()
    if ext is not None:
        tau = tau + ext
    if model.position_torque is not None:
        tau = tau + model.position_torque.torque(np.asarray(q, dtype=np.float64))
    qd, qdd = spline_rates(t, drive)
    # the static state at the start under the first sample's context
    sj = model.with_(I=float(model.I + I_t[0]), mglx=float(model.mglx + gx[0]), mgly=float(model.mgly + gy[0]),
                     position_torque=None).single_joint(smoothing=1e-6)
    q0 = float(sj.static_link_angle(np.array([drive[0]]))[0]) + float(tau[0]) / model.stiffness()
    q_sim, _, tau_s = link_forward(drive, fs, I=model.I, mglx=model.mglx, mgly=model.mgly, friction=model.friction,
                                   spring=model.spring, transmission_error=model.transmission_error, qd_m=qd, q0=q0,
                                   d_span=d_span, context=(I_t, gx, gy, tau))
    gain = 1.0 if model.transmission_error is None else 1.0 + model.transmission_error.derivative(drive)
    return q_sim, (model.J * qdd + model.b * qd + gain * tau_s) / model.torque_gain


def predict(model: JointModel, t, q, q_m, ext=None, *, rtol: float = 1e-4, atol: float = 1e-7, context=None):
    """(q_sim, u_sim) (T,): the link angle on the mocap clock (the model's delay applied) and the
    motor torque the model predicts when its link is driven by the recorded motor angle, Wiener-
    filtered (:func:`mocapfj.ident.output_error.wiener_drive`). ext : (T,) N m, the coupling torque
    (:func:`coupling_input`) or None. context : a robot joint's :class:`.context.LinkContext` at
    the samples of t (:func:`link_context`), or None for a single joint. A compiled kernel when
    the model is one it runs, else :func:`mocapfj.dynamics.simulate` on a budget of 20
    derivative evaluations per sample (raises RuntimeError beyond it)."""
    fs = 1.0 / float(np.median(np.diff(t)))
    # the motor angle drives the link without the encoder noise that would ring it where the real
    # link, driven by the true motion, does not (mocapfj.ident.output_error.wiener_drive)
    drive = wiener_drive_of(q_m, fs)
    if context is not None:
        q_sim, u_sim = _robot_link(model, t, q, drive, ext, context, 2.0 * float(np.nanmax(np.abs(q_m - q))))
        if model.delay_s:
            q_sim = shift_signal(t, q_sim, -model.delay_s)
        return q_sim, u_sim
    fast = _plain_link(model, t, drive, 2.0 * float(np.nanmax(np.abs(q_m - q))), ext)
    if fast is not None:
        q_sim, u_sim = fast
    else:
        def coupling_torque(tt):
            return np.interp(tt, t, ext) if np.ndim(tt) == 0 else np.interp(tt, t, ext)[:, None]

        res = simulate(model.single_joint(), t, PrescribedMotor.from_samples(t, drive),
                       tau_ext=coupling_torque if ext is not None else None, rtol=rtol, atol=atol,
                       max_evals=20 * t.size)
        q_sim, u_sim = res.q[:, 0], res.u[:, 0]
    if model.delay_s:
        q_sim = shift_signal(t, q_sim, -model.delay_s)        # mocap stamps are late: it saw q(t + delay)
    return q_sim, u_sim


def simulate_joint(model: JointModel, t, q, q_m, u, others_qdd: dict | None = None, *, trim_s: float = 1.0,
                   rtol: float = 1e-4, atol: float = 1e-7, period_s: float | None | str = "auto",
                   band_hz: float | None = None, smoothing_hz: float | None = None) -> OutputError:
    """Simulate `model` driven by the recorded motor angle and compare with the recording.

    t, q, q_m, u : (T,) on one clock (s, rad, rad, N m); others_qdd : {joint: (T,) rad/s^2} the
    other joints' link accelerations, for the model's coupling terms, and for a robot's joint
    the :class:`.context.RobotContext` (key :data:`.context.ROBOT_KEY`). The delay of the model
    shifts the simulated link angle onto the mocap samples. `trim_s` at both ends is left out
    of the fits (the simulation starts from the static state). period_s : the excitation's period
    for the noise floor; "auto" finds it in q_m (:func:`.compare.excitation_period_s`), None: none.
    band_hz : the comparison band; default the model's own (:func:`.compare.comparison_band_hz` at
    the deflections it simulates). Models compared with each other take one band.
    smoothing_hz : the corner of a low-pass the markers went through before export
    (`JointSignals.smoothing_hz`): the default band is at most SMOOTHED_BAND of it, and the
    deflection's white floor is read below it (:data:`.compare.SMOOTHED_WHITE`).
    """
    from .compare import SMOOTHED_WHITE, combined_fit, combined_floor_sd, compare_channel, comparison_band_hz

    t, q, q_m, u = (np.asarray(a, dtype=np.float64) for a in (t, q, q_m, u))
    fs = 1.0 / float(np.median(np.diff(t)))
    ext = coupling_input(model, others_qdd)
    ctx = link_context(model, others_qdd)
    q_sim, u_sim = predict(model, t, q, q_m, ext, rtol=rtol, atol=atol, context=ctx)
    d_rec, d_sim = q_m - q, q_m - q_sim
    keep = (t >= t[0] + trim_s) & (t <= t[-1] - trim_s) & np.isfinite(d_sim)
    r_d = np.full_like(t, np.nan)
    r_d[keep] = d_rec[keep] - d_sim[keep]
    r_d -= np.nanmean(r_d)
    r_u = np.full_like(t, np.nan)
    r_u[keep] = u[keep] - u_sim[keep]
    dc = d_rec[keep] - d_rec[keep].mean()
    e_d = np.linalg.norm(r_d[keep]) / np.linalg.norm(dc)
    e_u = np.linalg.norm(r_u[keep]) / np.linalg.norm(u[keep] - u[keep].mean())
    # the comparison in the model's band, against the recording's noise floor; the band from the
    # link's resonance at the deflections the model itself goes through (a stiffening spring's
    # slope over +-10 mrad can be 100x its slope over the 0.2 mrad a light joint deflects)
    if band_hz is None:
        lo, hi = np.nanpercentile(d_sim[keep], [1.0, 99.0]) if keep.any() else (-0.01, 0.01)
        inertia = model.I if ctx is None else model.I + float(np.mean(ctx.I))      # a robot's link: its mean
        band = comparison_band_hz(model.stiffness(lo, hi) if hi - lo > 1e-7 else model.stiffness(), inertia, fs)
        if smoothing_hz is not None:
            band = min(band, SMOOTHED_BAND * float(smoothing_hz))
    else:
        band = float(band_hz)
    inner = (t >= t[0] + trim_s) & (t <= t[-1] - trim_s)
    if period_s == "auto":
        period_s = _period_s(q_m[inner], fs)
    if smoothing_hz is None:
        cd = compare_channel(d_rec, d_sim, q, fs, band, keep, period_s, center=True)
    else:
        # markers smoothed before export: no white floor above the corner; below it the link
        # angle moves, its deflection from the motor's far less
        cd = compare_channel(d_rec, d_sim, d_rec, fs, band, keep, period_s, center=True,
                             white_hz=(SMOOTHED_WHITE[0] * smoothing_hz, SMOOTHED_WHITE[1] * smoothing_hz))
    cu = compare_channel(u, u_sim, u, fs, band, keep, period_s, bounded=True)
    return OutputError(t=t, q_sim=q_sim, delta_sim=d_sim, u_sim=u_sim, r_delta=r_d, r_u=r_u,
                       fit_delta=cd.fit, fit_u=cu.fit, fit=combined_fit(cd.e, cu.e),
                       floor_delta=cd.floor, floor_u=cu.floor, floor=combined_fit(cd.e_floor, cu.e_floor),
                       floor_sd=combined_floor_sd(cd, cu), floor_sd_delta=cd.floor_sd, floor_sd_u=cu.floor_sd,
                       band_hz=band, period_s=period_s, floor_method=cd.method if cd.method == cu.method else
                       f"{cd.method}/{cu.method}", noise_delta_rad=cd.noise_sd, noise_u_Nm=cu.noise_sd,
                       fit_full_delta=float(100 * (1 - e_d)), fit_full_u=float(100 * (1 - e_u)),
                       sd_delta=cd.sd_y, sd_u=cu.sd_y, smoothing_hz=smoothing_hz)


def simulate_signals(model: JointModel, s, others_qdd: dict | None = None, **kw) -> OutputError:
    """:func:`simulate_joint` on a joint's signals `s` (:class:`mocapfj.types.JointSignals`), with
    the corner of the smoothing its markers went through (`s.smoothing_hz`)."""
    return simulate_joint(model, s.t, s.q, s.q_m, s.u, others_qdd, smoothing_hz=s.smoothing_hz, **kw)
