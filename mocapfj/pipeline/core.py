"""Composition of the measurement stages: recordings summarised, scenarios simulated, the demo,
joint calibration, link angles and deflections, and a joint's signals on one clock."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import load_recording, read_markers, write_json
from ..types import JointAngles, JointGeometry, MarkerTrajectories, Recording

__all__ = ["summarize_markers", "summarize_recording", "inspect_path", "run_simulate", "run_demo", "run_joints",
           "joint_signals", "markers_in_parent_frame", "calibrate_joint", "auto_calibrate_joint"]


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


def default_scenario(name: str = "pa10_joint2") -> Path:
    """A shipped scenario file: datasets/NAME.toml in the working directory or beside the package."""
    for root in (Path.cwd(), Path(__file__).resolve().parents[1]):
        p = root / "datasets" / f"{name}.toml"
        if p.is_file():
            return p
    raise InputError(f"datasets/{name}.toml", "scenario", "the shipped scenario file (run from the repository)",
                     "no such file")


def run_demo(out: str | Path, duration_s: float | None = None) -> dict:
    """The pipeline so far, on a recording whose truth is known.

    Simulates the shipped pa10_joint2 scenario (seed 000 Table I, joint 2) into ``OUT/pa10_joint2``
    (bundle, truth.json, truth.csv), loads it back through the readers a lab's recording goes
    through, calibrates the joint and solves its angles and deflections (``OUT/joints``), compares
    the deflection with the truth, and writes ``OUT/summary.json``.
    """
    from ..io import read_csv_columns

    out = Path(out)
    summary = run_simulate(default_scenario(), out / "pa10_joint2", duration_s=duration_s, concealment=False)
    joints = run_joints(out / "pa10_joint2", out / "joints")
    truth = read_csv_columns(out / "pa10_joint2" / "truth.csv")
    for j in joints["joints"]:
        a = read_csv_columns(out / "joints" / f"{j['name']}.angles.csv")
        true_delta = np.interp(a["t_controller"], truth["time"], truth[f"delta_{j['name']}"])
        err = a["delta"] - true_delta
        ok = np.isfinite(err)
        err = err[ok] - err[ok].mean()
        j["deflection_error_rms_rad"] = float(np.sqrt(np.mean(err**2)))
        j["deflection_error_bound_rad"] = float(np.sqrt(np.mean(a["sigma_delta"][ok] ** 2)))
    summary["joints_fit"] = joints["joints"]
    write_json(out / "summary.json", summary)
    return summary


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

    scn = load_scenario(scenario)
    if duration_s is not None:
        if not duration_s > 0:
            raise InputError(None, "--duration", "a positive duration in s", duration_s)
        scn = scn.with_duration(duration_s)
    sr = record_scenario(scn, with_concealment=concealment)
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
    from ..synth.record import _layout, _rngs
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
    layout = _layout(scn, pa10_geometry(), _rngs(scn)[0])
    write_blob_clip(out, sr.recording.rig, layout, q_full, rng)
    return len(truth["images"]) + q_full.shape[0] * len(sr.recording.rig.cameras)


STATIC_PARENT_SD_M = 1e-3
"""A parent cluster whose markers move less than this (SD over the trial, metres) is static (a
braked link): one pose fitted over all frames is used, so the parent adds no per-frame noise."""


def markers_in_parent_frame(v_link: np.ndarray, v_parent: np.ndarray | None
                            ) -> tuple[np.ndarray, np.ndarray | None, bool]:
    """Link markers (T, P, 3) expressed in the parent cluster's frame.

    Returns the markers in the parent frame, the parent's template (None for the world) and
    whether the parent was found static. A parent cluster is located per frame by a rigid fit
    (Kabsch) to its template; when it does not move (`STATIC_PARENT_SD_M`), one pose fitted over
    all frames is used so that it adds no per-frame noise.
    """
    from ..joints.segments import cluster_template, kabsch, to_parent_frame

    if v_parent is None:
        return v_link, None, True
    template = cluster_template(v_parent)
    static = bool(np.nanmax(np.nanstd(v_parent, axis=0)) < STATIC_PARENT_SD_M)
    if static:
        R, t, _ = kabsch(template, np.nanmean(v_parent, axis=0)[None])
        R, t = np.broadcast_to(R, (v_link.shape[0], 3, 3)), np.broadcast_to(t, (v_link.shape[0], 3))
    else:
        R, t, _ = kabsch(template, v_parent)
    return to_parent_frame(v_link, R, t), template, static


def joint_frame_markers(rec: Recording, spec) -> tuple[np.ndarray, np.ndarray | None, bool]:
    """A recording joint's link markers in its parent's frame (`markers_in_parent_frame`)."""
    v = rec.markers.select(spec.link_markers)
    return markers_in_parent_frame(v, None if spec.parent_is_world else rec.markers.select(spec.parent_markers))


def fit_sara_geometry(v: np.ndarray, labels) -> JointGeometry:
    """A hinge from the motion of the link cluster as a rigid body in the parent frame (SARA).

    For joints between two moving segments, where the markers also move in ways a hinge does not
    (skin, pronation of a forearm): the axis comes from the cluster's rotations (Ehrig 2007),
    which such motion disturbs far less than marker positions. The template is the cluster at
    its first complete frame. `cov_axis` and `cov_point` are NaN: judge the axis by refitting on
    parts of the trial.
    """
    from ..joints import cluster_template, fit_sara, kabsch, predict_markers

    tmpl = cluster_template(v)
    R, t, _ = kabsch(tmpl, v)
    n_frames = R.shape[0]
    axis_i, _, c_i, _ = fit_sara(np.broadcast_to(np.eye(3), (n_frames, 3, 3)), np.zeros((n_frames, 3)), R, t)
    axis = axis_i / np.linalg.norm(axis_i)
    complete = np.flatnonzero(~np.isnan(v[..., 0]).any(axis=1))
    if complete.size == 0:
        raise InputError(None, "v", "a frame in which every link marker is seen", "none")
    ref = v[complete[0]]
    centroid = np.nanmean(v.reshape(-1, 3), axis=0)
    point = c_i + ((centroid - c_i) @ axis) * axis
    template = ref - point
    radii = np.linalg.norm(template - np.outer(template @ axis, axis), axis=1)
    nan33 = np.full((3, 3), np.nan)
    geometry = JointGeometry(axis=axis, point=point, template=template, labels=tuple(labels), radii=radii,
                             radius_rms=np.zeros(len(labels)), marker_rms=float("nan"), cov_axis=nan33,
                             cov_point=nan33, sigma_m=float("nan"), method="sara", n_frames=int(np.isfinite(R[:, 0, 0]).sum()))
    # residuals of the hinge through the cluster's own motion
    rel = v - point
    dist = np.linalg.norm(rel - (rel @ axis)[..., None] * axis, axis=-1)
    radius_rms = np.sqrt(np.nanmean((dist - radii) ** 2, axis=0))
    R_ref = R[np.flatnonzero(np.isfinite(R[:, 0, 0]))[0]]
    q = _twist(np.einsum("tij,kj->tik", R, R_ref), axis)
    resid = v - predict_markers(geometry, np.where(np.isfinite(q), q, 0.0))
    marker_rms = float(np.sqrt(np.nanmean(np.where(np.isfinite(q)[:, None, None], resid, np.nan) ** 2) * 3))
    from dataclasses import replace

    return replace(geometry, radius_rms=radius_rms, marker_rms=marker_rms, sigma_m=marker_rms / np.sqrt(3))


def _twist(R: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Twist angle about `axis` of each rotation R (T, 3, 3) (swing-twist split), unwrapped, rad."""
    ok = np.isfinite(R[:, 0, 0])
    w = 1.0 + R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2]  # 4 qw^2
    vx, vy, vz = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]  # 4 qw qv
    q = 2.0 * np.arctan2(vx * axis[0] + vy * axis[1] + vz * axis[2], w)
    q[ok] = np.unwrap(q[ok])
    q[~ok] = np.nan
    return q


def sara_angles(v: np.ndarray, geometry, t) -> JointAngles:
    """Angles of a SARA joint: the twist about its axis of the link cluster's rigid rotation.

    The cluster (its template in the parent frame) is fitted to each frame (Kabsch); frames with
    fewer than 3 markers are NaN. sigma_q is sigma_m / sqrt(sum of r_p^2 over the markers seen).
    """
    from ..joints import kabsch, predict_markers

    R, _, _ = kabsch(geometry.point + geometry.template, v)
    q = _twist(R, geometry.axis)
    seen = ~np.isnan(v[..., 0])
    valid = np.isfinite(q)
    r2 = (np.where(seen, geometry.radii**2, 0.0)).sum(axis=1)
    sigma_q = np.where(valid, geometry.sigma_m / np.sqrt(np.maximum(r2, 1e-300)), np.nan)
    resid = np.linalg.norm(v - predict_markers(geometry, np.where(valid, q, 0.0)), axis=-1)
    sq = np.where(seen & valid[:, None], resid, 0.0) ** 2
    marker_rms = np.where(valid, np.sqrt(sq.sum(axis=1) / np.maximum(seen.sum(axis=1), 1)), np.nan)
    n = np.where(valid, seen.sum(axis=1), 0)
    return JointAngles(t=np.asarray(t, float), q=q, sigma_q=sigma_q, marker_rms=marker_rms, n_markers=n,
                       n_rejected=np.zeros_like(n))


def calibrate_joint(v: np.ndarray, labels, t: np.ndarray, method: str = "ml"):
    """Fit a joint's geometry from its markers in the parent frame and solve its angles.

    Returns (JointGeometry, JointAngles). `method`: "ml" (maximum likelihood seeded by the
    bias-compensated fit), "halvorsen", "gamage_lasenby" or "sara" (`fit_sara_geometry`).
    """
    from ..joints.axis import fit_gamage_lasenby, fit_halvorsen, fit_hinge_ml

    if method == "gamage_lasenby":
        geometry = fit_gamage_lasenby(v, labels=labels)
    elif method == "halvorsen":
        geometry = fit_halvorsen(v, labels=labels)
    elif method == "ml":
        geometry, _ = fit_hinge_ml(v, labels=labels, init=fit_halvorsen(v, labels=labels))
    elif method == "sara":
        geometry = fit_sara_geometry(v, labels)
    else:
        raise InputError(None, "method", '"ml", "halvorsen", "gamage_lasenby" or "sara"', repr(method))
    return geometry, calibrate_joint_angles(v, geometry, t)


HINGE_MISFIT_RATIO = 5.0
"""`auto` fits by SARA when the ML hinge's marker residual exceeds this many times the link
cluster's own rigid-fit residual: the markers then do not move as a hinge (skin, a forearm that
also pronates), and the cluster's rotations locate the axis better than its marker positions."""


def auto_calibrate_joint(v: np.ndarray, labels, t):
    """Maximum likelihood, or SARA where the markers do not move as a hinge (`HINGE_MISFIT_RATIO`)."""
    from ..joints import cluster_template, kabsch

    geometry, angles = calibrate_joint(v, labels, t, "ml")
    _, _, rigid = kabsch(cluster_template(v), v)
    rigid_rms = float(np.nanmedian(rigid))
    if geometry.marker_rms > HINGE_MISFIT_RATIO * max(rigid_rms, 1e-6):
        return calibrate_joint(v, labels, t, "sara")
    return geometry, angles


def calibrate_joint_angles(v, geometry, t):
    """Angles of a joint with a given geometry (as `calibrate_joint` solves them for its method)."""
    from ..joints.angles import joint_angles

    if geometry.method == "sara":
        return sara_angles(v, geometry, t)
    return joint_angles(v, geometry, t)


def _flip(geometry):
    from dataclasses import replace

    return replace(geometry, axis=-geometry.axis)


def run_joints(recording: str | Path, out: str | Path, method: str = "auto") -> dict:
    """Joint geometry, link angles and deflections of every joint of a recording (``mocapfj joints``).

    Writes OUT/<joint>.joint.toml (the cluster calibration), OUT/<joint>.angles.csv (per mocap
    sample: times, q, sigma_q, q_m, delta, sigma_delta, tau, markers used, marker RMS) and
    OUT/joints.json (the summary printed by --json). `method` "auto" fits each joint by maximum
    likelihood, or by SARA where its markers do not move as a hinge (`auto_calibrate_joint`); or
    name one method for every joint.
    """
    from ..io import write_csv_columns
    from ..io.geometry import write_joint_geometry
    from ..joints.sync import deflection

    rec = load_recording(recording)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    joints = []
    for i, spec in enumerate(rec.joints):
        v, parent_template, static_parent = joint_frame_markers(rec, spec)
        try:
            geometry, angles = (auto_calibrate_joint(v, spec.link_markers, rec.markers.t) if method == "auto"
                                else calibrate_joint(v, spec.link_markers, rec.markers.t, method))
        except InputError as e:
            raise InputError(rec.root, f"joints[{spec.name}] ({e.field})", e.expected, e.got, e.hint) from None
        d = deflection(angles, rec.controller, i, rec.clock_offset_s)
        ok = np.isfinite(d.delta)
        if ok.sum() > 2 and np.corrcoef(angles.q[ok], d.q_m[ok])[0, 1] < 0:
            # the axis sign is a convention: link and motor angles increase together
            geometry = _flip(geometry)
            angles = calibrate_joint_angles(v, geometry, rec.markers.t)
            d = deflection(angles, rec.controller, i, rec.clock_offset_s)
        write_joint_geometry(out / f"{spec.name}.joint.toml", spec.name, geometry,
                             "world" if spec.parent_is_world else spec.parent_markers, parent_template,
                             extra={"recording": rec.name, "q_offset_rad": d.q_offset_rad})
        write_csv_columns(out / f"{spec.name}.angles.csv", {
            "t_mocap": angles.t, "t_controller": d.t, "q": d.q, "sigma_q": angles.sigma_q, "q_m": d.q_m,
            "delta": d.delta, "sigma_delta": d.sigma_delta, "tau": d.tau, "n_markers": angles.n_markers,
            "n_rejected": angles.n_rejected, "marker_rms": angles.marker_rms})
        valid = np.isfinite(angles.q)
        joints.append({
            "name": spec.name,
            "axis": geometry.axis,
            "point_m": geometry.point,
            "radii_mm": geometry.radii * 1e3,
            "radius_rms_mm": geometry.radius_rms * 1e3,
            "marker_rms_mm": float(np.sqrt(np.nanmean(angles.marker_rms**2)) * 1e3),
            "angle_sigma_rad": float(np.nanmedian(angles.sigma_q)),
            "n_frames": int(angles.q.size),
            "n_frames_invalid": int((~valid).sum()),
            "method": geometry.method,
            "q_range_deg": float(np.degrees(np.nanmax(angles.q) - np.nanmin(angles.q))) if valid.any() else None,
            "q_offset_rad": d.q_offset_rad,
            "deflection_rms_rad": float(np.sqrt(np.nanmean((d.delta - np.nanmean(d.delta)) ** 2))),
            "q_m_quantum_rad": d.q_m_quantum_rad,
            "parent_static": static_parent,
            "files": {"geometry": f"{spec.name}.joint.toml", "angles": f"{spec.name}.angles.csv"},
        })
    summary = {"recording": rec.name, "method": method, "joints": joints}
    write_json(out / "joints.json", summary)
    return summary


STEP1 = ("I", "mglx", "mgly", "c", "v", "J", "b")


def joint_signals(rec: Recording, angles_csv: str | Path, joint: int, min_valid: float = 0.95,
                  max_gap_s: float = 0.1):
    """A joint's link angle (from `run_joints`' angles CSV) and its controller signals on one clock.

    Returns (t, q, q_m, u, n_filled): the mocap samples on the controller clock, the link angle
    with gaps of up to `max_gap_s` filled by interpolation (n_filled samples: a counted repair),
    and the logged motor angle and torque low-passed (zero phase, 100 Hz or 0.45 x their rate)
    and interpolated there; samples outside the controller log are dropped. A longer gap, less
    than `min_valid` of the frames with an angle, or a NaN in the controller log is refused with
    the time it happens: interpolation across it would invent the motion the identification fits.
    """
    from ..io import read_csv_columns
    from ..ident.twostep import controller_on

    spec, log = rec.joints[joint], rec.controller
    a = read_csv_columns(angles_csv)
    t, q = a["t_controller"], a["q"]
    ok = np.isfinite(q)
    if ok.mean() < min_valid:
        raise InputError(rec.root, f"joints[{spec.name}] link angle",
                         f"a link angle in at least {100 * min_valid:.0f} % of the frames", f"{100 * ok.mean():.1f} %",
                         hint="check the markers' visibility")
    if not ok.all():
        edges = np.diff(np.concatenate([[0], (~ok).astype(np.int8), [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        dt = float(np.median(np.diff(t)))
        longest = int(np.argmax(stops - starts))
        gap = (stops[longest] - starts[longest] + 1) * dt
        if gap > max_gap_s:
            raise InputError(angles_csv, f"q (joint {spec.name})", f"gaps in the link angle of at most {max_gap_s:g} s",
                             f"{gap:.3f} s without an angle from t = {t[starts[longest]]:.3f} s",
                             hint="cut the trial around the gap, or check the markers' visibility there")
    q = np.interp(t, t[ok], q[ok])
    for name, x in (("q_m", log.q_m[:, joint]), ("tau", log.tau[:, joint])):
        bad = ~np.isfinite(x)
        if bad.any():
            raise InputError(rec.root, f"controller log {name} (joint {spec.name})", "finite samples",
                             f"{int(bad.sum())} NaN, the first at t = {log.t[np.argmax(bad)]:.4f} s",
                             hint="cut the trial where the log is complete")
    cutoff = min(100.0, 0.45 * log.rate_hz)
    q_m = controller_on(t, log.t, log.q_m[:, joint], log.rate_hz, cutoff)
    u = controller_on(t, log.t, log.tau[:, joint], log.rate_hz, cutoff)
    g = np.isfinite(q_m) & np.isfinite(u)
    return t[g], q[g], q_m[g], u[g], int((~ok).sum())
