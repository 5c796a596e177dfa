"""Composition of the stages for the CLI and for batch runs. Plain functions on plain data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import InputError
from .io import load_recording, read_markers, write_json, write_recording
from .types import MarkerTrajectories, Recording

__all__ = ["summarize_markers", "summarize_recording", "inspect_path", "run_demo"]


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
    """A recording's contents: streams, spans and, per joint, its markers and ranges."""
    ctl = rec.controller
    joints = []
    for i, j in enumerate(rec.joints):
        idx = [rec.markers.index(s) for s in j.link_markers]
        seen = ~np.isnan(rec.markers.xyz[:, idx, 0])
        q_m = ctl.q_m[:, i]
        joints.append({
            "name": j.name,
            "link_markers": list(j.link_markers),
            "parent_markers": "world" if j.parent_is_world else list(j.parent_markers),
            "gear_ratio": j.gear_ratio,
            "link_markers_missing_pct": float(100.0 * (1.0 - seen.mean())),
            "q_m_range_rad": [float(np.nanmin(q_m)), float(np.nanmax(q_m))],
            "tau_rms_Nm": float(np.sqrt(np.nanmean(ctl.tau[:, i] ** 2))),
        })
    return {
        "name": rec.name,
        "root": str(rec.root) if rec.root else None,
        "clock_offset_s": rec.clock_offset_s,
        "markers": summarize_markers(rec.markers, rec.marker_file),
        "controller": {
            "file": rec.controller_file,
            "n_samples": ctl.n_samples,
            "rate_hz": ctl.rate_hz,
            "t_start_s": float(ctl.t[0]),
            "t_end_s": float(ctl.t[-1]),
            "extra_columns": list(ctl.extra),
        },
        "urdf": str(rec.urdf) if rec.urdf else None,
        "rig_cameras": len(rec.rig.cameras) if rec.rig else 0,
        "detections": int(rec.detections.frame.size) if rec.detections else 0,
        "joints": joints,
    }


def inspect_path(path: str | Path) -> dict:
    """Summary of a bundle directory, a recording.toml, or a single C3D/TRC file."""
    path = Path(path)
    if path.suffix.lower() in (".c3d", ".trc"):
        return {"markers": summarize_markers(read_markers(path), path.name), "joints": []}
    if not path.exists():
        raise InputError(path, "RECORDING", "a bundle directory, a recording.toml, or a .c3d/.trc file", "no such path")
    return summarize_recording(load_recording(path))


def run_demo(out: str | Path, seed: int = 0) -> dict:
    """The pipeline so far, on a recording whose truth is known.

    Writes a toy one-joint bundle to ``OUT/recording``, loads it back through the same readers
    a user's bundle goes through, and writes ``OUT/summary.json``.
    """
    from .synth import TOY_TRUTH, toy_recording

    out = Path(out)
    rec = toy_recording(seed=seed)
    write_recording(rec, out / "recording")
    back = load_recording(out / "recording")
    seen = ~np.isnan(rec.markers.xyz)
    summary = summarize_recording(back)
    summary["truth"] = TOY_TRUTH
    summary["round_trip"] = {
        "marker_max_error_m": float(np.max(np.abs(back.markers.xyz[seen] - rec.markers.xyz[seen]))),
        "controller_identical": bool(np.array_equal(back.controller.q_m, rec.controller.q_m)
                                     and np.array_equal(back.controller.tau, rec.controller.tau)),
    }
    write_json(out / "summary.json", summary)
    return summary
