"""Turn a scenario into a recording bundle that looks like a real lab's, plus its truth.

The chain: simulate the true system under PD motor position control (Lightcap and Banks (2007), eq. 4 per joint,
or one Pinocchio model for ``model = "urdf"``) on the controller's clock; log the controller
(resolver-quantised q_m, torque with current noise); pose the PA-10-like arm at the instants the
mocap samples (the declared clock offset plus any planted `time_delay`); place marker clusters,
ray-cast occlusion in a ring of cameras, add 2D and 3D noise and dropouts; write the bundle.

Randomness: one seed per scenario, split with numpy's SeedSequence into independent streams
for the marker layout, the rig, the rendering noise and the controller noise, so the same
scenario file gives a byte-identical bundle.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from ..dynamics import PID, NLinkModel, SimulationResult, controller_log, element_to_table, simulate
from ..io import write_csv_columns, write_json, write_recording
from ..io.atomic import write_text_atomic
from ..types import ControllerLog, Detections, JointSpec, MarkerTrajectories, Recording, Rig
from .cameras import ring_rig
from .markers import DEFAULT_CLUSTERS, MarkerLayout, place_markers
from .render import render_markers
from .robot_mesh import base_pose, forward_kinematics, pa10_geometry
from .scenario import (Scenario, joint_drivetrain, joint_friction, joint_models, joint_spring, nominal_parameters,
                       reference_trajectory)
from .urdf import pa10_urdf

__all__ = ["SimulatedRecording", "simulate_scenario", "record_scenario", "write_scenario_bundle", "concealment",
           "scenario_rngs", "marker_layout",
           "measure_concealment", "angle_sigma"]


@dataclass(frozen=True, eq=False)
class SimulatedRecording:
    """A recording with everything that made it."""

    recording: Recording
    truth: dict
    sim: dict[str, SimulationResult]         # per joint name (one shared result for a URDF model)
    q_true_mocap: np.ndarray                  # (T_mocap, J) true link angles at the mocap instants, rad
    t_true_mocap: np.ndarray                  # (T_mocap,) those instants on the controller clock, s
    urdf: str | None
    timings_s: dict


def _clock_delay(scn: Scenario) -> float:
    return float(sum(e.params["delay_s"] for e in scn.effects if e.name == "time_delay"))


def _pid(scn: Scenario, joints) -> PID:
    refs = [reference_trajectory(j.reference) for j in joints]

    def reference(t):
        out = [f(t) for f in refs]
        return np.stack([o[0] for o in out], -1), np.stack([o[1] for o in out], -1)

    return PID(reference, kp=np.array([j.kp for j in joints]), kd=np.array([j.kd for j in joints]),
               ki=np.array([j.ki for j in joints]))


def simulate_scenario(scn: Scenario, with_effects: bool = True) -> dict[str, SimulationResult]:
    """Simulate the (true or nominal) system on the controller clock, 0..duration_s.

    Returns one SimulationResult per joint name (for a URDF scenario the same result, holding all
    joints, under every name).
    """
    m = scn.measurement
    t = np.arange(int(np.floor(scn.duration_s * m.controller_hz + 1e-9)) + 1) / m.controller_hz
    opts = dict(max_step=m.sim_max_step_s, rtol=m.sim_rtol, atol=m.sim_rtol * 1e-3)
    if scn.model == "urdf":
        eff = {j.name: (scn.effects_on(j.name) if with_effects else ()) for j in scn.joints}
        urdf = scenario_urdf(scn)
        model = NLinkModel.from_urdf(
            urdf, motor_inertia=[j.J for j in scn.joints],
            springs=[joint_spring(j, eff[j.name], scn.source) for j in scn.joints],
            motor_damping=[j.b for j in scn.joints],
            frictions=[joint_friction(j, eff[j.name], scn.source).with_smoothing(1e-3) for j in scn.joints],
            drivetrains=[joint_drivetrain(j, eff[j.name]) for j in scn.joints])
        res = simulate(model, t, _pid(scn, scn.joints), **opts)
        return {j.name: res for j in scn.joints}
    models = joint_models(scn, with_effects)
    out: dict[str, SimulationResult] = {}
    pending = list(scn.joints)
    while pending:  # a coupled joint is simulated after its source
        for j in pending:
            couplings = [e for e in scn.effects_on(j.name) if e.name == "coupling"] if with_effects else []
            if all(e.params["source"] in out for e in couplings):
                break
        else:
            raise ValueError(f"scenario {scn.name}: coupling effects form a cycle")
        srcs = [(float(e.params["inertia_kgm2"]), out[e.params["source"]]) for e in couplings]

        def coupling_torque(tt, srcs=srcs):
            return -sum(c * np.interp(tt, r.t, r.qdd[:, 0]) for c, r in srcs)

        out[j.name] = simulate(models[j.name], t, _pid(scn, [j]), tau_ext=coupling_torque if srcs else None, **opts)
        pending.remove(j)
    return out


def scenario_urdf(scn: Scenario) -> str:
    """URDF of the scenario's arm: its joints free, the others braked at ``robot.pose_rad``."""
    order = sorted(scn.joints, key=lambda j: j.axis)
    if [j.name for j in order] != [j.name for j in scn.joints]:
        raise ValueError(f"scenario {scn.name}: list URDF joints in PA-10 order")
    return pa10_urdf([j.axis for j in order], scn.pose_rad, joint_names=[j.name for j in order],
                     payload_kg=scn.payload_kg)


def _column(r: SimulationResult, name: str) -> int:
    """Column of joint `name` in a result (a single-joint result has one column)."""
    return r.joint_names.index(name) if r.q.shape[1] > 1 else 0


def _joint_signal(sim: dict[str, SimulationResult], scn: Scenario, name: str, field: str) -> np.ndarray:
    r = sim[name]
    return getattr(r, field)[:, _column(r, name)]


def _mocap_times(scn: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """(t_mocap on the mocap clock, the true controller-clock instants of those samples)."""
    m = scn.measurement
    shift = m.clock_offset_s + _clock_delay(scn)
    start = max(0.0, -shift)
    stop = scn.duration_s - max(0.0, shift)
    k0 = int(np.ceil(start * m.mocap_hz - 1e-9))
    k1 = int(np.floor(stop * m.mocap_hz + 1e-9))
    t_mocap = np.arange(k0, k1 + 1) / m.mocap_hz
    return t_mocap, t_mocap + shift


def _hermite(r_t, q, qd, t):
    return CubicHermiteSpline(r_t, q, qd)(t)


def _layout_labels(layout: MarkerLayout, link: int) -> tuple[str, ...]:
    return tuple(layout.labels[i] for i in np.flatnonzero(layout.link == link))


def angle_sigma(layout: MarkerLayout, labels, noise_m: float) -> float:
    """Cramér-Rao SD of a link angle from its markers: sigma / sqrt(sum r_p^2) (docs methods)."""
    idx = [layout.labels.index(s) for s in labels]
    r = layout.axis_radius()[idx]
    return float(noise_m / np.sqrt(np.sum(r**2)))


def concealment(scn: Scenario, sim_true, sim_nominal, t_ctrl_of_mocap, deflection_noise_sd: dict) -> list[dict]:
    """Each planted effect's contribution to the measured deflection, against its noise SD.

    The measured deflection pairs the logged q_m at the declared time with the link angle the
    mocap saw: delta(s) = q_m(s) - q(s + delay). The contribution is the RMS difference of that
    noise-free deflection between the true and the nominal system; an effect is concealed when
    it is below the per-sample noise SD of the measured deflection.
    """
    s = t_ctrl_of_mocap - _clock_delay(scn)  # declared controller-clock times of the mocap samples
    out = []
    for e in scn.effects:
        d = {}
        for label, sim, delay in (("true", sim_true, _clock_delay(scn)), ("nominal", sim_nominal, 0.0)):
            r = sim[e.joint]
            col = _column(r, e.joint)
            q = _hermite(r.t, r.q[:, col], r.qd[:, col], s + delay)
            qm = _hermite(r.t, r.q_m[:, col], r.qd_m[:, col], s)
            d[label] = qm - q
        rms = float(np.sqrt(np.mean((d["true"] - d["nominal"]) ** 2)))
        noise = deflection_noise_sd[e.joint]
        out.append({"name": e.name, "joint": e.joint, "params": e.params, "deflection_rms_rad": rms,
                    "deflection_noise_sd_rad": noise, "ratio": rms / noise, "concealed": bool(rms < noise)})
    return out


def _with_dropouts(m: MarkerTrajectories, rate: float, mean_frames: float, rng) -> MarkerTrajectories:
    """Lose 3D samples in bursts: starts at rate/mean_frames per sample, geometric lengths."""
    if rate <= 0:
        return m
    T, M = m.xyz.shape[:2]
    starts = rng.random((T, M)) < rate / mean_frames
    until = np.full((T, M), -1, dtype=np.int64)
    ti, mi = np.nonzero(starts)
    until[ti, mi] = ti + rng.geometric(1.0 / mean_frames, ti.size)
    lost = np.maximum.accumulate(until, axis=0) > np.arange(T)[:, None]
    xyz = m.xyz.copy()
    xyz[lost] = np.nan
    res = None if m.residual is None else np.where(lost, np.nan, m.residual)
    return MarkerTrajectories(t=m.t, xyz=xyz, labels=m.labels, rate_hz=m.rate_hz, residual=res)


def scenario_rngs(scn: Scenario):
    """Independent generators (layout, rig, render, log) from the scenario's seed."""
    return tuple(np.random.default_rng(s) for s in np.random.SeedSequence(scn.seed).spawn(4))


def marker_layout(scn: Scenario, geometry, rng) -> MarkerLayout:
    rest = forward_kinematics(np.asarray(scn.pose_rad, float), T_world_base=base_pose())
    return place_markers(geometry, rng, clusters=DEFAULT_CLUSTERS, T_world_link_check=rest)


def _quanta(scn: Scenario) -> np.ndarray:
    m = scn.measurement
    return 2 * np.pi / (2.0**m.resolver_bits * np.array([j.gear_ratio for j in scn.joints]))


def _noise(scn: Scenario, layout: MarkerLayout, link_labels) -> tuple[dict, dict]:
    """Per joint: the angle CRLB and the per-sample noise SD of the measured deflection, rad."""
    m, quantum = scn.measurement, _quanta(scn)
    sig_q, noise = {}, {}
    for i, (j, labels) in enumerate(zip(scn.joints, link_labels)):
        labels = labels or _layout_labels(layout, j.axis)
        sig_q[j.name] = angle_sigma(layout, labels, m.marker_noise_m)
        noise[j.name] = float(np.sqrt(sig_q[j.name] ** 2 + quantum[i] ** 2 / 12))
    return sig_q, noise


def measure_concealment(scn: Scenario) -> list[dict]:
    """Each planted effect's deflection RMS against the deflection noise SD, without rendering.

    Gives the same numbers as `record_scenario` (same seed, same marker layout).
    """
    rng_layout = scenario_rngs(scn)[0]
    layout = marker_layout(scn, pa10_geometry(), rng_layout)
    _, noise = _noise(scn, layout, [j.link_markers for j in scn.joints])
    _, t_true = _mocap_times(scn)
    return concealment(scn, simulate_scenario(scn), simulate_scenario(scn, with_effects=False), t_true, noise)


def record_scenario(scn: Scenario, *, with_concealment: bool = True, rig: Rig | None = None) -> SimulatedRecording:
    """Simulate, log, render and assemble the recording of a scenario (in memory).

    `rig`: the cameras to render with (another trial's, for trials in one lab); default the
    scenario's own ring of ``measurement.n_cameras`` cameras."""
    m = scn.measurement
    rng_layout, rng_rig, rng_render, rng_log = scenario_rngs(scn)
    timings = {}

    tic = time.perf_counter()
    sim = simulate_scenario(scn)
    timings["simulate"] = time.perf_counter() - tic

    # controller log: one ControllerLog over all joints
    tic = time.perf_counter()
    logs = {}
    done = set()
    for j in scn.joints:
        r = sim[j.name]
        if id(r) in done:
            continue
        done.add(id(r))
        gear = j.gear_ratio if scn.model == "single" else None
        if scn.model == "urdf":
            gears = {jj.gear_ratio for jj in scn.joints}
            gear = gears.pop() if len(gears) == 1 else None
            if gear is None:
                raise ValueError(f"scenario {scn.name}: a URDF scenario needs one gear ratio for all joints")
        log = controller_log(r, m.controller_hz, rng=rng_log, resolver_bits=m.resolver_bits, gear_ratio=gear,
                             current_noise_sd=m.torque_noise_Nm)
        for i, name in enumerate(log.joint_names):
            logs[name] = (log.t, log.q_m[:, i], log.tau[:, i])
    t_log = logs[scn.joints[0].name][0]
    controller = ControllerLog(t=t_log, q_m=np.column_stack([logs[j.name][1] for j in scn.joints]),
                               tau=np.column_stack([logs[j.name][2] for j in scn.joints]),
                               joint_names=tuple(j.name for j in scn.joints))
    timings["log"] = time.perf_counter() - tic

    # the arm at the mocap instants
    tic = time.perf_counter()
    t_mocap, t_true = _mocap_times(scn)
    q_full = np.tile(np.asarray(scn.pose_rad, float), (t_mocap.size, 1))
    q_true_mocap = np.empty((t_mocap.size, len(scn.joints)))
    for i, j in enumerate(scn.joints):
        q_true_mocap[:, i] = _hermite(sim[j.name].t, _joint_signal(sim, scn, j.name, "q"),
                                      _joint_signal(sim, scn, j.name, "qd"), t_true)
        q_full[:, j.axis - 1] = q_true_mocap[:, i]
    T_world_link = forward_kinematics(q_full, T_world_base=base_pose())
    geometry = pa10_geometry()
    layout = marker_layout(scn, geometry, rng_layout)
    rig = ring_rig(m.n_cameras, rng=rng_rig) if rig is None else rig
    rendering = render_markers(t_mocap, T_world_link, layout, geometry, rig, rng_render, rate_hz=m.mocap_hz,
                               pixel_noise_px=m.pixel_noise_px, noise_m=m.marker_noise_m)
    markers = _with_dropouts(rendering.markers, m.dropout_rate, m.dropout_frames, rng_render)
    det = rendering.detections
    keep = det.frame < int(round(m.detections_s * m.mocap_hz))
    detections = Detections(frame=det.frame[keep], camera=det.camera[keep], xy_px=det.xy_px[keep],
                            point_id=det.point_id[keep])
    timings["render"] = time.perf_counter() - tic

    specs = []
    for j in scn.joints:
        link = j.link_markers or _layout_labels(layout, j.axis)
        parent = j.parent_markers
        specs.append(JointSpec(name=j.name, motor_position=f"qm_{j.name}", motor_torque=f"tau_{j.name}",
                               gear_ratio=j.gear_ratio, link_markers=tuple(link),
                               parent_markers=parent if isinstance(parent, str) else tuple(parent)))
    urdf = scenario_urdf(scn) if scn.model == "urdf" else None
    rec = Recording(name=scn.name, markers=markers, controller=controller, joints=tuple(specs),
                    clock_offset_s=m.clock_offset_s, rig=rig, detections=detections,
                    spec={"scenario": {"name": scn.name, "seed": scn.seed, "synthetic": True}})

    # truth
    quantum = _quanta(scn)
    sig_q, noise = _noise(scn, layout, [spec.link_markers for spec in specs])
    truth = {
        "scenario": scn.name, "description": scn.description, "seed": scn.seed, "duration_s": scn.duration_s,
        "model": scn.model,
        "clock": {"declared_offset_s": m.clock_offset_s, "true_offset_s": m.clock_offset_s + _clock_delay(scn),
                  "delay_s": _clock_delay(scn)},
        "measurement": {k: getattr(m, k) for k in m.__dataclass_fields__},
        "joints": [{"name": j.name, "axis": j.axis, "nominal": nominal_parameters(j),
                    "true_friction": element_to_table(joint_friction(j, scn.effects_on(j.name), scn.source)),
                    "true_spring": element_to_table(joint_spring(j, scn.effects_on(j.name), scn.source)),
                    "angle_sigma_rad": sig_q[j.name], "q_m_quantum_rad": float(quantum[i]),
                    "deflection_noise_sd_rad": noise[j.name],
                    "marker_radii_m": [float(r) for r in layout.axis_radius()[[layout.labels.index(s) for s in spec.link_markers]]],
                    "link_markers": list(spec.link_markers)}
                   for i, (j, spec) in enumerate(zip(scn.joints, specs))],
        "effects": [{"name": e.name, "joint": e.joint, "params": e.params} for e in scn.effects],
        "files": {"truth_controller": "truth.csv", "truth_mocap": "truth_mocap.csv"},
    }
    if with_concealment and scn.effects:
        tic = time.perf_counter()
        nominal = simulate_scenario(scn, with_effects=False)
        truth["effects"] = concealment(scn, sim, nominal, t_true, noise)
        timings["concealment"] = time.perf_counter() - tic
    truth["timings_s"] = timings
    return SimulatedRecording(recording=rec, truth=truth, sim=sim, q_true_mocap=q_true_mocap,
                              t_true_mocap=t_true, urdf=urdf, timings_s=timings)


def write_scenario_bundle(sr: SimulatedRecording, out_dir, scenario_file: Path | None = None) -> Path:
    """Write the bundle (recording.toml last), truth.json, truth.csv, truth_mocap.csv and the scenario."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rec = sr.recording
    if sr.urdf is not None:
        write_text_atomic(out / "robot.urdf", sr.urdf)
        rec = replace(rec, urdf=out / "robot.urdf")
    names = [j.name for j in rec.joints]
    cols = {"time": sr.sim[names[0]].t}
    for name in names:
        r = sr.sim[name]
        c = _column(r, name)
        for field in ("q", "q_m", "u", "tau_s", "delta"):
            cols[f"{field}_{name}"] = getattr(r, field)[:, c]
    write_csv_columns(out / "truth.csv", cols)
    mcols = {"t_mocap": rec.markers.t, "t_controller_true": sr.t_true_mocap}
    for i, name in enumerate(names):
        mcols[f"q_{name}"] = sr.q_true_mocap[:, i]
    write_csv_columns(out / "truth_mocap.csv", mcols)
    truth = dict(sr.truth)
    truth.pop("timings_s", None)  # wall-clock times would make bundles differ run to run
    write_json(out / "truth.json", truth)
    if scenario_file is not None and Path(scenario_file).resolve() != (out / "scenario.toml").resolve():
        shutil.copyfile(scenario_file, out / ".scenario.toml.tmp")
        (out / ".scenario.toml.tmp").replace(out / "scenario.toml")
    return write_recording(rec, out)

