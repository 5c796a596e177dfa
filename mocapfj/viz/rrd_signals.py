"""The signals the recording derives from a run's files: the spring torques of the
deflection-torque loops, the identified joint, the windows discovery located."""

from __future__ import annotations

import numpy as np

from .rrd_data import JointRun, RunContents

__all__ = ["TIMELINE", "joint_params", "spring_torques", "spring_model_torque", "windows_of"]

TIMELINE = "time"
"""The recording's timeline: the controller clock, a duration in s."""
SPRING_LOWPASS_HZ = 10.0   # as discovery's residuals (mocapfj.discover.residuals.RESIDUAL_HZ)


def _fill(x: np.ndarray) -> np.ndarray:
    """x with its NaN samples interpolated (ends held), for filtering."""
    ok = np.isfinite(x)
    if ok.all() or not ok.any():
        return x
    i = np.arange(x.size)
    return np.interp(i, i[ok], x[ok])


def joint_params(contents: RunContents, name: str) -> dict | None:
    """The identified joint's entry of identify.json (None when not identified)."""
    for j in (contents.identify or {}).get("joints", []):
        if isinstance(j, dict) and j.get("name") == name and j.get("params"):
            return j
    return None


def spring_torques(j: JointRun, ident: dict | None) -> dict | None:
    """The spring torques at the joint's mocap samples, for the loops and the torque plot.

    Returns {t, delta, tau_s, model} (T,) each (s, rad, N m, N m), or None without a torque log:
    tau_s the motor-side spring torque u - J q_m'' - b q_m' (Lightcap and Banks 2007, eq. 4,
    motor row; J, b identified; the logged torque when not identified), every signal low-passed
    at 10 Hz (zero phase) before differentiating; delta the deflection low-passed the same way;
    model the identified spring f(delta) along that path (None when not identified).
    """
    a = j.angles
    if not all(k in a for k in ("q_m", "tau", "delta")):
        return None
    t = j.t
    if t.size < 64 or not np.isfinite(a["tau"]).any():
        return None
    from ..ident.conditioning import derivatives, lowpass

    fs = 1.0 / float(np.median(np.diff(t)))
    cut = min(SPRING_LOWPASS_HZ, 0.4 * fs)
    q_m, u, delta = (lowpass(_fill(a[k]), fs, cut) for k in ("q_m", "tau", "delta"))
    tau_s, model = u, None
    if ident is not None:
        p = ident["params"]
        J, b = (p[n]["value"] if n in p else 0.0 for n in ("J", "b"))
        qd, qdd = derivatives(q_m, fs)
        tau_s = u - J * qdd - b * qd
        model = spring_model_torque(ident.get("spring"), delta, t)
    nan = ~np.isfinite(a["delta"])
    delta, tau_s = np.where(nan, np.nan, delta), np.where(nan, np.nan, tau_s)
    if model is not None:
        model = np.where(nan, np.nan, model)
    return {"t": t, "delta": delta, "tau_s": tau_s, "model": model}


def spring_model_torque(spring: dict | None, delta: np.ndarray, t: np.ndarray) -> np.ndarray | None:
    """The identified spring's torque along delta (T,) rad at t (T,) s, N m: linear k delta + tau0
    (the zero offset identification fits), others through their :mod:`mocapfj.dynamics` element."""
    if not spring or "params" not in spring:
        return None
    p = spring["params"]
    if spring.get("model") == "linear":
        return p["k"] * delta + p.get("tau0", 0.0)
    from dataclasses import fields

    from ..dynamics.spec import SPRING_MODELS, element_from_table

    cls = SPRING_MODELS.get(spring.get("model"))
    if cls is None:
        return None
    names = {f.name for f in fields(cls) if f.init}
    el = element_from_table({"model": spring["model"], **{k: v for k, v in p.items() if k in names}})
    if getattr(el, "n_states", 0):
        return np.asarray(el.run(delta, t), dtype=np.float64)
    return np.asarray(el.torque(delta), dtype=np.float64)


def windows_of(discovery: dict | None, joint: str) -> list[tuple[str, float, float]]:
    """[(family, t_start_s, t_end_s)]: the windows discovery located for `joint` (its residual
    families' worst windows, discovery.json ``location``)."""
    loc = ((discovery or {}).get("location") or {}).get(joint) or {}
    out = []
    for family, d in loc.items():
        for w in (d or {}).get("worst_windows", []) if isinstance(d, dict) else []:
            out.append((family, float(w["t_start_s"]), float(w["t_end_s"])))
    return out
