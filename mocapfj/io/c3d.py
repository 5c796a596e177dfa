"""C3D marker files, converted to SI at the boundary.

Reading is done here, not by ezc3d: the header and the parameter section are parsed and every
offset, count and dimension is checked against the file's size before anything is allocated, so
a cut or corrupt file is one InputError in time and memory bounded by the file (ezc3d 1.7
segfaulted, hung or took 12 GB on a file cut inside its parameter section, and stops at 65535
frames). Positions are converted to metres from POINT:UNITS; occluded samples (a negative fourth
word, or NaN coordinates) are NaN. The fourth word of each point sample holds the residual in the
low byte and the camera mask in the high byte (C3D user guide, "3D point data"); ezc3d 1.7 swaps
the two bytes (pyomeca/ezc3d#386). Frame counts above 65535 follow the C3D convention: POINT:FRAMES
as a floating-point number, POINT:LONG_FRAMES, or TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD.

Writing: ezc3d lays out the parameters and data, in floating-point storage in millimetres with
POINT:SCALE = -0.01, so residuals keep 0.01 mm resolution up to 2.55 mm; this module then writes
the header scale word (ezc3d leaves it at -1, which the `c3d` package rejects), the fourth words
in the layout of the standard and, above 65535 frames, POINT:LONG_FRAMES; the file is renamed
into place when complete.

Times: sample i of a file whose first frame is f (1-based, header word 4) is at
t = (f - 1 + i) / POINT:RATE seconds on the mocap clock.
"""

from __future__ import annotations

import math
import os
import struct
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import MarkerTrajectories
from .atomic import atomic_path

__all__ = ["read_c3d", "write_c3d", "UNIT_TO_M", "WRITE_SCALE"]

UNIT_TO_M = {"mm": 1e-3, "cm": 1e-2, "dm": 1e-1, "m": 1.0, "in": 0.0254}
"""Length units accepted in POINT:UNITS and TRC headers, as metres per unit."""

WRITE_SCALE = -0.01
"""POINT:SCALE of written files: float storage, residual resolution 0.01 mm (up to 2.55 mm).
A file whose largest residual exceeds 2.55 mm is written with the smallest scale that holds it."""

_INTEL, _DEC, _MIPS = 84, 85, 86


def unit_factor(path, field: str, units) -> float:
    """Metres per unit for a unit string; InputError when missing or unknown."""
    u = (units or "").strip().lower()
    if not u:
        raise InputError(path, field, f"a length unit, one of {sorted(UNIT_TO_M)}", "nothing",
                         hint="the file does not say its units")
    if u in ("millimeters", "millimetres"):
        u = "mm"
    if u in ("meters", "metres"):
        u = "m"
    if u not in UNIT_TO_M:
        raise InputError(path, field, f"a length unit, one of {sorted(UNIT_TO_M)}", repr(units))
    return UNIT_TO_M[u]


_TYPES = {-1: 1, 1: 1, 2: 2, 4: 4}        # parameter element type -> bytes per element
MAX_COORD_M = 1.0e3
"""Largest coordinate accepted (m): a capture volume is metres across; beyond a kilometre the data
block is garbage or the units are wrong."""


class _Header:
    """The C3D header and parameter section, validated against the file's size (no field read
    outside the file, every count bounded by it)."""

    def __init__(self, raw: bytes, path: Path):
        def bad(field, expected, got, hint=None):
            return InputError(path, field, expected, got, hint=hint)

        size = len(raw)
        if size < 512:
            raise bad("file", "a C3D file (a 512-byte header at least)", f"{size} bytes")
        if raw[1] != 0x50:
            raise bad("file", "a C3D file (header byte 2 = 0x50)", f"0x{raw[1]:02x}", hint="not a C3D file")
        self.param_start = (raw[0] - 1) * 512
        if raw[0] < 2 or self.param_start + 4 > size:
            raise bad("header word 1", "the parameter section's block inside the file",
                      f"block {raw[0]} of a {size}-byte file", hint="the file is cut or not a C3D file")
        self.processor = raw[self.param_start + 3]
        if self.processor not in (_INTEL, _DEC, _MIPS):
            raise bad("parameter section", "a processor type 84 (Intel), 85 (DEC) or 86 (MIPS)", self.processor,
                      hint="not a C3D file, or a corrupt one")
        self.end = ">" if self.processor == _MIPS else "<"
        n_blocks = raw[self.param_start + 2]
        self.param_end = self.param_start + 512 * n_blocks
        if n_blocks < 1 or self.param_end > size:
            raise bad("parameter section", f"{n_blocks} blocks of 512 bytes inside the file",
                      f"a file of {size} bytes (the section would end at byte {self.param_end})",
                      hint="the file is cut inside its parameter section")
        words = struct.unpack(self.end + "HHHHH", raw[2:12])
        self.n_points, self.n_analog, self.first, self.last, _ = words
        self.scale = self._float(raw[12:16])
        self.data_block = struct.unpack(self.end + "H", raw[16:18])[0]
        self.rate = self._float(raw[20:24])
        self.params = self._parameters(raw, bad)

    def _float(self, b: bytes) -> float:
        if self.processor == _DEC:          # DEC F-float: swap the 16-bit halves, then / 4
            return struct.unpack("<f", b[2:4] + b[0:2])[0] / 4.0
        return struct.unpack(self.end + "f", b)[0]

    def _parameters(self, raw: bytes, bad) -> dict:
        """{GROUP: {NAME: value}}: strings for character data (a tuple for an array of them),
        numpy arrays (Fortran order flattened) for numbers."""
        groups: dict[int, str] = {}
        pending: list[tuple[int, str, object]] = []
        pos, stop = self.param_start + 4, self.param_end
        for _ in range((stop - pos) // 5 + 1):                    # every record is 5 bytes at least
            if pos + 2 > stop:
                break
            nchar = abs(struct.unpack("b", raw[pos:pos + 1])[0])
            gid = struct.unpack("b", raw[pos + 1:pos + 2])[0]
            if nchar == 0:
                break
            name_end = pos + 2 + nchar
            if name_end + 2 > stop:
                raise bad("parameter section", f"a parameter record inside the section (bytes {self.param_start}"
                          f"-{stop})", f"a record running to byte {name_end + 2}", hint="corrupt parameter section")
            name = raw[pos + 2:name_end].decode("latin-1").strip().upper()
            offset = struct.unpack(self.end + "h", raw[name_end:name_end + 2])[0]
            body = name_end + 2
            nxt = name_end + offset if offset > 0 else stop
            if nxt > stop or (offset > 0 and offset < 2):
                raise bad(f"parameter {name}", f"a record inside the parameter section (bytes {self.param_start}"
                          f"-{stop})", f"a next-record offset to byte {nxt}", hint="corrupt parameter section")
            if gid < 0:
                groups[-gid] = name
            elif gid > 0:
                pending.append((gid, name, self._value(raw, body, nxt, name, bad)))
            if offset == 0:
                break
            pos = nxt
        out: dict[str, dict] = {g: {} for g in groups.values()}
        for gid, name, value in pending:
            if gid in groups:
                out[groups[gid]].setdefault(name, value)       # the first of a repeated name
        return out

    def _value(self, raw: bytes, pos: int, stop: int, name: str, bad):
        if pos + 2 > stop:
            raise bad(f"parameter {name}", "a type and dimensions inside the record", "a record cut short")
        typ = struct.unpack("b", raw[pos:pos + 1])[0]
        ndim = raw[pos + 1]
        if typ not in _TYPES or ndim > 7 or pos + 2 + ndim > stop:
            raise bad(f"parameter {name}", "type -1, 1, 2 or 4 and at most 7 dimensions", f"type {typ}, {ndim} dimensions",
                      hint="corrupt parameter section")
        dims = tuple(raw[pos + 2:pos + 2 + ndim])
        count = int(np.prod(dims)) if ndim else 1
        start = pos + 2 + ndim
        if start + count * _TYPES[typ] > stop:
            raise bad(f"parameter {name}", f"{count} elements of {_TYPES[typ]} bytes inside its record",
                      f"a record of {stop - start} bytes", hint="corrupt parameter section")
        data = raw[start:start + count * _TYPES[typ]]
        if typ == -1:
            if ndim <= 1:
                return data.decode("latin-1").rstrip("\x00 ")
            width = dims[0]
            if width == 0:
                return ("",) * int(np.prod(dims[1:]))
            return tuple(data[i:i + width].decode("latin-1").rstrip("\x00 ") for i in range(0, len(data), width))
        if typ == 1:
            return np.frombuffer(data, np.uint8).astype(np.int64)
        if typ == 2:
            return np.frombuffer(data, self.end + "i2").astype(np.int64)
        with np.errstate(invalid="ignore", over="ignore"):     # signalling NaNs of a corrupt record
            if self.processor == _DEC:
                u = np.frombuffer(data, "<u2").reshape(-1, 2)
                return u[:, ::-1].copy().view("<u4").view("<f4").ravel().astype(np.float64) / 4.0
            return np.frombuffer(data, self.end + "f4").astype(np.float64)

    def get(self, group: str, name: str):
        return self.params.get(group, {}).get(name)

    def number(self, group: str, name: str):
        """The first element of a numeric parameter, or None."""
        v = self.get(group, name)
        if isinstance(v, np.ndarray) and v.size:
            return float(v[0])
        return None


def _unsigned(v: float) -> int:
    """An int16 word read as the unsigned count the C3D convention means (POINT:FRAMES, USED)."""
    v = int(v)
    return v + 65536 if v < 0 else v


def _frames(h: _Header) -> int:
    """The number of frames: POINT:FRAMES (floating point above 65535, the C3D convention),
    POINT:LONG_FRAMES or TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD when it says 65535, the
    header's range when the parameter is missing."""
    v = h.get("POINT", "FRAMES")
    if isinstance(v, np.ndarray) and v.size:
        if v.dtype.kind == "f":
            return int(round(float(v[0])))
        n = _unsigned(v[0])
        if n < 65535:
            return n
    long_frames = h.number("POINT", "LONG_FRAMES")
    if long_frames is not None and long_frames >= 65535:
        return int(round(long_frames))
    s, e = h.get("TRIAL", "ACTUAL_START_FIELD"), h.get("TRIAL", "ACTUAL_END_FIELD")
    if isinstance(s, np.ndarray) and isinstance(e, np.ndarray) and s.size >= 2 and e.size >= 2:
        start = (int(s[0]) & 0xFFFF) + 65536 * (int(s[1]) & 0xFFFF)
        end = (int(e[0]) & 0xFFFF) + 65536 * (int(e[1]) & 0xFFFF)
        if end >= start:
            return end - start + 1
    if isinstance(v, np.ndarray) and v.size:
        return _unsigned(v[0])
    return max(0, h.last - h.first + 1)


def _labels(h: _Header, used: int) -> tuple[str, ...]:
    """POINT:LABELS, LABELS2, ... concatenated, cut to POINT:USED, made unique."""
    names: list[str] = []
    for key in ["LABELS"] + [f"LABELS{i}" for i in range(2, 100)]:
        v = h.get("POINT", key)
        if v is None:
            break
        names.extend(s.strip() for s in ((v,) if isinstance(v, str) else v) if isinstance(s, str))
    names = names[:used] + [f"M{i + 1:03d}" for i in range(len(names), used)]
    seen: dict[str, int] = {}
    out = []
    for i, s in enumerate(names):
        s = s or f"M{i + 1:03d}"
        if s in seen:
            seen[s] += 1
            s = f"{s}_{seen[s]}"
        seen.setdefault(s, 1)
        out.append(s)
    return tuple(out)


def _layout(raw: bytes) -> tuple[int, int, int, int, int]:
    """(processor, n_points, analog_words_per_frame, data_start_byte, first_frame_1based)."""
    param_start = (raw[0] - 1) * 512
    processor = raw[param_start + 3]
    end = ">" if processor == _MIPS else "<"
    n_points, n_analog, first = struct.unpack(end + "HHH", raw[2:8])
    data_block = struct.unpack(end + "H", raw[16:18])[0]
    return processor, n_points, n_analog, (data_block - 1) * 512, first


def read_c3d(path: str | os.PathLike[str]) -> MarkerTrajectories:
    """Read marker trajectories from a C3D file.

    The header and the parameter section are parsed and checked against the file's size here
    (every offset, count and dimension inside the file), and the point data are read with numpy:
    a cut or corrupt file is one InputError in time and memory bounded by its size. Files of more
    than 65535 frames follow the C3D convention (POINT:FRAMES as a floating-point number, or
    POINT:LONG_FRAMES, or TRIAL:ACTUAL_START_FIELD and ACTUAL_END_FIELD).

    Returns
    -------
    MarkerTrajectories
        ``xyz`` (T, M, 3) in metres, NaN where occluded; ``residual`` (T, M) in metres from the
        residual byte times |POINT:SCALE|, NaN where occluded (0 means the system reported the
        sample as modelled or interpolated).

    Raises
    ------
    InputError
        Missing, cut or corrupt file; missing or unknown POINT:UNITS; non-positive POINT:RATE;
        non-finite coordinates or coordinates beyond MAX_COORD_M.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing C3D file", "no such file")
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(path, "file", "a readable C3D file", e.strerror or type(e).__name__) from None
    if len(raw) < 512:
        raise InputError(path, "file", "a readable C3D file", f"{len(raw)} bytes (a C3D header is 512)")
    h = _Header(raw, path)
    units = h.get("POINT", "UNITS")
    factor = unit_factor(path, "POINT:UNITS", units if isinstance(units, str) else (units[0] if units else ""))
    rate = h.number("POINT", "RATE")
    rate = h.rate if rate is None else rate
    if not (math.isfinite(rate) and rate > 0):
        raise InputError(path, "POINT:RATE", "a positive point rate in Hz", rate)
    scale = h.number("POINT", "SCALE")
    scale = h.scale if scale is None else scale
    if not (math.isfinite(scale) and scale != 0):
        raise InputError(path, "POINT:SCALE", "a non-zero finite scale", scale)
    n_points = h.n_points
    used = h.number("POINT", "USED")
    if used is not None and _unsigned(used) != n_points:
        raise InputError(path, "POINT:USED", f"the header's number of points ({n_points})", _unsigned(used),
                         hint="corrupt header or parameter section")
    n_frames = _frames(h)
    is_float = scale < 0
    words = 4 * n_points + h.n_analog
    item = 4 if is_float else 2
    start = (h.data_block - 1) * 512
    if h.data_block < 1 or start < h.param_end:
        raise InputError(path, "header word 9", f"a data block after the parameter section (block >= "
                         f"{h.param_end // 512 + 1})", h.data_block, hint="corrupt header")
    need = start + n_frames * words * item
    if need > len(raw):
        whole = max(0, (len(raw) - start) // max(words * item, 1))
        raise InputError(path, "POINT:FRAMES", f"{n_frames} frames of data ({need} bytes)",
                         f"a file of {len(raw)} bytes, which holds {whole} whole frames",
                         hint="the file is cut; export it again")
    labels = _labels(h, n_points)
    first0 = h.first - 1 if h.first > 0 else 0
    st = h.get("TRIAL", "ACTUAL_START_FIELD")
    if h.first == 65535 and isinstance(st, np.ndarray) and st.size >= 2:
        first0 = (int(st[0]) & 0xFFFF) + 65536 * (int(st[1]) & 0xFFFF) - 1
    t = (first0 + np.arange(n_frames)) / rate
    if not (n_points and n_frames):
        return MarkerTrajectories(t=t, xyz=np.zeros((n_frames, n_points, 3)), labels=labels, rate_hz=rate,
                                  residual=np.full((n_frames, n_points), np.nan))
    block = _point_block(raw, h, start, n_frames, words, is_float)        # (F, P, 4) in file units
    fourth = block[:, :, 3]
    xyz = block[:, :, :3] * (1.0 if is_float else abs(scale))
    invalid = ~np.isfinite(fourth) | (fourth < 0) | np.isnan(block[:, :, :3]).any(axis=2)   # NaN: some writers' "lost"
    fourth_int = np.clip(np.where(invalid, 0, fourth), 0, 2 ** 31 - 1).astype(np.int64)
    residual = (fourth_int & 0xFF).astype(np.float64) * abs(scale) * factor
    xyz = xyz * factor
    residual[invalid] = np.nan
    xyz[invalid] = np.nan
    valid = ~np.isnan(xyz)
    with np.errstate(invalid="ignore", over="ignore"):
        wild = valid & ~(np.abs(xyz) <= MAX_COORD_M)
    if wild.any():
        f, m, _ = np.argwhere(wild)[0]
        raise InputError(path, f"POINT data, marker {labels[m]}, frame {int(f) + 1}",
                         f"finite coordinates within {MAX_COORD_M:g} m of the origin",
                         f"{xyz[f, m].tolist()} m ({int(wild.any(axis=2).sum())} samples like it)",
                         hint="the data block is corrupt or POINT:UNITS is wrong")
    return MarkerTrajectories(t=t, xyz=xyz, labels=labels, rate_hz=rate, residual=residual)


def _point_block(raw: bytes, h: _Header, start: int, n_frames: int, words: int, is_float: bool) -> np.ndarray:
    """The point words (F, P, 4) as float64 in file units (integers unscaled)."""
    count = n_frames * words
    if is_float:
        with np.errstate(invalid="ignore", over="ignore"):     # signalling NaNs of a corrupt block
            if h.processor == _DEC:
                u = np.frombuffer(raw, "<u2", count=2 * count, offset=start).reshape(-1, 2)
                vals = u[:, ::-1].copy().view("<u4").view("<f4").ravel().astype(np.float64) / 4.0
            else:
                vals = np.frombuffer(raw, h.end + "f4", count=count, offset=start).astype(np.float64)
    else:
        vals = np.frombuffer(raw, h.end + "i2", count=count, offset=start).astype(np.float64)
    return vals.reshape(n_frames, words)[:, :4 * h.n_points].reshape(n_frames, h.n_points, 4)


def write_c3d(path: str | os.PathLike[str], markers: MarkerTrajectories, camera_mask=None) -> None:
    """Write marker trajectories as a C3D file (float storage, mm, POINT:SCALE = -0.01), atomically.

    Parameters
    ----------
    path : path-like
    markers : MarkerTrajectories
        Times must be uniform: ``t = (first + arange(T)) / rate_hz`` with an integer ``first >= 0``.
        Residuals (metres) are stored to 0.01 mm when all are at most 2.55 mm; otherwise the
        scale widens to max residual / 255 so that none is clipped. Samples without a residual
        are stored with residual 0.
    camera_mask : (T, M) int, optional
        Cameras that saw each sample, bit c for camera c; stored in the high byte of the fourth
        word (C3D user guide: bits 0-6 for the first seven cameras, so cameras from 7 on are not
        representable and left out).
    """
    import ezc3d

    rate = markers.rate_hz
    n_frames, n_markers = markers.xyz.shape[:2]
    frame_index = markers.t * rate
    first0 = int(np.round(frame_index[0])) if n_frames else 0
    if n_frames and (first0 < 0 or np.max(np.abs(frame_index - (first0 + np.arange(n_frames)))) > 1e-6):
        raise InputError(path, "t", f"uniform samples at {rate} Hz starting at a frame index >= 0",
                         "non-uniform or negative times", hint="resample before writing a C3D")
    if first0 + 1 > 65535:
        raise InputError(path, "t", "a first frame index below 65535 (the C3D header's word)", first0,
                         hint="shift the times to start nearer 0")
    if n_markers > 255:
        raise InputError(path, "labels", "at most 255 markers in one C3D file", n_markers)

    c = ezc3d.c3d()
    point = c["parameters"]["POINT"]
    point["RATE"]["value"] = [rate]
    point["LABELS"]["value"] = tuple(markers.labels)
    point["UNITS"]["value"] = ["mm"]
    res_mm = np.zeros((n_frames, n_markers)) if markers.residual is None else np.nan_to_num(markers.residual * 1e3)
    res_mm = np.maximum(res_mm, 0.0)
    scale = -max(abs(WRITE_SCALE), float(np.float32(res_mm.max() / 255.0)) if res_mm.size else 0.0)
    point["SCALE"]["value"] = [scale]
    pts = np.ones((4, n_markers, n_frames))
    pts[:3] = markers.xyz.transpose(2, 1, 0) * 1e3
    invalid = np.isnan(markers.xyz).any(axis=2)  # (F, M)
    pts[:3, invalid.T] = np.nan
    c["data"]["points"] = pts
    c["data"]["meta_points"]["residuals"] = np.where(invalid.T, -1.0, 0.0)[None]
    c["data"]["meta_points"]["camera_masks"] = np.zeros((7, n_markers, n_frames), bool)
    c["header"]["points"]["first_frame"] = first0
    if n_frames > 65535 or first0 + n_frames > 65535:
        # the C3D convention for long trials (ezc3d stops POINT:FRAMES and the header's range at
        # 65535): POINT:LONG_FRAMES, a floating-point count (ezc3d would store TRIAL:ACTUAL_*_FIELD
        # word pairs as floats, which other readers reject, so they are left out)
        c.add_parameter("POINT", "LONG_FRAMES", float(n_frames))

    res_byte = np.clip(np.round(res_mm / abs(np.float32(scale))), 0, 255)
    if camera_mask is not None:
        cm = np.asarray(camera_mask, dtype=np.int64)
        if cm.shape != (n_frames, n_markers):
            raise InputError(path, "camera_mask", f"shape ({n_frames}, {n_markers})", f"shape {cm.shape}")
        res_byte = res_byte + 256.0 * (cm & 0x7F)
    fourth = np.where(invalid, -1.0, res_byte).astype("<f4")

    path = Path(path)
    with atomic_path(path) as tmp:
        c.write(str(tmp))
        raw = bytearray(tmp.read_bytes())
        processor, n_points, n_analog, start, _ = _layout(bytes(raw))
        if processor != _INTEL or n_points != n_markers:  # pragma: no cover - ezc3d writes Intel
            raise RuntimeError(f"unexpected C3D layout from ezc3d: processor {processor}, {n_points} points")
        raw[12:16] = struct.pack("<f", scale)  # header word 7-8: scale factor
        if n_frames and n_markers:
            words_per_frame = 4 * n_points + n_analog
            data = np.frombuffer(raw, "<f4", count=n_frames * words_per_frame, offset=start)
            data = data.reshape(n_frames, words_per_frame).copy()
            data[:, 3 : 4 * n_points : 4] = fourth
            raw[start : start + data.nbytes] = data.tobytes()
        tmp.write_bytes(bytes(raw))
