"""The Python API: one typed path from a recording to results, in memory.

::

    import mocapfj
    rec = mocapfj.load("bundle")                 # a Recording (markers, controller log, joints)
    cal = mocapfj.joints(rec)                     # JointsResult: axis, centre, angles, deflection
    ident = mocapfj.identify(rec)                 # Identification: parameters, spring, JointModel
    found = mocapfj.discover(rec, model=ident)    # Discovery: what the model misses

Each stage returns a frozen result whose ``to_dict()`` is what the CLI prints with ``--json``;
:mod:`mocapfj.pipeline` writes the same results to files. Arrays work too:
:func:`identify_joint` takes (t, q, q_m, u) and :func:`mocapfj.discover.discover` takes
:class:`~mocapfj.types.JointSignals`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from .errors import InputError
from .types import JointSignals, Recording

__all__ = ["load", "joints", "signals", "identify", "identify_joint", "discover"]

RecordingLike = Recording | str | os.PathLike


def load(path: str | os.PathLike) -> Recording:
    """A recording bundle (its directory or recording.toml), checked (:func:`mocapfj.io.load_recording`)."""
    from .io import load_recording

    if not isinstance(path, (str, os.PathLike)):
        raise InputError(None, "path", "the path of a bundle or its recording.toml", type(path).__name__)
    return load_recording(path)


def _recording(rec: RecordingLike) -> Recording:
    if isinstance(rec, Recording):
        return rec
    if not isinstance(rec, (str, os.PathLike)):
        raise InputError(None, "recording", "a Recording, or the path of a bundle or its recording.toml",
                         type(rec).__name__)
    return load(rec)


def joints(rec: RecordingLike, method: str = "auto"):
    """Every joint's axis, centre and per-frame link angle and, with a controller log, its
    deflection: a :class:`mocapfj.joints.JointsResult` (:func:`mocapfj.joints.calibrate_joints`)."""
    from .joints.stage import calibrate_joints

    return calibrate_joints(_recording(rec), method)


def signals(rec: RecordingLike, calibration=None) -> dict[str, JointSignals]:
    """Each joint's link angle and controller signals on one clock (the mocap samples), cut to the
    span all joints share: {joint: JointSignals}. `calibration`: a JointsResult of `rec` (computed
    when not given)."""
    from .ident.conditioning import joint_signals
    from .joints.smoothing import smoothing_corner_hz

    rec = _recording(rec)
    cal = joints(rec) if calibration is None else calibration
    out = {}
    for j in cal.joints:
        if j.deflection is None:
            raise InputError(rec.root, f"joints[{j.name}]", "a controller log with the joint's motor columns",
                             "markers only", hint="identification needs the motor angle and torque")
        out[j.name] = replace(joint_signals(j.deflection, rec.controller, j.name, source=rec.root),
                              smoothing_hz=smoothing_corner_hz(j.angles))
    n = min(s.n_samples for s in out.values())
    return {k: s.head(n) for k, s in out.items()}


def identify_joint(t, q, q_m, u, *, fs_hz: float, **kw):
    """One joint from plain arrays (t, q, q_m, u on one clock, SI, link side): an
    :class:`mocapfj.ident.IdentifiedJoint` (:func:`mocapfj.ident.identify_joint`)."""
    from .ident.joint import identify_joint as _identify_joint

    return _identify_joint(t, q, q_m, u, fs_hz=fs_hz, **kw)


def _urdf_chain(rec: Recording) -> bool:
    """True when the recording has a URDF whose joints are exactly its joints, in order, and more
    than one: then the links are identified together (:mod:`mocapfj.ident.nlink`)."""
    if rec.urdf is None or len(rec.joints) < 2:
        return False
    from .ident.regressor import load_pin_model

    return tuple(load_pin_model(rec.urdf).names[1:]) == tuple(j.name for j in rec.joints)


def _identify_recording(rec: Recording, method: str, cutoff_hz, decimate: int, calibration=None,
                        fit_clock_offset: bool = False) -> tuple[list, dict | None]:
    """(IdentifiedJoint per joint, the n-link base-parameter summary or None)."""
    from .ident.joint import identify_signals
    from .ident.nlink import identify_nlink_joints

    sig = signals(rec, calibration)
    gear = {j.name: j.gear_ratio for j in rec.joints}
    if method in ("output_error", "motor_first") and _urdf_chain(rec):
        try:
            return identify_nlink_joints(rec.urdf, list(sig.values()), decimate=decimate, recording=rec.name,
                                         gear_ratios=[gear[n] for n in sig])
        except InputError as e:
            raise InputError(rec.root, f"n-link identification ({e.field})", e.expected, e.got, e.hint) from None
    out = []
    for name, s in sig.items():
        try:
            out.append(identify_signals(s, gear_ratio=gear[name], recording=rec.name, method=method,
                                        cutoff_hz=cutoff_hz, decimate=decimate, fit_clock_offset=fit_clock_offset))
        except InputError as e:
            raise InputError(rec.root, f"joints[{name}] ({e.field})", e.expected, e.got, e.hint) from None
    return out, None


def _same_data(a: Recording, b: Recording) -> bool:
    """The same marker trajectories and controller log (a repeat given twice, or a copy)."""
    def eq(x, y):
        return x is None and y is None or (x is not None and y is not None and x.shape == y.shape
                                           and np.array_equal(x, y, equal_nan=True))
    ma, mb = a.markers, b.markers
    ca, cb = a.controller, b.controller
    return (eq(None if ma is None else ma.xyz, None if mb is None else mb.xyz)
            and eq(None if ca is None else ca.tau, None if cb is None else cb.tau)
            and eq(None if ca is None else ca.q_m, None if cb is None else cb.q_m))


def _check_distinct(recs: list, names) -> None:
    """Repeats give the CV %: the same recording twice would report a spread of zero."""
    for i in range(len(recs)):
        for j in range(i):
            if _same_data(recs[i], recs[j]):
                raise InputError(None, "recordings", "distinct recordings (repeats of a trial give the mean and CV %)",
                                 f"{names[j]} and {names[i]} hold the same data")


def identify(recordings: RecordingLike | Sequence[RecordingLike], *, method: str = "output_error",
             cutoff_hz: float | None = None, decimate: int = 2, validation: RecordingLike | None = None,
             calibrations: Sequence | None = None, fit_clock_offset: bool = False):
    """Identify every joint of one or more recordings: an :class:`mocapfj.ident.Identification`.

    A recording with markers and a controller log: each joint's link angle from the joints stage,
    then :func:`identify_joint` (or, when its URDF holds exactly its joints, the n-link motor-first
    identification). Repeats of the same joints give the mean, SD and CV % (Lightcap and Banks
    2007, Table I). A recording without markers, with a URDF: rigid n-link identification from
    the controller log (:func:`mocapfj.ident.rigid.identify_rigid`), checked on `validation` when
    given. `calibrations`: the JointsResult of each recording, when already computed.
    `fit_clock_offset`: output error identifies an offset between the mocap and controller clocks
    with the dynamics and applies it (by default it is tested, reported, and the parameters it
    moves are flagged not determined).
    """
    from .ident.joint import IDENTIFY_METHODS
    from .ident.result import Identification, summarize_trials

    if recordings is None or not isinstance(recordings, (Recording, str, os.PathLike, list, tuple)):
        raise InputError(None, "recordings", "a recording or a list of them", type(recordings).__name__)
    recs = [recordings] if isinstance(recordings, (Recording, str, os.PathLike)) else list(recordings)
    if not recs:
        raise InputError(None, "recordings", "at least one recording", "none")
    recs = [_recording(r) for r in recs]
    if method not in IDENTIFY_METHODS:
        raise InputError(None, "method", f"one of {list(IDENTIFY_METHODS)}", repr(method))
    names = tuple(str(r.root) if r.root is not None else r.name for r in recs)
    cams = [r for r in recs if r.markers_from_cameras]
    if cams:
        raise InputError(cams[0].root, "markers", "3D markers", "a bundle whose markers are still 2D detections "
                         "of its cameras", hint="'mocapfj run' triangulates them first (or 'mocapfj triangulate')")
    if all(r.markers is None for r in recs):
        from .ident.rigid import identify_rigid

        val = _recording(validation) if validation is not None else None
        rigid = tuple(identify_rigid(r, validation=val if i == 0 else None) for i, r in enumerate(recs))
        return Identification(recordings=names, joints=(), rigid=rigid)
    if any(r.markers is None for r in recs):
        raise InputError(None, "recordings", "recordings of one kind: all with markers or all without", "a mix")
    if validation is not None:
        raise InputError(None, "validation", "a validation recording only for a rigid robot (no markers)",
                         "a recording with markers", hint="use 'discover --validation' for a flexible joint")
    _check_distinct(recs, names)
    trials, nlink = [], []
    for i, rec in enumerate(recs):
        cal = calibrations[i] if calibrations is not None else None
        joint_results, nl = _identify_recording(rec, method, cutoff_hz, decimate, cal, fit_clock_offset)
        trials += joint_results
        if nl is not None:
            nlink.append(nl)
    return Identification(recordings=names, joints=tuple(summarize_trials(trials)), nlink=tuple(nlink))


def joint_models(model, names: Sequence[str]) -> dict:
    """Joint models by name from a model file path, an Identification, or a {name: JointModel}."""
    from .discover import read_model_file
    from .ident.result import Identification

    if isinstance(model, Identification):
        models = {j.name: j.trials[0].model for j in model.joints if j.trials[0].model is not None}
        source = "the identification"
    elif isinstance(model, dict):
        models, source = dict(model), "<argument>"
    else:
        models, source = read_model_file(model), model
    missing = [n for n in names if n not in models]
    if missing:
        raise InputError(source, "joints", f"a model of every joint of the recording {list(names)}",
                         f"none for {missing}")
    return {n: models[n] for n in names}


def discover(rec: RecordingLike, *, model=None, validation: RecordingLike | None = None, calibration=None,
             validation_calibration=None, **kw):
    """What `model` misses in the recording: a :class:`mocapfj.discover.Discovery`.

    `model`: a model file (or scenario file) path, an :class:`mocapfj.ident.Identification` of
    this robot, or {joint: JointModel}; None: each joint identified on the spot (motor-first,
    linear spring). `validation`: a second recording on which the fit gain is proved. Other
    keywords go to :func:`mocapfj.discover.discover`.
    """
    from .discover import discover as _discover

    rec = _recording(rec)
    val_rec = _recording(validation) if validation is not None else None
    sig = signals(rec, calibration)
    if model is None:
        from .ident.joint import identify_signals

        gear = {j.name: j.gear_ratio for j in rec.joints}
        ids = {n: identify_signals(s, gear_ratio=gear[n], spring_models=("linear",)) for n, s in sig.items()}
        models = {n: r.model for n, r in ids.items()}
        # what the trial determined in them (discovery reads the viscous split's): NaN, not determined
        kw.setdefault("nominal_sds", {n: {p: float(x.std) if x.determined else float("nan") for p, x in r.params.items()}
                                      for n, r in ids.items()})
    else:
        models = joint_models(model, list(sig))
    val = signals(val_rec, validation_calibration) if val_rec is not None else None
    fs = next(iter(sig.values())).fs_hz
    if model is None:
        kw.setdefault("nominal_from_trial", True)
    return _discover(sig, models, fs_hz=fs, validation=val, **kw)



