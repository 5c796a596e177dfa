"""``mocapfj control-check``: a model file's joint validated by model-based control
(:mod:`mocapfj.ident.control_validation`, Bompos et al. (2007)). Reads the files, runs the API,
returns the summary; writes nothing. No maths here."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError

__all__ = ["run_control_check"]


def _joint(path, models: dict, joint: str | None):
    if joint is None:
        if len(models) != 1:
            raise InputError(path, "joints", "one joint, or --joint NAME", f"{len(models)} joints: {sorted(models)}")
        return next(iter(models.values()))
    if joint not in models:
        raise InputError(path, "joints.name", f"a joint named {joint!r}", f"{sorted(models)}")
    return models[joint]


def _floats(text: str, name: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in str(text).split(","))
    except ValueError:
        raise InputError(None, name, "comma-separated numbers", repr(text)) from None


def run_control_check(model: str | Path, plant: str | Path | None = None, joint: str | None = None,
                      q0: float = 0.3, amplitudes: str = "0.3,0.06", frequencies: str = "0.5,1.5",
                      ramp: float = 1.0, duration: float = 6.0, bandwidth: float = 5.0, zeta: float = 0.8,
                      rate: float = 400.0) -> dict:
    """Computed-torque tracking on the plant (the `plant` file's joint, default the model's own)
    with the model's flexible and rigid feedforward; the result's ``to_dict()`` plus the ratio
    rigid / flexible of the RMS and maximum link errors."""
    from ..discover.model import read_model_file
    from ..ident.control_validation import ComputedTorque, WindowedSines, control_check, lab_gains

    m = _joint(model, read_model_file(model), joint)
    p = m if plant is None else _joint(plant, read_model_file(plant), joint or m.name)
    traj = WindowedSines(q0, _floats(amplitudes, "amplitudes"), _floats(frequencies, "frequencies"), ramp)
    kp, kd = lab_gains(p, bandwidth, zeta)
    r = control_check(p, [ComputedTorque("flexible", m), ComputedTorque("rigid", m, flexible=False)], traj, duration,
                      kp=kp, kd=kd, rate_hz=rate)
    out = r.to_dict()
    out.update({"model": str(model), "plant": str(plant if plant is not None else model), "joint": m.name,
                "ratio_rms": r.ratio("rigid", "flexible"), "ratio_max": r.ratio("rigid", "flexible", "max")})
    return out
