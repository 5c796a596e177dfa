"""The report's sections from each stage's results: recording, calibration and coverage, joint
geometry, identification and the spring fit, FRF, discovery (:mod:`mocapfj.viz.report` puts
them together). Each reads the files of docs/formats.md; a file whose keys are not those mocapfj
writes is an InputError naming it.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from . import figures as F
from .document import Figure, Note, Paragraph, Section, Table
from .report_format import UNITS, fmt, pm, read_columns, read_result_json, read_toml

__all__ = ["recording_blocks", "calibration_sections", "joint_sections", "identification_sections",
           "frf_sections", "discovery_sections"]

MEANING = {"I": "link inertia", "J": "motor inertia (link side)", "k": "joint stiffness",
           "b": "motor viscous friction", "c": "link Coulomb friction", "v": "link viscous friction",
           "mglx": "gravity torque (sin q term)", "mgly": "gravity torque (cos q term)", "d": "spring damping",
           "g": "gravity stiffness about the operating point",
           "tau0": "spring torque at zero deflection"}


@contextlib.contextmanager
def _reading(path: Path) -> Iterator[None]:
    """Turn a missing key or a wrong type in a result file into one InputError naming the file."""
    try:
        yield
    except InputError:
        raise
    except (KeyError, TypeError, IndexError, ValueError, AttributeError) as e:
        what = f"key {e.args[0]!r} missing" if isinstance(e, KeyError) else " ".join(str(e).split())[:200]
        raise InputError(path, "contents", "the keys mocapfj writes there (docs/formats.md)", what) from None


def _slug(s: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in str(s))


def _vec(v, scale: float = 1.0, digits: int = 4) -> str:
    if v is None:
        return "n/a"
    return "[" + ", ".join(f"{scale * x:+.{digits}f}" for x in v) + "]"


def _sds(v, scale: float = 1.0) -> str:
    """A vector of SDs: unsigned, two significant digits."""
    return "n/a" if v is None else "[" + ", ".join(fmt(scale * x, 2) for x in v) + "]"


# ---------------------------------------------------------------- recording

def recording_blocks(s: dict, role: str, path) -> list:
    """Blocks summarising one bundle from :func:`mocapfj.pipeline.core.inspect_path`'s dict."""
    rows = [("name", str(s.get("name") or "")), ("bundle", str(path))]
    m, c = s.get("markers"), s.get("controller")
    if m is not None:
        res = "" if m.get("residual_median_mm") is None else f", median residual {fmt(m['residual_median_mm'], 3)} mm"
        rows.append(("markers", f"{m['file']}: {m['n_markers']} markers × {m['n_frames']} frames at "
                     f"{fmt(m['rate_hz'])} Hz, {fmt(m['t_start_s'])}–{fmt(m['t_end_s'])} s, "
                     f"{m['missing_pct']:.2f} % missing{res}"))
    else:
        rows.append(("markers", "none (a controller log only)"))
    if c is not None:
        rows.append(("controller", f"{c['file']}: {c['n_samples']} samples at {fmt(c['rate_hz'])} Hz, "
                     f"{fmt(c['t_start_s'])}–{fmt(c['t_end_s'])} s, clock offset {fmt(s.get('clock_offset_s'))} s"))
    else:
        rows.append(("controller", "none (markers only: axes and angles, no deflection)"))
    rows.append(("cameras", f"{s.get('rig_cameras', 0)} in the rig, {s.get('detections', 0)} 2D detections"))
    if s.get("urdf"):
        rows.append(("URDF", str(s["urdf"])))
    blocks = [Paragraph("The recording the stages ran on." if role == "recording" else
                        "The validation recording (held out: discovery judges each effect on it)."),
              Table(("item", "value"), tuple(rows))]
    jr = []
    for j in s.get("joints", []):
        parent = j["parent_markers"] if isinstance(j["parent_markers"], str) else ", ".join(j["parent_markers"])
        rng = j.get("q_m_range_rad")
        jr.append((j["name"], ", ".join(j["link_markers"]), parent, fmt(j.get("gear_ratio")),
                   fmt(j.get("link_markers_missing_pct"), 3),
                   "n/a" if rng is None else f"{np.degrees(rng[0]):+.1f} to {np.degrees(rng[1]):+.1f}",
                   fmt(j.get("tau_rms_Nm"), 3)))
    if jr:
        blocks.append(Table(("joint", "link markers", "parent", "gear ratio", "link markers missing (%)",
                             "motor angle range (deg, link side)", "torque RMS (N m)"), tuple(jr)))
    return blocks


# ---------------------------------------------------------------- calibration

def calibration_sections(files) -> list[Section]:
    blocks = []
    if "calibrate_rig" in files.stages:
        path = files.stages["calibrate_rig"] / "calibrate_rig.json"
        d = read_result_json(path)
        with _reading(path):
            blocks += _rig_blocks(d)
    if "triangulate" in files.stages:
        path = files.stages["triangulate"] / "triangulate.json"
        d = read_result_json(path)
        with _reading(path):
            blocks += _triangulation_blocks(d)
    return [Section("calibration", "Calibration and coverage", tuple(blocks))] if blocks else []


def _rig_blocks(d: dict) -> list:
    src = "a wand wave" if d.get("method") == "wand" else "board views"
    text = (f"Rig of {len(d['cameras'])} cameras from {src}: reprojection RMS {fmt(d['rms_px'], 3)} px "
            f"(start {fmt(d.get('initial_rms_px'), 3)} px), residual SD {fmt(d.get('sigma_px'), 3)} px.")
    if d.get("wand_length_mean_mm") is not None:
        text += (f" Wand length {fmt(d['wand_length_mean_mm'], 7)} mm (nominal {fmt(d.get('wand_length_mm'))} mm), "
                 f"SD {fmt(d.get('wand_length_sd_mm'), 3)} mm over {d.get('n_wand_lengths')} frames.")
    if d.get("world"):
        text += f" World frame: {d['world']}"
        text += (f" (L-frame fit {fmt(d['lframe_rms_mm'], 3)} mm RMS)." if d.get("lframe_rms_mm") is not None else ".")
    rows = []
    for c in d["cameras"]:
        ps = c.get("position_std_m")
        rows.append((c["name"], fmt(c.get("rms_px"), 3), fmt(c.get("rms_mm"), 3), str(c.get("n_observations", "")),
                     str(c.get("n_outliers", "")), _vec(c.get("position_m"), 1.0, 3),
                     _sds(ps, 1e3), _sds(c.get("rotation_std_deg")),
                     fmt(c.get("fx"), 6)))
    return [Paragraph(text),
            Table(("camera", "RMS (px)", "RMS (mm)", "points", "outliers", "centre (m)", "centre SD (mm)",
                   "orientation SD (deg)", "fx (px)"), tuple(rows)),
            Paragraph("SDs are relative to camera 0 (the gauge of the bundle adjustment)."),
            Figure("calibration_cameras.png", F.cameras_figure(d["cameras"]),
                   "Camera centres seen from above with their viewing directions (left) and each camera's "
                   "reprojection RMS with the number of points it saw (right).")]


def _triangulation_blocks(d: dict) -> list:
    tri = next(iter((d.get("triangulation") or {}).values()), {})
    text = (f"Triangulation: {len(d['labels'])} labelled markers × {d['n_frames']} frames at {fmt(d['rate_hz'])} Hz, "
            f"{fmt(d['points_per_frame'], 3)} points per frame, reprojection RMS {fmt(d['reprojection_rms_px'], 3)} px, "
            f"{100 * d['nan_share']:.2f} % of samples missing.")
    rows = [("points seen by fewer than 2 cameras", str(d.get("n_unseen", 0))),
            ("rejected by the robust views", str(d.get("n_rejected", 0))),
            ("samples filled from the rigid fit", str(d.get("gaps_filled", 0))),
            ("label swaps repaired", str(d.get("swaps_repaired", 0))),
            ("gaps left open", str(len(d.get("long_gaps") or [])))]
    if tri.get("views_mean") is not None:
        rows.append(("cameras per point (mean)", fmt(tri["views_mean"], 3)))
    if tri.get("predicted_sd_median_mm") is not None:
        rows.append(("predicted point SD (median)", f"{fmt(tri['predicted_sd_median_mm'], 3)} mm"))
    blocks = [Paragraph(text), Table(("coverage", "value"), tuple(rows))]
    by = {k: v for k, v in ((d.get("labelling") or {}).get("nan_share_by_label") or {}).items() if v}
    if by:
        worst = sorted(by.items(), key=lambda kv: -kv[1])[:12]
        blocks.append(Paragraph("Markers with missing samples (the most first):"))
        blocks.append(Table(("marker", "missing (%)"), tuple((k, f"{100 * v:.2f}") for k, v in worst)))
    return blocks


# ---------------------------------------------------------------- joints

def _joints_json(files):
    if files.joints_dir is None:
        return None, None
    path = files.joints_dir / "joints.json"
    return path, read_result_json(path)


def _angles(files, joint: str):
    """The joint's angles CSV columns, from the joints stage or a copy identify/discover keeps."""
    dirs = [files.joints_dir] if files.joints_dir is not None else []
    if "identify" in files.stages:
        dirs += sorted(p.parent for p in files.stages["identify"].glob("*/joints/joints.json"))
    for d in dirs:
        p = d / f"{joint}.angles.csv"
        if p.is_file():
            return p, read_columns(p)
    return None, None


def joint_sections(files) -> list[Section]:
    path, d = _joints_json(files)
    if d is None:
        return []
    out = [Section("joints", "Joint geometry", (Paragraph(
        f"Joint axes fitted to the link markers' motion (recording {d.get('recording', '')}, method "
        f"{d.get('method', '')}). The axis and its point are given in the parent cluster's frame; with a static "
        "parent also in the world. SDs from the fit's covariance (the point's is rank 2: it is the axis point "
        "nearest the markers, free along the axis)."),))]
    with _reading(path):
        for j in d["joints"]:
            out.append(_joint_section(files, j, path))
    return out


def _joint_section(files, j: dict, path: Path) -> Section:
    name = j["name"]
    tpath = files.joints_dir / (j.get("files") or {}).get("geometry", f"{name}.joint.toml")
    geo = read_toml(tpath) if tpath.is_file() else {}
    rows = [("method", str(j.get("method")), ""),
            ("frames", f"{j.get('n_frames')} ({j.get('n_frames_invalid', 0)} without an angle)", "")]
    cov_a = np.asarray(geo.get("cov_axis", np.full((3, 3), np.nan)), dtype=float)
    sd_tilt = np.sqrt(np.clip(np.sort(np.linalg.eigvalsh(cov_a))[::-1][:2], 0, None)) if np.isfinite(cov_a).all() else None
    rows.append(("axis (parent frame)", _vec(j["axis"], 1.0, 5),
                 "" if sd_tilt is None else f"tilt SD {sd_tilt[0] * 1e3:.3g}, {sd_tilt[1] * 1e3:.3g} mrad"))
    cov_p = np.asarray(geo.get("cov_point_m2", np.full((3, 3), np.nan)), dtype=float)
    sd_p = np.sqrt(np.clip(np.diag(cov_p), 0, None)) if np.isfinite(cov_p).all() else None
    rows.append(("axis point (parent frame)", _vec(j["point_m"], 1e3, 2) + " mm",
                 "" if sd_p is None else "SD " + _sds(sd_p, 1e6) + " µm"))
    if j.get("axis_world") is not None:
        rows.append(("axis (world)", _vec(j["axis_world"], 1.0, 5), ""))
        rows.append(("axis point (world)", _vec(j["point_world_m"], 1e3, 2) + " mm", ""))
    radii = j.get("radii_mm") or []
    rrms = j.get("radius_rms_mm") or [None] * len(radii)
    rows.append(("marker radii", ", ".join(fmt(r, 5) for r in radii) + " mm",
                 "RMS about the circle " + ", ".join(fmt(r, 2) for r in rrms) + " mm"))
    if geo.get("sigma_m") is not None:
        rows.append(("marker noise SD (fit)", f"{fmt(1e3 * geo['sigma_m'], 3)} mm", "per coordinate"))
    rows.append(("marker RMS (fit / angle solve)",
                 f"{fmt(j.get('fit_marker_rms_mm'), 3)} / {fmt(j.get('angle_marker_rms_mm', j.get('marker_rms_mm')), 3)} mm",
                 ""))
    rows.append(("link angle SD per frame", f"{fmt(1e3 * j['angle_sigma_rad'], 3)} mrad", "Cramér-Rao bound"))
    rows.append(("angle range", f"{fmt(j.get('q_range_deg'), 3)} deg", ""))
    if j.get("deflection_rms_rad") is not None:
        rows.append(("deflection RMS", f"{fmt(1e3 * j['deflection_rms_rad'], 4)} mrad", ""))
    if j.get("q_offset_rad") is not None:
        rows.append(("link angle zero offset", f"{fmt(j['q_offset_rad'])} rad", "aligned with the motor's zero"))
    blocks = [Table(("quantity", "value", "uncertainty / note"), tuple(rows))]
    apath, a = _angles(files, name)
    if a is not None and "q" in a and "t_mocap" in a:
        t = a.get("t_controller", a["t_mocap"])
        blocks.append(Figure(f"joint_{_slug(name)}_signals.png",
                             F.signals_figure(t, a["q"], a.get("q_m"), a.get("delta"), a.get("sigma_delta"),
                                              a.get("tau"), name),
                             f"Joint {name}: link and motor angle, deflection (each sample, and low-passed at 5 Hz), "
                             f"and the logged torque against time (from {apath.name})."))
    return Section(f"joints/{name}", "Joint geometry", tuple(blocks), subtitle=f"Joint {name}")


# ---------------------------------------------------------------- identification and the spring

def identification_sections(files) -> list[Section]:
    if "identify" not in files.stages:
        return []
    path = files.stages["identify"] / "identify.json"
    d = read_result_json(path)
    out = [Section("identification", "Identification", (Paragraph(
        f"Recordings: {', '.join(map(str, d.get('recordings', [])))}. A parameter is not determined when its SD is "
        "large against its value or when the data cannot tell it from another; the reason is given. Table-I-style "
        "tables are in table.md and table.csv beside identify.json."),))]
    springs = []
    with _reading(path):
        for j in d["joints"]:
            if "params" not in j:
                continue
            out.append(_identified_joint(j))
            if j.get("spring"):
                s = _spring_section(files, j)
                if s is not None:
                    springs.append(s)
    if springs:
        out.append(Section("spring", "Spring fit", (Paragraph(
            "The spring torque from the motor equation, tau_s = u - J q_m'' - b q_m' (J and b identified; q_m'' and "
            "q_m' by a cubic Savitzky-Golay filter over 44 ms), against the measured deflection, with the fitted "
            "spring. The mocap angle noise spreads the points sideways; the right panel averages it away."),)))
        out += springs
    return out


def _identified_joint(j: dict) -> Section:
    name = j["name"]
    params = j["params"]
    rows, flags, notes = [], [], []
    for p, e in params.items():
        det = e.get("determined", True)
        rows.append((p, MEANING.get(p, ""), pm(e.get("value"), e.get("std")), UNITS.get(p, ""),
                     fmt(e.get("rel_std_pct"), 3), "yes" if det else "not determined"))
        flags.append("" if det else "bad")
        if not det:
            notes.append(Note(f"{p} ({MEANING.get(p, p)}) is not determined: {e.get('reason') or 'no reason given'}.",
                              "warn"))
    text = (f"Method {j.get('method')}, spring {((j.get('spring') or {}).get('model'))}, {j.get('n_trials', 1)} trial(s); "
            f"torque RMS error {fmt(j.get('torque_rms'), 3)} N m")
    rs = j.get("residual_sd") or {}
    if rs:
        text += (f", residual SD {fmt(1e3 * rs['q_rad'], 3)} mrad in the link angle and {fmt(rs['u_Nm'], 3)} N m in "
                 "the torque")
    if j.get("band_hz") is not None:
        text += f", fitted below {fmt(j['band_hz'], 3)} Hz"
    cond = [f"{k.removeprefix('cond_').replace('_', '-')} {fmt(v, 3)}" for k, v in j.items()
            if k.startswith("cond_") and v is not None]
    text += (". Condition numbers: " + ", ".join(cond) + "." if cond else ".")
    blocks = [Paragraph(text),
              Table(("parameter", "meaning", "value ± SD", "unit", "rel. SD (%)", "determined"), tuple(rows),
                    tuple(flags))]
    blocks += notes
    comb = j.get("combinations") or {}
    if comb:
        blocks.append(Paragraph("Combinations the data determine even where their parts are not:"))
        blocks.append(Table(("combination", "value ± SD"), tuple((k, pm(v.get("value"), v.get("std")))
                                                                for k, v in comb.items())))
    co = j.get("clock_offset") or {}
    if co:
        blocks.append(Paragraph(
            f"Clock offset between markers and controller: {pm(1e3 * co['offset_s'], 1e3 * co['sd_s'])} ms "
            f"({'found and applied' if co.get('applied') else 'not applied'})."))
    names = list(params)
    blocks.append(Figure(f"identify_{_slug(name)}_sd.png",
                         F.parameter_sd_figure(names, [params[n].get("rel_std_pct") for n in names],
                                               [params[n].get("determined", True) for n in names], name),
                         f"Joint {name}: the relative SD of each parameter (log scale); red bars are the "
                         "parameters not determined."))
    return Section(f"identification/{name}", "Identification", tuple(blocks), subtitle=f"Joint {name}")


def _spring_curve(spring: dict, d: np.ndarray, tau_s: np.ndarray):
    """(tau0, k) of the line drawn: the fitted linear spring, else the model's stiffness with the
    offset the points give (a display choice, said in the caption)."""
    p = spring.get("params") or {}
    k = p.get("k", p.get("k1"))
    if k is None:
        return None
    if spring.get("model") == "linear" and p.get("tau0") is not None:
        return float(p["tau0"]), float(k), "the fitted linear spring"
    ok = np.isfinite(d) & np.isfinite(tau_s)
    tau0 = float(np.mean(tau_s[ok] - k * d[ok])) if ok.any() else 0.0
    return tau0, float(k), f"the {spring.get('model')} spring's stiffness k (offset from the points)"


def _spring_section(files, j: dict) -> Section | None:
    name, spring = j["name"], j["spring"]
    apath, a = _angles(files, name)
    if a is None or not {"q_m", "tau", "delta"} <= set(a):
        return None
    t = a.get("t_controller", a["t_mocap"])
    dt = float(np.nanmedian(np.diff(t)))
    qd, qdd = F.smooth_derivatives(a["q_m"], dt)
    params = j["params"]
    J = params.get("J", {}).get("value") or 0.0
    b = params.get("b", {}).get("value") or 0.0
    tau_s = a["tau"] - J * qdd - b * qd
    curve = _spring_curve(spring, a["delta"], tau_s)
    if curve is None:
        return None
    tau0, k, what = curve
    rate = F.smooth_derivatives(tau_s, dt, 0.1)[0]           # N m/s; at rest (below 10 % of its RMS) left out
    direction = np.where(np.abs(rate) < 0.1 * np.sqrt(np.nanmean(rate ** 2)), np.nan, np.sign(rate))
    ident = j["params"]
    sp = spring.get("params") or {}
    rows = tuple((p, pm(v, (ident.get(p) or {}).get("std")) if p in ident else pm(v, sp.get(f"{p}_std"))
                  if sp.get(f"{p}_std") is not None else fmt(v, 6), UNITS.get(p, ""))
                 for p, v in sp.items() if not p.endswith("_std"))
    blocks = [Paragraph(f"Spring model {spring.get('model')}"
                        + (f", R² {fmt(spring['r2'], 6)}" if spring.get("r2") is not None else "") + "."),
              Table(("spring parameter", "value (± SD)", "unit"), rows),
              Figure(f"spring_{_slug(name)}.png",
                     F.spring_figure(a["delta"], tau_s, k, tau0, name, direction, spring.get("r2")),
                     f"Joint {name}: spring torque against deflection with {what} (left); what the line leaves, "
                     "averaged in bins of spring torque separately while it rises and falls (right; samples at "
                     "rest left out): two curves apart are a hysteresis loop, a bend common to both a stiffness "
                     "that changes with the load.")]
    return Section(f"spring/{name}", "Spring fit", tuple(blocks), subtitle=f"Joint {name}")


# ---------------------------------------------------------------- FRF

def frf_sections(files) -> list[Section]:
    if "frf" not in files.stages:
        return []
    path = files.stages["frf"] / "frf.json"
    d = read_result_json(path)
    with _reading(path):
        return [_frf_section(files.stages["frf"], d, path)]


def _frf_section(root: Path, d: dict, path: Path) -> Section:
    fr = d["frf"]
    f = np.asarray(fr["frequencies_hz"], dtype=float)
    coh = np.asarray([np.nan if c is None else c for c in fr.get("coherence") or []], dtype=float)
    text = (f"FRF of {d['output']} over {d['input']} from {Path(str(d['file'])).name}: {f.size} excited lines "
            f"{fmt(f.min() if f.size else None, 4)}–{fmt(f.max() if f.size else None, 4)} Hz, {fr['estimator']} estimator"
            f"{' (closed loop)' if fr.get('closed_loop') else ''}, {fr.get('n_realisations')} realisation(s) × "
            f"{fr.get('n_periods')} period(s)")
    if d.get("period_s") is not None:
        text += f" of {fmt(d['period_s'])} s"
    text += f"; coherence min {fmt(np.nanmin(coh), 3) if coh.size and np.isfinite(coh).any() else 'n/a'}."
    dist = fr.get("distortion") or {}
    if dist.get("even") or dist.get("odd"):
        text += (f" Nonlinear distortion at the unexcited lines: even {fmt((dist.get('even') or {}).get('db'), 3)} dB, "
                 f"odd {fmt((dist.get('odd') or {}).get('db'), 3)} dB, noise {fmt(dist.get('noise_db'), 3)} dB "
                 "(relative to the output at the excited lines).")
    blocks = [Paragraph(text)]
    model = d.get("model")
    if model:
        rows = tuple((p, MEANING.get(p, ""), pm(e.get("value"), e.get("std")),
                      UNITS.get(p, "") if model.get("name") == "two_inertia" else "")
                     for p, e in model["params"].items())
        blocks.append(Paragraph(f"Fitted model {model['name']}: chi²/dof {fmt(model.get('chi2_red'), 3)} "
                                f"({fmt(model.get('chi2'), 4)} over {model.get('dof')} degrees of freedom)."))
        grav = d.get("gravity") or {}
        if "g_Nm_per_rad" in grav and model.get("name") == "two_inertia":
            how = ("fitted with the rest" if model.get("gravity_fitted")
                   else f"held: {grav.get('source', 'given')}")
            blocks.append(Paragraph(f"The link's gravity stiffness about its operating point g = "
                                    f"{pm(grav['g_Nm_per_rad'], grav.get('g_std_Nm_per_rad'))} N m/rad "
                                    f"({fmt(grav.get('share_of_k_pct'), 3)} % of k), {how}: the linear model without "
                                    "it would read it into k and I."))
        blocks.append(Table(("parameter", "meaning", "value ± SD", "unit"), rows))
    modes = d.get("modes") or []
    if modes:
        blocks.append(Table(("mode", "frequency (Hz)", "damping ratio"),
                            tuple((m["kind"], pm(m["f_hz"], m.get("f_hz_std")), pm(m["zeta"], m.get("zeta_std")))
                                  for m in modes)))
    cmp_ = d.get("comparison")
    if cmp_:
        text = (f"Against the time-domain identification of {cmp_['joint']} "
                f"({Path(str(cmp_.get('source', ''))).name}): {cmp_['verdict']}.")
        blocks.append(Note(text, "warn") if cmp_.get("disagree") else Paragraph(text))
        rows = []
        for p in cmp_["params"]:
            unit = UNITS.get(p["name"], "")
            if p["status"] == "not_compared":
                rows.append((p["name"], unit, pm(p["a"], p["a_std"]), pm(p["b"], p["b_std"]), "", "", p["reason"] or ""))
            else:
                rows.append((p["name"], unit, pm(p["a"], p["a_std"]), pm(p["b"], p["b_std"]), fmt(p["diff_pct"], 3),
                             fmt(p["z"], 2), p["status"]))
        rows += [(m["kind"], "Hz", fmt(m["f_hz_frf"], 5), fmt(m["f_hz_identify"], 5) + " (predicted)",
                  fmt(m["diff_pct"], 3), "", "") for m in cmp_.get("modes") or []]
        blocks.append(Table(("parameter", "unit", "FRF", "identify", "difference (%)", "in SDs", "verdict"),
                            tuple(rows)))
        blocks += [Paragraph(n[0].upper() + n[1:] + ".") for n in cmp_.get("notes") or []]
    csv = root / ((d.get("files") or {}).get("frf") or "frf.csv")
    if csv.is_file():
        c = read_columns(csv)
        mdl = c["model_real"] + 1j * c["model_imag"] if "model_real" in c else None
        unit = "rad/(N m)" if (model or {}).get("name") == "two_inertia" else "output unit per input unit"
        fd = np.geomspace(c["f_hz"].min() / 1.05, c["f_hz"].max() * 1.05, 800) if c["f_hz"].size else None
        dense = _model_curve(model, fd) if mdl is not None and fd is not None else None
        if dense is None:
            fd = None
        else:
            mdl = dense
        blocks.append(Figure("frf.png", F.frf_figure(c["f_hz"], c["magnitude"], c["phase_rad"], c.get("coherence"),
                                                     c.get("noise"), mdl, modes, unit, fd),
                             f"Frequency response {d['output']}/{d['input']}: magnitude with its ±2 SD band, phase and "
                             "coherence at the excited lines; the fitted model in red; vertical lines at the modes "
                             "(dotted: anti-resonance)."))
    return Section("frf", "Frequency response", tuple(blocks))


def _model_curve(model: dict | None, f_hz: np.ndarray) -> np.ndarray | None:
    """The fitted FRF model on a dense grid (mocapfj.ident.frf_fit / frf_single), or None when
    frf.json's model is not one of those (then the figure draws it at the lines)."""
    if not model:
        return None
    p = {n: e.get("value") for n, e in (model.get("params") or {}).items()}
    if any(v is None for v in p.values()):
        return None
    if model.get("name") == "two_inertia" and {"J", "I", "k"} <= set(p):
        from ..ident.frf_fit import two_inertia_frf

        return two_inertia_frf(f_hz, p["J"], p["I"], p["k"], p.get("d", 0.0), p.get("b", 0.0), p.get("v", 0.0),
                               output=model.get("output", "motor"), g=float(model.get("gravity_stiffness") or 0.0))
    if model.get("name") == "rational" and model.get("order") and model.get("w_norm"):
        from ..ident.frf_single import rational_frf

        nb, na = model["order"]
        if not all(f"b_{i}" in p for i in range(nb + 1)):
            return None
        b = [p[f"b_{i}"] for i in range(nb, -1, -1)]
        a = [p.get(f"a_{i}", 1.0 if i == na else None) for i in range(na, -1, -1)]
        if any(x is None for x in a):
            return None
        return rational_frf(f_hz, b, a, w_norm=model["w_norm"], tau=p.get("tau", 0.0))
    return None


# ---------------------------------------------------------------- discovery

def discovery_sections(files) -> list[Section]:
    if "discover" not in files.stages:
        return []
    root = files.stages["discover"]
    path = root / "discovery.json"
    d = read_result_json(path)
    with _reading(path):
        return _discovery(root, d, path)


def _fit_rows(d: dict) -> tuple:
    rows = []
    val = d.get("validation") or {}
    for joint, fb in (d.get("fits") or {}).items():
        for where, fits in (("trial", fb), ("validation", (val.get("fits") or {}).get(joint))):
            if not fits:
                continue
            b, a = fits["before"], fits.get("after") or fits["before"]
            rows.append((joint, where, pm(b["fit"], None), pm(a["fit"], None), f"{a['fit'] - b['fit']:+.3f}",
                         pm(a.get("floor"), a.get("floor_sd")), fmt(a.get("band_hz"), 3)))
    return tuple(rows)


def _discovery(root: Path, d: dict, path: Path) -> list[Section]:
    effects = d.get("effects") or []
    head = [Note(f"Verdict: {d.get('verdict')}. {str(d.get('stopped', '')).capitalize()}.",
                 "warn" if effects else "info"),
            Paragraph("Fit (%) of the simulated model against the recording: 100 (1 − sqrt((e_δ² + e_u²) / 2)), "
                      "e the normalised error ||y − ŷ|| / ||y − mean(y)|| of the deflection (δ) and of the motor "
                      "torque (u), in the band the model claims. The noise floor is the fit a perfect model would "
                      "reach on this recording (± its SD); the gap to it is what is left to explain.")]
    fr = _fit_rows(d)
    if fr:
        head.append(Table(("joint", "recording", "fit before (%)", "fit after (%)", "change (points)", "noise floor (%)",
                           "band (Hz)"), fr))
    out = [Section("discovery", "Discovery", tuple(head))]
    val_gain = {(e["name"], e["joint"]): e.get("fit_gain_pct") for e in (d.get("validation") or {}).get("effects", [])}
    loc = d.get("location") or {}
    for i, e in enumerate(effects):
        out.append(_effect_section(i, e, loc, val_gain))
    rej = d.get("rejected") or []
    if rej:
        out.append(Section("discovery/rejected", "Discovery", (
            Paragraph("Found significant in the equation error but not kept:"),
            Table(("effect", "joint", "reason"), tuple((r["name"], r["joint"], r.get("reason", "")) for r in rej))),
            subtitle="Effects tested and rejected"))
    reid = d.get("reidentified") or {}
    rrows = [(j, r.get("evidence", ""), pm(r.get("fit_nominal"), None), pm(r.get("fit_found"), None),
              pm(r.get("fit_reidentified"), r.get("fit_reidentified_sd")), str(r.get("adopted")))
             for j, r in reid.items() if isinstance(r, dict) and "error" not in r]
    if rrows:
        out.append(Section("discovery/reidentified", "Discovery", (
            Paragraph("The nominal parameters re-identified with the effects free, judged on held-out data: which "
                      "model is adopted."),
            Table(("joint", "evidence", "fit nominal (%)", "fit with the effects (%)", "fit re-identified (%)",
                   "adopted"), tuple(rrows))), subtitle="Re-identification"))
    res = root / "residuals.csv"
    if res.is_file():
        out += _residual_sections(res, d, loc)
    return out


def _effect_section(i: int, e: dict, loc: dict, val_gain: dict) -> Section:
    name, joint = e["name"], e["joint"]
    L = e.get("location") or {}
    blocks = [Paragraph(e.get("explanation") or "")]
    where = [("signal", str(L.get("signal", ""))), ("where", str(L.get("where", L.get("found_by", ""))))]
    windows = ((loc.get(joint) or {}).get(L.get("residual", "spring")) or {}).get("worst_windows") or []
    if windows:
        where.append(("located windows (largest residual)",
                      ", ".join(f"{fmt(w['t_start_s'])}–{fmt(w['t_end_s'])} s" for w in windows)))
    where.append(("p-value", fmt(e.get("p_value"), 3)))
    where.append(("fit gain on this recording", f"{fmt(e.get('fit_gain_pct'), 3)} points"))
    for label, h in (L.get("held_out") or {}).items():
        where.append((f"held-out gain ({label})", pm(h.get("gain_points"), h.get("sd_points")) + " points"))
    if val_gain.get((name, joint)) is not None:
        where.append(("fit gain on the validation recording", f"{fmt(val_gain[(name, joint)], 3)} points"))
    blocks.append(Table(("where / evidence", "value"), tuple(where)))
    params = e.get("parameters") or {}
    if params:
        blocks.append(Table(("parameter", "value", "unit"), tuple((p, fmt(v, 5), UNITS.get(p, "")) for p, v in
                                                                  params.items() if not p.endswith("_std"))))
    cands = L.get("candidates") or []
    if cands:
        blocks.append(Paragraph("Candidates compared on held-out data (the gain in fit points ± SD):"))
        blocks.append(Table(("candidate", "held-out gain (points)", "admissible"),
                            tuple((c["name"], pm(c.get("held_out_gain_points"), c.get("held_out_gain_sd_points")),
                                   "yes" if c.get("admissible") else "no") for c in cands),
                            tuple("good" if c["name"] == name else "" for c in cands)))
    blocks.append(Paragraph(f"Residuals before and after: see the figure for joint {joint} below."))
    return Section(f"discovery/{i}", "Discovery", tuple(blocks), subtitle=f"Effect {i + 1}: {name} on joint {joint}")


def _residual_sections(res: Path, d: dict, loc: dict) -> list[Section]:
    c = read_columns(res)
    t = c.get("t")
    if t is None:
        raise InputError(res, "t", "a time column t (s)", "missing")
    out = []
    joints = sorted({k.split("_r_")[0] for k in c if "_r_" in k})
    for joint in joints:
        chans = []
        for key, label, unit, scale in (("delta", "deflection residual", "mrad", 1e3),
                                        ("u", "torque residual", "N m", 1.0)):
            b, a = c.get(f"{joint}_r_{key}_before"), c.get(f"{joint}_r_{key}_after")
            if b is not None and a is not None:
                chans.append((label, unit, scale, b, a))
        if not chans:
            continue
        names = [e["name"] for e in d.get("effects") or [] if e["joint"] == joint]
        res_key = next((e.get("location", {}).get("residual") for e in d.get("effects") or []
                        if e["joint"] == joint), "spring")
        windows = [(w["t_start_s"], w["t_end_s"]) for w in
                   ((loc.get(joint) or {}).get(res_key or "spring") or {}).get("worst_windows") or []]
        band = (((d.get("fits") or {}).get(joint) or {}).get("after") or {}).get("band_hz")
        title = f"joint {joint}: residuals " + (f"before and after {', '.join(names)}" if names else "(no effect added)")
        rms = [(lab, np.sqrt(np.nanmean((s * b) ** 2)), np.sqrt(np.nanmean((s * a) ** 2)), u)
               for lab, u, s, b, a in chans]
        out.append(Section(f"discovery/residuals/{joint}", "Discovery", (
            Paragraph("RMS over the whole recording (unfiltered): " + "; ".join(
                f"{lab} {fmt(rb, 4)} → {fmt(ra, 4)} {u}" for lab, rb, ra, u in rms) + "."),
            Figure(f"discover_{_slug(joint)}_residuals.png", F.residuals_figure(t, chans, windows, title, band),
                   f"Joint {joint}: the simulated model's residuals (recording minus model) before (grey) and after "
                   f"(blue) the effects were added, low-passed to the fit's band; shaded: the windows where the "
                   f"residual was largest.")), subtitle=f"Residuals of joint {joint}"))
    return out
