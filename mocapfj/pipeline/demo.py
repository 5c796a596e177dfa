"""``mocapfj demo``: the whole product on a recording whose truth is known, through the cameras.

PA-10 joint 2 (Lightcap and Banks 2007, Table I) with a harmonic drive's soft wind-up (the
stiffness rising with the load, K1 < K2 < K3) concealed below the noise (the concealed-effect
suite's stiffening pair: an identification trial and a validation trial) is
simulated as 8 cameras' 2D marker blobs and a controller log. The demo then does what a lab does:
calibrates the rig from a simulated wand wave and L-frame (the cameras' intrinsics given, as
from a prior intrinsic calibration), writes two bundles whose markers are the cameras' blobs
(``[rig] clusters``: the marker clusters' templates, measured once), and runs ``mocapfj run`` on
them: triangulation and labelling, joint axes, link angles and deflections, identification,
discovery of the missing physics proved on the validation trial, the rerun recording and the
report. ``OUT/demo.json`` compares what was found with what was planted.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..io import write_json

__all__ = ["DEMO_SCENARIOS", "DEMO_DURATION_S", "run_demo"]

DEMO_SCENARIOS = ("suite/stiffening_ident", "suite/stiffening_valid")
WAND_FRAMES = 600            # 6 s of wand wave at 100 Hz
LFRAME_FRAMES = 20


def _camera_bundle(sr, scn, rig, out: Path) -> Path:
    """The simulated recording as a lab's camera bundle: the controller log, the cameras' blobs,
    the calibrated rig and the clusters' templates; no 3D markers."""
    from ..io.clusters import write_clusters
    from ..io.recording import write_recording
    from ..synth.record import marker_layout, scenario_rngs
    from ..synth.robot_mesh import pa10_geometry
    from ..types import MarkerCluster

    layout = marker_layout(scn, pa10_geometry(), scenario_rngs(scn)[0])
    clusters = [MarkerCluster(f"link{li}", [layout.labels[i] for i in layout.cluster(li)],
                              layout.p_link[layout.cluster(li)]) for li in np.unique(layout.link)]
    rec = sr.recording
    spec = {k: v for k, v in dict(rec.spec).items() if k not in ("markers", "rig")}
    spec["rig"] = {"file": "rig.toml", "detections": "detections.csv", "clusters": "clusters.toml",
                   "rate_hz": float(scn.measurement.mocap_hz)}
    cam = replace(rec, markers=None, marker_file="", rig=rig, spec=spec, root=None)
    out.mkdir(parents=True, exist_ok=True)
    write_clusters(out / "clusters.toml", clusters)
    return write_recording(cam, out).parent


def _calibrate_rig(true_rig, out: Path, rng: np.random.Generator) -> dict:
    """The rig from a simulated wand wave and L-frame, intrinsics given (run_calibrate_rig)."""
    from ..io import write_detections
    from ..io.calib import read_wand, write_rig
    from ..synth.wand import lframe_detections, wand_wave
    from ..types import Camera, Rig
    from .calibrate import run_calibrate_rig
    from .core import default_scenario

    wand_file = default_scenario("pa10_joint2").parents[1] / "calibration" / "wands" / "wand_3marker_500mm.toml"
    wand = read_wand(wand_file)
    raw = out / "calibrate_rig" / "wand"     # the wave and the L-frame as the cameras saw them
    raw.mkdir(parents=True, exist_ok=True)
    write_rig(raw / "intrinsics.toml", Rig(tuple(Camera(c.name, c.size, c.K, c.dist, np.eye(3), np.zeros(3))
                                                 for c in true_rig.cameras), {"units": "m"}))
    write_detections(raw / "wand.csv", wand_wave(true_rig, wand, WAND_FRAMES, rng, noise_px=0.2).detections)
    write_detections(raw / "lframe.csv", lframe_detections(true_rig, wand, LFRAME_FRAMES, rng, noise_px=0.2))
    return run_calibrate_rig(out / "calibrate_rig", wand=wand_file, detections=raw / "wand.csv",
                             intrinsics=raw / "intrinsics.toml", lframe=raw / "lframe.csv", progress=False)


def _rig_error(true_rig, rig) -> dict:
    """Largest camera-centre and orientation differences between the calibrated and true rigs."""
    from ..vision.camera import camera_centre_world

    dc = [float(np.linalg.norm(camera_centre_world(a) - camera_centre_world(b)))
          for a, b in zip(true_rig.cameras, rig.cameras)]
    da = [float(np.degrees(np.arccos(np.clip((np.trace(a.R_cam_world @ b.R_cam_world.T) - 1) / 2, -1, 1))))
          for a, b in zip(true_rig.cameras, rig.cameras)]
    return {"camera_centre_error_max_mm": 1e3 * max(dc), "camera_rotation_error_max_deg": max(da)}


def _simulated(sr, scn, bundle: Path) -> dict:
    """What ``mocapfj simulate`` prints for the identification trial's simulated bundle."""
    from ..io import load_recording
    from .core import summarize_recording

    s = summarize_recording(load_recording(bundle))
    s.update(images=0, scenario=scn.name, duration_s=scn.duration_s, effects=sr.truth["effects"],
             truth={"joints": [{k: j[k] for k in ("name", "angle_sigma_rad", "deflection_noise_sd_rad")}
                               for j in sr.truth["joints"]], "clock": sr.truth["clock"]})
    return s


def _joints_against_truth(joints_dir: Path, sim: Path) -> list[dict]:
    """The joints stage's summary per joint with its deflection's error against the simulator's
    truth (mean removed: the link angle's zero is a convention) and the Cramér-Rao bound of it."""
    from ..io import read_csv_columns, read_json

    truth = read_csv_columns(sim / "truth.csv")
    out = []
    for j in read_json(joints_dir / "joints.json")["joints"]:
        a = read_csv_columns(joints_dir / f"{j['name']}.angles.csv")
        err = a["delta"] - np.interp(a["t_controller"], truth["time"], truth[f"delta_{j['name']}"])
        ok = np.isfinite(err)
        err = err[ok] - err[ok].mean()
        j["deflection_error_rms_rad"] = float(np.sqrt(np.mean(err**2)))
        j["deflection_error_bound_rad"] = float(np.sqrt(np.mean(a["sigma_delta"][ok] ** 2)))
        out.append(j)
    return out


DEMO_DURATION_S = 30.0       # of the scenarios' 60 s: the effect is named from 12 s on; 30 s keeps the demo near 1.5 min


def run_demo(out: str | Path, duration_s: float | None = DEMO_DURATION_S,
             progress: Callable[[str], None] | None = None) -> dict:
    """Simulate, calibrate, triangulate, identify, discover and report (module docstring).

    Writes OUT/simulation/<trial> (the simulator's bundles with their truth), OUT/recordings/<trial>
    (the camera bundles), OUT/run (the run directory of ``mocapfj run``: report.html,
    recording.rrd, each stage's results, and calibrate_rig/ with the wand wave in wand/) and
    OUT/demo.json (the planted effect, what discovery named, the fits). Returns demo.json's
    contents.
    """
    from ..io.calib import read_rig
    from ..synth.record import record_scenario, write_scenario_bundle
    from ..synth.scenario import check_scenario, load_scenario
    from .core import default_scenario
    from .run import run_pipeline

    from ..io.outdir import MARKER

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).touch()
    say = progress or (lambda line: None)
    t0 = time.perf_counter()
    timings = {}
    sims, scns = [], []
    for name in DEMO_SCENARIOS:
        scn = load_scenario(default_scenario(name))
        if duration_s is not None:
            scn = scn.with_duration(duration_s)
            check_scenario("--duration", scn)
        scn = replace(scn, measurement=replace(scn.measurement, detections_s=scn.duration_s))
        say(f"simulating {scn.name}: {scn.duration_s:g} s, {scn.measurement.n_cameras} cameras ...")
        # one lab, one rig; the planted effect's concealment is measured on the identification trial
        sr = record_scenario(scn, with_concealment=not sims, rig=sims[0].recording.rig if sims else None)
        write_scenario_bundle(sr, out / "simulation" / scn.name, default_scenario(name))
        sims.append(sr)
        scns.append(scn)
    timings["simulate_s"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    say("calibrating the rig from a wand wave ...")
    true_rig = sims[0].recording.rig
    # into the run directory, so the report's calibration section holds it
    cal = _calibrate_rig(true_rig, out / "run", np.random.default_rng(np.random.SeedSequence([scns[0].seed, 11])))
    rig = read_rig(out / "run" / "calibrate_rig" / "rig.toml")
    timings["calibrate_rig_s"] = time.perf_counter() - t1

    bundles = [_camera_bundle(sr, scn, rig, out / "recordings" / scn.name) for sr, scn in zip(sims, scns)]
    t2 = time.perf_counter()
    run = run_pipeline(bundles[0], out / "run", validation=bundles[1], progress=say)
    timings["run_s"] = time.perf_counter() - t2
    timings["total_s"] = time.perf_counter() - t0

    planted = [{"name": e["name"], "joint": e["joint"], "ratio": e.get("ratio"), "concealed": e.get("concealed")}
               for e in sims[0].truth["effects"]]
    summary = _simulated(sims[0], scns[0], out / "simulation" / scns[0].name)   # the keys of mocapfj simulate
    summary.update({"scenarios": [s.name for s in scns], "planted": planted,
                    "rig": {"n_cameras": len(rig.cameras), "wand_length_sd_mm": cal.get("wand_length_sd_mm"),
                            "reprojection_rms_px": cal.get("rms_px"), **_rig_error(true_rig, rig)},
                    "run": run.to_dict()})
    summary["timings_s"] = {**{k: round(v, 2) for k, v in sims[0].timings_s.items()},
                            **{k: round(v, 2) for k, v in timings.items()}}
    if run.stage("joints").status in ("done", "skipped"):
        summary["joints_fit"] = _joints_against_truth(out / "run" / "joints", out / "simulation" / scns[0].name)
    disc = run.stage("discover")
    if disc.status == "done" and disc.summary is not None:
        d = disc.summary
        summary["found"] = [{"name": e["name"], "joint": e["joint"]} for e in d.get("effects", [])]
        summary["fits"] = {j: {k: f[k].get("fit") for k in ("before", "after")} for j, f in d.get("fits", {}).items()}
        summary["validation"] = d.get("validation")
        summary["named_planted"] = sorted({e["name"] for e in summary["found"]} & {p["name"] for p in planted})
    tri = run.stage("triangulate")
    if tri.status == "done" and tri.summary is not None:
        summary["triangulation"] = {k: tri.summary.get(k) for k in ("n_frames", "reprojection_rms_px", "nan_share",
                                                                    "swaps_repaired", "gaps_filled")}
    write_json(out / "demo.json", summary)
    return summary
