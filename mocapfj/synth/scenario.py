"""Scenario files: what a synthetic recording contains and the physics behind it.

A scenario (``datasets/*.toml``, format ``mocapfj.scenario/1``) names a robot, the joints that
move with their dynamics and motor references, the measurement chain and a list of effects
planted in the true system. `load_scenario` parses and checks it; `joint_models` builds the
flexible-joint models with or without the effects. docs/formats.md § Scenario lists every key.

The effect vocabulary is the discovery vocabulary (`EFFECTS`); each effect changes one joint of
the true system, and the nominal system is the same scenario without its effects:

| effect | keys | what the true system gets |
|---|---|---|
| hysteresis, stiffening | spring = {model table} | this spring instead of the nominal one |
| backlash | gap_rad | a dead zone of that width around the nominal spring |
| transmission_error | amplitudes_rad, phases_rad, orders | e(q_m), periodic in the wave-generator angle |
| position_dependent_friction | amplitudes_Nm, phases_rad, orders | Coulomb level rippling with the link angle |
| stribeck, friction_asymmetry | friction = {model table} | this friction instead of the nominal one |
| time_delay | delay_s | mocap clock late by delay_s beyond the declared offset |
| coupling | source, inertia_kgm2 | torque -inertia * q''(source joint) on this joint |
| gravity_mismatch | k, a, b, free_length, q0 | a spring gravity balancer (not of the m g l sin q form) |
| drive_gain | gain | actual motor torque = gain x logged torque |
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..dynamics import (Backlash, Drivetrain, GravityBalancer, PositionDependent, SingleJoint, TransmissionError,
                        element_from_table)
from ..dynamics.spec import FRICTION_MODELS, SPRING_MODELS
from ..errors import InputError
from ..validate import check_scalar
from ..io.tomlio import check_format, describe, read_toml, require

__all__ = ["EFFECTS", "Scenario", "ScenarioJoint", "Measurement", "Effect", "load_scenario", "joint_models",
           "reference_trajectory", "joint_friction", "joint_spring", "joint_drivetrain"]

EFFECTS = ("hysteresis", "stiffening", "backlash", "transmission_error", "position_dependent_friction", "stribeck",
           "friction_asymmetry", "time_delay", "coupling", "gravity_mismatch", "drive_gain")

_EFFECT_KEYS = {
    "hysteresis": {"spring"}, "stiffening": {"spring"}, "backlash": {"gap_rad"},
    "transmission_error": {"amplitudes_rad", "phases_rad", "orders"},
    "position_dependent_friction": {"amplitudes_Nm", "phases_rad", "orders"},
    "stribeck": {"friction"}, "friction_asymmetry": {"friction"}, "time_delay": {"delay_s"},
    "coupling": {"source", "inertia_kgm2"}, "gravity_mismatch": {"k", "a", "b", "free_length", "q0"},
    "drive_gain": {"gain"},
}
_EFFECT_REQUIRED = {
    "hysteresis": {"spring"}, "stiffening": {"spring"}, "backlash": {"gap_rad"},
    "transmission_error": {"amplitudes_rad", "phases_rad"}, "position_dependent_friction": {"amplitudes_Nm", "phases_rad"},
    "stribeck": {"friction"}, "friction_asymmetry": {"friction"}, "time_delay": {"delay_s"},
    "coupling": {"source", "inertia_kgm2"}, "gravity_mismatch": {"k", "a", "b"}, "drive_gain": {"gain"},
}


_EFFECT_BOUNDS = {
    ("time_delay", "delay_s"): (0.0, 1.0),
    ("transmission_error", "amplitudes_rad"): (-0.1, 0.1),
    ("backlash", "gap_rad"): (0.0, 0.1),
    ("coupling", "inertia_kgm2"): (0.0, 1e4),
    ("drive_gain", "gain"): (0.1, 10.0),
}
"""Plausible ranges of effect parameters (a transmission error of 1e3 rad hung the simulator)."""


@dataclass(frozen=True)
class Measurement:
    """The measurement chain: rates, noise, cameras, clocks (SI units)."""

    mocap_hz: float = 250.0
    controller_hz: float = 1000.0
    marker_noise_m: float = 2e-4
    pixel_noise_px: float = 0.15
    n_cameras: int = 8
    resolver_bits: int = 16
    torque_noise_Nm: float = 0.3
    clock_offset_s: float = 0.0   # declared in recording.toml: t_controller = t_mocap + offset
    dropout_rate: float = 0.002   # fraction of 3D samples lost in random bursts (beyond occlusion)
    dropout_frames: float = 5.0   # mean burst length, frames
    detections_s: float = 2.0     # 2D detections are written for the first detections_s seconds
    sim_max_step_s: float = 5e-3
    sim_rtol: float = 1e-6


@dataclass(frozen=True)
class ScenarioJoint:
    """One moving joint: PA-10 joint number, parameters of Lightcap and Banks (2007), eq. (4), reference, PD gains."""

    name: str
    axis: int                      # PA-10 joint number 1..6
    gear_ratio: float
    I: float                       # link inertia, single-joint models only (URDF models take it from the URDF)
    J: float
    mglx: float
    mgly: float
    b: float
    friction: dict
    spring: dict
    reference: dict                # f0_hz, q0_rad, amplitudes_rad, phases_rad (Lightcap and Banks (2007), eq. 9)
    kp: float
    kd: float
    ki: float = 0.0
    link_markers: tuple[str, ...] = ()
    parent_markers: tuple[str, ...] | str = "world"


@dataclass(frozen=True)
class Effect:
    name: str
    joint: str
    params: dict


@dataclass(frozen=True)
class Scenario:
    """A parsed scenario file; `doc` keeps the file's tables for truth.json."""

    name: str
    description: str
    seed: int
    duration_s: float
    model: str                     # "single": each joint its own SingleJoint; "urdf": one NLinkModel
    pose_rad: tuple[float, ...]
    payload_kg: float
    joints: tuple[ScenarioJoint, ...]
    effects: tuple[Effect, ...]
    measurement: Measurement
    source: Path | None = None
    doc: dict = field(default_factory=dict)

    def joint(self, name: str) -> ScenarioJoint:
        for j in self.joints:
            if j.name == name:
                return j
        raise InputError(self.source, "joint", f"one of {[j.name for j in self.joints]}", repr(name))

    def effects_on(self, joint: str) -> tuple[Effect, ...]:
        return tuple(e for e in self.effects if e.joint == joint)

    def with_duration(self, duration_s: float) -> "Scenario":
        return replace(self, duration_s=float(duration_s))

    def without_effects(self) -> "Scenario":
        return replace(self, effects=())


def _num(path, tab, key, where, default=None, positive=False):
    v = require(path, tab, key, (int, float), where, default=default)
    if v is None:
        return None
    v = float(v)
    if v != v and default is not None and default != default:  # NaN default: "not used by this model"
        return v
    return check_scalar(v, f"{where}.{key}" if where else key, positive=positive, file=path)


def _integer(path, tab, key, where="", default=None) -> int:
    v = _num(path, tab, key, where, default=default)
    if v != int(v):
        raise InputError(path, f"{where}.{key}" if where else key, "an integer", v)
    return int(v)


def _floats(path, tab, key, where, n=None):
    v = require(path, tab, key, list, where)
    try:
        a = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        raise InputError(path, f"{where}.{key}", "a list of numbers", describe(v)) from None
    if not all(math.isfinite(x) for x in a):
        raise InputError(path, f"{where}.{key}", "finite numbers", describe(v))
    if n is not None and len(a) != n:
        raise InputError(path, f"{where}.{key}", f"{n} numbers", len(a))
    return a


def _reference(path, tab, where) -> dict:
    ref = require(path, tab, "reference", dict, where)
    w = f"{where}.reference"
    amps = _floats(path, ref, "amplitudes_rad", w)
    phases = _floats(path, ref, "phases_rad", w, len(amps))
    return {"f0_hz": _num(path, ref, "f0_hz", w, positive=True), "q0_rad": _num(path, ref, "q0_rad", w, default=0.0),
            "amplitudes_rad": amps, "phases_rad": phases,
            "ramp_s": _num(path, ref, "ramp_s", w, default=2.0)}


MAX_RATE_HZ = 20000.0
"""Largest mocap or controller rate a scenario may ask for, Hz."""
MAX_SAMPLES = 5e7
"""Largest number of controller samples (duration x rate) one simulation may produce."""
MAX_CAMERAS = 64


def check_scenario(path, scn: "Scenario") -> None:
    """What the simulator needs of a parsed scenario: bounds that keep it within this machine's
    time and memory (rates, duration x rate, cameras), integer seed and resolver bits in range,
    three or more distinct link markers not shared with the parent, noises >= 0; InputError
    naming the key."""
    m = scn.measurement
    for key in ("mocap_hz", "controller_hz"):
        v = getattr(m, key)
        if not (math.isfinite(v) and 0 < v <= MAX_RATE_HZ):
            raise InputError(path, f"measurement.{key}", f"a rate in (0, {MAX_RATE_HZ:g}] Hz", v)
    n = scn.duration_s * max(m.controller_hz, m.mocap_hz)
    if not n <= MAX_SAMPLES:
        raise InputError(path, "duration_s", f"a duration x rate of at most {MAX_SAMPLES:g} samples",
                         f"{scn.duration_s:g} s x {max(m.controller_hz, m.mocap_hz):g} Hz")
    if not (2 <= m.n_cameras <= MAX_CAMERAS):
        raise InputError(path, "measurement.n_cameras", f"2 to {MAX_CAMERAS} cameras", m.n_cameras)
    if not 8 <= m.resolver_bits <= 32:
        raise InputError(path, "measurement.resolver_bits", "8 to 32 bits", m.resolver_bits)
    if not (0 <= scn.seed < 2 ** 63):
        raise InputError(path, "seed", "a non-negative integer", scn.seed)
    for j in scn.joints:
        labels = list(j.link_markers)
        if len(labels) < 3 or len(set(labels)) != len(labels) or not all(isinstance(x, str) and x for x in labels):
            raise InputError(path, f"joints[{j.name}].link_markers", "3 or more distinct marker labels", describe(labels))
        if not isinstance(j.parent_markers, str) and set(j.parent_markers) & set(labels):
            raise InputError(path, f"joints[{j.name}].parent_markers", "labels other than the link's",
                             sorted(set(j.parent_markers) & set(labels)))
    for key in ("marker_noise_m", "pixel_noise_px", "torque_noise_Nm", "dropout_rate"):
        v = getattr(m, key)
        if not (math.isfinite(v) and v >= 0):
            raise InputError(path, f"measurement.{key}", "a finite value >= 0", v)


def load_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Parse and check a scenario file (format ``mocapfj.scenario/1``); every error names the file."""
    path = Path(path)
    try:
        scn = _load_scenario(path)
    except InputError as e:
        if e.file == "<argument>":                 # a check of a model element: name this file
            raise InputError(path, e.field, e.expected, e.got, e.hint) from None
        raise
    except (ValueError, TypeError) as e:          # a value the model elements cannot take
        raise InputError(path, "scenario", "values the simulator accepts",
                         str(e).splitlines()[0][:200] if str(e) else type(e).__name__) from None
    check_scenario(path, scn)
    return scn


def _load_scenario(path: Path) -> Scenario:
    doc = read_toml(path)
    check_format(path, doc, "scenario", 1)
    name = require(path, doc, "name", str, default=path.stem)
    robot = require(path, doc, "robot", dict, default={})
    model = require(path, robot, "model", str, "robot", default="single")
    if model not in ("single", "urdf"):
        raise InputError(path, "robot.model", '"single" or "urdf"', repr(model))
    pose = _floats(path, robot, "pose_rad", "robot", 6) if "pose_rad" in robot else (0.0,) * 6
    meas_tab = require(path, doc, "measurement", dict, default={})
    meas_kwargs = {}
    for f_name, f_default in Measurement.__dataclass_fields__.items():
        if f_name in meas_tab:
            v = _num(path, meas_tab, f_name, "measurement")
            if isinstance(f_default.default, int) and v != int(v):
                raise InputError(path, f"measurement.{f_name}", "an integer", v)
            meas_kwargs[f_name] = int(v) if isinstance(f_default.default, int) else v
    unknown = sorted(set(meas_tab) - set(Measurement.__dataclass_fields__))
    if unknown:
        raise InputError(path, "measurement", f"keys among {sorted(Measurement.__dataclass_fields__)}", f"unknown {unknown}")

    joints = []
    for i, tab in enumerate(require(path, doc, "joints", list)):
        w = f"joints[{i}]"
        jname = require(path, tab, "name", str, w)
        w = f"joints[{jname}]"
        friction = require(path, tab, "friction", dict, w)
        spring = require(path, tab, "spring", dict, w)
        element_from_table(friction, FRICTION_MODELS, path, f"{w}.friction")  # checked here, built later
        element_from_table(spring, SPRING_MODELS, path, f"{w}.spring")
        control = require(path, tab, "control", dict, w)
        axis = _integer(path, tab, "axis", w)
        if not 1 <= axis <= 6:
            raise InputError(path, f"{w}.axis", "a PA-10 joint number from 1 to 6", axis)
        parent = tab.get("parent_markers", "world")
        joints.append(ScenarioJoint(
            name=jname, axis=axis, gear_ratio=_num(path, tab, "gear_ratio", w, positive=True),
            I=_num(path, tab, "I", w, positive=True, default=None if model == "single" else float("nan")),
            J=_num(path, tab, "J", w, positive=True),
            mglx=_num(path, tab, "mglx", w, default=0.0), mgly=_num(path, tab, "mgly", w, default=0.0),
            b=_num(path, tab, "b", w, default=0.0), friction=friction, spring=spring,
            reference=_reference(path, tab, w), kp=_num(path, control, "kp", f"{w}.control", positive=True),
            kd=_num(path, control, "kd", f"{w}.control", default=0.0), ki=_num(path, control, "ki", f"{w}.control", default=0.0),
            link_markers=tuple(require(path, tab, "link_markers", list, w)),
            parent_markers=parent if isinstance(parent, str) else tuple(parent)))
    if not joints:
        raise InputError(path, "joints", "at least one [[joints]] table", "none")
    if len({j.axis for j in joints}) != len(joints):
        raise InputError(path, "joints.axis", "each PA-10 joint moved by one joint only", [j.axis for j in joints])
    names = [j.name for j in joints]

    effects = []
    for i, tab in enumerate(require(path, doc, "effects", list, default=[])):
        w = f"effects[{i}]"
        ename = require(path, tab, "name", str, w)
        if ename not in EFFECTS:
            raise InputError(path, f"{w}.name", f"one of {list(EFFECTS)}", repr(ename))
        joint = require(path, tab, "joint", str, w)
        if joint not in names:
            raise InputError(path, f"{w}.joint", f"one of the scenario's joints {names}", repr(joint))
        params = {k: v for k, v in tab.items() if k not in ("name", "joint")}
        extra = sorted(set(params) - _EFFECT_KEYS[ename])
        missing = sorted(_EFFECT_REQUIRED[ename] - set(params))
        if extra or missing:
            raise InputError(path, w, f"{ename} keys {sorted(_EFFECT_KEYS[ename])} (required {sorted(_EFFECT_REQUIRED[ename])})",
                             f"unknown {extra}" if extra else f"missing {missing}")
        if ename == "coupling" and params["source"] not in names:
            raise InputError(path, f"{w}.source", f"one of the scenario's joints {names}", repr(params["source"]))
        for key, value in params.items():
            vals = value if isinstance(value, list) else [value]
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals) and vals:
                if not all(math.isfinite(v) for v in vals):
                    raise InputError(path, f"{w}.{key}", "finite numbers", value)
                lo, hi = _EFFECT_BOUNDS.get((ename, key), (-math.inf, math.inf))
                if not all(lo <= v <= hi for v in vals):
                    raise InputError(path, f"{w}.{key}", f"values in [{lo:g}, {hi:g}]", value)
        effects.append(Effect(ename, joint, params))

    return Scenario(
        name=name, description=require(path, doc, "description", str, default=""),
        seed=_integer(path, doc, "seed", default=0), duration_s=_num(path, doc, "duration_s", "", positive=True),
        model=model, pose_rad=pose, payload_kg=_num(path, robot, "payload_kg", "robot", default=0.0),
        joints=tuple(joints), effects=tuple(effects), measurement=Measurement(**meas_kwargs), source=path, doc=doc)


def reference_trajectory(ref: dict):
    """Motor reference of Lightcap and Banks (2007), eq. (9), a finite Fourier series, as a function of t.

    q_ref(t) = q0 + s(t) sum_l a_l [sin(l w t + phi_l) - sin(phi_l)],  w = 2 pi f0,
    with a smooth ramp s(t) from 0 to 1 over ``ramp_s`` (a C1 start from rest at q0).
    Returns a function t -> (q_ref, qd_ref), arrays of the shape of t, rad and rad/s.
    """
    a = np.asarray(ref["amplitudes_rad"], float)
    ph = np.asarray(ref["phases_rad"], float)
    w = 2 * np.pi * ref["f0_hz"] * np.arange(1, a.size + 1)
    q0, ramp = ref["q0_rad"], ref.get("ramp_s", 2.0)

    def fn(t):
        t = np.asarray(t, dtype=np.float64)
        arg = t[..., None] * w + ph
        f = (a * (np.sin(arg) - np.sin(ph))).sum(-1)
        fd = (a * w * np.cos(arg)).sum(-1)
        if ramp > 0:
            x = np.clip(t / ramp, 0.0, 1.0)
            s = x * x * (3 - 2 * x)
            sd = np.where((t > 0) & (t < ramp), 6 * x * (1 - x) / ramp, 0.0)
        else:
            s, sd = np.ones_like(t), np.zeros_like(t)
        return q0 + s * f, s * fd + sd * f

    return fn


def joint_friction(j: ScenarioJoint, effects, source):
    """The friction element of a scenario joint with the given effects planted."""
    fr = element_from_table(j.friction, FRICTION_MODELS, source, f"joints[{j.name}].friction")
    for e in effects:
        if e.name in ("stribeck", "friction_asymmetry"):
            fr = element_from_table(e.params["friction"], FRICTION_MODELS, source, f"effects[{e.name}].friction")
    for e in effects:
        if e.name == "position_dependent_friction":
            amps = tuple(float(x) for x in e.params["amplitudes_Nm"])
            orders = tuple(float(x) for x in e.params.get("orders", [1.0] * len(amps)))
            fr = PositionDependent(fr, orders=orders, amplitudes=amps,
                                   phases=tuple(float(x) for x in e.params["phases_rad"]))
    return fr


def joint_spring(j: ScenarioJoint, effects, source):
    """The spring element of a scenario joint with the given effects planted."""
    sp = element_from_table(j.spring, SPRING_MODELS, source, f"joints[{j.name}].spring")
    for e in effects:
        if e.name in ("hysteresis", "stiffening"):
            sp = element_from_table(e.params["spring"], SPRING_MODELS, source, f"effects[{e.name}].spring")
    for e in effects:
        if e.name == "backlash":
            sp = Backlash(float(e.params["gap_rad"]), sp)
    return sp


def joint_drivetrain(j: ScenarioJoint, effects) -> Drivetrain:
    """The drivetrain of a scenario joint with the given effects planted."""
    te = bal = None
    gain = 1.0
    for e in effects:
        p = e.params
        if e.name == "transmission_error":
            amps = tuple(float(x) for x in p["amplitudes_rad"])
            te = TransmissionError(j.gear_ratio, amps, tuple(float(x) for x in p["phases_rad"]),
                                   tuple(float(x) for x in p.get("orders", [1.0, 2.0][: len(amps)])))
        elif e.name == "gravity_mismatch":
            bal = GravityBalancer(k=float(p["k"]), a=float(p["a"]), b=float(p["b"]),
                                  free_length=float(p.get("free_length", 0.0)), q0=float(p.get("q0", 0.0)))
        elif e.name == "drive_gain":
            gain = float(p["gain"])
    return Drivetrain(transmission_error=te, balancer=bal, torque_gain=gain)


def joint_models(scn: Scenario, with_effects: bool = True, smoothing: float = 1e-3) -> dict[str, SingleJoint]:
    """The SingleJoint model of each joint (true system with its effects, or nominal without).

    Friction is smoothed with tanh(q'/`smoothing`) for the stiff integrator. Clock and
    coupling effects are not part of a joint model; the recorder applies them.
    """
    out = {}
    for j in scn.joints:
        eff = scn.effects_on(j.name) if with_effects else ()
        fr = joint_friction(j, eff, scn.source).with_smoothing(smoothing)
        out[j.name] = SingleJoint(I=j.I, J=j.J, spring=joint_spring(j, eff, scn.source), mglx=j.mglx, mgly=j.mgly, b=j.b,
                                  friction=fr, drivetrain=joint_drivetrain(j, eff), name=j.name)
    return out


def nominal_parameters(j: ScenarioJoint) -> dict:
    """The seed-000 parameter set of a joint (names as in Lightcap and Banks (2007), Table I) plus its elements."""
    return {"I": j.I, "J": j.J, "mglx": j.mglx, "mgly": j.mgly, "b": j.b, "gear_ratio": j.gear_ratio,
            "friction": j.friction, "spring": j.spring}

