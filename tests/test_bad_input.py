"""Bad input as a user meets it, through the command line: one line naming the file, the field and
what was expected, exit 2, no traceback (the C3D cases are in tests/io/test_c3d.py and
tests/test_cli.py)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.io import write_recording
from mocapfj.synth import toy_recording


def _cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "mocapfj.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


def _one_line_error(r, *needles):
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    for n in needles:
        assert n in r.stderr, r.stderr


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    d = tmp_path_factory.mktemp("bad") / "toy"
    write_recording(toy_recording(duration_s=3.0), d)
    return d


def _edit_csv(b, fn):
    """The bundle's controller CSV rewritten by fn(head, rows) -> rows (rows: lists of cells);
    returns the file and its header."""
    csv = b / "controller.csv" if (b / "controller.csv").is_file() else next(b.glob("*.csv"))
    lines = csv.read_text().splitlines()
    head = lines[0].split(",")
    rows = fn(head, [ln.split(",") for ln in lines[1:]])
    csv.write_text("\n".join([lines[0]] + [",".join(r) for r in rows]) + "\n")
    return csv, head


def _set_column(prefix, f):
    """An _edit_csv function: the first column whose name starts with prefix mapped by f (cell -> cell)."""
    def edit(head, rows):
        j = next(i for i, c in enumerate(head) if c.startswith(prefix))
        for r in rows:
            r[j] = f(r[j])
        return rows
    return edit


def _copy(bundle, tmp_path):
    import shutil

    shutil.copytree(bundle, tmp_path / "b")
    return tmp_path / "b"


def test_a_non_utf8_byte_in_recording_toml(bundle, tmp_path):
    b = _copy(bundle, tmp_path)
    with open(b / "recording.toml", "ab") as f:
        f.write(b"# \xff\n")
    _one_line_error(_cli("inspect", b), "recording.toml: byte ", "expected UTF-8 text, got byte 0xff")


def test_a_non_utf8_byte_in_the_controller_csv(bundle, tmp_path):
    b = _copy(bundle, tmp_path)
    csv = next(b.glob("*.csv"))
    raw = csv.read_bytes()
    i = raw.index(b"\n", 100)
    csv.write_bytes(raw[:i] + b"\xe9" + raw[i:])
    _one_line_error(_cli("inspect", b), f"{csv.name}: byte {i}: expected UTF-8 text, got byte 0xe9")


def test_a_torque_column_of_zeros(bundle, tmp_path):
    b = _copy(bundle, tmp_path)
    _edit_csv(b, _set_column("tau", lambda v: "0"))
    _one_line_error(_cli("identify", b, "--out", tmp_path / "o", "--method", "two_step"),
                    "controller log tau", "expected a motor torque that varies", "the constant 0 in all")


@pytest.mark.parametrize("factor, says", [(100000, "a factor that leaves at least 200"),
                                          (0, "an integer decimation factor >= 1")])
def test_a_decimation_the_recording_cannot_take(bundle, tmp_path, factor, says):
    _one_line_error(_cli("identify", bundle, "--out", tmp_path / "o", "--decimate", factor), "(decimate)", says)


# -- outputs: whole or nothing, never over an input ----------------------------------------------

def _tree(d):
    return sorted((str(p.relative_to(d)), p.stat().st_size) for p in d.rglob("*"))


def test_out_may_not_be_inside_or_contain_an_input(bundle, tmp_path):
    before = _tree(bundle)
    _one_line_error(_cli("joints", bundle, "--out", bundle), "--out: path: expected a directory that is not")
    _one_line_error(_cli("joints", bundle, "--out", bundle / "res"), "expected a directory outside the input bundles")
    _one_line_error(_cli("joints", bundle / "recording.toml", "--out", bundle.parent), "does not contain an input")
    assert _tree(bundle) == before
    # discover --model OUT/model.toml --out OUT would overwrite its own input model
    out = tmp_path / "out"
    out.mkdir()
    (out / ".mocapfj-output").write_text("")
    (out / "model.toml").write_text("mine\n")
    _one_line_error(_cli("discover", bundle, "--model", out / "model.toml", "--out", out), "holds the input")
    assert (out / "model.toml").read_text() == "mine\n"


def test_out_holding_other_files_is_refused_and_kept(bundle, tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me\n")
    _one_line_error(_cli("joints", bundle, "--out", out), "expected a new or empty directory", "holds other files")
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


def test_a_failed_run_leaves_nothing_and_a_second_run_replaces_the_first(bundle, tmp_path):
    out = tmp_path / "o"
    r = _cli("identify", bundle, "--out", out, "--decimate", "100000")
    _one_line_error(r, "(decimate)")
    assert not out.exists() and list(tmp_path.iterdir()) == []         # no OUT/00_<name>/joints, no staging
    assert _cli("joints", bundle, "--out", out).returncode == 0
    first = _tree(out)
    assert ("joints.json" in {n for n, _ in first}) and ".mocapfj-output" in {n for n, _ in first}
    assert _cli("joints", bundle, "--out", out).returncode == 0
    assert _tree(out) == first and sorted(p.name for p in tmp_path.iterdir()) == ["o"]


def test_a_killed_runs_staging_directory_is_removed_by_the_next_run(bundle, tmp_path):
    stale = tmp_path / ".o.999999999.mocapfj-tmp"                      # no such process
    (stale / "joints").mkdir(parents=True)
    assert _cli("joints", bundle, "--out", tmp_path / "o").returncode == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]


def test_an_interrupt_as_the_staging_directory_is_made_leaves_nothing(tmp_path, monkeypatch):
    """A Ctrl-C that lands as the staging directory has just been made (before the block that
    removes it on failure) left it behind: the test below failed so under load."""
    from pathlib import Path

    from mocapfj.io.outdir import staged_output

    real = Path.mkdir

    def mkdir(self, *a, **k):
        real(self, *a, **k)
        if self.name.endswith(".mocapfj-tmp"):
            raise KeyboardInterrupt

    monkeypatch.setattr(Path, "mkdir", mkdir)
    with pytest.raises(KeyboardInterrupt):
        with staged_output(tmp_path / "o"):
            pass
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("sig, code, says", [("SIGINT", 130, "interrupted"), ("SIGTERM", 143, "terminated")])
def test_ctrl_c_and_sigterm_print_one_line_and_leave_nothing(bundle, tmp_path, sig, code, says):
    import signal
    import time

    out = tmp_path / "o"
    # two_step: seconds of work after the staging directory appears (the default output error refuses a
    # 3 s trial at once, which under load could end the run before the signal lands)
    p = subprocess.Popen([sys.executable, "-m", "mocapfj.cli", "identify", str(bundle), "--out", str(out),
                          "--method", "two_step"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # (a suite started in the background inherits SIGINT ignored, and a Python started so keeps it)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".o.*.mocapfj-tmp")) and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert p.poll() is None, "the run ended before it could be interrupted"
    p.send_signal(getattr(signal, sig))
    _, err = p.communicate(timeout=60)
    # a shell reads exit(128 + n) and death by signal n alike ($? = 128 + n): at times (1 run in 6
    # on an idle machine, before this session's changes too) the interpreter ends by the signal
    # after the message, which is the same to the user
    assert p.returncode in (code, 128 - code) and err.count("\n") == 1 and says in err and "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == []


# -- files named in recording.toml stay inside the bundle ----------------------------------------

def _name_controller(b, name):
    t = (b / "recording.toml").read_text()
    csv = next(b.glob("*.csv")).name
    (b / "recording.toml").write_text(t.replace(f'file = "{csv}"', f'file = "{name}"'))
    return csv


def test_a_file_outside_the_bundle_is_refused_without_printing_it(bundle, tmp_path):
    b = _copy(bundle, tmp_path)
    _name_controller(b, "/etc/passwd")
    r = _cli("inspect", b)
    _one_line_error(r, "controller.file: expected a file inside the bundle", "'/etc/passwd', which resolves outside it",
                    "--allow-outside-bundle")
    assert "root:" not in r.stderr
    # ../ and a symlink leading out: refused, and read when the user says so
    b2 = _copy(bundle, tmp_path / "two")
    csv = _name_controller(b2, "../log.csv")
    (b2 / csv).rename(tmp_path / "two" / "log.csv")
    _one_line_error(_cli("inspect", b2), "'../log.csv', which resolves outside it")
    assert _cli("inspect", b2, "--allow-outside-bundle").returncode == 0
    b3 = _copy(bundle, tmp_path / "three")
    csv = next(b3.glob("*.csv"))
    csv.rename(tmp_path / "three" / "elsewhere.csv")
    csv.symlink_to(tmp_path / "three" / "elsewhere.csv")
    _one_line_error(_cli("inspect", b3), f"'{csv.name}', which resolves outside it")


def test_a_bad_cell_is_located_not_echoed(bundle, tmp_path):
    b = _copy(bundle, tmp_path)

    def secret(head, rows):
        rows[2][1] = "secret"
        return rows

    _edit_csv(b, secret)
    r = _cli("inspect", b)
    _one_line_error(r, "row 4 column", "expected a number, got 6 characters of text")
    assert "secret" not in r.stderr


# -- an undeclared clock offset: estimated with the dynamics, reported, never silent physics ------

@pytest.fixture(scope="module")
def pa10_20s(tmp_path_factory):
    from pathlib import Path

    root = tmp_path_factory.mktemp("clock")
    scn = Path(__file__).resolve().parents[1] / "datasets" / "pa10_joint2.toml"
    r = _cli("simulate", scn, "--out", root / "p", "--duration", "20", "--no-concealment", timeout=300)
    assert r.returncode == 0, r.stderr
    return root / "p"


def _shift_controller(src, dst, seconds):
    import shutil

    shutil.copytree(src, dst)
    _edit_csv(dst, _set_column("time", lambda v: repr(float(v) + seconds)))
    return dst


def test_an_undeclared_10_ms_clock_offset_is_found_and_what_it_moves_is_flagged(pa10_20s, tmp_path):
    """The controller log's clock 10 ms behind the mocap's, recording.toml declaring none: the
    offset is fitted with the dynamics (the link's own lag stays the model's), reported within
    0.5 ms, and the viscous split it moves (v ~ k dt: 30-40 % per millisecond here) is flagged
    not determined instead of reported as v +28 %, b -22 % with small SDs."""
    import json

    b = _shift_controller(pa10_20s, tmp_path / "b", 0.010)
    r = _cli("identify", b, "--out", tmp_path / "o", "--json", timeout=600)
    assert r.returncode == 0, r.stderr
    (j,) = json.loads(r.stdout)["joints"]
    clk = j["clock_offset"]
    assert clk["found"] and not clk["applied"] and abs(clk["offset_s"] - 0.010) < min(5e-4, 3 * clk["sd_s"])
    assert not j["params"]["v"]["determined"] and not j["params"]["b"]["determined"]
    assert "clock offset" in j["params"]["v"]["reason"] and "--fit-clock-offset" in j["params"]["v"]["reason"]
    # applied on request: the offset's own uncertainty (about a millisecond) keeps the split open
    r = _cli("identify", b, "--out", tmp_path / "o2", "--json", "--fit-clock-offset", timeout=600)
    (j,) = json.loads(r.stdout)["joints"]
    assert j["clock_offset"]["applied"] and not j["params"]["v"]["determined"]
    for n in ("mglx", "c", "k"):
        p = j["params"][n]
        assert p["determined"] and abs(p["value"] - {"mglx": 111.64, "c": 9.28, "k": 1.19e4}[n]) < 3 * p["std"] + 0.02 * abs(p["value"])


def test_the_declared_synchronisation_is_not_second_guessed(pa10_20s, tmp_path):
    import json

    r = _cli("identify", pa10_20s, "--out", tmp_path / "o", "--json", timeout=600)
    (j,) = json.loads(r.stdout)["joints"]
    assert not j["clock_offset"]["found"] and abs(j["clock_offset"]["offset_s"]) < 1e-3


# -- data consistent in form and wrong in fact --------------------------------------------------

def test_millimetres_labelled_as_metres(bundle, tmp_path):
    import ezc3d

    b = _copy(bundle, tmp_path)
    c3d = next(b.glob("*.c3d"))
    c = ezc3d.c3d(str(c3d))
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    c.write(str(c3d))
    _one_line_error(_cli("inspect", b), f"{c3d.name}: POINT:UNITS: expected units that make joint",
                    "m across", "millimetre coordinates labelled as metres?")


@pytest.mark.parametrize("scale, says", [(180 / 3.141592653589793, "q_m looks like degrees"),
                                         (2.0, "check gear_ratio")])
def test_a_motor_angle_in_the_wrong_unit(bundle, tmp_path, scale, says):
    b = _copy(bundle, tmp_path)
    csv, head = _edit_csv(b, _set_column("qm", lambda v: repr(float(v) * scale)))
    qm = next(c for c in head if c.startswith("qm"))
    _one_line_error(_cli("joints", b, "--out", tmp_path / "o"), f"{csv.name}: {qm} (joint",
                    "expected a motor angle on the link side", says)


def test_a_link_resonating_under_a_fast_excitation_is_not_a_wrong_unit():
    """A multisine through the joint's resonance moves the link 7x more than the motor at 6 Hz:
    the scale is judged below 1 Hz, where the link follows the motor (slope 1: no error); the
    same record with q_m in degrees is still refused."""
    from types import SimpleNamespace

    from mocapfj.joints.stage import _check_motor_scale

    fs = 250.0
    t = np.arange(int(30 * fs)) / fs
    q_m = 0.1 * np.sin(2 * np.pi * 0.3 * t) + 0.02 * np.sin(2 * np.pi * 6.0 * t)
    q = 0.1 * np.sin(2 * np.pi * 0.3 * t) + 0.14 * np.sin(2 * np.pi * 6.0 * t + 0.4)
    rec = SimpleNamespace(markers=SimpleNamespace(rate_hz=fs), root=None, controller_file="")
    spec = SimpleNamespace(gear_ratio=50.0, motor_position="qm_j2", name="j2")
    assert abs(float(np.polyfit(q, q_m, 1)[0]) - 1) > 0.5                 # unfiltered it would look wrong
    _check_motor_scale(rec, spec, q, q_m)
    with pytest.raises(InputError, match="q_m looks like degrees"):
        _check_motor_scale(rec, spec, q, np.degrees(q_m))


def test_swapped_labels_and_a_spike_are_repaired_and_reported(bundle, tmp_path):
    """Two link markers' trajectories exchanged from t = 1.5 s and a 5-frame 0.5 m spike on a
    third: relabelled from the cluster's pose (the pose jumps where the labels change) and the
    spike removed, both counted; the angles are those of the clean recording."""
    import json
    from dataclasses import replace

    from mocapfj.io import load_recording, read_c3d, write_c3d

    b = _copy(bundle, tmp_path)
    spec = load_recording(b).joints[0]
    c3d = next(b.glob("*.c3d"))
    m = read_c3d(c3d)
    i, j, k = (m.index(s) for s in spec.link_markers[:3])
    x = m.xyz.copy()
    late = m.t >= 1.5
    x[late, i], x[late, j] = m.xyz[late, j], m.xyz[late, i]
    x[200:205, k] += 0.5
    write_c3d(c3d, replace(m, xyz=x))
    clean = json.loads(_cli("joints", bundle, "--out", tmp_path / "c", "--json").stdout)["joints"][0]
    r = _cli("joints", b, "--out", tmp_path / "o", "--json")
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)["joints"][0]
    rep = got["marker_repairs"]["link"]
    assert rep["swaps"] == [{"labels": [spec.link_markers[0], spec.link_markers[1]], "frames": int(late.sum()),
                             "from_s": pytest.approx(1.5)}]
    assert rep["removed"] == {spec.link_markers[2]: 5}
    assert got["angle_marker_rms_mm"] == pytest.approx(clean["angle_marker_rms_mm"], rel=0.02)
    assert got["q_range_deg"] == pytest.approx(clean["q_range_deg"], abs=0.05)


# -- fuzz: mutated bytes of every input file ----------------------------------------------------

def _fuzz_once(bundle, tmp_path, name, data):
    import contextlib
    import io
    import shutil
    import warnings

    from mocapfj.cli import main

    d = tmp_path / f"f{data.draw(st_ints(0, 10**9))}"
    shutil.copytree(bundle, d)
    f = next(d.glob(name))
    raw = bytearray(f.read_bytes())
    for _ in range(data.draw(st_ints(1, 6))):
        i = data.draw(st_ints(0, len(raw) - 1))
        raw[i] = data.draw(st_ints(0, 255))
    if data.draw(st_bools()):
        raw = raw[:data.draw(st_ints(0, len(raw)))]
    f.write_bytes(bytes(raw))
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("error")                  # numpy's warnings are handled where they arise
        code = main(["inspect", str(d)])
    shutil.rmtree(d)
    assert code in (0, 2)
    assert err.getvalue().count("\n") == (1 if code == 2 else 0), err.getvalue()


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

st_ints, st_bools = st.integers, st.booleans


@pytest.mark.parametrize("name", ["recording.toml", "*.csv", "*.c3d"])
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_mutated_input_files_give_exit_0_or_one_line_and_2(bundle, tmp_path_factory, name, data):
    _fuzz_once(bundle, tmp_path_factory.mktemp("fuzz"), name, data)


def test_negative_friction_is_a_finding_not_a_result(pa10_20s, tmp_path):
    """Motor-first on the 10 ms offset: v = -99 and b = 144 came out as a normal result; a negative
    friction is reported not determined with its likely causes, and its split partner with it."""
    import json

    b = _shift_controller(pa10_20s, tmp_path / "b", 0.010)
    r = _cli("identify", b, "--out", tmp_path / "o", "--json", "--method", "motor_first", timeout=600)
    assert r.returncode == 0, r.stderr
    p = json.loads(r.stdout)["joints"][0]["params"]
    assert p["v"]["value"] < 0 and not p["v"]["determined"] and "clock offset" in p["v"]["reason"]
    assert not p["b"]["determined"] and "partner v came out negative" in p["b"]["reason"]


def test_metres_labelled_as_millimetres(bundle, tmp_path):
    import ezc3d

    b = _copy(bundle, tmp_path)
    c3d = next(b.glob("*.c3d"))
    c = ezc3d.c3d(str(c3d))
    c["data"]["points"][:3] /= 1000.0                   # the coordinates in metres, the label still mm
    c.write(str(c3d))
    _one_line_error(_cli("inspect", b), "POINT:UNITS: expected units that make joint",
                    "metre coordinates labelled as millimetres?")


@pytest.mark.parametrize("old, new, says", [
    ("gear_ratio = ", "gear_ratio = inf #", "gear_ratio: expected a positive, finite gear ratio, got inf"),
    ("clock_offset_s = ", "clock_offset_s = nan #", "markers.clock_offset_s: expected a finite offset in seconds, at most a "
                                                    "day, got nan"),
    ("clock_offset_s = ", "clock_offset_s = 1e308 #", "at most a day, got 1e+308"),
    ("[controller]", "[sync]\nduration_tolerance_s = nan\n\n[controller]",
     "sync.duration_tolerance_s: expected a non-negative, finite tolerance in seconds, got nan")])
def test_non_finite_numbers_in_recording_toml_name_the_key(bundle, tmp_path, old, new, says):
    b = _copy(bundle, tmp_path)
    t = (b / "recording.toml").read_text()
    assert old in t
    (b / "recording.toml").write_text(t.replace(old, new, 1))
    _one_line_error(_cli("inspect", b), f"recording.toml: {says}" if "sync" in says or "markers" in says else says)



# -- found by an adversarial sweep (247 corrupted bundles) ---------------------------------------

def _edit_toml(b, old, new):
    t = (b / "recording.toml").read_text()
    assert old in t
    (b / "recording.toml").write_text(t.replace(old, new, 1))


@pytest.mark.parametrize("name", ["../../evil", "", "j2\\u0000x", "j" * 300])
def test_a_joint_name_that_would_make_a_path(bundle, tmp_path, name):
    b = _copy(bundle, tmp_path)
    t = (b / "recording.toml").read_text()
    import re

    (b / "recording.toml").write_text(re.sub(r'name = "j1"', lambda m: f'name = "{name}"', t, count=1))
    _one_line_error(_cli("joints", b, "--out", tmp_path / "o"), "joints[0].name: expected a joint name of 1-64")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b"]          # nothing written anywhere


def test_odd_files_and_values(bundle, tmp_path):
    b = _copy(bundle, tmp_path)
    c3d = next(b.glob("*.c3d"))
    c3d.unlink()
    c3d.symlink_to(c3d.name)                                               # a symlink to itself
    _one_line_error(_cli("inspect", b), "markers.file: expected a file inside the bundle", "a symlink that leads to itself")
    b = _copy(bundle, tmp_path / "2")
    _edit_toml(b, 'format = "mocapfj.recording/1"', 'format = "mocapfj.recording/' + "9" * 5000 + '"')
    r = _cli("inspect", b)
    _one_line_error(r, "format: expected format")
    assert len(r.stderr) < 300
    (tmp_path / "afile").write_text("")
    _one_line_error(_cli("joints", bundle, "--out", tmp_path / "afile" / "sub"), "--out: path: expected a directory whose "
                                                                                 "parents are directories")


def test_the_same_recording_twice_is_not_two_trials(bundle, tmp_path):
    import shutil

    shutil.copytree(bundle, tmp_path / "copy")
    _one_line_error(_cli("identify", bundle, tmp_path / "copy", "--out", tmp_path / "o", "--method", "two_step"),
                    "expected distinct recordings", "hold the same data")


def _edit_times(b, fn):
    """_edit_csv with fn(index of the time column, rows) -> rows."""
    return _edit_csv(b, lambda head, rows: fn(head.index("time"), rows))[0]


def test_a_controller_log_with_a_gap_or_at_2_hz(bundle, tmp_path):
    b = _copy(bundle, tmp_path)
    csv = _edit_times(b, lambda i, rows: rows[:1000] + rows[1050:])
    _one_line_error(_cli("inspect", b), f"{csv.name}: column 'time': expected a log without gaps", "rows missing between")
    b = _copy(bundle, tmp_path / "2")
    csv = _edit_times(b, lambda i, rows: rows[::500] + ([rows[-1]] if (len(rows) - 1) % 500 else []))
    _one_line_error(_cli("inspect", b), f"{csv.name}: column 'time': expected a controller log at half the mocap rate")


def test_jittered_stamps_of_a_uniform_log_are_put_back_on_its_tick(bundle, tmp_path):
    """Stamps scattered by +-0.3 ms around a 1 ms tick (the values sampled on the tick): read on
    the tick, which the summary says; the joints' deflection is that of the clean log."""
    import json

    rng = np.random.default_rng(0)

    def jitter(i, rows):
        for r in rows[1:-1]:
            r[i] = repr(float(r[i]) + rng.uniform(-3e-4, 3e-4))
        return rows

    b = _copy(bundle, tmp_path)
    _edit_times(b, jitter)
    r = _cli("inspect", b, "--json")
    assert r.returncode == 0 and "uniform 1 ms tick" in json.loads(r.stdout)["controller"]["time_note"]
    clean = json.loads(_cli("joints", bundle, "--out", tmp_path / "c", "--json").stdout)["joints"][0]
    got = json.loads(_cli("joints", b, "--out", tmp_path / "o", "--json").stdout)["joints"][0]
    assert got["deflection_rms_rad"] == pytest.approx(clean["deflection_rms_rad"], rel=1e-3)


# -- a second sweep: scenario files, URDFs, the Python API ---------------------------------------

@pytest.mark.parametrize("old, new, says", [
    ("controller_hz = 1000.0", "controller_hz = 1e9", "measurement.controller_hz: expected a rate in (0, 20000] Hz"),
    ("n_cameras = 8", "n_cameras = 100000", "measurement.n_cameras: expected 2 to 64 cameras"),
    ("marker_noise_m = 2.0e-4", "marker_noise_m = -1e-4", "measurement.marker_noise_m: expected a finite value >= 0")])
def test_a_scenario_that_would_exhaust_the_machine_or_crash(tmp_path, old, new, says):
    """controller_hz = 1e9 or 100000 cameras were killed for memory (24 GB), a negative noise a
    traceback: each is one line naming the scenario file and key, at once."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "datasets" / "pa10_joint2.toml").read_text()
    assert old in text
    scn = tmp_path / "s.toml"
    scn.write_text(text.replace(old, new, 1))
    _one_line_error(_cli("simulate", scn, "--out", tmp_path / "o", "--duration", "2", timeout=60), f"s.toml: {says}")


def test_a_transmission_error_of_1000_rad_is_refused_not_simulated_forever(tmp_path):
    from pathlib import Path

    src = Path(__file__).resolve().parents[1] / "datasets" / "suite" / "transmission_error_ident.toml"
    import re

    head, effects = src.read_text().split("[[effects]]", 1)
    text = head + "[[effects]]" + re.sub(r"amplitudes_rad = \[[^\]]*\]", "amplitudes_rad = [1e3, 1e3]", effects, count=1)
    (tmp_path / "te.toml").write_text(text)
    _one_line_error(_cli("simulate", tmp_path / "te.toml", "--out", tmp_path / "o", "--duration", "2", timeout=60),
                    "te.toml: effects[0].amplitudes_rad: expected values in [-0.1, 0.1]")


def test_a_bad_urdf_is_one_error_and_the_parser_stays_quiet(capfd):
    from mocapfj import InputError
    from mocapfj.io.urdf import build_pin_model

    good = ('<robot name="r"><link name="base"/><link name="l1"><inertial><mass value="{m}"/>'
            '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
            '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>'
            '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')
    assert build_pin_model(good.format(m=2.0)).njoints == 2
    for text, says in ((good.format(m="nan"), "mass \\[nan\\] is not a float"), ("<robot", "XML_ERROR")):
        with pytest.raises(InputError, match=rf"<URDF string>: urdf: expected a valid URDF, got .*{says}"):
            build_pin_model(text)
    assert capfd.readouterr().err == ""


def test_the_api_refuses_what_is_not_a_recording():
    import mocapfj
    from mocapfj import InputError

    for call in (lambda: mocapfj.load(None), lambda: mocapfj.joints(42), lambda: mocapfj.identify(None),
                 lambda: mocapfj.signals([])):
        with pytest.raises(InputError, match="expected"):
            call()


@pytest.mark.parametrize("old, new, says", [("k = ", "k = -1.0 #", "spring.k: expected a positive, finite stiffness"),
                                            ("gear_ratio = ", "gear_ratio = 0.0 #", "gear_ratio: expected a positive"),
                                            ("I = ", "I = -5.0 #", "].I: expected a positive, finite number")])
def test_a_model_file_with_impossible_values(tmp_path, old, new, says):
    """discover --model: a negative stiffness or a zero gear ratio was simulated (exit 0), a
    negative inertia failed as <argument>: each names the model file and key."""
    from pathlib import Path

    from mocapfj import InputError
    from mocapfj.discover import read_model_file
    from mocapfj.discover.model import write_model_file

    scn = Path(__file__).resolve().parents[1] / "datasets" / "pa10_joint2.toml"
    good = tmp_path / "good.toml"
    write_model_file(good, read_model_file(scn).values())
    text = good.read_text()
    assert old in text
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(old, new, 1))
    with pytest.raises(InputError) as e:
        read_model_file(bad)
    assert str(e.value).startswith(f"{bad}: joints[j2]") and says in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("old, new, says", [("seed = ", "seed = -1 #", "seed: expected a non-negative integer"),
                                            ("n_cameras = 8", "n_cameras = 8.5", "n_cameras: expected an integer"),
                                            ('"L2_2"', '"L2_1"', "link_markers: expected 3 or more distinct marker labels")])
def test_scenario_values_the_simulator_cannot_take(tmp_path, old, new, says):
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "datasets" / "pa10_joint2.toml").read_text()
    assert old in text
    (tmp_path / "s.toml").write_text(text.replace(old, new, 1))
    _one_line_error(_cli("simulate", tmp_path / "s.toml", "--out", tmp_path / "o", "--duration", "2", timeout=60),
                    f"s.toml: ", says)
