"""Bad input as a user meets it, through the command line: one line naming the file, the field and
what was expected, exit 2, no traceback (the C3D cases are in tests/io/test_c3d.py and
tests/test_cli.py)."""

from __future__ import annotations

import subprocess
import sys

import pytest

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
    csv = next(b.glob("*.csv"))
    lines = csv.read_text().splitlines()
    head = lines[0].split(",")
    j = next(i for i, c in enumerate(head) if c.startswith("tau"))
    rows = [",".join("0" if k == j else v for k, v in enumerate(ln.split(","))) for ln in lines[1:]]
    csv.write_text("\n".join([lines[0]] + rows) + "\n")
    _one_line_error(_cli("identify", b, "--out", tmp_path / "o", "--method", "two_step"),
                    "controller log tau", "expected a motor torque that varies", "the constant 0 in all")


@pytest.mark.parametrize("factor, says", [(100000, "a factor that leaves at least 200"),
                                          (0, "an integer decimation factor >= 1")])
def test_a_decimation_the_recording_cannot_take(bundle, tmp_path, factor, says):
    _one_line_error(_cli("identify", bundle, "--out", tmp_path / "o", "--decimate", factor), "(decimate)", says)
