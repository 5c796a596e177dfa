"""The joints stage: every joint of a recording calibrated, its link angle solved per frame and,
with a controller log, its deflection (``mocapfj joints``; :func:`mocapfj.joints` in the API).

Returns a :class:`JointsResult` in memory; ``to_dict()`` is the ``--json`` summary. Files are
written by :mod:`mocapfj.pipeline`, not here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .repair import repair_cluster
from ..types import Deflection, JointAngles, JointGeometry, Recording
from .calibrate import CALIBRATION_METHODS, ParentFrame, calibrate_joint, flip_axis, markers_in_parent_frame, solve_angles
from .sync import deflection

__all__ = ["JointResult", "JointsResult", "calibrate_joints", "NO_CONTROLLER_NOTE"]

NO_CONTROLLER_NOTE = ("no deflection: the recording has no controller log for this joint (markers only); "
                      "axis, centre and link angles are given")


def _mm(x) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x) * 1e3


@dataclass(frozen=True, eq=False)
class JointResult:
    """One joint calibrated from its markers.

    Attributes
    ----------
    name : str
    geometry : JointGeometry
        Axis, point, template in the parent frame (docs/conventions.md).
    angles : JointAngles
        Link angle per mocap frame (mocap clock), with the geometry's zero.
    deflection : Deflection or None
        On the controller clock (the link angle's zero aligned to the motor's); None without a
        controller log for this joint.
    parent : ParentFrame
        The frame of `geometry`: the world, a static parent (its pose in the world is known) or a
        moving parent cluster.
    parent_labels : tuple of str, or "world"
    method : str
        The calibration method asked for ("auto" picks per joint; `geometry.method` says which).
    repairs : {"link": ClusterRepair dict, "parent": ...} of the clusters whose markers were
        relabelled or had samples removed (:func:`.repair.repair_cluster`), or None.
    """

    name: str
    geometry: JointGeometry
    angles: JointAngles
    deflection: Deflection | None
    parent: ParentFrame
    parent_labels: tuple[str, ...] | str
    method: str
    repairs: dict | None = None

    @property
    def axis_world(self) -> np.ndarray | None:
        """The axis direction in the world frame (3,), when the parent is static or the world."""
        if self.parent.R_world_parent is None:
            return None
        return self.parent.R_world_parent @ self.geometry.axis

    @property
    def point_world(self) -> np.ndarray | None:
        """The axis point in the world frame (3,) m, when the parent is static or the world."""
        if self.parent.R_world_parent is None:
            return None
        return self.parent.R_world_parent @ self.geometry.point + self.parent.t_world_parent

    def to_dict(self) -> dict:
        """The ``joints`` entry of ``mocapfj joints --json`` (README, docs/formats.md)."""
        g, a, d = self.geometry, self.angles, self.deflection
        valid = np.isfinite(a.q)
        angle_rms = float(np.sqrt(np.nanmean(a.marker_rms**2))) if valid.any() else float("nan")
        out = {
            "name": self.name,
            "axis": g.axis,
            "point_m": g.point,
            "axis_world": self.axis_world,
            "point_world_m": self.point_world,
            "radii_mm": g.radii * 1e3,
            "radius_rms_mm": g.radius_rms * 1e3,
            "marker_rms_mm": _mm(angle_rms),
            "angle_marker_rms_mm": _mm(angle_rms),
            "fit_marker_rms_mm": _mm(g.marker_rms),
            "angle_sigma_rad": float(np.nanmedian(a.sigma_q)) if valid.any() else None,
            "n_frames": int(a.q.size),
            "n_frames_invalid": int((~valid).sum()),
            "method": g.method,
            "q_range_deg": float(np.degrees(np.nanmax(a.q) - np.nanmin(a.q))) if valid.any() else None,
            "q_offset_rad": None if d is None else d.q_offset_rad,
            "deflection_rms_rad": None if d is None else float(np.sqrt(np.nanmean((d.delta - np.nanmean(d.delta)) ** 2))),
            "q_m_quantum_rad": None if d is None else d.q_m_quantum_rad,
            "parent_static": self.parent.static,
        }
        if self.repairs:
            out["marker_repairs"] = self.repairs
        if d is None:
            out["note"] = NO_CONTROLLER_NOTE
        return out


@dataclass(frozen=True, eq=False)
class JointsResult:
    """Every joint of a recording calibrated (:func:`calibrate_joints`)."""

    recording: str
    method: str
    joints: tuple[JointResult, ...]

    def joint(self, name: str) -> JointResult:
        for j in self.joints:
            if j.name == name:
                return j
        raise InputError(None, "joint", f"one of {[j.name for j in self.joints]}", repr(name))

    def to_dict(self) -> dict:
        """``mocapfj joints --json``: recording, method and one entry per joint."""
        return {"recording": self.recording, "method": self.method, "joints": [j.to_dict() for j in self.joints]}


MOTOR_SCALE_RANGE = (0.8, 1.25)
"""Accepted slope of the motor angle (link side) against the mocap's link angle: the two differ by
the deflection only, a fraction of a percent of the motion in a geared joint."""


SCALE_CUTOFF_HZ = 1.0
"""The scale check compares the two angles below this frequency (zero-phase low-pass)."""


def _check_motor_scale(rec: Recording, spec, q: np.ndarray, q_m: np.ndarray) -> None:
    """The motor angle moves as the link does (q_m = q + deflection): its slope against the mocap
    angle is 1. Degrees for radians, the motor side for the link side (a missing gear ratio), or a
    wrong gear ratio show as a slope far from 1 and are refused, naming the likely cause."""
    ok = np.isfinite(q) & np.isfinite(q_m)
    if ok.sum() < 10:
        return
    qq, mm = q[ok] - q[ok].mean(), q_m[ok] - q_m[ok].mean()
    rate = rec.markers.rate_hz if rec.markers is not None else None
    if rate and qq.size > 3 * int(rate / SCALE_CUTOFF_HZ):
        # below SCALE_CUTOFF_HZ the link follows the motor (a joint's resonance lies well above):
        # a fast excitation (a multisine through the resonance) moves the link more than the motor
        from scipy.signal import butter, sosfiltfilt

        sos = butter(2, SCALE_CUTOFF_HZ / (0.5 * rate), output="sos")
        qq, mm = sosfiltfilt(sos, qq), sosfiltfilt(sos, mm)
    if np.ptp(qq) < np.radians(5.0) or not float(qq @ qq) > 0:
        return                                   # too little motion to judge the scale
    slope = float(qq @ mm) / float(qq @ qq)
    lo, hi = MOTOR_SCALE_RANGE
    if lo <= abs(slope) <= hi:
        return
    n = spec.gear_ratio
    if abs(slope / np.degrees(1.0) - 1) < 0.1:
        cause = "q_m looks like degrees: the controller log's angles must be in radians"
    elif n != 1 and abs(slope / n - 1) < 0.1:
        cause = f"q_m looks like the motor side: it must be divided by gear_ratio ({n:g}) (docs/conventions.md)"
    elif n != 1 and abs(slope * n - 1) < 0.1:
        cause = f"q_m looks divided by the gear ratio twice (gear_ratio {n:g})"
    else:
        cause = f"check gear_ratio ({n:g}) and the units of the motor angle column"
    where = (rec.root / rec.controller_file) if rec.root is not None and rec.controller_file else rec.root
    raise InputError(where, f"{spec.motor_position} (joint {spec.name})",
                     "a motor angle on the link side that moves with the mocap's link angle (slope 1)",
                     f"a slope of {slope:.4g} over {np.degrees(np.ptp(qq)):.0f} deg of motion", hint=cause)


def calibrate_joints(rec: Recording, method: str = "auto") -> JointsResult:
    """Joint geometry, link angles and (with a controller log) deflections of every joint of `rec`.

    `method` "auto" fits each joint by maximum likelihood, or by SARA where its markers do not move
    as a hinge (:func:`.calibrate.auto_calibrate_joint`); or name one method of
    `CALIBRATION_METHODS` for every joint. The axis sign is a convention: it is chosen so that the
    link angle and the motor angle increase together (docs/conventions.md); without a motor, as
    the fit gives it.
    """
    if method not in CALIBRATION_METHODS:
        raise InputError(None, "method", f"one of {list(CALIBRATION_METHODS)}", repr(method))
    if rec.markers_from_cameras:
        raise InputError(rec.root, "markers", "3D markers (the joints stage calibrates axes from markers)",
                         "a bundle whose markers are still 2D detections of its cameras",
                         hint="'mocapfj run' triangulates them first (or 'mocapfj triangulate')")
    if rec.markers is None:
        raise InputError(rec.root, "markers", "a marker file (the joints stage calibrates axes from markers)",
                         "a recording without [markers]", hint="a rigid robot's log is identified by 'identify'")
    joints = []
    for spec in rec.joints:
        if not spec.has_markers:
            continue
        v = rec.markers.select(spec.link_markers)
        v_parent = None if spec.parent_is_world else rec.markers.select(spec.parent_markers)
        repairs = {}
        source = (rec.root / rec.marker_file) if rec.root is not None and rec.marker_file else rec.root
        for key, labels in (("link", spec.link_markers), ("parent", None if v_parent is None else spec.parent_markers)):
            if labels is None:
                continue
            fixed, rep = repair_cluster(v if key == "link" else v_parent, labels, rec.markers.t, source=source,
                                        where=f" (joints[{spec.name}] {key} cluster)")
            if rep.changed:
                repairs[key] = rep.to_dict()
                if key == "link":
                    v = fixed
                else:
                    v_parent = fixed
        v, parent = markers_in_parent_frame(v, v_parent)
        try:
            geometry, angles = calibrate_joint(v, spec.link_markers, rec.markers.t, method)
        except InputError as e:
            raise InputError(rec.root, f"joints[{spec.name}] ({e.field})", e.expected, e.got, e.hint) from None
        d = None
        ctl = rec.controller
        if ctl is not None and spec.name in ctl.joint_names:
            d = deflection(angles, ctl, spec.name, rec.clock_offset_s)
            ok = np.isfinite(d.delta)
            if ok.sum() > 2 and np.corrcoef(angles.q[ok], d.q_m[ok])[0, 1] < 0:
                geometry = flip_axis(geometry)
                angles = solve_angles(v, geometry, rec.markers.t)
                d = deflection(angles, ctl, spec.name, rec.clock_offset_s)
            _check_motor_scale(rec, spec, angles.q, d.q_m)
        joints.append(JointResult(name=spec.name, geometry=geometry, angles=angles, deflection=d, parent=parent,
                                  parent_labels=spec.parent_markers, method=method, repairs=repairs or None))
    if not joints:
        raise InputError(rec.root, "joints", "at least one joint with link_markers", "none")
    return JointsResult(recording=rec.name, method=method, joints=tuple(joints))
