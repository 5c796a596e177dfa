"""A run as one rerun recording (``RUN_DIR/recording.rrd``): the 3D scene, the joints' signals,
the discovery's residuals, the deflection-torque loops and the FRF, with a default blueprint.

Entity paths (docs/visualisation.md, "The rerun recording"); the timeline ``time`` is the
controller clock (duration, s):

- ``/world/cameras/<cam>``: Transform3D (camera to world) and Pinhole (frustum);
- ``/world/markers/<cluster>``: Points3D over time, labelled (a joint's link and parent clusters,
  the other markers grouped by label prefix);
- ``/world/joints/<j>/axis`` and ``/circles``: the fitted axis and each link marker's circle about
  it (LineStrips3D, static when the parent does not move);
- ``/world/links``: segments parent cluster centroid -> axis point -> link cluster centroid
  (the robot without a URDF); ``/robot/...``: the bundle's URDF posed by the measured angles;
- ``/world/joints/<j>/magnified`` (``magnify`` > 1): the link markers where they would be with
  the deflection magnified, next to ``/rigid`` (where a rigid joint would put them);
- ``/plots/<j>/...``: Scalars (angle q, q_m; deflection; torque tau, spring, spring_model;
  residuals before/after discovery, the located windows as points);
- ``/loops/<j>``, ``/frf/magnitude``, ``/frf/phase``: plots drawn in 2D views (:mod:`.rrd_plots`);
- ``/summary``: a Markdown document of the run (what is shown, what was left out).

Every time series is sent columnar (``send_columns``); nothing is logged frame by frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .rrd_data import JointRun, RunContents, load_run
from .rrd_signals import TIMELINE, joint_params, spring_torques, windows_of

__all__ = ["write_run_recording", "write_recording_file", "log_run", "link_markers_at", "axis_segment", "marker_circles",
           "marker_clusters", "parent_poses", "strips_column", "send_scalars"]

AXIS_HALF_LENGTH_M = 0.25
CIRCLE_POINTS = 65
PALETTE = [(230, 80, 60), (60, 130, 230), (60, 180, 90), (220, 160, 40), (160, 90, 200), (40, 180, 190),
           (200, 90, 140), (120, 120, 120)]


def _rr():
    import rerun as rr

    return rr


def _time(t):
    return [_rr().TimeColumn(TIMELINE, duration=np.asarray(t, dtype=np.float64))]


def send_scalars(rec, path: str, t, y) -> int:
    """Send one scalar series (NaN samples left out); returns the number of samples sent."""
    rr = _rr()
    t, y = np.asarray(t, dtype=np.float64), np.asarray(y, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(y)
    if not ok.any():
        return 0
    rec.send_columns(path, indexes=_time(t[ok]), columns=rr.Scalars.columns(scalars=y[ok]))
    return int(ok.sum())


def strips_column(strips: np.ndarray, archetype: str = "LineStrips3D"):
    """A columnar LineStrips3D/LineStrips2D ``strips`` component, one strip per row, built directly
    in Arrow (rerun's per-strip conversion costs ~50 us a strip).

    strips : (N, K, D) float, N rows of one strip of K points in D = 3 (or 2) dimensions.
    """
    import pyarrow as pa

    rr = _rr()
    n, k, dim = strips.shape
    item = pa.field("item", pa.float32(), nullable=False)
    point_t = pa.list_(item, dim)
    strip_t = pa.list_(pa.field("item", point_t, nullable=False))
    values = pa.array(np.ascontiguousarray(strips, dtype=np.float32).ravel(), type=pa.float32())
    points = pa.FixedSizeListArray.from_arrays(values, type=point_t)
    offsets = pa.array(np.arange(0, n * k + 1, k, dtype=np.int32))
    arr = pa.ListArray.from_arrays(offsets, points, type=strip_t)
    desc = getattr(rr, archetype).descriptor_strips()

    class _Batch:
        def as_arrow_array(self):
            return arr

        def component_descriptor(self):
            return desc

    return rr.ComponentColumn(desc, _Batch())


def _colour(i: int) -> tuple[int, int, int]:
    return PALETTE[i % len(PALETTE)]


# ---------------------------------------------------------------- geometry


def parent_poses(contents: RunContents, j: JointRun) -> tuple[np.ndarray, np.ndarray, bool]:
    """R_world_parent (T, 3, 3), t_world_parent (T, 3) at the marker frames, and whether the parent
    is static (one pose: the mean rotation projected on SO(3) and the mean translation, T = 1)."""
    if not j.parent_labels or j.parent_template is None or contents.markers is None:
        return np.eye(3)[None], np.zeros((1, 3)), True
    from ..joints.segments import kabsch

    m = contents.markers
    idx = [m.labels.index(lab) for lab in j.parent_labels if lab in m.labels]
    if len(idx) < 3:
        return np.eye(3)[None], np.zeros((1, 3)), True
    tmpl = j.parent_template[[j.parent_labels.index(m.labels[i]) for i in idx]]
    R, t, _ = kabsch(tmpl, m.xyz[:, idx])
    ok = np.isfinite(R[:, 0, 0])
    static = bool(j.summary.get("parent_static", False)) or not np.any(ok)
    if static:
        if not np.any(ok):
            return np.eye(3)[None], np.zeros((1, 3)), True
        U, _, Vt = np.linalg.svd(R[ok].mean(axis=0))
        Rm = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
        return Rm[None], t[ok].mean(axis=0)[None], True
    return R, t, False


def axis_segment(axis: np.ndarray, point: np.ndarray, half_length_m: float = AXIS_HALF_LENGTH_M) -> np.ndarray:
    """(2, 3) m: the axis line from point - h axis to point + h axis (same frame as the inputs)."""
    a = np.asarray(axis, dtype=np.float64)
    return np.stack([point - half_length_m * a, point + half_length_m * a])


def marker_circles(g, n: int = CIRCLE_POINTS) -> np.ndarray:
    """(P, n, 3) m, parent frame: each link marker's circle about the fitted axis (centre on the
    axis at the marker's height along it, the fitted radius)."""
    a = g.axis / np.linalg.norm(g.axis)
    h = g.template @ a                                           # (P,) height of each marker along the axis
    centres = g.point + h[:, None] * a
    u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(a, u)
    phi = np.linspace(0.0, 2 * np.pi, n)
    ring = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v    # (n, 3)
    return centres[:, None, :] + g.radii[:, None, None] * ring[None]


def link_markers_at(j: JointRun, q: np.ndarray) -> np.ndarray:
    """(T, P, 3) m, parent frame: the link markers' template at link angles q (T,) rad (aligned
    with the motor's zero): point + R(axis, q - q_offset) template (docs/formats.md, joint.toml)."""
    from ..rotations import rotate

    g = j.geometry
    return g.point + rotate(g.axis, (np.asarray(q, dtype=np.float64) - j.q_offset_rad)[:, None], g.template[None])


def _to_world(R, t, p):
    """p (T, ..., 3) parent frame -> world with poses (T or 1, 3, 3), (T or 1, 3)."""
    shape = p.shape
    flat = p.reshape(shape[0], -1, 3)
    return (np.einsum("tij,tpj->tpi", R, flat) + t[:, None, :]).reshape(shape)


def _sample_poses(R, t, t_markers, t_query):
    """The parent pose at the times t_query (nearest marker frame); a static pose unchanged."""
    if R.shape[0] == 1:
        return R, t
    k = np.clip(np.searchsorted(t_markers, t_query), 0, t_markers.size - 1)
    return R[k], t[k]


# ---------------------------------------------------------------- logging


def _log_cameras(rec, rig) -> list[str]:
    rr = _rr()
    paths = []
    for cam in rig.cameras:
        R_world_cam = cam.R_cam_world.T
        path = f"world/cameras/{cam.name}"
        rec.log(path, rr.Transform3D(translation=-R_world_cam @ cam.t_cam_world, mat3x3=R_world_cam), static=True)
        rec.log(path, rr.Pinhole(image_from_camera=cam.K, resolution=list(cam.size), camera_xyz=rr.ViewCoordinates.RDF,
                                 image_plane_distance=0.25), static=True)
        paths.append(path)
    return paths


def marker_clusters(contents: RunContents) -> dict[str, list[int]]:
    """{cluster name: marker indices}: each joint's link (``<j>_link``) and parent (``<j>_parent``)
    markers, the others grouped by the label before its last underscore."""
    m = contents.markers
    out, taken = {}, set()
    for spec in (contents.recording.joints if contents.recording is not None else ()):
        for role, labels in (("link", spec.link_markers), ("parent", spec.parent_markers)):
            if isinstance(labels, str):
                continue
            idx = [m.labels.index(lab) for lab in labels if lab in m.labels and m.labels.index(lab) not in taken]
            if idx:
                out[f"{spec.name}_{role}"] = idx
                taken.update(idx)
    for i, lab in enumerate(m.labels):
        if i not in taken:
            out.setdefault(lab.rsplit("_", 1)[0] if "_" in lab else "markers", []).append(i)
    return out


def _log_markers(rec, contents: RunContents) -> dict[str, np.ndarray]:
    """Each cluster's markers over time; returns {cluster: (T, 3) centroid, NaN where none seen}."""
    rr = _rr()
    m = contents.markers
    t = m.t + contents.clock_offset_s
    centroids = {}
    for c, (name, idx) in enumerate(marker_clusters(contents).items()):
        xyz = m.xyz[:, idx]                                         # (T, P, 3)
        ok = np.isfinite(xyz).all(axis=2)
        counts = ok.sum(axis=1)
        keep = counts > 0
        labels = np.asarray([m.labels[i] for i in idx], dtype=object)
        path = f"world/markers/{name}"
        rec.log(path, rr.Points3D.from_fields(colors=[_colour(c)], radii=0.006), static=True)
        cols = rr.Points3D.columns(positions=xyz[ok], labels=np.broadcast_to(labels, ok.shape)[ok].tolist())
        rec.send_columns(path, indexes=_time(t[keep]), columns=cols.partition(lengths=counts[keep]))
        with np.errstate(invalid="ignore"):
            centroids[name] = np.where(keep[:, None], np.nansum(np.where(ok[..., None], xyz, 0), axis=1)
                                       / np.maximum(counts, 1)[:, None], np.nan)
    return centroids


def _log_joint_geometry(rec, contents: RunContents, j: JointRun, c: int, magnify: float) -> None:
    rr = _rr()
    g = j.geometry
    R, t, static = parent_poses(contents, j)
    base = f"world/joints/{j.name}"
    seg = axis_segment(g.axis, g.point)                              # parent frame
    circles = marker_circles(g)
    colour = _colour(c)
    if static:
        rec.log(f"{base}/axis", rr.LineStrips3D([_to_world(R, t, seg[None])[0]], radii=0.004, colors=[colour],
                                                labels=[f"{j.name} axis"]), static=True)
        world = _to_world(R, t, circles.reshape(1, -1, 3)).reshape(circles.shape)
        rec.log(f"{base}/circles", rr.LineStrips3D(list(world), radii=0.0015, colors=[colour]), static=True)
    else:
        tm = contents.markers.t + contents.clock_offset_s
        ok = np.isfinite(R[:, 0, 0])
        rec.log(f"{base}/axis", rr.LineStrips3D.from_fields(radii=0.004, colors=[colour], labels=[f"{j.name} axis"]),
                static=True)
        rec.send_columns(f"{base}/axis", indexes=_time(tm[ok]),
                         columns=[strips_column(_to_world(R[ok], t[ok], np.broadcast_to(seg, (ok.sum(), 2, 3))))])
        flat = _to_world(R[ok], t[ok], np.broadcast_to(circles.reshape(-1, 3), (ok.sum(), circles.size // 3, 3)))
        rec.log(f"{base}/circles", rr.LineStrips3D.from_fields(radii=0.0015, colors=[colour]), static=True)
        rec.send_columns(f"{base}/circles", indexes=_time(tm[ok]),
                         columns=[strips_column(flat.reshape(-1, CIRCLE_POINTS, 3)).partition(
                             lengths=np.full(ok.sum(), len(circles)))])
    a = j.angles
    if magnify != 1.0 and "q_m" in a and "delta" in a:
        ok = np.isfinite(a["q_m"]) & np.isfinite(a["delta"])
        tj = j.t[ok]
        Rq, tq = _sample_poses(R, t, contents.markers.t + contents.clock_offset_s if contents.markers is not None
                               else tj, tj)
        if Rq.shape[0] == 1:
            Rq, tq = np.repeat(Rq, tj.size, 0), np.repeat(tq, tj.size, 0)
        P = g.template.shape[0]
        for name, q, col in (("rigid", a["q_m"][ok], (150, 150, 150)),
                             ("magnified", a["q_m"][ok] - magnify * a["delta"][ok], colour)):
            pts = _to_world(Rq, tq, link_markers_at(j, q))
            rec.log(f"{base}/{name}", rr.Points3D.from_fields(colors=[col], radii=0.008,
                                                              labels=[f"{j.name} {name} x{magnify:g}"] * P), static=True)
            rec.send_columns(f"{base}/{name}", indexes=_time(tj),
                             columns=rr.Points3D.columns(positions=pts.reshape(-1, 3)).partition(lengths=np.full(tj.size, P)))


def _log_links(rec, contents: RunContents, centroids: dict) -> None:
    """Segments parent centroid -> axis point -> link centroid per joint, at the marker frames."""
    rr = _rr()
    tm = contents.markers.t + contents.clock_offset_s
    strips = []
    for j in contents.joints:
        link, parent = centroids.get(f"{j.name}_link"), centroids.get(f"{j.name}_parent")
        if link is None:
            continue
        R, t, _ = parent_poses(contents, j)
        point = _to_world(R, t, np.broadcast_to(j.geometry.point, (R.shape[0], 3))[:, None])[:, 0]
        point = np.broadcast_to(point, link.shape)
        start = parent if parent is not None else point
        strips.append(np.stack([start, point, link], axis=1))        # (T, 3, 3)
    if not strips:
        return
    s = np.stack(strips, axis=1)                                     # (T, J, 3, 3)
    ok = np.isfinite(s).all(axis=(1, 2, 3))
    rec.log("world/links", rr.LineStrips3D.from_fields(radii=0.012, colors=[(90, 90, 100)]), static=True)
    rec.send_columns("world/links", indexes=_time(tm[ok]),
                     columns=[strips_column(s[ok].reshape(-1, 3, 3)).partition(lengths=np.full(ok.sum(), len(strips)))])


def _log_urdf(rec, contents: RunContents) -> list[str]:
    """The bundle's URDF under /robot, its joints named like the run's posed by the measured link
    angles (mocap frames). The URDF's root frame is taken as the mocap world."""
    rr = _rr()
    tree = rr.urdf.UrdfTree.from_file_path(contents.urdf, entity_path_prefix="robot")
    tree.log_urdf_to_recording(recording=rec)
    posed = []
    for j in contents.joints:
        uj = next((x for x in tree.joints() if x.name == j.name), None)
        if uj is None or uj.joint_type not in ("revolute", "continuous"):
            continue
        ok = np.isfinite(j.angles["q"])
        rec.send_columns(f"robot_joints/{j.name}", indexes=_time(j.t[ok]),
                         columns=uj.compute_transform_columns(j.angles["q"][ok], clamp=False))
        posed.append(j.name)
    return posed


def _log_joint_series(rec, contents: RunContents, j: JointRun, c: int) -> None:
    rr = _rr()
    a, t = j.angles, j.t
    base = f"plots/{j.name}"
    ctl = contents.recording.controller if contents.recording is not None else None
    ci = ctl.joint_names.index(j.name) if ctl is not None and j.name in ctl.joint_names else None
    rec.log(f"{base}/angle/q", rr.SeriesLines(names=["q (link, mocap), rad"], colors=[_colour(c)]), static=True)
    send_scalars(rec, f"{base}/angle/q", t, a["q"])
    if ci is not None or "q_m" in a:
        rec.log(f"{base}/angle/q_m", rr.SeriesLines(names=["q_m (motor / N), rad"], colors=[(40, 40, 40)]), static=True)
        if ci is not None:
            send_scalars(rec, f"{base}/angle/q_m", ctl.t, ctl.q_m[:, ci])
        else:
            send_scalars(rec, f"{base}/angle/q_m", t, a["q_m"])
    if "delta" in a:
        rec.log(f"{base}/deflection/delta", rr.SeriesLines(names=["deflection q_m - q, rad"], colors=[_colour(c)]),
                static=True)
        send_scalars(rec, f"{base}/deflection/delta", t, a["delta"])
    if ci is not None or "tau" in a:
        rec.log(f"{base}/torque/tau", rr.SeriesLines(names=["tau (logged), N m"], colors=[(40, 40, 40)]), static=True)
        if ci is not None:
            send_scalars(rec, f"{base}/torque/tau", ctl.t, ctl.tau[:, ci])
        else:
            send_scalars(rec, f"{base}/torque/tau", t, a["tau"])
    ident = joint_params(contents, j.name)
    s = spring_torques(j, ident)
    if s is not None and ident is not None:
        rec.log(f"{base}/torque/spring", rr.SeriesLines(names=["spring u - J q_m'' - b q_m', N m"],
                                                        colors=[_colour(c)]), static=True)
        send_scalars(rec, f"{base}/torque/spring", s["t"], s["tau_s"])
        if s["model"] is not None:
            rec.log(f"{base}/torque/spring_model",
                    rr.SeriesLines(names=[f"spring model ({ident['spring']['model']}), N m"], colors=[(230, 160, 30)]),
                    static=True)
            send_scalars(rec, f"{base}/torque/spring_model", s["t"], s["model"])


def _log_residuals(rec, contents: RunContents) -> None:
    rr = _rr()
    r = contents.residuals or {}
    t = r.get("t")
    names = sorted({k.rsplit("_r_", 1)[0] for k in r if "_r_" in k})
    for name in names:
        base = f"plots/{name}/residuals"
        for key, label, unit, colour in (("delta_before", "deflection residual before", "rad", (150, 150, 150)),
                                         ("delta_after", "deflection residual after", "rad", (60, 130, 230)),
                                         ("u_before", "torque residual before", "N m", (150, 150, 150)),
                                         ("u_after", "torque residual after", "N m", (230, 80, 60))):
            col = f"{name}_r_{key}"
            if col in r:
                path = f"{base}/{key.split('_')[0]}/{key.split('_')[1]}"
                rec.log(path, rr.SeriesLines(names=[f"{label}, {unit}"], colors=[colour]), static=True)
                send_scalars(rec, path, t, r[col])
        col = f"{name}_r_u_before"
        for k, (family, t0, t1) in enumerate(windows_of(contents.discovery, name)):
            if col not in r:
                break
            inside = (t >= t0) & (t <= t1)
            path = f"{base}/located/{family}_{k}"
            rec.log(path, rr.SeriesPoints(names=[f"located ({family} residual) {t0:g}-{t1:g} s"],
                                          colors=[(250, 200, 0)], marker_sizes=[2.0]), static=True)
            send_scalars(rec, path, t[inside], r[col][inside])
    for effect in (contents.discovery or {}).get("effects", []):
        where = windows_of(contents.discovery, effect.get("joint", ""))
        t0 = where[0][1] if where else 0.0
        rec.set_time(TIMELINE, duration=t0)
        rec.log("discovery/log", rr.TextLog(f"{effect.get('name')} on {effect.get('joint')}: "
                                            f"{effect.get('explanation', '')}", level="INFO"))
    rec.reset_time()


def summary_markdown(contents: RunContents, shown: list[str]) -> str:
    """The /summary document: the run, what the recording shows and what it leaves out."""
    lines = [f"# Run {contents.root.name}", ""]
    m = contents.manifest or {}
    if m.get("recording"):
        lines.append(f"- recording: `{m['recording']}`")
    for st in m.get("stages", []):
        extra = f" ({st.get('reason') or st.get('error')})" if st.get("reason") or st.get("error") else ""
        lines.append(f"- stage {st.get('name')}: {st.get('status')}{extra}")
    d = contents.discovery
    if d:
        lines += ["", f"**Discovery**: {d.get('verdict', '')}", ""]
        for e in d.get("effects", []):
            lines.append(f"- {e.get('name')} on {e.get('joint')}: {e.get('explanation', '')}")
    lines += ["", "Shown: " + (", ".join(shown) if shown else "nothing")]
    if contents.notes:
        lines += ["", "Left out:"] + [f"- {n}" for n in contents.notes]
    return "\n".join(lines) + "\n"


def log_run(rec, contents: RunContents, *, magnify: float = 1.0, timings: dict | None = None) -> list[str]:
    """Log a run's contents into an open rerun RecordingStream; returns what was shown (one word
    per part). Static scene first, then the columnar series; the caller saves and disconnects.
    `timings`, when given, receives the seconds each part took (benchmarks/bench_viz.py)."""
    import time

    from .rrd_plots import log_frf, log_loops

    rr = _rr()
    if not (np.isfinite(magnify) and magnify > 0):
        from ..errors import InputError

        raise InputError(None, "magnify", "a positive factor", magnify)
    timings = {} if timings is None else timings
    shown = []
    centroids = {}

    def part(name, fn, *args):
        tic = time.perf_counter()
        out = fn(*args)
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - tic
        return out

    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    if contents.rig is not None:
        part("cameras", _log_cameras, rec, contents.rig)
        shown.append("cameras")
    if contents.markers is not None:
        centroids = part("markers", _log_markers, rec, contents)
        shown.append("markers")
    for c, j in enumerate(contents.joints):
        part("joint geometry", _log_joint_geometry, rec, contents, j, c, magnify)
    if contents.joints:
        shown.append("joint axes")
    if contents.urdf is not None and contents.joints:
        if part("robot (URDF)", _log_urdf, rec, contents):
            shown.append("robot (URDF)")
    elif contents.markers is not None and contents.joints:
        part("links", _log_links, rec, contents, centroids)
        shown.append("links")
    for c, j in enumerate(contents.joints):
        part("joint signals", _log_joint_series, rec, contents, j, c)
    if contents.joints:
        shown.append("joint signals")
    if contents.residuals is not None:
        part("residuals", _log_residuals, rec, contents)
        shown.append("residuals")
    if part("loops", log_loops, rec, contents):
        shown.append("loops")
    if part("FRF", log_frf, rec, contents):
        shown.append("FRF")
    rec.log("summary", rr.TextDocument(summary_markdown(contents, shown), media_type=rr.MediaType.MARKDOWN), static=True)
    return shown


def write_recording_file(contents: RunContents, out, *, magnify: float = 1.0, timings: dict | None = None) -> Path:
    """Write `contents` as a .rrd file at `out` (atomically) with the default blueprint;
    `timings` as in :func:`log_run`, plus "save" (the flush to disk on disconnect)."""
    from ..io.atomic import atomic_path
    from .rrd_blueprint import run_blueprint

    rr = _rr()
    out = Path(out)
    rec = rr.RecordingStream("mocapfj", recording_id=f"mocapfj-{contents.root.resolve().name}")
    with atomic_path(out) as tmp:
        rec.save(str(tmp), default_blueprint=run_blueprint(contents))
        try:
            log_run(rec, contents, magnify=magnify, timings=timings)
        finally:
            import time

            tic = time.perf_counter()
            rec.disconnect()                   # writes the footer: the file is complete
            if timings is not None:
                timings["save"] = time.perf_counter() - tic
    return out


def write_run_recording(run_dir, out=None, *, magnify: float = 1.0) -> Path:
    """Build RUN_DIR/recording.rrd (or `out`) from a run directory's files.

    Parameters
    ----------
    run_dir : path
        A run directory (``mocapfj run --out``, docs/formats.md) or one command's ``--out``.
    out : path, optional
        The .rrd to write (default RUN_DIR/recording.rrd).
    magnify : float
        Draw the link markers also where they would be with the deflection magnified this many
        times (``/world/joints/<j>/magnified``); 1 draws only the measured markers.

    Returns the path written. InputError when run_dir holds no results.
    """
    contents = load_run(run_dir)
    return write_recording_file(contents, Path(run_dir) / "recording.rrd" if out is None else out, magnify=magnify)
