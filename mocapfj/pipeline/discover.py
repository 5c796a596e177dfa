"""Composition of discovery (`run_discover`, ``mocapfj discover``): joints, signals, the nominal
model (a file, or identified on the spot), `mocapfj.discover.discover`, and its files."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..io import load_recording, write_json
from ..types import Recording
from .core import joint_signals, run_joints
from .identify import identify_signals

def _discovery_signals(recording, out: Path) -> tuple[Recording, dict]:
    """run_joints, then every joint's signals on the mocap samples (common span)."""
    from ..discover import JointSignals

    rec = load_recording(recording)
    run_joints(recording, out)
    sig = {spec.name: joint_signals(rec, out / f"{spec.name}.angles.csv", i) for i, spec in enumerate(rec.joints)}
    n = min(s[0].size for s in sig.values())
    return rec, {name: JointSignals(s[0][:n], s[1][:n], s[2][:n], s[3][:n]) for name, s in sig.items()}


def _identified_models(rec: Recording, signals: dict) -> dict:
    """The nominal model of each joint identified on the spot (motor-first: linear spring,
    Coulomb + viscous friction, gravity; the spring's zero is the recording's)."""
    from ..discover import JointModel
    from ..dynamics import CoulombViscous, LinearSpring

    models = {}
    for spec in rec.joints:
        s = signals[spec.name]
        res = identify_signals(s.t, s.q, s.q_m, s.u, rec.markers.rate_hz, spring_models=("linear",))
        v = {n: res["values"][n][0] for n in res["values"]}
        models[spec.name] = JointModel(name=spec.name, gear_ratio=spec.gear_ratio, I=v["I"], J=v["J"], mglx=v["mglx"],
                                       mgly=v["mgly"], b=v["b"], friction=CoulombViscous(c=v["c"], v=v["v"]),
                                       spring=LinearSpring(k=v["k"]))
    return models


def _verdict(d) -> str:
    """One line: the effects found, and any mismatch the library leaves unexplained."""
    left = [f"{j} ({fam} residual {r[f'{fam}_rms_Nm']:.3g} N m RMS)" for j, r in d.remaining.items()
            for fam in ("spring", "link") if r[f"{fam}_unexplained"]]
    found = ", ".join(f"{e['name']} ({e['joint']})" for e in d.effects)
    if not d.effects and not left:
        return "no missing physics found"
    if not left:
        return f"missing physics: {found}"
    tail = "a mismatch no effect of the library explains remains on " + ", ".join(left) + " (see location)"
    return f"missing physics: {found}; {tail}" if d.effects else f"no effect of the library found; {tail}"


def run_discover(recording, out: str | Path, model: str | Path | None = None, validation=None) -> dict:
    """``mocapfj discover``: what the model misses in the recording (:mod:`mocapfj.discover`).

    The model: a model file (or a scenario file, read without its effects), else each joint
    identified on the spot (`identify_signals`, linear spring). Writes OUT/joints (and
    OUT/validation_joints), OUT/discovery.json, the augmented model OUT/model.toml and the
    before/after residuals OUT/residuals.csv (t, and per joint r_delta_before/after rad, r_u_before/after N m).
    """
    from ..discover import discover, read_model_file, write_model_file
    from ..io import write_csv_columns

    out = Path(out)
    if validation is not None:
        load_recording(validation)                  # refuse a bad validation bundle before the long work
    if model is not None:
        read_model_file(model)
    rec, signals = _discovery_signals(recording, out / "joints")
    if model is not None:
        models = read_model_file(model)
        missing = [n for n in signals if n not in models]
        if missing:
            raise InputError(model, "joints", f"a model of every joint of the recording {list(signals)}",
                             f"none for {missing}")
        models = {n: models[n] for n in signals}
    else:
        models = _identified_models(rec, signals)
    val = None
    if validation is not None:
        _, val = _discovery_signals(validation, out / "validation_joints")
    d = discover(signals, models, fs_hz=rec.markers.rate_hz, validation=val)
    summary = {"recording": str(recording), "model": str(model) if model is not None else "identified",
               "effects": d.effects, "fit_before": d.fit_before, "fit_after": d.fit_after, "fits": d.fits,
               "location": d.location, "validation": d.validation, "stopped": d.stopped, "remaining": d.remaining,
               "verdict": _verdict(d)}
    write_json(out / "discovery.json", summary)
    write_model_file(out / "model.toml", d.models.values(),
                     [{k: e[k] for k in ("name", "joint", "parameters", "p_value")} for e in d.effects])
    cols = {}
    for name, r in d.residuals.items():
        cols.setdefault("t", r["t"])
        for key in ("r_delta_before", "r_delta_after", "r_u_before", "r_u_after"):
            cols[f"{name}_{key}"] = r[key]
    if cols:
        write_csv_columns(out / "residuals.csv", cols)
    return summary
