"""The run's rerun recording (mocapfj.viz.rrd) read back with rerun.chunk.RrdReader: entity paths,
archetypes and logged values against the run's own files (angles.csv, joint.toml, joints.json,
identify.json, residuals.csv, frf.csv, the bundle's markers, rig and controller log); `mocapfj view`
without a viewer; bad input."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.io import load_recording, read_csv_columns, read_json, write_csv_columns
from mocapfj.io.geometry import read_joint_geometry

DATA = Path(__file__).parent / "data"
MAGNIFY = 10.0


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A run directory from real stage outputs: a 6 s PA-10 joint 2 simulation, its joints and
    identify stages, a closed-loop multisine FRF, and the real discovery outputs of tests/viz/data."""
    from mocapfj.ident.multisine import design_multisine
    from mocapfj.pipeline import default_scenario, run_identify, run_joints, run_simulate
    from mocapfj.pipeline.frf import run_frf
    from mocapfj.viz.rrd import write_run_recording

    from ..ident.frf_sim import simulate_multisine

    d = tmp_path_factory.mktemp("viz")
    rec, out = d / "rec", d / "run"
    run_simulate(default_scenario("pa10_joint2"), rec, duration_s=6.0, concealment=False)
    run_joints(rec, out / "joints")
    run_identify([rec], out / "identify", method="motor_first")
    shutil.copytree(DATA / "discover", out / "discover")
    fs = 1 / 0.003
    ms = design_multisine(fs, 1024, 0.5, 12.0, rms=0.01, seed=5)
    u, y, r = simulate_multisine(dict(J=0.75, I=1.165, k=1150.0, d=1.0, b=0.8, v=0.3), [ms], 6, kp=300.0, kd=30.0,
                                 noise_sd=1.0, seed=6)
    write_csv_columns(d / "log.csv", {"time": np.arange(u.shape[1]) / fs, "tau": u[0], "qm": y[0], "qref": r[0]})
    run_frf(d / "log.csv", out / "frf", input="tau", output="qm", reference="qref")
    (out / "run.json").write_text(json.dumps({
        "format": "mocapfj.run/1", "recording": str(rec.resolve()), "validation": None, "created_utc": "",
        "mocapfj_version": "test", "stages": [{"name": n, "status": "done", "dir": n, "files": [], "inputs_sha256": None,
                                               "seconds": None, "error": None}
                                              for n in ("joints", "identify", "discover", "frf")]}))
    rrd = write_run_recording(out, magnify=MAGNIFY)
    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    return {"rec": rec, "out": out, "rrd": rrd, "reader": reader, "store": reader.store()}


def _rows(store, path, column):
    """(times s, values) of one temporal column of an entity, in time order; values as a list."""
    ts, vs = [], []
    for ch in store.stream().filter(content=path).to_chunks():
        if ch.entity_path != path or ch.is_static:
            continue
        rb = ch.to_record_batch()
        if column not in rb.schema.names:
            continue
        ts.append(np.asarray(rb.column("time").cast("int64").to_numpy(zero_copy_only=False)) * 1e-9)
        vs += rb.column(column).to_pylist()
    if not ts:
        return np.empty(0), []
    t = np.concatenate(ts)
    order = np.argsort(t, kind="stable")
    return t[order], [vs[i] for i in order]


def _static(store, path, column):
    for ch in store.stream().filter(content=path).to_chunks():
        if ch.entity_path == path and ch.is_static:
            rb = ch.to_record_batch()
            if column in rb.schema.names:
                return rb.column(column).to_pylist()[0]
    raise AssertionError(f"no static {column} on {path}")


def _scalars(store, path):
    t, v = _rows(store, path, "Scalars:scalars")
    return t, np.array([x[0] for x in v])


def test_entities_and_archetypes(run):
    sch = run["store"].schema()
    paths = set(sch.entity_paths())
    for p in ("/world/cameras/cam_0", "/world/markers/j2_link", "/world/markers/j2_parent", "/world/joints/j2/axis",
              "/world/joints/j2/circles", "/world/joints/j2/magnified", "/world/joints/j2/rigid", "/world/links",
              "/plots/j2/angle/q", "/plots/j2/angle/q_m", "/plots/j2/deflection/delta", "/plots/j2/torque/tau",
              "/plots/j2/torque/spring", "/plots/j2/torque/spring_model", "/plots/j2/residuals/u/before",
              "/plots/j2/residuals/u/after", "/plots/j2/residuals/delta/after", "/loops/j2/measured",
              "/loops/j2/model", "/loops/j2/now", "/frf/magnitude/measured", "/frf/phase/model", "/summary"):
        assert p in paths, p
    arch = set(sch.archetypes())
    for a in ("Pinhole", "Points3D", "LineStrips3D", "Scalars", "SeriesLines", "SeriesPoints", "Points2D",
              "LineStrips2D", "Transform3D", "TextDocument", "TextLog"):
        assert f"rerun.archetypes.{a}" in arch, a
    assert run["reader"].blueprints(), "no default blueprint"
    assert subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(run["rrd"])], capture_output=True).returncode == 0


def test_joint_series_equal_the_files(run):
    a = read_csv_columns(run["out"] / "joints" / "j2.angles.csv")
    store = run["store"]
    t, q = _scalars(store, "/plots/j2/angle/q")
    ok = np.isfinite(a["q"])
    np.testing.assert_array_equal(q, a["q"][ok])
    np.testing.assert_allclose(t, a["t_controller"][ok], atol=1e-9)
    t, d = _scalars(store, "/plots/j2/deflection/delta")
    np.testing.assert_array_equal(d, a["delta"][np.isfinite(a["delta"])])
    ctl = load_recording(run["rec"]).controller                     # q_m and tau at the controller's 1 kHz
    t, qm = _scalars(store, "/plots/j2/angle/q_m")
    np.testing.assert_array_equal(qm, ctl.q_m[:, 0])
    np.testing.assert_allclose(t, ctl.t, atol=1e-9)
    _, tau = _scalars(store, "/plots/j2/torque/tau")
    np.testing.assert_array_equal(tau, ctl.tau[:, 0])


def test_markers_and_cameras_equal_the_bundle(run):
    rec = load_recording(run["rec"])
    store = run["store"]
    t, pos = _rows(store, "/world/markers/j2_link", "Points3D:positions")
    _, labels = _rows(store, "/world/markers/j2_link", "Points3D:labels")
    m = rec.markers
    k = 100
    i = int(np.argmin(np.abs(m.t + rec.clock_offset_s - t[k])))
    for lab, p in zip(labels[k], pos[k]):
        np.testing.assert_allclose(p, m.xyz[i, m.labels.index(lab)], atol=1e-6)
    assert sorted(set(labels[k])) == sorted(rec.joints[0].link_markers)
    cam = rec.rig.cameras[3]
    K = np.array(_static(store, f"/world/cameras/{cam.name}", "Pinhole:image_from_camera"), dtype=float)
    np.testing.assert_allclose(K.reshape(3, 3).T, cam.K, rtol=1e-6)                 # stored column-major
    centre = np.array(_static(store, f"/world/cameras/{cam.name}", "Transform3D:translation")).ravel()
    np.testing.assert_allclose(centre, -cam.R_cam_world.T @ cam.t_cam_world, atol=1e-6)


def test_axis_and_circles_match_the_joint_calibration(run):
    js = read_json(run["out"] / "joints" / "joints.json")["joints"][0]
    _, g, _ = read_joint_geometry(run["out"] / "joints" / "j2.joint.toml")
    store = run["store"]
    seg = np.array(_static(store, "/world/joints/j2/axis", "LineStrips3D:strips")[0])
    a_w, p_w = np.array(js["axis_world"]), np.array(js["point_world_m"])     # the joints stage's world axis
    direction = (seg[1] - seg[0]) / np.linalg.norm(seg[1] - seg[0])
    assert np.degrees(np.arccos(min(1.0, abs(direction @ a_w)))) < 0.01
    np.testing.assert_allclose(0.5 * (seg[0] + seg[1]), p_w, atol=2e-5)
    np.testing.assert_allclose(np.linalg.norm(seg[1] - seg[0]), 0.5, rtol=1e-5)
    circles = [np.array(c) for c in _static(store, "/world/joints/j2/circles", "LineStrips3D:strips")]
    assert len(circles) == len(g.radii)
    for c, radius in zip(circles, g.radii):                  # every point at the fitted radius from the axis
        v = c - p_w
        dist = np.linalg.norm(v - np.outer(v @ a_w, a_w), axis=1)
        np.testing.assert_allclose(dist, radius, atol=2e-5)
        assert np.ptp(v @ a_w) < 1e-5                         # in one plane across the axis


def test_magnified_deflection(run):
    """The magnified link is turned from the rigid one (q_m) by MAGNIFY x the deflection, about the axis."""
    js = read_json(run["out"] / "joints" / "joints.json")["joints"][0]
    a = read_csv_columns(run["out"] / "joints" / "j2.angles.csv")
    store = run["store"]
    t, rigid = _rows(store, "/world/joints/j2/rigid", "Points3D:positions")
    _, mag = _rows(store, "/world/joints/j2/magnified", "Points3D:positions")
    ok = np.isfinite(a["q_m"]) & np.isfinite(a["delta"])
    np.testing.assert_allclose(t, a["t_controller"][ok], atol=1e-9)
    a_w, p_w = np.array(js["axis_world"]), np.array(js["point_world_m"])
    k = int(np.argmax(np.abs(a["delta"][ok])))
    r, m = np.array(rigid[k])[0] - p_w, np.array(mag[k])[0] - p_w
    r, m = r - (r @ a_w) * a_w, m - (m @ a_w) * a_w
    angle = np.arctan2(np.cross(r, m) @ a_w, r @ m)           # from rigid to magnified, about the axis
    np.testing.assert_allclose(angle, -MAGNIFY * a["delta"][ok][k], rtol=1e-4)       # float32 positions


def test_spring_loop_and_model(run):
    """The loop's model points are the identified linear spring; the motor-side spring torque
    follows the deflection with that stiffness (Lightcap and Banks 2007, Fig. 6)."""
    ident = read_json(run["out"] / "identify" / "identify.json")["joints"][0]
    k, tau0 = ident["spring"]["params"]["k"], ident["spring"]["params"]["tau0"]
    store = run["store"]
    model = np.array(_static(store, "/loops/j2/model", "Points2D:positions"))
    np.testing.assert_allclose(model[:, 1], k * model[:, 0] * 1e-3 + tau0, rtol=1e-6, atol=1e-4)   # float32
    meas = np.array(_static(store, "/loops/j2/measured", "Points2D:positions"))
    slope = np.polyfit(meas[:, 0] * 1e-3, meas[:, 1], 1)[0]
    assert abs(slope / k - 1) < 0.05, (slope, k)
    _, now = _rows(store, "/loops/j2/now", "Points2D:positions")
    np.testing.assert_allclose(np.array(now, dtype=float).reshape(-1, 2), meas, rtol=1e-6)


def test_residuals_and_located_windows(run):
    r = read_csv_columns(DATA / "discover" / "residuals.csv")
    store = run["store"]
    for key in ("delta_before", "delta_after", "u_before", "u_after"):
        t, v = _scalars(store, f"/plots/j2/residuals/{key.split('_')[0]}/{key.split('_')[1]}")
        ok = np.isfinite(r[f"j2_r_{key}"])
        np.testing.assert_array_equal(v, r[f"j2_r_{key}"][ok])
        np.testing.assert_allclose(t, r["t"][ok], atol=1e-9)
    t, v = _scalars(store, "/plots/j2/residuals/located/spring_0")     # discovery's worst spring window, 42-44 s
    inside = (r["t"] >= 42.0) & (r["t"] <= 44.0)
    np.testing.assert_array_equal(v, r["j2_r_u_before"][inside])
    assert t.min() >= 42.0 and t.max() <= 44.0


def test_frf_equals_frf_csv(run):
    c = read_csv_columns(run["out"] / "frf" / "frf.csv")
    store = run["store"]
    strip = np.array(_static(store, "/frf/magnitude/measured", "LineStrips2D:strips")[0])
    np.testing.assert_allclose(strip[:, 0], np.log10(c["f_hz"]), atol=1e-6)
    np.testing.assert_allclose(strip[:, 1], 20 * np.log10(np.hypot(c["G_real"], c["G_imag"])), atol=1e-4)
    model = np.array(_static(store, "/frf/magnitude/model", "LineStrips2D:strips")[0])
    np.testing.assert_allclose(model[:, 1], 20 * np.log10(np.hypot(c["model_real"], c["model_imag"])), atol=1e-4)


def test_plot_transform_puts_y_up():
    from mocapfj.viz.rrd_plots import PLOT_H, PLOT_W, plot_transform

    tr, sc = plot_transform((-2.0, 6.0), (10.0, 30.0))
    to_screen = lambda x, y: tr[:2] + sc[:2] * np.array([x, y])          # noqa: E731
    np.testing.assert_allclose(to_screen(-2.0, 10.0), [0.0, PLOT_H])   # lower-left data corner at the bottom
    np.testing.assert_allclose(to_screen(6.0, 30.0), [PLOT_W, 0.0])


def test_urdf_posed_by_measured_angles(run, tmp_path):
    """A bundle with a URDF: the robot is logged and its joint j2 turned by the measured q."""
    from mocapfj.io import write_text_atomic
    from mocapfj.synth.urdf import pa10_urdf
    from mocapfj.viz.rrd import write_recording_file
    from mocapfj.viz.rrd_data import load_run

    rec = tmp_path / "rec"
    shutil.copytree(run["rec"], rec)
    write_text_atomic(rec / "robot.urdf", pa10_urdf([2], joint_names=["j2"]))
    toml = (rec / "recording.toml").read_text()
    (rec / "recording.toml").write_text(toml + '\n[model]\nurdf = "robot.urdf"\n')
    out = tmp_path / "run"
    shutil.copytree(run["out"] / "joints", out / "joints")
    (out / "run.json").write_text(json.dumps({"format": "mocapfj.run/1", "recording": str(rec), "stages": []}))
    contents = load_run(out)
    assert contents.urdf is not None
    from rerun.chunk import RrdReader

    store = RrdReader(write_recording_file(contents, out / "recording.rrd")).store()
    paths = set(store.schema().entity_paths())
    assert any(p.startswith("/robot/") for p in paths) and "/world/links" not in paths
    a = read_csv_columns(out / "joints" / "j2.angles.csv")
    t, quat = _rows(store, "/robot_joints/j2", "Transform3D:quaternion")
    ok = np.isfinite(a["q"])
    assert len(quat) == ok.sum()
    from scipy.spatial.transform import Rotation

    R = Rotation.from_quat(np.array(quat, dtype=float).reshape(-1, 4))       # x, y, z, w: origin x R(axis, q)
    turn = (R[0].inv() * R).magnitude()                                      # |q - q[0]| about the joint's axis
    np.testing.assert_allclose(turn, np.abs(a["q"][ok] - a["q"][ok][0]), atol=1e-5)


def test_single_command_out_and_bad_input(run, tmp_path):
    from mocapfj.viz.rrd import write_run_recording

    d = tmp_path / "discover"
    shutil.copytree(DATA / "discover", d)
    from rerun.chunk import RrdReader

    paths = set(RrdReader(write_run_recording(d)).store().schema().entity_paths())
    assert "/plots/j2/residuals/u/after" in paths and "/summary" in paths
    with pytest.raises(InputError, match="run directory"):
        write_run_recording(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="results"):
        write_run_recording(tmp_path / "empty")


def test_view_builds_when_stale_without_opening(run, tmp_path):
    import os

    from mocapfj.pipeline.view import recording_is_stale, run_view, viewer_command, web_url

    out = tmp_path / "run"
    shutil.copytree(run["out"] / "identify", out / "identify")
    s = run_view(out, open_viewer=False)
    assert s["built"] and Path(s["recording"]).is_file() and not recording_is_stale(out)
    assert not run_view(out, open_viewer=False)["built"]
    later = Path(s["recording"]).stat().st_mtime + 10
    os.utime(out / "identify" / "identify.json", (later, later))
    assert recording_is_stale(out) and run_view(out, open_viewer=False)["built"]
    cmd = viewer_command(out / "recording.rrd", web=True, web_port=9191, grpc_port=9877)
    assert cmd[:4] == [sys.executable, "-m", "rerun", str(out / "recording.rrd")] and "--web-viewer" in cmd
    assert cmd[cmd.index("--web-viewer-port") + 1] == "9191" and cmd[cmd.index("--port") + 1] == "9877"
    assert web_url("h", 9191, 9877) == "http://h:9191/?url=rerun%2Bhttp%3A%2F%2Fh%3A9877%2Fproxy"


def test_view_cli_bad_input_exits_2(tmp_path):
    p = subprocess.run([sys.executable, "-m", "mocapfj.cli", "view", str(tmp_path / "missing"), "--no-open"],
                       capture_output=True, text=True)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "run directory" in p.stderr
