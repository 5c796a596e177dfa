"""C3D reading and writing (mocapfj.io.c3d).

Real files: ../shared/realdata/c3d_samples — Kinetics Toolkit wheelchair-racing trials (metres,
~70 Hz) and the c3d.org Sample01 gait trial Eb015 in two encodings, REAL (pr) and INT (pi).
"""

from __future__ import annotations

import struct
import warnings

import ezc3d
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mocapfj import InputError, MarkerTrajectories
from mocapfj.io import read_c3d, write_c3d

SAMPLE01 = "c3d_samples/c3d_org_sample01"


def read_with_c3d_package(path):
    """The independent pure-Python reader: (xyz (F, M, 3) in file units, residual (F, M) or NaN, labels, rate, first)."""
    import c3d

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with open(path, "rb") as h:
            r = c3d.Reader(h)
            arr = np.stack([p.copy() for _, p, _ in r.read_frames()], 0)  # (F, M, 5)
            labels = tuple(s.strip() for s in r.point_labels)
            rate, first = r.point_rate, r.first_frame
    invalid = arr[:, :, 3] < 0
    xyz = arr[:, :, :3].astype(np.float64)
    xyz[invalid] = np.nan
    res = np.where(invalid, np.nan, arr[:, :, 3].astype(np.float64))
    return xyz, res, labels, rate, first


# -- real files -------------------------------------------------------------------------------

def test_every_real_c3d_loads_with_parameters_matching(realdata):
    files = sorted((realdata / "c3d_samples").rglob("*.c3d"))
    assert len(files) == 9
    for f in files:
        m = read_c3d(f)
        c = ezc3d.c3d(str(f))
        P = c["parameters"]["POINT"]
        assert m.n_frames == int(P["FRAMES"]["value"][0]) == c["data"]["points"].shape[2], f
        assert m.rate_hz == pytest.approx(float(P["RATE"]["value"][0])), f
        used = int(P["USED"]["value"][0])
        assert m.labels == tuple(s.strip() for s in P["LABELS"]["value"][:used]), f
        assert np.allclose(np.diff(m.t), 1.0 / m.rate_hz), f
        # metres: a lab is a few metres across whatever the file's unit
        assert 0.2 < np.nanmax(np.abs(m.xyz)) < 5.0, f


def test_sample01_real_and_int_encodings_agree_within_point_scale(realdata):
    pr = read_c3d(realdata / SAMPLE01 / "Eb015pr.c3d")
    pi = read_c3d(realdata / SAMPLE01 / "Eb015pi.c3d")
    scale_m = abs(float(ezc3d.c3d(str(realdata / SAMPLE01 / "Eb015pi.c3d"))["parameters"]["POINT"]["SCALE"]["value"][0])) * 1e-3
    assert pr.labels == pi.labels and pr.n_frames == pi.n_frames == 450 and pr.rate_hz == pi.rate_hz == 50.0
    assert np.array_equal(np.isnan(pr.xyz), np.isnan(pi.xyz))
    assert np.nanmax(np.abs(pr.xyz - pi.xyz)) <= scale_m  # 0.083 mm
    np.testing.assert_allclose(pr.residual, pi.residual, atol=1e-12, equal_nan=True)


def test_sample01_units_and_labels(realdata):
    m = read_c3d(realdata / SAMPLE01 / "Eb015pr.c3d")
    assert len(m.labels) == 26  # POINT:USED, though POINT:LABELS holds 48 names
    assert {"RTH1", "RTH2", "RTH3", "RTH4", "RSK1", "RSK2", "RSK3", "RSK4"} <= set(m.labels)
    raw = ezc3d.c3d(str(realdata / SAMPLE01 / "Eb015pr.c3d"))["data"]["points"]
    np.testing.assert_allclose(m.xyz[:, 0, :], raw[:3, 0, :].T * 1e-3, equal_nan=True)  # mm -> m


def test_residuals_match_the_independent_reader(realdata):
    """The residual byte is the low byte of the 4th word (C3D user guide); ezc3d 1.7 swaps them."""
    for name in ("Eb015pr.c3d", "Eb015pi.c3d"):
        f = realdata / SAMPLE01 / name
        m = read_c3d(f)
        xyz, res, labels, rate, first = read_with_c3d_package(f)
        assert labels[: len(m.labels)] == m.labels
        np.testing.assert_allclose(m.residual, res[:, : len(m.labels)] * 1e-3, atol=1e-9, equal_nan=True)
        assert np.nanstd(m.residual[:, 0]) > 0  # residuals vary frame to frame; camera masks do not


# -- writing ----------------------------------------------------------------------------------

def _markers(rng, n_frames=40, n_markers=5, rate=250.0, first=0, drop=0.1, resid=True):
    xyz = rng.normal(0.0, 0.8, (n_frames, n_markers, 3))
    xyz[rng.random((n_frames, n_markers)) < drop] = np.nan
    r = np.where(np.isnan(xyz[..., 0]), np.nan, rng.uniform(0, 2.5e-3, (n_frames, n_markers))) if resid else None
    t = (first + np.arange(n_frames)) / rate
    return MarkerTrajectories(t=t, xyz=xyz, labels=tuple(f"M{i}" for i in range(n_markers)), rate_hz=rate, residual=r)


def test_written_file_reads_back_identically_through_ezc3d_and_c3d(tmp_path):
    m = _markers(np.random.default_rng(1), first=7)
    path = tmp_path / "w.c3d"
    write_c3d(path, m)
    # ezc3d
    c = ezc3d.c3d(str(path))
    P = c["parameters"]["POINT"]
    assert P["UNITS"]["value"][0] == "mm" and P["SCALE"]["value"][0] == pytest.approx(-0.01)
    ez = c["data"]["points"][:3].transpose(2, 1, 0)
    f32_mm = (m.xyz * 1e3).astype(np.float32).astype(np.float64)
    np.testing.assert_array_equal(ez, f32_mm)  # NaN where occluded, float32 mm elsewhere
    # c3d package
    xyz, res, labels, rate, first = read_with_c3d_package(path)
    np.testing.assert_array_equal(xyz, f32_mm)
    assert labels == m.labels and rate == 250.0 and first == 8  # 1-based first frame
    # residuals to 0.01 mm through both the c3d package and mocapfj
    np.testing.assert_allclose(res * 1e-3, m.residual, atol=0.5e-5 + 1e-9, equal_nan=True)
    back = read_c3d(path)
    np.testing.assert_allclose(back.residual, res * 1e-3, atol=1e-12, equal_nan=True)
    np.testing.assert_allclose(back.t, m.t, rtol=0, atol=1e-12)
    # header scale word agrees with POINT:SCALE (ezc3d alone leaves -1 there)
    assert struct.unpack("<f", path.read_bytes()[12:16])[0] == pytest.approx(-0.01)


@settings(max_examples=25, deadline=None)
@given(n_frames=st.integers(1, 30), n_markers=st.integers(1, 12), first=st.integers(0, 500),
       rate=st.sampled_from([50.0, 100.0, 120.0, 250.0, 69.5]), seed=st.integers(0, 2**16))
def test_c3d_round_trip_property(tmp_path_factory, n_frames, n_markers, first, rate, seed):
    m = _markers(np.random.default_rng(seed), n_frames, n_markers, rate, first)
    path = tmp_path_factory.mktemp("c3d") / "p.c3d"
    write_c3d(path, m)
    back = read_c3d(path)
    assert back.labels == m.labels and back.rate_hz == rate
    assert np.array_equal(np.isnan(back.xyz), np.isnan(m.xyz))
    # float32 millimetres: relative 6e-8
    np.testing.assert_allclose(back.xyz, m.xyz, rtol=1.2e-7, atol=1e-9, equal_nan=True)
    np.testing.assert_allclose(back.residual, m.residual, atol=0.5e-5 + 1e-9, equal_nan=True)
    np.testing.assert_allclose(back.t, m.t, atol=1e-9)


def test_large_residuals_widen_the_scale_instead_of_clipping(tmp_path):
    m = _markers(np.random.default_rng(2), drop=0.0)
    big = MarkerTrajectories(t=m.t, xyz=m.xyz, labels=m.labels, rate_hz=m.rate_hz, residual=m.residual * 4)  # up to 10 mm
    write_c3d(tmp_path / "b.c3d", big)
    back = read_c3d(tmp_path / "b.c3d")
    step = np.nanmax(big.residual) / 255
    assert np.nanmax(np.abs(back.residual - big.residual)) <= step / 2 + 1e-9


def test_a_failed_write_leaves_no_file(tmp_path):
    m = _markers(np.random.default_rng(3))
    bad = MarkerTrajectories(t=m.t ** 2, xyz=m.xyz, labels=m.labels, rate_hz=m.rate_hz)  # non-uniform times
    with pytest.raises(InputError, match="uniform samples"):
        write_c3d(tmp_path / "x.c3d", bad)
    assert list(tmp_path.iterdir()) == []


# -- bad input --------------------------------------------------------------------------------

def test_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.c3d: file: expected an existing C3D file"):
        read_c3d(tmp_path / "nope.c3d")


def test_not_a_c3d(tmp_path):
    p = tmp_path / "junk.c3d"
    p.write_bytes(b"\x00" * 100)
    with pytest.raises(InputError, match=r"junk\.c3d: file: expected a readable C3D file"):
        read_c3d(p)


def test_missing_units(tmp_path):
    m = _markers(np.random.default_rng(4))
    p = tmp_path / "u.c3d"
    write_c3d(p, m)
    c = ezc3d.c3d(str(p))
    c["parameters"]["POINT"]["UNITS"]["value"] = [""]
    c.write(str(tmp_path / "nounits.c3d"))
    with pytest.raises(InputError, match=r"nounits\.c3d: POINT:UNITS: expected a length unit.*got nothing"):
        read_c3d(tmp_path / "nounits.c3d")


# -- cut, corrupt and long files (issue: bad input) ----------------------------------------------

def _valid_file(tmp_path, n_frames=200, n_markers=4):
    m = _markers(np.random.default_rng(5), n_frames, n_markers, drop=0.05)
    p = tmp_path / "v.c3d"
    write_c3d(p, m)
    return p, m


def test_a_file_cut_anywhere_is_one_error_naming_the_cut(tmp_path):
    """Every cut through the header, the parameter section and the data block: an InputError (a
    cut inside the parameter section once segfaulted, hung or took 12 GB in ezc3d)."""
    p, m = _valid_file(tmp_path)
    raw = p.read_bytes()
    cut = tmp_path / "cut.c3d"
    data_start = (struct.unpack("<H", raw[16:18])[0] - 1) * 512
    data_end = data_start + 200 * 4 * 16                  # 200 frames of 4 markers x 4 floats
    for n in list(range(0, data_start + 64, 7)) + [len(raw) // 2, data_end - 1]:
        cut.write_bytes(raw[:n])
        with pytest.raises(InputError, match=r"cut\.c3d: ") as e:
            read_c3d(cut)
        assert "\n" not in str(e.value)
    cut.write_bytes(raw[:len(raw) // 2])
    with pytest.raises(InputError, match=r"POINT:FRAMES: expected 200 frames .* holds \d+ whole frames .*the file is cut"):
        read_c3d(cut)


def test_corrupt_parameter_records_are_refused(tmp_path):
    p, _ = _valid_file(tmp_path)
    raw = bytearray(p.read_bytes())
    start = (raw[0] - 1) * 512
    bad = tmp_path / "bad.c3d"
    # the parameter section claims more blocks than the file has
    b = raw.copy()
    b[start + 2] = 250
    bad.write_bytes(bytes(b))
    with pytest.raises(InputError, match=r"parameter section: expected 250 blocks .*cut inside its parameter section"):
        read_c3d(bad)
    # the first record's next-record offset points past the section
    b = raw.copy()
    nchar = abs(struct.unpack("b", bytes(b[start + 4:start + 5]))[0])
    off = start + 4 + 2 + nchar
    b[off:off + 2] = struct.pack("<h", 32000)
    bad.write_bytes(bytes(b))
    with pytest.raises(InputError, match=r"expected a record inside the parameter section"):
        read_c3d(bad)
    # an unknown processor type
    b = raw.copy()
    b[start + 3] = 99
    bad.write_bytes(bytes(b))
    with pytest.raises(InputError, match=r"processor type 84"):
        read_c3d(bad)


def test_garbage_or_infinite_coordinates_are_refused_with_the_marker_and_frame(tmp_path):
    p, m = _valid_file(tmp_path, n_frames=50, n_markers=3)
    raw = bytearray(p.read_bytes())
    start = (struct.unpack("<H", raw[16:18])[0] - 1) * 512
    bad = tmp_path / "g.c3d"
    b = raw.copy()                                   # frame 11, marker 2, x: 3e35 mm
    i = start + (10 * 12 + 4) * 4
    b[i:i + 4] = struct.pack("<f", 3e35)
    b[i + 12:i + 16] = struct.pack("<f", 0.0)        # a valid sample
    bad.write_bytes(bytes(b))
    with pytest.raises(InputError, match=rf"POINT data, marker {m.labels[1]}, frame 11: expected finite coordinates within 1000 m"):
        read_c3d(bad)
    b = raw.copy()
    b[i:i + 4] = struct.pack("<f", np.inf)
    bad.write_bytes(bytes(b))
    with pytest.raises(InputError, match=r"frame 11: expected finite coordinates"):
        read_c3d(bad)


@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_mutated_bytes_give_markers_or_one_error(tmp_path_factory, data):
    """Random bytes overwritten anywhere in a valid file: a MarkerTrajectories or an InputError,
    never another exception (bounded: the reader allocates no more than the file's size)."""
    d = tmp_path_factory.mktemp("fuzz")
    p, _ = _valid_file(d, n_frames=30, n_markers=3)
    raw = bytearray(p.read_bytes())
    for _ in range(data.draw(st.integers(1, 8))):
        i = data.draw(st.integers(0, len(raw) - 1))
        raw[i] = data.draw(st.integers(0, 255))
    if data.draw(st.booleans()):
        raw = raw[:data.draw(st.integers(0, len(raw)))]
    q = d / "m.c3d"
    q.write_bytes(bytes(raw))
    import tracemalloc

    tracemalloc.start()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")              # numpy's warnings handled where they arise
            got = read_c3d(q)
    except InputError as e:
        assert "\n" not in str(e) and str(e).startswith(str(q))
    else:
        assert isinstance(got, MarkerTrajectories)
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert peak < 40 * len(raw) + 2_000_000, peak     # bounded by the file's size (a cut file took 12 GB)


def test_ten_minutes_at_250_hz_round_trip(tmp_path):
    """150001 frames: more than the 65535 that the header's words and an int16 POINT:FRAMES can
    say; written with POINT:LONG_FRAMES (C3D convention), read back whole, also by the c3d package."""
    n = 150001
    rng = np.random.default_rng(6)
    xyz = np.cumsum(rng.normal(0, 1e-4, (n, 3, 3)), axis=0) + 1.0
    xyz[rng.random((n, 3)) < 0.01] = np.nan
    m = MarkerTrajectories(t=np.arange(n) / 250.0, xyz=xyz, labels=("A", "B", "C"), rate_hz=250.0)
    p = tmp_path / "long.c3d"
    write_c3d(p, m)
    back = read_c3d(p)
    assert back.n_frames == n and back.t[-1] == pytest.approx(600.0)
    np.testing.assert_allclose(back.xyz, m.xyz, rtol=1.2e-7, equal_nan=True)
    import c3d

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with open(p, "rb") as h:
            assert c3d.Reader(h).frame_count == n
