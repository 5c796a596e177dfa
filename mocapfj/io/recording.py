"""Recording bundles: a directory with ``recording.toml``, a marker file, a controller CSV and
optional URDF, rig and 2D detections (docs/formats.md).

The keys of recording.toml are a contract with users' scripts: this module adds keys, it never
renames them. Keys it does not interpret are kept in `Recording.spec` and written back.
"""

from __future__ import annotations

import contextlib
import contextvars

import copy
import os
import re
import shutil
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import WORLD, ControllerLog, JointSpec, MarkerTrajectories, Recording
from .atomic import atomic_path
from .c3d import read_c3d, write_c3d
from .calib import read_rig, write_rig
from .csvio import check_increasing, read_csv_columns, write_csv_columns
from .results import read_detections, write_detections
from .tomlio import check_format, describe, read_toml, require, write_toml
from .trc import read_trc, write_trc

__all__ = [
    "files_outside_bundle",
    "FORMAT",
    "DEFAULT_DURATION_TOLERANCE_S",
    "load_recording",
    "with_markers",
    "write_recording",
    "read_markers",
    "write_markers",
    "read_controller",
]

FORMAT = "mocapfj.recording/1"
FORMAT_VERSION = 1
DEFAULT_DURATION_TOLERANCE_S = 0.1
"""How far the start and the end of the two streams may differ (after the declared clock
offset) before the bundle is refused; ``[sync] duration_tolerance_s`` overrides it."""

_JOINT_KEYS = ("name", "motor_position", "motor_torque", "gear_ratio", "link_markers", "parent_markers")


def read_markers(path: str | os.PathLike[str]) -> MarkerTrajectories:
    """Read a C3D or TRC marker file, chosen by its suffix."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        return read_c3d(path)
    if suffix == ".trc":
        return read_trc(path)
    raise InputError(path, "markers.file", "a .c3d or .trc file", repr(path.name))


def write_markers(path: str | os.PathLike[str], markers: MarkerTrajectories) -> None:
    """Write a C3D or TRC marker file, chosen by its suffix, atomically."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        write_c3d(path, markers)
    elif suffix == ".trc":
        write_trc(path, markers)
    else:
        raise InputError(path, "markers.file", "a .c3d or .trc file", repr(path.name))


MAX_STEP_RATIO = 10.0
"""A controller time step this many times its median is a gap (rows lost), not jitter."""
MAX_CONTROLLER_VALUE = 1e9
"""Largest magnitude accepted in a controller column the joints use (rad, N m, s): beyond, the log
is corrupt (1e300 overflowed the statistics downstream) or its unit is wrong."""


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_controller(path, time_column: str, joints: tuple[JointSpec, ...]) -> ControllerLog:
    """Read a controller CSV into a ControllerLog, checking every column the joints name."""
    cols = read_csv_columns(path)
    wanted = [("controller.time_column", time_column)]
    for j in joints:
        wanted += [(f"joints[{j.name}].motor_position", j.motor_position),
                   (f"joints[{j.name}].motor_torque", j.motor_torque)]
    names = list(cols)
    if names and all(_is_number(c) for c in names):
        raise InputError(path, "header", "a first row of column names", "a row of numbers",
                         hint="add the header row the recording.toml names")
    for field, col in wanted:
        if col not in cols:
            shown = ", ".join(repr(c[:40]) for c in names[:12]) + (f", ... ({len(names)} columns)" if len(names) > 12 else "")
            raise InputError(path, f"column {col[:40]!r} (named by {field})", f"one of the CSV columns [{shown}]",
                             "no such column")
    t = cols[time_column]
    check_increasing(path, f"column {time_column!r}", t)
    if t.size > 2:
        steps = np.diff(t)
        med = float(np.median(steps))
        if steps.max() > MAX_STEP_RATIO * med:
            i = int(np.argmax(steps))
            raise InputError(path, f"column {time_column!r}", f"a log without gaps (steps below {MAX_STEP_RATIO:g} x its "
                             f"median {1e3 * med:.3g} ms)", f"rows missing between t = {t[i]:.4f} and {t[i + 1]:.4f} s "
                             f"(rows {i + 2}-{i + 3})", hint="cut the trial where the log is complete")
    for _, col in wanted:
        x = cols[col]
        with np.errstate(invalid="ignore"):
            wild = np.abs(x) > MAX_CONTROLLER_VALUE
        if wild.any():
            i = int(np.argmax(wild))
            raise InputError(path, f"column {col!r}", f"values below {MAX_CONTROLLER_VALUE:g} in magnitude (SI: rad, "
                             "N m, s)", f"{x[i]:.3g} at row {i + 2} ({int(wild.sum())} such values)",
                             hint="a corrupt log or a wrong unit")
    used = {time_column} | {j.motor_position for j in joints} | {j.motor_torque for j in joints}
    n = t.shape[0]
    q_m = np.column_stack([cols[j.motor_position] for j in joints]) if joints else np.empty((n, 0))
    tau = np.column_stack([cols[j.motor_torque] for j in joints]) if joints else np.empty((n, 0))
    extra = {k: v for k, v in cols.items() if k not in used}
    t, note = _uniform_tick(t, q_m)
    return ControllerLog(t=t, q_m=q_m, tau=tau, joint_names=tuple(j.name for j in joints), extra=extra,
                         time_note=note)


def _uniform_tick(t: np.ndarray, q_m: np.ndarray) -> tuple[np.ndarray, str | None]:
    """A controller samples on its tick; its logged stamps may scatter around it (the logging
    thread's clock). When the stamps deviate from their straight-line fit by less than half a step
    and the motor angle is smoother on that uniform tick than on the stamps (its third differences
    smaller: the values were sampled uniformly, the stamps are noisy), the tick replaces them
    (and the note says so); otherwise the stamps stand (the values were taken when stamped)."""
    if t.size < 8 or q_m.size == 0:
        return t, None
    k = np.arange(t.size, dtype=np.float64)
    slope, icpt = np.polyfit(k, t, 1)
    tick = icpt + slope * k
    dev = np.abs(t - tick)
    if not (0 < slope and dev.max() > 1e-3 * slope and dev.max() < 0.5 * slope):
        return t, None
    on_stamps = np.column_stack([np.interp(tick, t, q_m[:, j]) for j in range(q_m.shape[1])])
    rough_tick = float(np.sum(np.diff(q_m, 3, axis=0) ** 2))
    rough_stamps = float(np.sum(np.diff(on_stamps, 3, axis=0) ** 2))
    if rough_tick < 0.5 * rough_stamps:
        return tick, (f"time stamps scattered by up to {1e3 * dev.max():.3g} ms around a uniform {1e3 * slope:.4g} ms "
                      "tick, on which the motor angle is smoother: the tick is used")
    return t, None


def _str_list(path, table, key, where) -> tuple[str, ...]:
    value = require(path, table, key, list, where)
    if not value or not all(isinstance(s, str) and s for s in value):
        raise InputError(path, f"{where}.{key}", "a non-empty list of marker labels", repr(value))
    return tuple(value)


_JOINT_NAME = re.compile(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]{0,63}")


def _parse_joint(path, tab, i, has_markers: bool, has_controller: bool) -> JointSpec:
    where = f"joints[{i}]"
    if not isinstance(tab, dict):
        raise InputError(path, where, "a [[joints]] table", describe(tab))
    name = require(path, tab, "name", str, where)
    if not _JOINT_NAME.fullmatch(name):
        raise InputError(path, f"{where}.name", "a joint name of 1-64 letters, digits, '_', '-' or '.', not starting "
                         "with '.' (it names output files)", describe(name))
    where = f"joints[{name}]"
    gear = (require(path, tab, "gear_ratio", (int, float), where) if has_controller
            else require(path, tab, "gear_ratio", (int, float), where, default=1.0))
    if not (np.isfinite(gear) and gear > 0):
        raise InputError(path, f"{where}.gear_ratio", "a positive, finite gear ratio", gear)
    parent = tab.get("parent_markers", WORLD)
    if isinstance(parent, str):
        if parent != WORLD:
            raise InputError(path, f"{where}.parent_markers", f'a list of marker labels or "{WORLD}"', repr(parent))
    else:
        parent = _str_list(path, tab, "parent_markers", where)
    if has_controller:
        motor_position = require(path, tab, "motor_position", str, where)
        motor_torque = require(path, tab, "motor_torque", str, where)
    else:
        motor_position = motor_torque = ""
    link = _str_list(path, tab, "link_markers", where) if has_markers else ()
    return JointSpec(name=name, motor_position=motor_position, motor_torque=motor_torque, gear_ratio=float(gear),
                     link_markers=link, parent_markers=parent,
                     extra={k: v for k, v in tab.items() if k not in _JOINT_KEYS})


_OUTSIDE = contextvars.ContextVar("mocapfj_files_outside_bundle", default=False)


@contextlib.contextmanager
def files_outside_bundle(allowed: bool = True):
    """Within this block, :func:`load_recording` reads files that recording.toml names outside its
    bundle (``../``, absolute paths, symlinks leading out); the CLI's ``--allow-outside-bundle``."""
    token = _OUTSIDE.set(bool(allowed))
    try:
        yield
    finally:
        _OUTSIDE.reset(token)


def _bundle_file(root: Path, toml_path: Path, field: str, name: str) -> Path:
    """The file `name` of recording.toml's `field`, inside the bundle: resolved (symlinks
    followed) it must lie under the bundle's own resolved directory, unless allowed
    (:func:`files_outside_bundle`). The message names the path given, never the file's text."""
    p = root / name
    try:
        real = p.resolve()
    except (RuntimeError, OSError) as e:                 # a symlink loop
        raise InputError(toml_path, field, f"a file inside the bundle {root}", f"{describe(name)}: {type(e).__name__}",
                         hint="a symlink that leads to itself") from None
    if not _OUTSIDE.get() and not real.is_relative_to(root.resolve()):
        raise InputError(toml_path, field, f"a file inside the bundle {root}", f"{name!r}, which resolves outside it",
                         hint="pass --allow-outside-bundle to read files elsewhere")
    if not p.is_file():
        raise InputError(toml_path, field, f"an existing file inside {root}", f"{name!r} (no such file)")
    return p


def load_recording(path: str | os.PathLike[str]) -> Recording:
    """Load a recording bundle from its directory (or its recording.toml).

    A bundle may hold markers and a controller log (a flexible-joint robot), markers only (no
    ``[controller]``: a passive hinge or a human joint) or a controller log only (no ``[markers]``,
    with a URDF: a rigid robot). Checks, each an InputError naming file and field: the format
    version; the marker and controller files exist; every column and marker label the joints name exists; no named
    marker is missing in every frame; controller time increases strictly; the two streams cover
    the same span (within ``[sync] duration_tolerance_s``, default 0.1 s) after the declared
    clock offset.
    """
    path = Path(path)
    toml_path = path / "recording.toml" if path.is_dir() else path
    if not toml_path.is_file():
        raise InputError(toml_path, "file", "a recording bundle directory holding recording.toml", "no such file")
    root = toml_path.parent
    doc = read_toml(toml_path)
    check_format(toml_path, doc, "recording", FORMAT_VERSION)
    name = require(toml_path, doc, "name", str, default=root.name)

    rig_doc = doc.get("rig")
    from_cameras = "markers" not in doc and isinstance(rig_doc, dict) and "clusters" in rig_doc
    if "markers" not in doc and "controller" not in doc and not from_cameras:
        raise InputError(toml_path, "markers, controller", "a [markers] table, a [controller] table or both", "neither")
    has_markers, has_controller = "markers" in doc, "controller" in doc
    marker_file, offset = "", 0.0
    if from_cameras:                    # the markers come from the cameras: the run triangulates them
        for key, kind in (("file", str), ("detections", str), ("clusters", str), ("rate_hz", (int, float))):
            require(toml_path, rig_doc, key, kind, "rig")
        rate = float(rig_doc["rate_hz"])
        if not (np.isfinite(rate) and rate > 0):
            raise InputError(toml_path, "rig.rate_hz", "the cameras' frame rate, Hz (positive)", describe(rate))
        offset = float(require(toml_path, rig_doc, "clock_offset_s", (int, float), "rig", default=0.0))
        if not (np.isfinite(offset) and abs(offset) <= 86400.0):
            raise InputError(toml_path, "rig.clock_offset_s", "a finite offset in seconds, at most a day",
                             describe(offset))
        _bundle_file(root, toml_path, "rig.clusters", rig_doc["clusters"])
    if has_markers:
        mk = require(toml_path, doc, "markers", dict)
        marker_file = require(toml_path, mk, "file", str, "markers")
        offset = float(require(toml_path, mk, "clock_offset_s", (int, float), "markers", default=0.0))
        if not (np.isfinite(offset) and abs(offset) <= 86400.0):
            raise InputError(toml_path, "markers.clock_offset_s", "a finite offset in seconds, at most a day",
                             describe(offset))
    controller_file, time_column = "", "time"
    if has_controller:
        ct = require(toml_path, doc, "controller", dict)
        controller_file = require(toml_path, ct, "file", str, "controller")
        time_column = require(toml_path, ct, "time_column", str, "controller", default="time")
    joints_raw = require(toml_path, doc, "joints", list)
    if not joints_raw:
        raise InputError(toml_path, "joints", "at least one [[joints]] table", "none")
    joints = tuple(_parse_joint(toml_path, tab, i, has_markers or from_cameras, has_controller)
                   for i, tab in enumerate(joints_raw))
    names = [j.name for j in joints]
    if len(set(names)) != len(names):
        raise InputError(toml_path, "joints.name", "unique joint names", names)

    markers = controller = None
    if has_markers:
        markers = read_markers(_bundle_file(root, toml_path, "markers.file", marker_file))
        _check_markers(root / marker_file, markers, joints)
    if has_controller:
        controller = read_controller(_bundle_file(root, toml_path, "controller.file", controller_file), time_column,
                                     joints)
    if has_markers and has_controller:
        sync = require(toml_path, doc, "sync", dict, default={})
        tol = float(require(toml_path, sync, "duration_tolerance_s", (int, float), "sync",
                            default=DEFAULT_DURATION_TOLERANCE_S))
        if not (np.isfinite(tol) and tol >= 0):
            raise InputError(toml_path, "sync.duration_tolerance_s", "a non-negative, finite tolerance in seconds", tol)
        _check_spans(toml_path, markers, controller, offset, tol)
        if markers.n_frames > 1 and controller.n_samples > 1:
            fs_c = 1.0 / float(np.median(np.diff(controller.t)))
            if fs_c < 0.5 * markers.rate_hz:
                raise InputError(root / controller_file, f"column {time_column!r}",
                                 f"a controller log at half the mocap rate at least ({0.5 * markers.rate_hz:g} Hz: the "
                                 "motor angle is interpolated at every mocap frame)", f"{fs_c:.3g} Hz")

    urdf = rig = detections = None
    model = require(toml_path, doc, "model", dict, default={})
    if "urdf" in model:
        urdf = _bundle_file(root, toml_path, "model.urdf", require(toml_path, model, "urdf", str, "model"))
    rig_tab = require(toml_path, doc, "rig", dict, default={})
    if "file" in rig_tab:
        rig = read_rig(_bundle_file(root, toml_path, "rig.file", require(toml_path, rig_tab, "file", str, "rig")))
    if "detections" in rig_tab:
        det_path = _bundle_file(root, toml_path, "rig.detections", require(toml_path, rig_tab, "detections", str, "rig"))
        detections = read_detections(det_path)
        if rig is not None and detections.camera.size:
            bad = (detections.camera < 0) | (detections.camera >= len(rig.cameras))
            if bad.any():
                i = int(np.argmax(bad))
                raise InputError(det_path, f"column 'camera' (row {i + 2})",
                                 f"a camera index of the rig, 0-{len(rig.cameras) - 1}", int(detections.camera[i]))

    return Recording(
        name=name, markers=markers, controller=controller, joints=joints, clock_offset_s=offset,
        marker_file=marker_file, controller_file=controller_file, time_column=time_column,
        urdf=urdf, rig=rig, detections=detections, root=root, spec=doc,
    )


def with_markers(rec: Recording, markers: MarkerTrajectories, marker_file: str | os.PathLike[str]) -> Recording:
    """A bundle whose markers come from its cameras (``[rig] clusters``, no ``[markers]``) with
    the markers triangulated from them: the checks :func:`load_recording` makes on a marker file
    (the joints' labels, the spans of the two streams, the controller's rate) made on these."""
    from dataclasses import replace

    path = Path(marker_file)
    _check_markers(path, markers, rec.joints)
    ctl = rec.controller
    if ctl is not None:
        sync = rec.spec.get("sync", {}) if isinstance(rec.spec.get("sync", {}), dict) else {}
        tol = float(sync.get("duration_tolerance_s", DEFAULT_DURATION_TOLERANCE_S))
        _check_spans(path, markers, ctl, rec.clock_offset_s, tol)
        if markers.n_frames > 1 and ctl.n_samples > 1:
            fs_c = 1.0 / float(np.median(np.diff(ctl.t)))
            if fs_c < 0.5 * markers.rate_hz:
                raise InputError(rec.controller_file, f"column {rec.time_column!r}",
                                 f"a controller log at half the camera rate at least ({0.5 * markers.rate_hz:g} Hz)",
                                 f"{fs_c:.3g} Hz")
    return replace(rec, markers=markers, marker_file=str(path))


def _check_markers(path, markers: MarkerTrajectories, joints) -> None:
    for j in joints:
        labels = list(j.link_markers) + ([] if j.parent_is_world else list(j.parent_markers))
        for s in labels:
            if s not in markers.labels:
                raise InputError(path, f"marker {s!r} (named by joints[{j.name}])",
                                 f"a label in the marker file ({len(markers.labels)} labels: {', '.join(markers.labels[:12])}"
                                 f"{', ...' if len(markers.labels) > 12 else ''})", "no such label")
            if np.all(np.isnan(markers.xyz[:, markers.index(s), 0])):
                raise InputError(path, f"marker {s!r} (named by joints[{j.name}])", "a marker seen in at least one frame",
                                 f"missing (NaN) in all {markers.n_frames} frames")
        _check_cluster_size(path, markers, j.name, list(j.link_markers))


CLUSTER_SPAN_M = (5e-3, 10.0)
"""Plausible span of a joint's link-marker cluster, m: markers are centimetres apart at least and a
robot link is metres long at most. Outside, the file's units are wrong (millimetre coordinates
labelled as metres give clusters hundreds of metres across)."""


def _check_cluster_size(path, markers: MarkerTrajectories, joint: str, labels: list) -> None:
    """The median over frames of the largest distance between the joint's link markers, against
    CLUSTER_SPAN_M."""
    if len(labels) < 2:
        return
    xyz = markers.xyz[:, [markers.index(s) for s in labels]]               # (T, M, 3)
    d = np.linalg.norm(xyz[:, :, None] - xyz[:, None], axis=-1)           # (T, M, M), NaN where lost
    per_frame = np.nan_to_num(d, nan=0.0).reshape(d.shape[0], -1).max(axis=1)
    seen = per_frame[per_frame > 0]                                       # frames with two markers
    if not seen.size:
        return
    span = float(np.median(seen))
    lo, hi = CLUSTER_SPAN_M
    if lo <= span <= hi:
        return
    field = "POINT:UNITS" if str(path).lower().endswith(".c3d") else "Units"
    cause = ("millimetre coordinates labelled as metres?" if span > hi else "metre coordinates labelled as millimetres?")
    raise InputError(path, field, f"units that make joint {joint}'s link-marker cluster {lo * 1e3:g} mm to {hi:g} m across",
                     f"{span:.4g} m across ({', '.join(labels)})", hint=cause)


def _check_spans(path, markers, controller, offset, tol) -> None:
    if markers.n_frames == 0 or controller.n_samples == 0:
        raise InputError(path, "markers/controller", "samples in both streams",
                         f"{markers.n_frames} marker frames and {controller.n_samples} controller rows")
    m0, m1 = markers.t[0] + offset, markers.t[-1] + offset
    c0, c1 = controller.t[0], controller.t[-1]
    if abs(m0 - c0) > tol or abs(m1 - c1) > tol:
        raise InputError(
            path, "streams", f"marker and controller streams covering the same time span within {tol} s",
            f"markers {m0:.4f}..{m1:.4f} s ({m1 - m0:.4f} s) vs controller {c0:.4f}..{c1:.4f} s ({c1 - c0:.4f} s) "
            f"on the controller clock",
            hint="trim the longer stream, declare markers.clock_offset_s, or raise sync.duration_tolerance_s",
        )


def recording_spec(rec: Recording) -> dict:
    """recording.toml contents for `rec`: its spec with the known keys set from its fields."""
    doc = copy.deepcopy(dict(rec.spec))
    doc["format"] = FORMAT
    doc["name"] = rec.name
    doc.setdefault("markers", {})
    doc["markers"]["file"] = rec.marker_file
    doc["markers"]["clock_offset_s"] = float(rec.clock_offset_s)
    doc.setdefault("controller", {})
    doc["controller"]["file"] = rec.controller_file
    doc["controller"]["time_column"] = rec.time_column
    if rec.markers is None:
        del doc["markers"]
    if rec.markers_from_cameras:
        doc["rig"]["clock_offset_s"] = float(rec.clock_offset_s)
    if rec.controller is None:
        del doc["controller"]
    joints = []
    for j in rec.joints:
        tab = dict(j.extra)
        tab.update(name=j.name, gear_ratio=j.gear_ratio,
                   parent_markers=WORLD if j.parent_is_world else list(j.parent_markers))
        if rec.controller is not None:
            tab.update(motor_position=j.motor_position, motor_torque=j.motor_torque)
        if rec.markers is not None or rec.markers_from_cameras:
            tab["link_markers"] = list(j.link_markers)
        joints.append(tab)
    doc["joints"] = joints
    if rec.urdf is not None:
        doc.setdefault("model", {})["urdf"] = doc.get("model", {}).get("urdf", "robot.urdf")
    if rec.rig is not None:
        doc.setdefault("rig", {}).setdefault("file", "rig.toml")
    if rec.detections is not None:
        doc.setdefault("rig", {}).setdefault("detections", "detections.csv")
    return doc


def write_recording(rec: Recording, out_dir: str | os.PathLike[str]) -> Path:
    """Write `rec` as a bundle in `out_dir` (created); returns the recording.toml path.

    Every file is written atomically, recording.toml last, so an interrupted write never leaves
    a bundle that loads with half its data.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = recording_spec(rec)
    if rec.markers is not None:
        write_markers(out / rec.marker_file, rec.markers)
    if rec.controller is not None:
        cols = {rec.time_column: rec.controller.t}
        for i, j in enumerate(rec.joints):
            cols[j.motor_position] = rec.controller.q_m[:, i]
            cols[j.motor_torque] = rec.controller.tau[:, i]
        for k, v in rec.controller.extra.items():
            cols.setdefault(k, v)
        write_csv_columns(out / rec.controller_file, cols)
    if rec.urdf is not None:
        target = out / doc["model"]["urdf"]
        if Path(rec.urdf).resolve() != target.resolve():
            with atomic_path(target) as tmp:
                shutil.copyfile(rec.urdf, tmp)
    if rec.rig is not None:
        write_rig(out / doc["rig"]["file"], rec.rig)
    if rec.detections is not None:
        write_detections(out / doc["rig"]["detections"], rec.detections)
    write_toml(out / "recording.toml", doc)
    return out / "recording.toml"
