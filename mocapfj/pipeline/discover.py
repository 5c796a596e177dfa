"""Files over discovery (``mocapfj discover``): the joints stage of the recording (and of the
validation recording) written, :func:`mocapfj.discover` run, and its results written."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from ..io import load_recording, write_json
from .core import write_joints

__all__ = ["run_discover", "write_discovery"]


def run_discover(recording, out: str | Path, model: str | Path | None = None, validation=None) -> dict:
    """``mocapfj discover``: what the model misses in the recording (:mod:`mocapfj.discover`).

    The model: a model file (or a scenario file, read without its effects), else each joint
    identified on the spot (linear spring). Writes OUT/joints (and OUT/validation_joints),
    OUT/discovery.json, the augmented model OUT/model.toml and the before/after residuals
    OUT/residuals.csv (t, and per joint r_delta_before/after rad, r_u_before/after N m); without
    a model file, the model identified on the spot as OUT/nominal.toml.
    """
    from threadpoolctl import threadpool_limits

    # one BLAS thread throughout: the re-identification's worker runs on the other core, and idle
    # BLAS threads spin on it (mocapfj.discover.discover)
    with threadpool_limits(1, user_api="blas"):
        return _run_discover(recording, out, model, validation)


def _run_discover(recording, out, model, validation) -> dict:
    from ..api import discover
    from ..discover import read_model_file
    from ..joints.stage import calibrate_joints

    out = Path(out)
    val_rec = load_recording(validation) if validation is not None else None   # refuse a bad one before the long work
    if model is not None:
        read_model_file(model)
    rec = load_recording(recording)
    cal = calibrate_joints(rec)
    ahead = None
    if model is not None:
        # the re-identification needs only this recording and the model: started in a worker
        # now, it runs beside the validation recording's joints and the search (same result)
        from ..api import joint_models, signals
        from ..discover.engine import reidentification_ahead

        sig = signals(rec, cal)
        ahead = reidentification_ahead(sig, joint_models(model, list(sig)),
                                       {j.name for j in val_rec.joints} if val_rec is not None else None)
    try:
        write_joints(cal, out / "joints")
        val_cal = None
        if val_rec is not None:
            val_cal = calibrate_joints(val_rec)
            write_joints(val_cal, out / "validation_joints")
        d = discover(rec, model=model, validation=val_rec, calibration=cal, validation_calibration=val_cal,
                     **({"ahead": ahead} if ahead is not None else {}))
    finally:
        if ahead is not None:
            ahead.close()
    d = replace(d, recording=str(recording), model_source=str(model) if model is not None else "identified")
    return write_discovery(d, out)


def write_discovery(d, out: str | Path) -> dict:
    """Write a :class:`mocapfj.discover.Discovery` into OUT: discovery.json (its ``to_dict()``),
    the augmented model model.toml, the before/after residuals residuals.csv and, when the nominal
    model was identified on the spot (no model file), that model as nominal.toml (what the effects
    were searched against); returns the summary."""
    from ..discover import write_model_file
    from ..io import write_csv_columns

    out = Path(out)
    summary = d.to_dict()
    write_json(out / "discovery.json", summary)
    write_model_file(out / "model.toml", d.models.values(),
                     [{k: e[k] for k in ("name", "joint", "parameters", "p_value")} for e in d.effects])
    if d.model_source == "identified":
        write_model_file(out / "nominal.toml", d.nominal.values())
    cols = {}
    for name, r in d.residuals.items():
        cols.setdefault("t", r["t"])
        for key in ("r_delta_before", "r_delta_after", "r_u_before", "r_u_after"):
            cols[f"{name}_{key}"] = r[key]
    if cols:
        write_csv_columns(out / "residuals.csv", cols)
    return summary
