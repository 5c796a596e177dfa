"""Files over the measurement stages: recordings summarised (``inspect``), scenarios simulated
(``simulate``), and the joints stage's results written (``joints``). The maths is in
the stages (:mod:`mocapfj.joints`, :mod:`mocapfj.synth`); this module composes them and writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import load_recording, read_markers, write_json
from ..types import MarkerTrajectories, Recording

__all__ = ["summarize_markers", "summarize_recording", "inspect_path", "default_scenario", "run_simulate",
           "write_joints", "run_joints"]


def summarize_markers(m: MarkerTrajectories, file: str = "") -> dict:
    """Counts and spans of a marker file, for people and for --json."""
    seen = ~np.isnan(m.xyz[..., 0])
    res = m.residual[seen] if m.residual is not None else np.empty(0)
    return {
        "file": file,
        "n_frames": m.n_frames,
        "n_markers": len(m.labels),
        "rate_hz": m.rate_hz,
        "t_start_s": float(m.t[0]) if m.n_frames else None,
        "t_end_s": float(m.t[-1]) if m.n_frames else None,
        "labels": list(m.labels),
        "missing_pct": float(100.0 * (1.0 - seen.mean())) if seen.size else 100.0,
        "residual_median_mm": float(np.nanmedian(res) * 1e3) if res.size and np.isfinite(res).any() else None,
    }


def summarize_recording(rec: Recording) -> dict:
    """A recording's contents: streams, spans and, per joint, its markers and ranges (None for a
    stream the bundle does not have: markers only, or a rigid robot's log only)."""
    ctl, mk = rec.controller, rec.markers
    joints = []
    for j in rec.joints:
        entry = {"name": j.name, "link_markers": list(j.link_markers),
                 "parent_markers": "world" if j.parent_is_world else list(j.parent_markers),
                 "gear_ratio": j.gear_ratio, "link_markers_missing_pct": None, "q_m_range_rad": None, "tau_rms_Nm": None}
        if mk is not None and j.has_markers:
            idx = [mk.index(s) for s in j.link_markers]
            entry["link_markers_missing_pct"] = float(100.0 * (1.0 - (~np.isnan(mk.xyz[:, idx, 0])).mean()))
        if ctl is not None and j.name in ctl.joint_names:
            i = ctl.joint_names.index(j.name)
            entry["q_m_range_rad"] = [float(np.nanmin(ctl.q_m[:, i])), float(np.nanmax(ctl.q_m[:, i]))]
            entry["tau_rms_Nm"] = float(np.sqrt(np.nanmean(ctl.tau[:, i] ** 2)))
        joints.append(entry)
    controller = None if ctl is None else {
        "file": rec.controller_file, "n_samples": ctl.n_samples, "rate_hz": ctl.rate_hz,
        "t_start_s": float(ctl.t[0]), "t_end_s": float(ctl.t[-1]), "extra_columns": list(ctl.extra)}
    if ctl is not None and ctl.time_note:
        controller["time_note"] = ctl.time_note
    return {
        "name": rec.name,
        "root": str(rec.root) if rec.root else None,
        "clock_offset_s": rec.clock_offset_s,
        "markers": None if mk is None else summarize_markers(mk, rec.marker_file),
        "controller": controller,
        "urdf": str(rec.urdf) if rec.urdf else None,
        "rig_cameras": len(rec.rig.cameras) if rec.rig else 0,
        "detections": int(rec.detections.frame.size) if rec.detections else 0,
        "markers_from_cameras": rec.markers_from_cameras,
        "joints": joints,
    }


def inspect_path(path: str | Path) -> dict:
    """Summary of a bundle directory, a recording.toml, or a single C3D/TRC file."""
    path = Path(path)
    if path.suffix.lower() in (".c3d", ".trc") and not path.is_dir():
        return {"markers": summarize_markers(read_markers(path), path.name), "joints": []}
    if not path.exists():
        raise InputError(path, "RECORDING", "a bundle directory, a recording.toml, or a .c3d/.trc file", "no such path")
    return summarize_recording(load_recording(path))


def default_scenario(name: str = "pa10_joint2") -> Path:
    """A shipped scenario file: datasets/NAME.toml in the working directory or beside the package."""
    for root in (Path.cwd(), Path(__file__).resolve().parents[2]):
        p = root / "datasets" / f"{name}.toml"
        if p.is_file():
            return p
    raise InputError(f"datasets/{name}.toml", "scenario", "the shipped scenario file (run from the repository)",
                     "no such file")


def run_simulate(scenario: str | Path, out: str | Path, duration_s: float | None = None,
                 concealment: bool = True, images: bool = False) -> dict:
    """Simulate a scenario file into a recording bundle with its truth (``mocapfj simulate``).

    Writes OUT/recording.toml and the bundle's files, truth.json (parameters, planted effects
    with their concealment numbers), truth.csv (true signals on the controller clock),
    truth_mocap.csv (true link angles at the mocap instants) and a copy of the scenario. With
    `images`, also OUT/images/: board calibration views and a blob clip with their truth
    (the scenario's ``[images]`` table: ``views``, ``clip_frames``, ``board``).
    """
    from ..synth.record import record_scenario, write_scenario_bundle
    from ..synth.scenario import load_scenario

    from ..synth.scenario import check_scenario

    scn = load_scenario(scenario)
    if duration_s is not None:
        if not duration_s > 0:
            raise InputError(None, "--duration", "a positive duration in s", duration_s)
        scn = scn.with_duration(duration_s)
        check_scenario("--duration", scn)
    try:
        sr = record_scenario(scn, with_concealment=concealment)
    except InputError as e:
        if e.file == "<argument>":              # a model element's own check: name the scenario
            raise InputError(scenario, e.field, e.expected, e.got, e.hint) from None
        raise
    write_scenario_bundle(sr, out, Path(scenario))
    n_images = _write_images(scn, sr, Path(out) / "images") if images else 0
    summary = summarize_recording(load_recording(out))
    summary["images"] = n_images
    summary["scenario"] = scn.name
    summary["duration_s"] = scn.duration_s
    summary["effects"] = sr.truth["effects"]
    summary["truth"] = {"joints": [{k: j[k] for k in ("name", "angle_sigma_rad", "deflection_noise_sd_rad")}
                                   for j in sr.truth["joints"]], "clock": sr.truth["clock"]}
    summary["timings_s"] = sr.timings_s
    return summary


def _write_images(scn, sr, out: Path) -> int:
    """Board views and a blob clip for a simulated recording; returns the number of images."""
    from ..io.calib import board_from_table
    from ..io.tomlio import require
    from ..synth.record import marker_layout, scenario_rngs
    from ..synth.robot_mesh import pa10_geometry
    from ..synth.views import DEFAULT_BOARD, write_blob_clip, write_board_views

    tab = require(scn.source, scn.doc, "images", dict, default={})
    views = int(require(scn.source, tab, "views", int, "images", default=8))
    frames = int(require(scn.source, tab, "clip_frames", int, "images", default=10))
    board = board_from_table(tab["board"], scn.source, "images.board") if "board" in tab else DEFAULT_BOARD
    rng = np.random.default_rng(np.random.SeedSequence([scn.seed, 7]))
    truth = write_board_views(out, sr.recording.rig, board, views, rng)
    q_full = np.tile(np.asarray(scn.pose_rad, float), (min(frames, sr.q_true_mocap.shape[0]), 1))
    for i, j in enumerate(scn.joints):
        q_full[:, j.axis - 1] = sr.q_true_mocap[: q_full.shape[0], i]
    layout = marker_layout(scn, pa10_geometry(), scenario_rngs(scn)[0])
    write_blob_clip(out, sr.recording.rig, layout, q_full, rng)
    return len(truth["images"]) + q_full.shape[0] * len(sr.recording.rig.cameras)


def write_joints(cal, out: str | Path) -> dict:
    """Write a joints stage's results (a :class:`mocapfj.joints.JointsResult`) into OUT.

    OUT/<joint>.joint.toml (the cluster calibration), OUT/<joint>.angles.csv (per mocap sample:
    times, q, sigma_q, markers used, marker RMS and, with a controller log, q_m, delta,
    sigma_delta, tau) and OUT/joints.json (the summary printed by --json, with the files).
    """
    from ..io import write_csv_columns
    from ..io.geometry import write_joint_geometry

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = cal.to_dict()
    for j, entry in zip(cal.joints, summary["joints"]):
        d, a = j.deflection, j.angles
        extra = {"recording": cal.recording}
        if d is not None:
            extra["q_offset_rad"] = d.q_offset_rad
        write_joint_geometry(out / f"{j.name}.joint.toml", j.name, j.geometry, j.parent_labels, j.parent.template,
                             extra=extra)
        cols = {"t_mocap": a.t}
        if d is not None:
            cols.update(t_controller=d.t, q=d.q, sigma_q=a.sigma_q, q_m=d.q_m, delta=d.delta, sigma_delta=d.sigma_delta,
                        tau=d.tau)
        else:
            cols.update(q=a.q, sigma_q=a.sigma_q)
        cols.update(n_markers=a.n_markers, n_rejected=a.n_rejected, marker_rms=a.marker_rms)
        write_csv_columns(out / f"{j.name}.angles.csv", cols)
        entry["files"] = {"geometry": f"{j.name}.joint.toml", "angles": f"{j.name}.angles.csv"}
    write_json(out / "joints.json", summary)
    return summary


def run_joints(recording: str | Path, out: str | Path, method: str = "auto") -> dict:
    """``mocapfj joints``: :func:`mocapfj.joints.calibrate_joints` on a bundle, written by
    :func:`write_joints`; returns the summary."""
    from ..joints.stage import calibrate_joints

    return write_joints(calibrate_joints(load_recording(recording), method), out)
