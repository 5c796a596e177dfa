"""``mocapfj COMMAND ...``: argument parsing only; the work is in mocapfj.pipeline.

Every command reads paths, writes into ``--out DIR`` (inputs are never modified, files are
written atomically), prints a short human summary, and with ``--json`` prints one JSON object on
stdout. Bad input: one line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from . import __version__
from .errors import InputError
from .io import to_jsonable

IDENTIFY_METHODS = ("output_error", "motor_first", "two_step")   # mocapfj.ident.IDENTIFY_METHODS (not imported here)

def _work(args):
    """Where a command writes: the staging directory main() made beside --out."""
    return getattr(args, "stage", None) or args.out


def _inputs(args) -> list:
    """The paths a command reads (that --out must keep clear of)."""
    out = []
    for name in ("scenario", "recording", "model", "validation", "board", "wand", "detections", "intrinsics", "lframe",
                 "csv", "wrench_file", "urdf", "mdh", "compare"):
        if getattr(args, name, None):
            out.append(getattr(args, name))
    views = [p for paths in (getattr(args, "camera", None) or []) for p in paths]
    if args.command == "triangulate":
        views += [args.rig] + list(args.inputs) + list(args.clusters or [])
    return out + list(getattr(args, "recordings", None) or []) + list(getattr(args, "images", None) or []) + views


def _emit(args, summary: dict, human: Callable[[dict], str]) -> None:
    if getattr(args, "json", False):
        print(json.dumps(to_jsonable(summary), allow_nan=False))
    else:
        print(human(summary))


def _human_recording(s: dict) -> str:
    m, c = s.get("markers"), s.get("controller")
    lines = []
    if s.get("name"):
        lines.append(f"recording {s['name']}")
    if m is not None:
        lines.append(f"  markers    {m['file']}: {m['n_markers']} markers x {m['n_frames']} frames at "
                     f"{m['rate_hz']:.6g} Hz, {m['missing_pct']:.1f} % missing")
    elif s.get("markers_from_cameras"):
        lines.append(f"  markers    from {s['rig_cameras']} cameras: {s['detections']} 2D detections, triangulated by "
                     "'mocapfj run'")
    elif "controller" in s:
        lines.append("  markers    none (a controller log only: a rigid robot)")
    if c is not None:
        lines.append(f"  controller {c['file']}: {c['n_samples']} samples at {c['rate_hz']:.6g} Hz, "
                     f"{c['t_start_s']:.3f}..{c['t_end_s']:.3f} s (clock offset {s['clock_offset_s']} s)")
        if c.get("time_note"):
            lines.append(f"             {c['time_note']}")
    elif "controller" in s:
        lines.append("  controller none (markers only: axes and angles, no deflection)")
    for j in s["joints"]:
        parent = j["parent_markers"] if isinstance(j["parent_markers"], str) else ", ".join(j["parent_markers"])
        parts = [f"  joint {j['name']}:"]
        if j["link_markers"]:
            missing = ("" if j["link_markers_missing_pct"] is None
                       else f" ({j['link_markers_missing_pct']:.1f} % missing)")
            parts.append(f"link markers {', '.join(j['link_markers'])}{missing}, "
                         f"parent {parent}" + ("," if j["q_m_range_rad"] is not None else ""))
        if j["q_m_range_rad"] is not None:
            parts.append(f"q_m {j['q_m_range_rad'][0]:+.3f}..{j['q_m_range_rad'][1]:+.3f} rad, "
                         f"tau rms {j['tau_rms_Nm']:.3g} N m")
        lines.append(" ".join(parts))
    return "\n".join(lines)


def _cmd_demo(args) -> int:
    from .pipeline import run_demo

    s = run_demo(_work(args), duration_s=args.duration, progress=_progress(args))

    def human(s):
        r, p = s["rig"], s["planted"]
        lines = [f"demo: {s['duration_s']:g} s of PA-10 joint 2 through {r['n_cameras']} cameras, planted "
                 + ", ".join(f"{e['name']} on {e['joint']} ({e['ratio']:.2f} x the noise SD"
                             + (", concealed)" if e["concealed"] else ")") for e in p),
                 f"  rig from a wand wave: reprojection RMS {r['reprojection_rms_px']:.3f} px, wand length SD "
                 f"{r['wand_length_sd_mm']:.2f} mm, camera centres within {r['camera_centre_error_max_mm']:.1f} mm "
                 "of the truth"]
        lines.append(_human_run_stages(s["run"]))
        for j in s.get("joints_fit", []):
            lines.append(f"  {j['name']}: deflection through the cameras within {j['deflection_error_rms_rad'] * 1e3:.3f} "
                         f"mrad RMS of the truth (Cramer-Rao bound {j['deflection_error_bound_rad'] * 1e3:.3f} mrad)")
        if "found" in s:
            named = ", ".join(f"{e['name']} on {e['joint']}" for e in s["found"]) or "nothing"
            lines.append(f"  discovery named: {named}; planted effects named: {', '.join(s['named_planted']) or 'none'}")
            for j, f in s["fits"].items():
                v = (s.get("validation") or {}).get("fit_before", {}).get(j), (s.get("validation") or {}).get("fit_after", {}).get(j)
                lines.append(f"  {j}: fit {f['before']:.2f} % -> {f['after']:.2f} %"
                             + (f"; on the validation trial {v[0]:.2f} % -> {v[1]:.2f} %" if v[0] is not None else ""))
        failed = s["run"]["failed"]
        if failed:
            lines.append(f"  the demo stopped: stage {failed} failed (above); {args.out}/demo.json says how far it got")
        else:
            lines.append(f"  {s['timings_s']['total_s']:.0f} s; " + _where_to_look(Path(args.out) / "run")
                         + f"; summary {args.out}/demo.json")
        return "\n".join(lines)

    _emit(args, s, human)
    return 1 if s["run"]["failed"] else 0


def _progress(args):
    """Progress on stderr (stdout stays the summary, or with --json one JSON object): on a terminal
    a bar over run's stages with the stage at work, each finished stage's line above it; else the
    lines alone (logs, CI)."""
    import re

    if not sys.stderr.isatty():
        return lambda line: print(line, file=sys.stderr, flush=True)
    from tqdm import tqdm

    bar = None

    def say(line: str) -> None:
        nonlocal bar
        m = re.match(r"\[(\d+)/(\d+)\] (\S+)(.*)", line)
        if m is None:
            if bar is not None:
                bar.write(line, file=sys.stderr)
            else:
                print(line, file=sys.stderr, flush=True)
            return
        k, n, name, rest = int(m[1]), int(m[2]), m[3], m[4]
        if bar is None:
            bar = tqdm(total=n, desc="mocapfj run", unit="stage", file=sys.stderr, leave=False,
                       bar_format="{desc} {n_fmt}/{total_fmt} stages |{bar}| {elapsed}")
        if rest == " ...":
            bar.set_description(f"mocapfj run: {name}")
            return
        bar.write(line, file=sys.stderr)
        bar.n = k
        bar.refresh()
        if k == n:
            bar.close()
            bar = None
    return say


def _human_run_stages(s: dict) -> str:
    lines = []
    for st in s["stages"]:
        if st["status"] in ("done", "skipped"):
            what = f"done in {st['seconds']:.1f} s" if st["status"] == "done" else "inputs unchanged, kept"
            lines.append(f"  {st['name']:<12} {what}")
        elif st["status"] == "failed":
            lines.append(f"  {st['name']:<12} FAILED: {st['error']}")
        else:
            lines.append(f"  {st['name']:<12} {st['status'].replace('_', ' ')}: {st.get('reason') or ''}")
    return "\n".join(lines)


def _where_to_look(out) -> str:
    """The closing line of run and demo: the report, the recording, else the results."""
    out = Path(out)
    look = [str(out / f) for f in ("report.html", "recording.rrd") if (out / f).is_file()]
    if not look:
        return f"results in {out}/<stage>/ (run.json lists them)"
    return "look at " + " and ".join(look) + (f" ('mocapfj view {out}' opens the recording)"
                                               if (out / "recording.rrd").is_file() else "")


def _cmd_run(args) -> int:
    from .pipeline.run import STAGES, run_pipeline

    stages = None
    if args.stages:
        stages = [x.strip() for x in args.stages.split(",") if x.strip()]
        bad = [x for x in stages if x not in STAGES]
        if bad:
            raise InputError("--stages", "names", f"stages among {', '.join(STAGES)}", ", ".join(bad))
    r = run_pipeline(args.recording, args.out, validation=args.validation, stages=stages,
                     progress=_progress(args), force=args.force)
    s = r.to_dict()

    def human(s):
        lines = [f"run of {s['recording']}" + (f" (validation {s['validation']})" if s["validation"] else ""),
                 _human_run_stages(s)]
        if s["failed"]:
            lines.append(f"  stage {s['failed']} failed; the stages before it are in {args.out}; fix the input and "
                         "run again: finished stages whose inputs did not change are kept")
        else:
            lines.append("  " + _where_to_look(args.out))
        return "\n".join(lines)

    _emit(args, s, human)
    return 1 if r.failed else 0


def _human_simulate(s: dict, out) -> str:
    lines = [_human_recording(s), f"  scenario {s['scenario']}: {s['duration_s']:g} s simulated in "
             + ", ".join(f"{k} {v:.1f} s" for k, v in s["timings_s"].items())]
    for j in s["truth"]["joints"]:
        lines.append(f"  truth {j['name']}: angle CRLB {j['angle_sigma_rad'] * 1e3:.3f} mrad, deflection noise SD "
                     f"{j['deflection_noise_sd_rad'] * 1e3:.3f} mrad")
    for e in s["effects"]:
        if "ratio" in e:
            lines.append(f"  effect {e['name']} on {e['joint']}: deflection RMS {e['deflection_rms_rad'] * 1e3:.3f} mrad "
                         f"= {e['ratio']:.2f} x noise SD ({'concealed' if e['concealed'] else 'VISIBLE'})")
        else:
            lines.append(f"  effect {e['name']} on {e['joint']}")
    lines.append(f"  wrote {out} (bundle, truth.json, truth.csv, truth_mocap.csv"
                 + (f", {s['images']} images" if s.get("images") else "") + ")")
    return "\n".join(lines)


def _cmd_simulate(args) -> int:
    from .pipeline import run_simulate

    s = run_simulate(args.scenario, _work(args), duration_s=args.duration, concealment=not args.no_concealment,
                     images=args.images)
    _emit(args, s, lambda s: _human_simulate(s, args.out))
    return 0


def _cmd_joints(args) -> int:
    from .pipeline import run_joints

    s = run_joints(args.recording, _work(args), method=args.method)

    def human(s):
        lines = [f"recording {s['recording']}: joint geometry ({s['method']})"]
        for j in s["joints"]:
            lines.append(
                f"  joint {j['name']} ({j['method']}): axis [{', '.join(f'{x:+.4f}' for x in j['axis'])}], point "
                f"[{', '.join(f'{x:.4f}' for x in j['point_m'])}] m (parent frame), radii "
                f"{', '.join(f'{r:.1f}' for r in j['radii_mm'])} mm (RMS {max(j['radius_rms_mm']):.2f} mm), "
                f"marker RMS {j['angle_marker_rms_mm']:.2f} mm in the angle solve")
            if j["axis_world"] is not None:
                lines.append(f"    in the world: axis [{', '.join(f'{x:+.4f}' for x in j['axis_world'])}], point "
                             f"[{', '.join(f'{x:.4f}' for x in j['point_world_m'])}] m")
            line = (f"    angle SD {j['angle_sigma_rad'] * 1e3:.3f} mrad over {j['q_range_deg']:.1f} deg, "
                    f"{j['n_frames']} frames ({j['n_frames_invalid']} without an angle)")
            if j["deflection_rms_rad"] is not None:
                line += f", deflection RMS {j['deflection_rms_rad'] * 1e3:.3f} mrad"
            lines.append(line)
            for key, rep in (j.get("marker_repairs") or {}).items():
                parts = [f"{'/'.join(w['labels'])} exchanged in {w['frames']} frames from t = {w['from_s']:.3f} s"
                         for w in rep["swaps"]]
                parts += [f"{n} samples of {m} off the cluster removed" for m, n in rep["removed"].items()]
                lines.append(f"    {key} markers repaired: " + "; ".join(parts))
            if "note" in j:
                lines.append(f"    {j['note']}")
        lines.append(f"  wrote {args.out} (<joint>.joint.toml, <joint>.angles.csv, joints.json)")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _cmd_identify(args) -> int:
    from .pipeline import run_identify

    s = run_identify(args.recordings, _work(args), method=args.method, cutoff_hz=args.cutoff, decimate=args.decimate,
                     validation=args.validation, fit_clock_offset=args.fit_clock_offset)

    def human(s):
        lines = [f"identified {len(s['recordings'])} recording(s)"]
        if "rigid" in s:
            r = s["rigid"]
            lines.append(f"  rigid robot (URDF): {len(r['base_params'])} base parameters, friction {r['friction']}, "
                         f"cond {r['cond']:.3g}, torque RMS {r['torque_rms']:.3g} N m"
                         + (f", {r['n_resampled']} samples resampled" if r["n_resampled"] else ""))
            for n, v in r["base_params"].items():
                lines.append(f"    {n} = {v['value']:.6g} +- {v['std']:.2g}")
            if "validation" in s:
                lines.append("  validation torque RMS: " + ", ".join(f"{j} {v:.3g} N m" for j, v in s["validation"].items()))
        for j in s["joints"]:
            p = j.get("params")
            if not p:
                continue
            lines.append(f"  joint {j['name']} ({j['n_trials']} trial(s)): " + ", ".join(
                f"{n} {p[n]['value']:.4g}" + ("" if p[n].get("determined", True) else " (not determined)")
                for n in ("I", "mglx", "mgly", "c", "v", "J", "b", "k") if n in p))
            cond = (f", cond two-step {j['cond_two_step']:.0f} vs one-step {j['cond_one_step']:.0f}"
                    if "cond_two_step" in j else "")
            lines.append(f"    method {j['method']}, spring {j['spring']['model']}{cond}, torque RMS "
                         f"{j['torque_rms']:.3g} N m, {j['frames_filled']} angle frames filled")
            clk = j.get("clock_offset") or {}
            if clk.get("found"):
                lines.append(f"    clock offset: the mocap {abs(clk['offset_s']) * 1e3:.3g} +- {clk['sd_s'] * 1e3:.2g} ms "
                             f"{'behind' if clk['offset_s'] > 0 else 'ahead of'} the controller log (chi-square "
                             f"{clk['chi2']:.0f}), " + ("applied (--fit-clock-offset)" if clk["applied"] else
                                                       "not declared: what it moves is flagged below"))
            for n, why in j.get("not_determined", {}).items():
                lines.append(f"    {n} not determined: {why}")
        if "nlink" in s:
            nl = s["nlink"]
            lines.append(f"  links (URDF, {len(nl['base_params'])} base parameters, cond {nl['cond']:.0f}, torque RMS "
                         f"{nl['torque_rms']:.3g} N m): " + ", ".join(
                             f"{n} = {v['value']:.4g}" for n, v in nl["base_params"].items()))
        lines.append(f"  wrote {args.out}/identify.json, table.md, table.csv")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _with_sds_text(params: dict, sds: dict) -> str:
    """"name value +- SD" for each parameter with an SD (list-valued ones item by item)."""
    out = []
    for k, sd in sds.items():
        v = params.get(k)
        if isinstance(sd, list) and isinstance(v, list):
            out.append(f"{k} " + ", ".join(f"{a:.4g} +- {b:.2g}" for a, b in zip(v, sd)))
        elif isinstance(v, (int, float)):
            out.append(f"{k} {v:.4g} +- {sd:.2g}")
    return "; ".join(out)


def _cmd_discover(args) -> int:
    from .pipeline import run_discover

    s = run_discover(args.recording, _work(args), model=args.model, validation=args.validation)

    def human(s):
        lines = [f"discover {s['recording']} against {s['model']}: {s['verdict']}"]
        for e in s["effects"]:
            lines.append(f"  {e['name']} on {e['joint']} (p = {e['p_value']:.1e}, fit {e['fit_gain_pct']:+.2f} %): "
                         f"{e['explanation']}")
            if e.get("parameter_sds"):
                lines.append("    parameters +- SD (the trial's noise, the effect's form and the other parameters "
                             "given): " + _with_sds_text(e["parameters"], e["parameter_sds"]))
            for name, why in (e.get("not_determined") or {}).items():
                lines.append(f"    {name} not determined: {why}")
        for j in s["fit_before"]:
            f = s["fits"][j]["after"]
            smoothed = (f"; markers smoothed before export, corner about {f['markers_smoothed_hz']:.3g} Hz"
                        if f.get("markers_smoothed_hz") else "")
            line = (f"  {j}: fit {s['fit_before'][j]:.2f} % -> {s['fit_after'][j]:.2f} % (noise floor {f['floor']:.2f} %, "
                    f"below {f['band_hz']:.3g} Hz{smoothed})")
            if s["validation"] and j in s["validation"]["fit_before"]:
                v = s["validation"]
                line += (f"; validation {v['fit_before'][j]:.2f} % -> {v['fit_after'][j]:.2f} % "
                         f"(floor {v['fits'][j]['after']['floor']:.2f} %)")
            lines.append(line)
            r = s.get("reidentified", {}).get(j)
            if r and "error" not in r:
                line = (f"  {j} re-identified, nominal parameters free (on the {r['evidence']}): fit "
                        f"{r['fit_nominal']:.2f} % nominal, {r['fit_reidentified']:.2f} % re-identified")
                if "fit_with_effects" in r:
                    line += f", {r['fit_with_effects']:.2f} % with {', '.join(e['name'] for e in r['effects'])}"
                lines.append(line + f"; adopted: {r['adopted']}")
                c = r.get("clock_equivalent")
                if c:
                    lines.append(f"  note: {j}'s viscous friction moved {c['v_change_pct']:+.0f} % ({c['v_sds']:+.1f} SD) "
                                 f"from the nominal: what a clock offset of {1e3 * c['offset_s']:+.2f} ms between the "
                                 "mocap and the controller log would do (v ~ k dt; only the torque tells them apart, "
                                 "and output error reports no offset below 1 ms): check the synchronisation before "
                                 "reading it as friction")
            elif r:
                lines.append(f"  {j}: {r['error']}")
        lines.append(f"  wrote {args.out}/discovery.json, model.toml, residuals.csv")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _cmd_calibrate_camera(args) -> int:
    from .pipeline.calibrate import run_calibrate_camera

    s = run_calibrate_camera(args.images, args.board, _work(args), model=args.model, name=args.name,
                             every=args.every, progress=not args.json)

    def human(s):
        sd = s["std"]
        lines = [f"camera {s['camera']} ({s['image_size'][0]} x {s['image_size'][1]} px, {s['model']} distortion): "
                 f"{s['n_views_used']} of {s['n_views']} views used, {s['n_points']} features, RMS {s['rms_px']:.3f} px",
                 f"  fx {s['fx']:.2f} +- {sd['fx']:.2f}  fy {s['fy']:.2f} +- {sd['fy']:.2f}  cx {s['cx']:.2f} +- "
                 f"{sd['cx']:.2f}  cy {s['cy']:.2f} +- {sd['cy']:.2f} px",
                 "  dist " + ", ".join(f"{n} {v:+.5f} +- {sd[n]:.1e}" for n, v in zip(s["dist_names"], s["dist"])),
                 f"  image coverage {s['coverage_pct']:.0f} % of cells"]
        lines += [f"  warning: {w}" for w in s["warnings"]]
        lines.append(f"  wrote {args.out} ({', '.join(s['files'].values())})")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _cmd_calibrate_rig(args) -> int:
    from .pipeline.calibrate import run_calibrate_rig

    s = run_calibrate_rig(_work(args), board=args.board, cameras=args.camera, wand=args.wand,
                          detections=args.detections, intrinsics=args.intrinsics, lframe=args.lframe,
                          refine_intrinsics=args.refine_intrinsics, every=args.every, progress=not args.json)

    def human(s):
        head = (f"rig of {len(s['cameras'])} cameras from {'board views' if s['method'] == 'board' else 'a wand wave'}: "
                f"RMS {s['rms_px']:.3f} px (start {s['initial_rms_px']:.2f} px), residual SD {s['sigma_px']:.3f} px, "
                f"intrinsics refined: {', '.join(s['refined_intrinsics']) or 'none'}")
        lines = [head]
        if s["method"] == "wand":
            lines.append(f"  wand length {s['wand_length_mean_mm']:.3f} mm (nominal {s['wand_length_mm']:.1f}), SD "
                         f"{s['wand_length_sd_mm']:.3f} mm over {s['n_wand_lengths']} frames; world: {s['world']}"
                         + (f" (L-frame fit {s['lframe_rms_mm']:.2f} mm RMS)" if s.get("lframe_rms_mm") is not None else ""))
        for c in s["cameras"]:
            pos = ", ".join(f"{x:+.4f}" for x in c["position_m"])
            sd = ", ".join(f"{x * 1000:.2f}" for x in c["position_std_m"])
            extra = f", {c['rms_mm']:.2f} mm" if "rms_mm" in c else ""
            lines.append(f"  {c['name']}: RMS {c['rms_px']:.3f} px{extra}, {c['n_observations']} points "
                         f"({c['n_outliers']} outliers), centre [{pos}] m +- [{sd}] mm, fx {c['fx']:.2f}"
                         + (f" +- {c['std']['fx']:.2f}" if "fx" in c["std"] else "") + " px")
        lines.append(f"  wrote {args.out} ({', '.join(s['files'].values())})")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _cmd_triangulate(args) -> int:
    from .pipeline.triangulate import run_triangulate

    s = run_triangulate(args.inputs, args.rig, _work(args), clusters=args.clusters, rate_hz=args.rate,
                        sigma_px=args.sigma_px, max_gap_s=args.max_gap, progress=not args.json)

    def human(s):
        rms = s["reprojection_rms_px"]
        lines = [f"{len(s['labels'])} markers x {s['n_frames']} frames at {s['rate_hz']:.6g} Hz from {s['n_cameras']} cameras: "
                 f"{s['points_per_frame']:.1f} points per frame, reprojection RMS "
                 + (f"{rms:.3f} px" if rms is not None else "n/a") + f", {100 * s['nan_share']:.1f} % NaN",
                 f"  {s['n_unseen']} points seen by fewer than 2 cameras, {s['n_rejected']} rejected by the robust "
                 f"views, {s['n_nonfinite_ignored']} non-finite detections ignored",
                 f"  {s['gaps_filled']} samples filled from the rigid fit, {s['swaps_repaired']} swaps repaired, "
                 f"{s.get('n_long_gaps', 0)} gaps left open"]
        lines.append(f"  wrote {args.out} ({', '.join(s['files'].values())})")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _cmd_inspect(args) -> int:
    from .pipeline import inspect_path

    _emit(args, inspect_path(args.recording), _human_recording)
    return 0


def _cmd_batch(args) -> int:
    from .pipeline.batch import run_batch

    def progress(line):
        print(line, file=sys.stderr, flush=True)

    stages = None if args.stages is None else [x.strip() for x in args.stages.split(",") if x.strip()]
    r = run_batch(args.recordings, _work(args), method=args.method, stages=stages, scheduler=args.scheduler,
                  workers=args.workers, progress=progress)
    s = r.to_dict()
    s["trials"] = [{k: t[k] for k in ("name", "group", "status", "stage", "error", "seconds")} for t in s["trials"]]

    def human(s):
        lines = [f"batch of {s['n_recordings']} recording(s): {s['n_done']} done, {s['n_failed']} failed "
                 f"({s['cluster']}, {s['seconds']:.1f} s)"]
        for row in s["table"]:
            if row["parameter"] == "torque_rms":
                continue
            cv = "" if row["n"] < 2 else f" +- {row['sd']:.3g} (CV {row['cv_pct']:.2f} %)"
            lines.append(f"  {row['group']} {row['joint']} {row['parameter']}: {row['mean']:.5g}{cv} over "
                         f"{row['n']} trial(s)" + ("" if row["determined"] else " (not determined)"))
        for f in s["failed"]:
            lines.append(f"  FAILED {f['name']} at {f['stage']}: {f['error']}")
        lines.append(f"  wrote {args.out} (a run directory per recording, batch.json, batch.csv, trials.csv, "
                     "batch.md)")
        return "\n".join(lines)

    _emit(args, s, human)
    return 1 if r.failed else 0


def _allow_outside_bundle(parser) -> None:
    parser.add_argument("--allow-outside-bundle", action="store_true",
                        help="read files that recording.toml names outside its bundle (../, absolute paths, symlinks)")


def _cmd_algebraic(args) -> int:
    from .pipeline.algebraic import run_algebraic

    s = run_algebraic(args.csv, _work(args), output=args.output, input=args.input, time=args.time, start=args.start,
                      duration=args.duration, window=args.window, offset=not args.no_offset, inertia=args.inertia,
                      damping=args.damping)

    def human(s):
        j = s["joints"][0]
        lines = [f"{j['name']} over {j['segment_s'][0]:.4g}..{j['segment_s'][1]:.4g} s"]
        for key in ("algebraic", "log_decrement"):
            e = j.get(key)
            if e is None:
                continue
            if "error" in e:
                lines.append(f"  {key}: not available ({e['error']})")
                continue
            line = (f"  {key}: f0 {e['f0_hz']:.4g} +- {e['f0_hz_std']:.2g} Hz (omega0 {e['omega0']:.5g} rad/s), "
                    f"zeta {e['zeta']:.4g} +- {e['zeta_std']:.2g}, fit {e['fit_pct']:.1f} %")
            if "stiffness" in e:
                line += f", K {e['stiffness']:.5g} +- {e['stiffness_std']:.2g} N m/rad"
            lines.append(line)
        if "note" in j:
            lines.append(f"  note: {j['note']}")
        if "agree" in j:
            lines.append(f"  the two estimates {'agree' if j['agree'] else 'DISAGREE'} (omega0 "
                         f"{j['agreement_sd']['omega0']:+.1f} SD, zeta {j['agreement_sd']['zeta']:+.1f} SD)")
        if "sliding" in j:
            sl = j["sliding"]
            lines.append(f"  sliding {sl['window_s'] * 1e3:.0f} ms windows ({sl['n_valid']} of {sl['n_windows']}): "
                         f"f0 {sl['f0_hz_median']:.4g} Hz, zeta {sl['zeta_median']:.4g} (median)")
        lines.append(f"  wrote {args.out}/algebraic.json" + (", sliding.csv" if "sliding" in j else ""))
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _cmd_precompensate(args) -> int:
    from .pipeline.algebraic import run_precompensate

    s = run_precompensate(args.csv, _work(args), reference=args.reference, time=args.time, omega0=args.omega0,
                          zeta=args.zeta, model=args.model, iterations=args.iterations, damping=args.damping,
                          method=args.method)

    def human(s):
        warn = ("\n  the reference has content near the resonance, which eq. 17 amplifies: --method inverse, or a "
                "jerk-limited reference" if s["predicted_peak_ratio"] < 1 else "")
        return (f"pre-compensated {s['reference']} ({s['method']}, omega0 {s['omega0']:.5g} rad/s, zeta {s['zeta']:.4g}): "
                f"the model's link error {s['predicted_peak_before']:.3g} -> {s['predicted_peak_after']:.3g} rad peak "
                f"({s['predicted_peak_ratio']:.1f}x){warn}\n  wrote {args.out}/command.csv, precompensate.json")

    _emit(args, s, human)
    return 0


def _cmd_control_check(args) -> int:
    from .pipeline.control_check import run_control_check

    s = run_control_check(args.model, plant=args.plant, joint=args.joint, q0=args.q0, amplitudes=args.amplitudes,
                          frequencies=args.frequencies, ramp=args.ramp, duration=args.duration,
                          bandwidth=args.bandwidth, zeta=args.zeta, rate=args.rate)

    def human(s):
        lines = [f"computed-torque tracking, joint {s['joint']} of {s['plant']} ({s['duration_s']:g} s, "
                 f"{s['rate_hz']:g} Hz, kp {s['kp']:.4g}, kd {s['kd']:.4g}), feedforward from {s['model']}:"]
        for r in s["runs"]:
            lines.append(f"  {r['name']:<9} link error RMS {1e3 * r['rms_rad']:.4g} mrad, max {1e3 * r['max_rad']:.4g} "
                         f"mrad, feedback share {r['feedback_share']:.3f}")
        lines.append(f"  rigid / flexible: RMS {s['ratio_rms']:.2f}x, max {s['ratio_max']:.2f}x")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _cmd_clamped(args) -> int:
    from .pipeline.clamped import run_clamped

    s = run_clamped(args.csv, _work(args), positions=args.positions, torques=args.torques, wrench=args.wrench,
                    wrench_file=args.wrench_file, time=args.time, urdf=args.urdf, mdh=args.mdh, frame=args.frame,
                    joints=args.joints, cutoff=args.cutoff, decimate_cutoff=args.decimate_cutoff)

    def human(s):
        lines = [f"clamped end-effector stiffness from {s['file']}"]
        for j in s["joints"]:
            for key in ("motor_torque", "wrench"):
                if key in j:
                    f = j[key]
                    lines.append(f"  {j['name']} by {key.replace('_', ' ')}: k {f['k']:.4g} N m/rad "
                                 f"({f['k_rel_std_pct']:.2g} %), offset {f['offset']:.4g} N m, "
                                 f"|W chi - Y| / |Y| {f['rel_error_pct']:.3g} %")
            if "rel_diff_pct" in j:
                lines.append(f"  {j['name']}: the two differ by {j['rel_diff_pct']:.3g} % ({j['diff_sd']:.1f} SD)")
        lines += [f"  note: {n}" for n in s.get("notes", [])]
        lines.append(f"  wrote {args.out}/clamped.json, table.md")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _cmd_frf(args) -> int:
    import statistics

    from .pipeline.frf import run_frf

    s = run_frf(args.recording, _work(args), input=args.input, output=args.output, reference=args.reference,
                time=args.time, period_s=args.period,
                model=args.model or ("rational" if args.single_record else "two_inertia"), transient=args.transient,
                realisations=args.realisations, estimator=args.estimator, single_record=args.single_record,
                order=args.order, steady_period=args.steady_period, compare=args.compare, joint=args.joint,
                gravity_stiffness=args.gravity_stiffness)

    def human(s):
        f = s["frf"]
        fr = f["frequencies_hz"]
        if s.get("single_record"):
            lines = [f"FRF {s['output']} / {s['input']} from {s['file']}: {len(fr)} lines {fr[0]:.4g}-{fr[-1]:.4g} Hz, "
                     f"one record, local polynomial method ({f['lpm']['dof']} degrees of freedom per line), "
                     f"coherence median {statistics.median(f['coherence']):.3f}"]
        else:
            lines = [f"FRF {s['output']} / {s['input']} from {s['file']}: {len(fr)} lines {fr[0]:.4g}-{fr[-1]:.4g} Hz, "
                     f"{f['estimator']} estimator, {f['n_realisations']} realisation(s) x {f['n_periods']} periods of "
                     f"{s['period_s']:.6g} s, coherence min {min(f['coherence']):.3f}"]
        d = f["distortion"]
        parts = [f"{k} {d[k]['db']:.1f} dB" + (" (above the noise)" if d[k]["detected"] else "")
                 for k in ("even", "odd") if d[k]["db"] is not None]
        if not s.get("single_record"):
            lines.append("  distortion at the detection lines: " + (", ".join(parts) + f", noise {d['noise_db']:.1f} dB"
                                                                   if parts else "no unexcited line in the band"))
        if s["model"]:
            m = s["model"]
            g = s.get("gravity") or {}
            if "g_Nm_per_rad" in g:
                lines.append(f"  gravity stiffness {g['g_Nm_per_rad']:.4g} +- {g.get('g_std_Nm_per_rad', 0):.2g} N m/rad "
                             f"({g.get('share_of_k_pct', 0):+.2f} % of k), {g['source']}")
            # a parameter at its bound (0) prints as 0, not as the optimiser's 1e-31
            lines.append(f"  {m['name']}: " + ", ".join(
                f"{n} {p['value'] if abs(p['value']) > 1e-9 * p['std'] else 0.0:.4g} +- {p['std']:.2g}"
                for n, p in m["params"].items()) + f" (chi2/dof {m['chi2_red']:.2f})")
            for md in s["modes"]:
                lines.append(f"  {md['kind']} {md['f_hz']:.4g} +- {md['f_hz_std']:.2g} Hz, zeta {md['zeta']:.3g} +- "
                             f"{md['zeta_std']:.2g}")
        lines += [f"  note: {n}" for n in s.get("notes", [])]
        c = s.get("comparison")
        if c:
            lines.append(f"  against the time-domain identification of {c['joint']} ({c['source']}): {c['verdict']}")
            lines += [f"    {line}" for line in c["lines"]]
            lines += [f"    {m['kind']}: FRF {m['f_hz_frf']:.4g} Hz, predicted by identify {m['f_hz_identify']:.4g} Hz "
                      f"({m['diff_pct']:+.2f} %)" for m in c["modes"]]
        lines.append(f"  wrote {args.out}/frf.json, frf.csv")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def _cmd_view(args) -> int:
    from .pipeline.view import run_view

    s = run_view(args.run_dir, web=args.web, open_viewer=not args.no_open, magnify=args.magnify, rebuild=args.rebuild)
    if args.json:
        _emit(args, s, str)
    elif args.no_open:
        print(f"{'built' if s['built'] else 'up to date'}: {s['recording']}\n  open with: " + " ".join(s["command"])
              + (f"\n  then browse {s['url']}" if s["url"] else ""))
    return 0


def _cmd_report(args) -> int:
    from .pipeline.report import run_report

    s = run_report(args.run_dir)

    def human(s):
        lines = [f"report of {s['run_dir']}: {len(s['sections'])} sections ({', '.join(s['sections'])}), "
                 f"{len(s['figures'])} figures"]
        for m in s["stages_missing"]:
            lines.append(f"  not run: {m['name']} ({m['reason']})")
        lines.append(f"  wrote {s['html']}, {s['markdown']} (figures in {s['figures_dir']})")
        return "\n".join(lines)

    _emit(args, s, human)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="mocapfj",
        description="Measure flexible-joint robots with motion capture and identify their joint dynamics.",
        epilog="Each command writes into --out DIR, prints a short summary (or one JSON object with "
               "--json) and exits 2 with a one-line message on bad input.")
    p.add_argument("--version", action="version", version=f"mocapfj {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)

    d = sub.add_parser("demo", help="every stage on a simulated recording through cameras, with known truth",
                       description="Simulates PA-10 joint 2 with a concealed stiffening as 8 cameras' blobs and a "
                                   "controller log, calibrates the rig from a wand wave, then runs every stage "
                                   "(mocapfj run) into OUT/run: report.html, recording.rrd. About 2-3 minutes.")
    d.add_argument("--out", default="demo_out", help="output directory (default: demo_out)")
    d.add_argument("--duration", type=float, default=30.0,
                   help="seconds of each trial (default 30; the scenarios are 60 s; the effect is named from about 12 s)")
    d.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    d.set_defaults(func=_cmd_demo, in_place=True)      # the run inside is resumable; its paths stay true

    rn = sub.add_parser("run", help="every stage that applies, from a recording to a report",
                        description="triangulate (a bundle of cameras' detections), joints, identify, discover, "
                                    "the rerun recording and the report, into OUT/<stage>/ (docs/formats.md, Run "
                                    "directory). Resumable: a finished stage whose inputs did not change is kept. "
                                    "A failing stage leaves the finished ones and says why (exit 1).")
    rn.add_argument("recording", help="recording bundle directory or recording.toml")
    rn.add_argument("--out", required=True, help="run directory (created; rerun into it to resume)")
    rn.add_argument("--validation", default=None, help="a second recording of the same joints, on which discovery "
                    "proves its fit gain")
    rn.add_argument("--stages", default=None, help="comma-separated stages to run (default all that apply)")
    rn.add_argument("--force", action="store_true", help="rerun every stage, even those whose inputs did not change")
    rn.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    _allow_outside_bundle(rn)
    rn.set_defaults(func=_cmd_run, in_place=True)

    sm = sub.add_parser("simulate", help="simulate a scenario file into a recording bundle with its truth")
    sm.add_argument("scenario", help="scenario TOML (datasets/*.toml)")
    sm.add_argument("--out", required=True, help="output bundle directory")
    sm.add_argument("--duration", type=float, default=None, help="override the scenario's duration_s")
    sm.add_argument("--no-concealment", action="store_true",
                    help="skip the nominal run that measures each planted effect against the noise")
    sm.add_argument("--images", action="store_true",
                    help="also write images/: board calibration views and a blob clip, with their truth")
    sm.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    sm.set_defaults(func=_cmd_simulate)

    jn = sub.add_parser("joints", help="joint axes, link angles and deflections from markers")
    jn.add_argument("recording", help="recording bundle directory or recording.toml")
    jn.add_argument("--out", required=True, help="output directory")
    jn.add_argument("--method", default="auto", choices=["auto", "ml", "halvorsen", "gamage_lasenby", "sara"],
                    help="axis fit (default auto: maximum likelihood, or SARA where the markers do not move as a hinge)")
    jn.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    _allow_outside_bundle(jn)
    jn.set_defaults(func=_cmd_joints)

    idf = sub.add_parser("identify", help="identification of joint dynamics and spring model")
    idf.add_argument("recordings", nargs="+", help="recording bundles; repeats of the same joints give CV %%")
    idf.add_argument("--out", required=True, help="output directory")
    idf.add_argument("--method", default="output_error", choices=list(IDENTIFY_METHODS),
                     help="output_error (default: the link simulated on the motor's motion, compared with the mocap "
                          "angle and the torque), motor_first (motor equation, then link equation) or two_step "
                          "(Lightcap and Banks 2007)")
    idf.add_argument("--cutoff", type=float, default=None,
                     help="two_step method: low-pass on the angles before differentiation, Hz (default 10)")
    idf.add_argument("--validation", default=None,
                     help="rigid robot (no markers): a second recording on which each joint's torque RMS is reported")
    idf.add_argument("--decimate", type=int, default=2, help="parallel decimation factor")
    idf.add_argument("--fit-clock-offset", action="store_true",
                     help="output_error: identify an offset between the mocap and controller clocks with the "
                          "dynamics and apply it (by default it is tested and reported, and what it moves is flagged)")
    idf.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    _allow_outside_bundle(idf)
    idf.set_defaults(func=_cmd_identify)

    dc = sub.add_parser("discover", help="locate, name and model what the model misses in a recording")
    dc.add_argument("recording", help="recording bundle directory or recording.toml")
    dc.add_argument("--out", required=True, help="output directory")
    dc.add_argument("--model", default=None,
                    help="model file (or scenario file) to compare with; default: identified on the spot")
    dc.add_argument("--validation", default=None, help="a second recording on which to prove the fit improves")
    dc.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    _allow_outside_bundle(dc)
    dc.set_defaults(func=_cmd_discover)

    cc = sub.add_parser("calibrate-camera", help="calibrate camera intrinsics from board views")
    cc.add_argument("images", nargs="+", metavar="IMAGES",
                    help="images or videos of the board (a directory stands for the images and videos in it)")
    cc.add_argument("--board", required=True, help="calibration target TOML (calibration/boards/*.toml)")
    cc.add_argument("--out", required=True, help="output directory")
    cc.add_argument("--model", default="standard", choices=["standard", "no_k3", "rational"],
                    help="distortion coefficients: standard (k1 k2 p1 p2 k3, default), no_k3 (k1 k2 p1 p2), "
                         "rational (k1..k6 p1 p2)")
    cc.add_argument("--name", default="cam_0", help="camera name in the rig file (default cam_0)")
    cc.add_argument("--every", type=int, default=1, help="use every N-th video frame (default 1)")
    cc.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    cc.set_defaults(func=_cmd_calibrate_camera)

    cr = sub.add_parser("calibrate-rig", help="calibrate a multi-camera rig (board views or a wand wave)",
                        description="Board: --board B.toml and one --camera per camera with its views (the k-th view "
                                    "of every camera is frame k). Wand: --wand W.toml --detections blobs.csv "
                                    "--intrinsics rig.toml [--lframe lframe.csv].")
    cr.add_argument("--out", required=True, help="output directory")
    cr.add_argument("--board", default=None, help="calibration target TOML (calibration/boards/*.toml)")
    cr.add_argument("--camera", action="append", nargs="+", default=None, metavar="VIEWS",
                    help="one camera's views: images, a directory of them or a video (repeat per camera, in order)")
    cr.add_argument("--wand", default=None, help="wand TOML (calibration/wands/*.toml): marker spacing, L-frame")
    cr.add_argument("--detections", default=None,
                    help="wand blobs: CSV with frame, camera, x_px, y_px[, point_id] (docs/formats.md)")
    cr.add_argument("--lframe", default=None, help="the still L-frame's blobs (same CSV columns): sets the world")
    cr.add_argument("--intrinsics", default=None,
                    help="rig TOML with each camera's intrinsics (required for --wand; a start for --board)")
    cr.add_argument("--refine-intrinsics", default=None,
                    choices=["fixed", "default", "all"],
                    help="intrinsics refined with the poses: fixed, default (fx fy cx cy k1 k2 p1 p2) or all "
                         "(default: default for boards, fixed for a wand)")
    cr.add_argument("--every", type=int, default=1, help="use every N-th video frame (default 1)")
    cr.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    cr.set_defaults(func=_cmd_calibrate_rig)

    tr = sub.add_parser("triangulate", help="2D detections to labelled 3D marker trajectories (C3D)",
                        description="DETECTIONS: a CSV with frame, camera, x_px, y_px[, point_id], or one video, "
                                    "image directory or image per camera of the rig, in camera order.")
    tr.add_argument("inputs", nargs="+", metavar="DETECTIONS", help="detections CSV, or each camera's video/images")
    tr.add_argument("--rig", required=True, help="rig TOML (anipose-compatible, docs/formats.md)")
    tr.add_argument("--clusters", action="append", default=None, metavar="CLUSTERS",
                    help="clusters file (mocapfj.clusters/1) or joint calibration (mocapfj.joint/1); repeatable")
    tr.add_argument("--out", required=True, help="output directory")
    tr.add_argument("--rate", type=float, default=None, help="frame rate, Hz (required for a CSV or images)")
    tr.add_argument("--sigma-px", type=float, default=None,
                    help="pixel noise SD (default: the rig's sigma_px, else from the residuals)")
    tr.add_argument("--max-gap", type=float, default=0.1, help="longest gap filled from the rigid fit, s (default 0.1)")
    tr.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    tr.set_defaults(func=_cmd_triangulate)

    i = sub.add_parser("inspect", help="check and summarise a recording bundle or a C3D/TRC file")
    i.add_argument("recording", help="bundle directory, recording.toml, or marker file")
    i.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    _allow_outside_bundle(i)
    i.set_defaults(func=_cmd_inspect)

    al = sub.add_parser("algebraic", help="fast omega0 and zeta of a joint's oscillation (algebraic estimator, "
                                          "logarithmic decrement)")
    al.add_argument("csv", help="CSV with a header row (docs/formats.md)")
    al.add_argument("--output", required=True, help="column of the link angle or the deflection, rad")
    al.add_argument("--input", default=None, help="column of the motor angle (link side, rad) driving the joint; "
                                                  "omit for a free vibration after a stop")
    al.add_argument("--time", default="time", help="time column, s (default time)")
    al.add_argument("--start", type=float, default=None, help="start of the segment, s (default the first sample)")
    al.add_argument("--duration", type=float, default=None, help="length of the segment, s (default to the end)")
    al.add_argument("--window", type=float, default=None, help="also estimate over sliding windows of this length, s")
    al.add_argument("--no-offset", action="store_true", help="the equilibrium is known: y - u rests at 0")
    al.add_argument("--inertia", type=float, default=None, help="link inertia J, kg m^2: report K = J omega0^2")
    al.add_argument("--damping", default="auto", choices=["auto", "link", "spring"],
                    help="damping on the link's velocity (their eq. 9), on the deflection rate, or the better fit "
                         "(default auto; a free vibration cannot tell them apart)")
    al.add_argument("--out", required=True, help="output directory")
    al.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    al.set_defaults(func=_cmd_algebraic)

    pc = sub.add_parser("precompensate", help="motor command anticipating the joint's deflection (Oueslati et al. "
                                              "2012, eq. 17)")
    pc.add_argument("csv", help="CSV with the reference trajectory")
    pc.add_argument("--reference", required=True, help="column of the reference, rad (link side)")
    pc.add_argument("--time", default="time", help="time column, s (default time)")
    pc.add_argument("--omega0", type=float, default=None, help="natural frequency, rad/s")
    pc.add_argument("--zeta", type=float, default=None, help="damping ratio")
    pc.add_argument("--model", default=None, help="algebraic.json from mocapfj algebraic (instead of --omega0/--zeta)")
    pc.add_argument("--iterations", type=int, default=1, help="1: their law; more repeat the correction on the model")
    pc.add_argument("--method", default="eq17", choices=["eq17", "inverse"],
                    help="eq17: their law (default); inverse: the command whose simulated link is the reference")
    pc.add_argument("--damping", default=None, choices=["link", "spring"],
                    help="the model's damping form (default: the one in --model, else link)")
    pc.add_argument("--out", required=True, help="output directory")
    pc.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    pc.set_defaults(func=_cmd_precompensate)

    cc = sub.add_parser("control-check", help="validate a joint model by computed-torque tracking against the rigid "
                                              "model (Bompos et al. 2007)")
    cc.add_argument("model", help="model file (mocapfj.model/1, e.g. from identify or discover) or scenario TOML")
    cc.add_argument("--plant", default=None, help="the true joint's file (default: the model itself)")
    cc.add_argument("--joint", default=None, help="joint name (default: the file's only joint)")
    cc.add_argument("--q0", type=float, default=0.3, help="reference centre, rad (default 0.3)")
    cc.add_argument("--amplitudes", default="0.3,0.06", help="reference sine amplitudes, rad, comma-separated")
    cc.add_argument("--frequencies", default="0.5,1.5", help="reference sine frequencies, Hz, comma-separated")
    cc.add_argument("--ramp", type=float, default=1.0, help="ramp-in of the reference, s (default 1)")
    cc.add_argument("--duration", type=float, default=6.0, help="simulated time, s (default 6)")
    cc.add_argument("--bandwidth", type=float, default=5.0, help="motor PD loop bandwidth on I + J, Hz (default 5)")
    cc.add_argument("--zeta", type=float, default=0.8, help="motor PD loop damping (default 0.8)")
    cc.add_argument("--rate", type=float, default=400.0, help="control rate, Hz (default 400, the PA-10's 2.5 ms)")
    cc.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    cc.set_defaults(func=_cmd_control_check)

    cl = sub.add_parser("clamped", help="joint stiffness with the end-effector clamped (Jubien et al. 2014)")
    cl.add_argument("csv", help="controller CSV: time, motor angles and torques (link side)")
    cl.add_argument("--positions", required=True, help="motor angle columns, comma-separated, in joint order, rad")
    cl.add_argument("--torques", default=None, help="motor torque columns, comma-separated, N m")
    cl.add_argument("--wrench", default=None, help="six columns fx,fy,fz,mx,my,mz (N, N m, tool frame; 0 = not measured)")
    cl.add_argument("--wrench-file", default=None, help="the force sensor's own CSV (with a --time column)")
    cl.add_argument("--urdf", default=None, help="robot URDF (for the wrench)")
    cl.add_argument("--mdh", default=None, help="modified DH CSV (alpha,d,theta_offset,r) or kr500 (for the wrench)")
    cl.add_argument("--frame", default="tool", help="the frame the wrench is expressed in (default tool)")
    cl.add_argument("--joints", default=None, help="joint numbers to identify, 1-based, comma-separated (default all)")
    cl.add_argument("--time", default="time", help="time column, s (default time)")
    cl.add_argument("--cutoff", type=float, default=10.0, help="low-pass cut-off, Hz (default 10)")
    cl.add_argument("--decimate-cutoff", type=float, default=5.0, help="decimation filter cut-off, Hz (default 5)")
    cl.add_argument("--out", required=True, help="output directory")
    cl.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    cl.set_defaults(func=_cmd_clamped)

    fr = sub.add_parser("frf", help="frequency response and two-inertia model from multisine data "
                        "(Makarov et al. 2012)")
    fr.add_argument("recording", metavar="CSV_OR_RECORDING",
                    help="a CSV with a time column, or a recording bundle (its controller CSV)")
    fr.add_argument("--input", required=True, help="input column, e.g. motor torque (N m, link side)")
    fr.add_argument("--output", required=True, help="output column, e.g. motor angle (rad, link side)")
    fr.add_argument("--reference", default=None, help="closed loop: the reference column (indirect estimator)")
    fr.add_argument("--time", default=None, help="time column, s (default: the bundle's, else time)")
    fr.add_argument("--period", type=float, default=None,
                    help="excitation period, s (default: found where the reference, else the input, repeats)")
    fr.add_argument("--model", default=None, choices=["two_inertia", "rational", "none"],
                    help="model fitted to the FRF (default two_inertia: J, I, k, d, b, v; with --single-record "
                         "rational: B(s)/A(s) of degrees --order; none: the FRF only)")
    fr.add_argument("--single-record", action="store_true",
                    help="one record without repeated periods: FRF by the local polynomial method "
                         "(Pintelon et al. 2010), open loop")
    fr.add_argument("--steady-period", action="store_true",
                    help="with --single-record: the record is one whole period in steady state (G = Y/U, the "
                         "local polynomials for the noise only; for modes narrower than a DFT line)")
    fr.add_argument("--order", type=int, nargs=2, default=None, metavar=("NB", "NA"),
                    help="degrees of B and A of the rational model (default 4 4)")
    fr.add_argument("--estimator", default="auto", choices=["auto", "h1", "harmonic", "indirect"],
                    help="auto (default): indirect with --reference, else harmonic mean")
    fr.add_argument("--transient", default="auto",
                    help="periods dropped at the start of each realisation (default auto: those that differ "
                         "from the late periods beyond the noise, at least 1)")
    fr.add_argument("--realisations", default="auto",
                    help="the record holds this many equal consecutive realisations (default auto: a new one "
                         "starts where a period differs from the one before as an independent multisine does)")
    fr.add_argument("--compare", default=None, metavar="IDENTIFY",
                    help="the time-domain identification of the same joint (identify.json, its directory or a run "
                         "directory): the two-inertia parameters and modes held against it, disagreements named")
    fr.add_argument("--joint", default=None, help="with --compare: the joint of the identification (default its only one)")
    fr.add_argument("--gravity-stiffness", type=float, default=None, metavar="G",
                    help="the link's gravity stiffness G'(q0) at the operating point, N m/rad (negative when gravity "
                         "pulls the link away from it), held in the two-inertia fit; default: fitted with the rest "
                         "(and, with --compare, held against the one identify's mglx, mgly imply)")
    fr.add_argument("--out", required=True, help="output directory")
    fr.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    fr.set_defaults(func=_cmd_frf)

    vw = sub.add_parser("view", help="open a run in the rerun viewer (builds RUN_DIR/recording.rrd when missing or older "
                                     "than the results)")
    vw.add_argument("run_dir", help="run directory (mocapfj run --out) or one command's --out")
    vw.add_argument("--web", action="store_true",
                    help="serve a web viewer over HTTP instead of a window (a headless machine: open the printed URL)")
    vw.add_argument("--magnify", type=float, default=1.0,
                    help="also draw the link where it would be with the deflection magnified this many times "
                         "(rebuilds the recording)")
    vw.add_argument("--rebuild", action="store_true", help="rebuild the recording even when it is up to date")
    vw.add_argument("--no-open", action="store_true", help="only build the recording and print the viewer command")
    vw.add_argument("--json", action="store_true", help="with --no-open: print a JSON summary on stdout")
    vw.set_defaults(func=_cmd_view)

    rp = sub.add_parser("report", help="(re)build a run's report: RUN_DIR/report.html (self-contained) and report.md",
                        description="Reads the run's results (docs/formats.md, 'Run directory'; or one command's "
                                    "--out, e.g. an identify or discover directory) and writes report.html, "
                                    "report.md and report_files/ into it. Nothing else there is touched.")
    rp.add_argument("run_dir", help="run directory (mocapfj run --out) or one command's --out")
    rp.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    rp.set_defaults(func=_cmd_report)

    ba = sub.add_parser("batch", help="many recordings in parallel on Dask, parameters across repeated trials",
                        description="One Dask task per recording (mocapfj run into OUT/<recording>/), "
                                    "then the mean, SD and CV % of every parameter across the repeated trials "
                                    "of each joint (OUT/batch.json, batch.csv, trials.csv, batch.md). A failed "
                                    "recording is reported and the others finish (exit 1). docs/batch.md.")
    ba.add_argument("recordings", nargs="+", metavar="RECORDING", help="recording bundles (directories or recording.toml)")
    ba.add_argument("--out", required=True, help="output directory")
    ba.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="an existing Dask scheduler, e.g. tcp://host:8786 (default: a local cluster)")
    ba.add_argument("--workers", type=int, default=None, metavar="N",
                    help="worker processes of the local cluster, one thread each (default: the cores, at most 4)")
    ba.add_argument("--stages", default=None,
                    help="comma-separated stages of mocapfj run (default all that apply; joints,identify for the "
                         "parameters only)")
    ba.add_argument("--method", default="output_error", choices=list(IDENTIFY_METHODS),
                    help="identification method (as identify --method; two_step is Lightcap and Banks 2007's)")
    ba.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    ba.set_defaults(func=_cmd_batch)

    return p


def _terminate(signum, frame):
    raise SystemExit(128 + signum)           # unwinds like Ctrl-C: staging directories removed


def _run(args) -> int:
    """The command, writing into a staging directory beside --out (mocapfj.io.outdir)."""
    if getattr(args, "out", None) is not None:
        from .io.outdir import check_output_dir, staged_output

        check_output_dir(args.out, _inputs(args))
        if getattr(args, "in_place", False):        # run: resumable, each stage staged on its own
            return int(args.func(args))
        with staged_output(args.out) as stage:
            args.stage = stage
            return int(args.func(args))
    return int(args.func(args))


def _keep_freed_memory() -> None:
    """glibc only: keep freed blocks up to 32 MB in the process for reuse, instead of returning
    each to the kernel. Output error allocates and frees arrays of a few MB (a minute at 1 kHz,
    eight sensitivities) thousands of times; with glibc's default, every one is mapped afresh and
    page-faulted in, which made a discovery's re-identification 20-30 % slower (measured: 12.2 ->
    9.4 s). A command runs once and exits, so the memory kept is returned at exit."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):               # not glibc (musl has no mallopt): as it is
        return
    M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD = -1, -2, -3
    mallopt(M_MMAP_THRESHOLD, 32 << 20)
    mallopt(M_TRIM_THRESHOLD, 256 << 20)
    mallopt(M_TOP_PAD, 64 << 20)


def main(argv: Sequence[str] | None = None) -> int:
    import signal

    parser = build_parser()
    args = parser.parse_args(argv)
    if argv is None:                         # a command of its own process, not a call from Python
        _keep_freed_memory()
    try:
        previous = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:                       # not the main thread (an embedding application)
        previous = None
    try:
        if getattr(args, "allow_outside_bundle", False):
            from .io import files_outside_bundle

            with files_outside_bundle():
                return _run(args)
        return _run(args)
    except InputError as e:
        msg = str(e)
        if e.file == "<argument>" and e.field in vars(args):
            # a Python argument that came from a command-line option: name the option
            msg = msg.replace(f"<argument>: {e.field}:", "--" + e.field.replace("_", "-") + ":", 1)
        print(f"mocapfj: error: {msg}", file=sys.stderr)
        return 2
    except OSError as e:
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        print(f"mocapfj: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("mocapfj: interrupted; nothing was written", file=sys.stderr)
        return 130
    except SystemExit as e:
        if e.code == 128 + signal.SIGTERM:
            print("mocapfj: terminated; nothing was written", file=sys.stderr)
        raise
    except Exception as e:                   # a check that should have caught it did not
        text = " ".join(str(e).split())[:300] or type(e).__name__
        print(f"mocapfj: error: {type(e).__name__}: {text} (an input mocapfj did not check; nothing was written; "
              "please report it with the input)", file=sys.stderr)
        return 2
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
