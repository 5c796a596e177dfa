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

__all__ = ["JointModel", "read_model_file", "write_model_file", "fit_pct", "simulate_joint", "OutputError"]

MODEL_FORMAT = "mocapfj.model/1"


def _joint_from_table(tab: dict, path, i: int) -> JointModel:
    w = f"joints[{i}]"
    name = require(path, tab, "name", str, w)
    w = f"joints[{name}]"
    num = {k: float(require(path, tab, k, (int, float), w)) for k in ("I", "J", "mglx", "mgly", "b")}
    for k, v in num.items():
        ok = np.isfinite(v) and (v > 0 if k in ("I", "J") else v >= 0 if k == "b" else True)
        if not ok:
            what = "positive" if k in ("I", "J") else "non-negative" if k == "b" else "finite"
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


def read_model_file(path: str | Path) -> dict[str, JointModel]:
    """Joint models by name from a model file, or from a scenario file without its effects."""
    path = Path(path)
    doc = read_toml(path)
    fmt = doc.get("format")
    if fmt not in (MODEL_FORMAT, "mocapfj.scenario/1"):
        raise InputError(path, "format", f'"{MODEL_FORMAT}" (or a "mocapfj.scenario/1" file)', repr(fmt))
    joints = doc.get("joints")
    if not isinstance(joints, list) or not joints:
        raise InputError(path, "joints", "one [[joints]] table per joint", describe(joints))
    try:
        models = [_joint_from_table(t, path, i) for i, t in enumerate(joints)]
    except InputError as e:
        if e.file == "<argument>":              # a model element's own check: name this file
            raise InputError(path, e.field, e.expected, e.got, e.hint) from None
        raise
    names = [m.name for m in models]
    if len(set(names)) != len(names):
        raise InputError(path, "joints.name", "one table per joint", f"{sorted({n for n in names if names.count(n) > 1})} "
                         "more than once")
    return {m.name: m for m in models}


def write_model_file(path: str | Path, models, effects: list[dict] | None = None) -> None:
    """Write joint models (and, for the record, the effects that made them) atomically."""
    doc = {"format": MODEL_FORMAT, "joints": [m.to_table() for m in models]}
    if effects:
        doc["discovered"] = effects
    write_toml(path, doc)


def fit_pct(y: np.ndarray, y_hat: np.ndarray) -> float:
    """100 (1 - ||y - y_hat|| / ||y - mean(y)||) over the samples where both are finite (docs/conventions.md)."""
    ok = np.isfinite(y) & np.isfinite(y_hat)
    y, y_hat = y[ok], y_hat[ok]
    den = np.linalg.norm(y - y.mean())
    return float(100.0 * (1.0 - np.linalg.norm(y - y_hat) / den)) if den > 0 else float("nan")


@dataclass(frozen=True, eq=False)
class OutputError:
    """An output-error simulation compared with a recording (one joint, mocap samples).

    t (T,) s; q_sim, delta_sim, u_sim: simulated link angle, deflection q_m - q and logged motor
    torque (rad, rad, N m); r_delta, r_u: recorded minus simulated (the deflection's constant,
    the link-angle zero the joints stage cannot know, removed); fit_delta, fit_u: fit % of each;
    fit: the joint's fit %, 100 (1 - sqrt((e_delta^2 + e_u^2) / 2)) with e the normalised error
    of each (the deflection shows what mocap sees, the torque what the drive sees).
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


def simulate_joint(model: JointModel, t, q, q_m, u, others_qdd: dict | None = None, *, trim_s: float = 1.0,
                   rtol: float = 1e-4, atol: float = 1e-7) -> OutputError:
    """Simulate `model` driven by the recorded motor angle and compare with the recording.

    t, q, q_m, u : (T,) on one clock (s, rad, rad, N m); others_qdd : {joint: (T,) rad/s^2} the
    other joints' link accelerations, for the model's coupling terms. The delay of the model
    shifts the simulated link angle onto the mocap samples. `trim_s` at both ends is left out
    of the fits (the simulation starts from the static state).
    """
    t, q, q_m, u = (np.asarray(a, dtype=np.float64) for a in (t, q, q_m, u))
    ext = None
    if model.coupling:
        others_qdd = others_qdd or {}
        missing = [s for s in model.coupling if s not in others_qdd]
        if missing:
            raise InputError(None, f"joints[{model.name}].coupling", "source joints in the recording", missing)
        ext = -sum(c * np.asarray(others_qdd[s]) for s, c in model.coupling.items())

    def coupling_torque(tt):
        return np.interp(tt, t, ext) if np.ndim(tt) == 0 else np.interp(tt, t, ext)[:, None]
    res = simulate(model.single_joint(), t, PrescribedMotor.from_samples(t, q_m),
                   tau_ext=coupling_torque if ext is not None else None, rtol=rtol, atol=atol)
    q_sim = res.q[:, 0]
    if model.delay_s:
        q_sim = shift_signal(t, q_sim, -model.delay_s)        # mocap stamps are late: it saw q(t + delay)
    u_sim = res.u[:, 0]
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
    return OutputError(t=t, q_sim=q_sim, delta_sim=d_sim, u_sim=u_sim, r_delta=r_d, r_u=r_u,
                       fit_delta=float(100 * (1 - e_d)), fit_u=float(100 * (1 - e_u)),
                       fit=float(100 * (1 - np.sqrt((e_d**2 + e_u**2) / 2))))
