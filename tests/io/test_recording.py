"""Recording bundles (mocapfj.io.recording): lossless round trip and every refused input."""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocapfj import InputError, MarkerTrajectories
from mocapfj.io import load_recording, read_toml, write_recording, write_toml
from mocapfj.synth import toy_recording


@pytest.fixture
def bundle(tmp_path) -> Path:
    write_recording(toy_recording(duration_s=1.0, seed=3), tmp_path / "b")
    return tmp_path / "b"


def edit_toml(bundle: Path, fn) -> None:
    doc = read_toml(bundle / "recording.toml")
    fn(doc)
    write_toml(bundle / "recording.toml", doc)


def assert_same_recording(a, b) -> None:
    assert a.name == b.name and a.clock_offset_s == b.clock_offset_s
    assert a.markers.labels == b.markers.labels and a.markers.rate_hz == b.markers.rate_hz
    np.testing.assert_allclose(b.markers.xyz, a.markers.xyz, rtol=1.2e-7, atol=1e-9, equal_nan=True)
    np.testing.assert_allclose(b.markers.t, a.markers.t, atol=1e-12)
    np.testing.assert_array_equal(b.controller.t, a.controller.t)
    np.testing.assert_array_equal(b.controller.q_m, a.controller.q_m)
    np.testing.assert_array_equal(b.controller.tau, a.controller.tau)
    assert list(a.controller.extra) == list(b.controller.extra)
    for k in a.controller.extra:
        np.testing.assert_array_equal(a.controller.extra[k], b.controller.extra[k])
    assert [vars(j) for j in a.joints] == [vars(j) for j in b.joints]


def test_toy_bundle_has_the_contract_keys(bundle):
    doc = tomllib.loads((bundle / "recording.toml").read_text())
    assert doc["format"] == "mocapfj.recording/1"
    assert doc["markers"]["file"] == "markers.c3d" and doc["markers"]["clock_offset_s"] == 0.0
    assert doc["controller"] == {"file": "controller.csv", "time_column": "time"}
    j = doc["joints"][0]
    assert set(j) == {"name", "motor_position", "motor_torque", "gear_ratio", "link_markers", "parent_markers"}


def test_round_trip_keeps_unknown_keys_and_extra_columns(bundle, tmp_path):
    edit_toml(bundle, lambda d: (d.update(operator="A. N. Other", notes={"load_kg": 4.5}),
                                 d["joints"][0].update(brake="on")))
    csv = bundle / "controller.csv"
    lines = csv.read_text().splitlines()
    csv.write_text("\n".join([lines[0] + ",temp_c"] + [ln + f",{20 + i * 0.001!r}" for i, ln in enumerate(lines[1:])]) + "\n")
    rec = load_recording(bundle)
    assert rec.spec["operator"] == "A. N. Other" and rec.joints[0].extra == {"brake": "on"}
    assert "temp_c" in rec.controller.extra
    write_recording(rec, tmp_path / "again")
    back = load_recording(tmp_path / "again")
    assert_same_recording(rec, back)
    assert read_toml(tmp_path / "again" / "recording.toml") == read_toml(bundle / "recording.toml")


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**16), offset=st.floats(-0.05, 0.05), trc=st.booleans(),
       world=st.booleans(), duration=st.floats(0.2, 1.5))
def test_bundle_round_trip_property(tmp_path_factory, seed, offset, trc, world, duration):
    rec = toy_recording(duration_s=duration, seed=seed)
    joint = replace(rec.joints[0], parent_markers="world") if world else rec.joints[0]
    rec = replace(rec, clock_offset_s=offset, joints=(joint,), marker_file="m.trc" if trc else "m.c3d")
    d = tmp_path_factory.mktemp("bundle")
    write_recording(rec, d)
    back = load_recording(d)
    assert_same_recording(rec, back)
    write_recording(back, d / "second")
    assert_same_recording(back, load_recording(d / "second"))


def test_inputs_are_never_modified(bundle, tmp_path):
    before = {p.name: p.read_bytes() for p in bundle.iterdir()}
    write_recording(load_recording(bundle), tmp_path / "out")
    assert {p.name: p.read_bytes() for p in bundle.iterdir()} == before


def test_rig_urdf_and_detections_travel_with_the_bundle(bundle, tmp_path):
    from mocapfj import Camera, Detections, Rig

    cam = Camera("c0", (640, 480), np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), np.zeros(5), np.eye(3), np.array([0, 0, 2.0]))
    det = Detections(frame=np.array([0, 0, 1]), camera=np.array([0, 1, 0]), xy_px=np.array([[1.5, 2.5], [3, 4], [5, 6]]),
                     point_id=np.array([2, -1, 0]))
    (tmp_path / "robot.urdf").write_text("<robot name='r'/>")
    cam1 = replace(cam, name="c1")                     # the detections name cameras 0 and 1
    rec = replace(load_recording(bundle), rig=Rig((cam, cam1)), detections=det, urdf=tmp_path / "robot.urdf")
    write_recording(rec, tmp_path / "full")
    back = load_recording(tmp_path / "full")
    assert back.urdf.read_text() == "<robot name='r'/>"
    np.testing.assert_allclose(back.rig.cameras[0].K, cam.K)
    np.testing.assert_array_equal(back.detections.xy_px, det.xy_px)
    np.testing.assert_array_equal(back.detections.point_id, det.point_id)


# -- bad input: each names the file, the field and what was expected ---------------------------

def test_missing_bundle(tmp_path):
    with pytest.raises(InputError, match=r"nothing: file: expected a recording bundle directory holding recording\.toml, got no such file"):
        load_recording(tmp_path / "nothing")


def test_missing_marker_file(bundle):
    (bundle / "markers.c3d").unlink()
    with pytest.raises(InputError, match=r"recording\.toml: markers\.file: expected an existing file inside .*got 'markers\.c3d' \(no such file\)"):
        load_recording(bundle)


def test_missing_controller_file(bundle):
    (bundle / "controller.csv").unlink()
    with pytest.raises(InputError, match=r"recording\.toml: controller\.file: expected an existing file.*'controller\.csv'"):
        load_recording(bundle)


def test_unknown_column(bundle):
    edit_toml(bundle, lambda d: d["joints"][0].update(motor_torque="tau_J1"))
    with pytest.raises(InputError, match=r"controller\.csv: column 'tau_J1' \(named by joints\[j1\]\.motor_torque\): "
                                         r"expected one of the CSV columns \['time', 'qm_j1', 'tau_j1'\], got no such column"):
        load_recording(bundle)


def test_unknown_time_column(bundle):
    edit_toml(bundle, lambda d: d["controller"].update(time_column="t"))
    with pytest.raises(InputError, match=r"controller\.csv: column 't' \(named by controller\.time_column\)"):
        load_recording(bundle)


def test_marker_label_not_in_c3d(bundle):
    edit_toml(bundle, lambda d: d["joints"][0].update(link_markers=["L1_1", "L1_2", "L9_9"]))
    with pytest.raises(InputError, match=r"markers\.c3d: marker 'L9_9' \(named by joints\[j1\]\): expected a label in the marker file "
                                         r"\(7 labels: L1_1, .*\), got no such label"):
        load_recording(bundle)


def test_marker_nan_in_every_frame(bundle, tmp_path):
    rec = load_recording(bundle)
    xyz = rec.markers.xyz.copy()
    xyz[:, 2] = np.nan
    m = MarkerTrajectories(t=rec.markers.t, xyz=xyz, labels=rec.markers.labels, rate_hz=rec.markers.rate_hz)
    write_recording(replace(rec, markers=m), tmp_path / "nan")
    with pytest.raises(InputError, match=r"markers\.c3d: marker 'L1_3' \(named by joints\[j1\]\): expected a marker seen in at least one frame, "
                                         r"got missing \(NaN\) in all 251 frames"):
        load_recording(tmp_path / "nan")


def test_non_monotonic_controller_time(bundle):
    csv = bundle / "controller.csv"
    lines = csv.read_text().splitlines()
    lines[5], lines[6] = lines[6], lines[5]
    csv.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"controller\.csv: column 'time': expected strictly increasing times, got 0\.004 after 0\.005 at row 7"):
        load_recording(bundle)


def test_streams_of_different_duration(bundle):
    csv = bundle / "controller.csv"
    lines = csv.read_text().splitlines()
    csv.write_text("\n".join(lines[:600]) + "\n")  # controller stops at 0.598 s, markers at 1.0 s
    with pytest.raises(InputError, match=r"recording\.toml: streams: expected marker and controller streams covering the same time span "
                                         r"within 0\.1 s, got markers 0\.0000\.\.1\.0000 s .* vs controller 0\.0000\.\.0\.5980 s"):
        load_recording(bundle)
    edit_toml(bundle, lambda d: d.update(sync={"duration_tolerance_s": 0.5}))
    assert load_recording(bundle).controller.n_samples == 599


def test_declared_offset_counts_in_the_span_check(bundle):
    edit_toml(bundle, lambda d: d["markers"].update(clock_offset_s=0.3))
    with pytest.raises(InputError, match=r"markers 0\.3000\.\.1\.3000 s"):
        load_recording(bundle)


def test_newer_format_version(bundle):
    edit_toml(bundle, lambda d: d.update(format="mocapfj.recording/2"))
    with pytest.raises(InputError, match=r"recording\.toml: format: expected version 1 or older, got version 2 "
                                         r"\(the file was written by a newer mocapfj: upgrade mocapfj to read it\)"):
        load_recording(bundle)


def test_missing_format(bundle):
    edit_toml(bundle, lambda d: d.pop("format"))
    with pytest.raises(InputError, match=r"recording\.toml: format: expected format = \"mocapfj\.recording/1\", got None"):
        load_recording(bundle)


def test_wrong_type(bundle):
    edit_toml(bundle, lambda d: d["joints"][0].update(gear_ratio="fifty"))
    with pytest.raises(InputError, match=r"recording\.toml: joints\[j1\]\.gear_ratio: expected a value of type integer or number, got 'fifty'"):
        load_recording(bundle)


def test_toml_syntax_error(bundle):
    (bundle / "recording.toml").write_text("format = \n")
    with pytest.raises(InputError, match=r"recording\.toml: syntax: expected valid TOML"):
        load_recording(bundle)


def test_wrong_marker_suffix(bundle):
    (bundle / "markers.c3d").rename(bundle / "markers.csv")
    edit_toml(bundle, lambda d: d["markers"].update(file="markers.csv"))
    with pytest.raises(InputError, match=r"markers\.csv: markers\.file: expected a \.c3d or \.trc file"):
        load_recording(bundle)
