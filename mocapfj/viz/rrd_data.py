"""What a run directory holds, read once for the rerun recording (:mod:`mocapfj.viz.rrd`).

A run directory (docs/formats.md, "Run directory") has one subdirectory per stage; a single
command's ``--out`` (``joints``, ``identify``, ``discover``, ``frf``) is read the same way. What
is absent is left out: :class:`RunContents` holds None there and says why in ``notes``.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import load_recording, read_csv_columns, read_json, read_markers, read_rig
from ..io.geometry import read_joint_geometry
from ..types import JointGeometry, MarkerTrajectories, Recording, Rig

__all__ = ["JointRun", "RunContents", "load_run", "RESULT_FILES"]

RESULT_FILES = ("run.json", "joints/joints.json", "identify/identify.json", "discover/discovery.json",
                "frf/frf.json", "triangulate/triangulate.json", "calibrate_rig/rig.toml")
"""The files (relative to a run directory) whose presence makes it a run; a single command's
--out holds one of their names directly."""


@dataclass(frozen=True, eq=False)
class JointRun:
    """One joint of the joints stage.

    name : the joint's name.
    geometry : its :class:`JointGeometry` (axis, point and link template in the parent frame).
    parent_labels : the parent cluster's marker labels, or () when the parent is the world.
    parent_template : (P, 3) m, the parent markers in the parent frame (None for the world).
    q_offset_rad : added to the fit's angle to align its zero with the motor's (0 without a log).
    angles : the columns of ``<joint>.angles.csv`` ({name: (T,) array}: t_mocap, t_controller, q,
        q_m, delta, tau, ...), rad, N m, s.
    summary : the joint's entry of joints.json ({} when absent): axis_world, point_world_m when
        the parent is static.
    """

    name: str
    geometry: JointGeometry
    parent_labels: tuple[str, ...]
    parent_template: np.ndarray | None
    q_offset_rad: float
    angles: dict
    summary: dict = field(default_factory=dict)

    @property
    def t(self) -> np.ndarray:
        """(T,) s, the angles' time on the controller clock (the mocap clock without a log)."""
        return self.angles["t_controller"] if "t_controller" in self.angles else self.angles["t_mocap"]


@dataclass(frozen=True, eq=False)
class RunContents:
    """Everything the recording shows, in memory (each None or empty when the run lacks it).

    root : the run directory.
    recording : the recording bundle the run was made from (markers, controller log, rig, URDF).
    markers : the 3D markers (the triangulate stage's when it ran, else the bundle's).
    clock_offset_s : t_controller = t_mocap + offset for `markers`.
    rig : the cameras (calibrate_rig/rig.toml when that stage ran, else the bundle's rig).
    urdf : the robot's URDF (the bundle's ``[model] urdf``).
    joints : the joints stage's joints.
    identify : identify.json; discovery : discovery.json; residuals : residuals.csv columns.
    frf : frf.json; frf_lines : frf.csv columns.
    manifest : run.json.
    notes : what was left out and why, one line each.
    """

    root: Path
    recording: Recording | None = None
    markers: MarkerTrajectories | None = None
    clock_offset_s: float = 0.0
    rig: Rig | None = None
    urdf: Path | None = None
    joints: tuple[JointRun, ...] = ()
    identify: dict | None = None
    discovery: dict | None = None
    residuals: dict | None = None
    frf: dict | None = None
    frf_lines: dict | None = None
    manifest: dict | None = None
    notes: tuple[str, ...] = ()

    @property
    def has_results(self) -> bool:
        return bool(self.joints or self.identify or self.discovery or self.frf or self.markers is not None
                    or self.rig is not None)


def _stage_dir(root: Path, stage: str, marker: str) -> Path | None:
    """RUN_DIR/<stage> when it holds `marker`, else RUN_DIR itself when it does (one command's --out)."""
    if (root / stage / marker).is_file():
        return root / stage
    if (root / marker).is_file():
        return root
    return None


def _read_joints(d: Path) -> tuple[JointRun, ...]:
    summary = read_json(d / "joints.json")
    by_name = {j.get("name"): j for j in summary.get("joints", []) if isinstance(j, dict)}
    out = []
    for path in sorted(d.glob("*.joint.toml")):
        name, geometry, parent = read_joint_geometry(path)
        with open(path, "rb") as f:
            extra = tomllib.load(f).get("extra", {})
        labels = parent.get("labels", "world")
        world = isinstance(labels, str)
        template = None if world or "template_m" not in parent else np.asarray(parent["template_m"], dtype=np.float64)
        angles_path = d / by_name.get(name, {}).get("files", {}).get("angles", f"{name}.angles.csv")
        if not angles_path.is_file():
            raise InputError(d, f"joints[{name}]", f"its angles file {angles_path.name}", "no such file")
        angles = read_csv_columns(angles_path)
        for col in ("t_mocap", "q"):
            if col not in angles:
                raise InputError(angles_path, col, "a column of the angles file (docs/formats.md)", "absent")
        out.append(JointRun(name=name, geometry=geometry, parent_labels=() if world else tuple(labels),
                            parent_template=template, q_offset_rad=float(extra.get("q_offset_rad", 0.0)),
                            angles=angles, summary=by_name.get(name, {})))
    return tuple(out)


def _bundle_path(root: Path, manifest, identify, discovery) -> Path | None:
    """The recording bundle the run was made from: run.json's `recording`, else the one
    identify.json or discovery.json names."""
    for cand in ((manifest or {}).get("recording"), ((identify or {}).get("recordings") or [None])[0],
                 (discovery or {}).get("recording")):
        if isinstance(cand, str) and cand:
            p = Path(cand)
            return p if p.is_absolute() else (root / p)
    return None


def load_run(run_dir) -> RunContents:
    """Read a run directory (or one command's --out) into :class:`RunContents`.

    Raises InputError when `run_dir` is not a directory or holds none of the results
    (:data:`RESULT_FILES`), or when a result file there is malformed.
    """
    root = Path(run_dir)
    if not root.is_dir():
        raise InputError(root, "run directory", "a directory written by mocapfj run (or one command's --out)",
                         "no such directory" if not root.exists() else "a file")
    notes = []
    manifest = read_json(root / "run.json") if (root / "run.json").is_file() else None
    if manifest is not None and manifest.get("format", "").split("/")[0] != "mocapfj.run":
        raise InputError(root / "run.json", "format", '"mocapfj.run/1"', repr(manifest.get("format")))
    d = _stage_dir(root, "joints", "joints.json")
    if d is None and (root / "discover" / "joints" / "joints.json").is_file():
        d = root / "discover" / "joints"
    joints = _read_joints(d) if d is not None else ()
    d = _stage_dir(root, "identify", "identify.json")
    identify = read_json(d / "identify.json") if d is not None else None
    d = _stage_dir(root, "discover", "discovery.json")
    discovery = read_json(d / "discovery.json") if d is not None else None
    residuals = read_csv_columns(d / "residuals.csv") if d is not None and (d / "residuals.csv").is_file() else None
    if not joints and d is not None and (d / "joints" / "joints.json").is_file():
        joints = _read_joints(d / "joints")
    d = _stage_dir(root, "frf", "frf.json")
    frf = read_json(d / "frf.json") if d is not None else None
    frf_lines = read_csv_columns(d / "frf.csv") if d is not None and (d / "frf.csv").is_file() else None

    recording = None
    bundle = _bundle_path(root, manifest, identify, discovery)
    if bundle is not None:
        if (bundle / "recording.toml").is_file() or bundle.name == "recording.toml":
            recording = load_recording(bundle)
        else:
            notes.append(f"the recording bundle {bundle} is not there: no markers, cameras or controller log")
    markers, offset = (recording.markers, recording.clock_offset_s) if recording is not None else (None, 0.0)
    d = _stage_dir(root, "triangulate", "markers.c3d")
    if d is not None:
        markers, offset = read_markers(d / "markers.c3d"), (recording.clock_offset_s if recording else 0.0)
    rig = recording.rig if recording is not None else None
    d = _stage_dir(root, "calibrate_rig", "rig.toml")
    if d is not None:
        rig = read_rig(d / "rig.toml")
    urdf = recording.urdf if recording is not None else None
    if urdf is None:
        notes.append("no URDF in the bundle: the links are drawn as segments between the marker clusters")
    out = RunContents(root=root, recording=recording, markers=markers, clock_offset_s=float(offset), rig=rig,
                      urdf=urdf, joints=joints, identify=identify, discovery=discovery, residuals=residuals,
                      frf=frf, frf_lines=frf_lines, manifest=manifest, notes=tuple(notes))
    if not out.has_results:
        raise InputError(root, "results", "a run directory holding at least one of " + ", ".join(RESULT_FILES),
                         "none of them")
    return out
