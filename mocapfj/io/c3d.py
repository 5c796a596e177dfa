"""C3D marker files through ezc3d, converted to SI at the boundary.

Reading: positions come from ezc3d and are converted to metres from POINT:UNITS; occluded
samples are NaN. The fourth word of each point sample (residual in the low byte, camera mask in
the high byte, C3D user guide "3D point data") is decoded here from the data block, because
ezc3d 1.7 swaps those two bytes (pyomeca/ezc3d#386): its "residuals" are the camera byte.

Writing: floating-point storage in millimetres with POINT:SCALE = -0.01, so residuals keep
0.01 mm resolution up to 2.55 mm. ezc3d lays out the parameters and data; this module then
writes the header scale word (ezc3d leaves it at -1, which the `c3d` package rejects) and the
fourth words in the layout of the standard, and renames the file into place.

Times: sample i of a file whose first frame is f (1-based, header word 4) is at
t = (f - 1 + i) / POINT:RATE seconds on the mocap clock.
"""

from __future__ import annotations

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


def _param(c, group: str, name: str):
    try:
        return c["parameters"][group][name]["value"]
    except KeyError:
        return None


def _labels(c, used: int) -> tuple[str, ...]:
    """POINT:LABELS, LABELS2, ... concatenated, cut to POINT:USED, made unique."""
    names: list[str] = []
    point = c["parameters"]["POINT"]
    for key in ["LABELS"] + [f"LABELS{i}" for i in range(2, 100)]:
        if key not in point:
            break
        names.extend(str(s).strip() for s in point[key]["value"])
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


def _fourth_words(raw: bytes, n_frames: int, is_float: bool) -> np.ndarray:
    """The 4th word of every point sample as int32 (negative = invalid), shape (F, P)."""
    processor, n_points, n_analog, start, _ = _layout(raw)
    words_per_frame = 4 * n_points + n_analog
    count = n_frames * words_per_frame
    if is_float:
        if processor == _DEC:
            # DEC F-float: swap the two 16-bit halves to get IEEE bits, then divide by 4.
            u = np.frombuffer(raw, "<u2", count=2 * count, offset=start).reshape(-1, 2)
            vals = u[:, ::-1].copy().view("<u4").view("<f4").ravel() / 4.0
        else:
            vals = np.frombuffer(raw, ">f4" if processor == _MIPS else "<f4", count=count, offset=start)
        vals = vals.reshape(n_frames, words_per_frame)[:, 3 : 4 * n_points : 4]
        return np.where(np.isfinite(vals), vals, -1).astype(np.int32)
    vals = np.frombuffer(raw, ">i2" if processor == _MIPS else "<i2", count=count, offset=start)
    return vals.reshape(n_frames, words_per_frame)[:, 3 : 4 * n_points : 4].astype(np.int32)


def read_c3d(path: str | os.PathLike[str]) -> MarkerTrajectories:
    """Read marker trajectories from a C3D file.

    Returns
    -------
    MarkerTrajectories
        ``xyz`` (T, M, 3) in metres, NaN where occluded; ``residual`` (T, M) in metres from the
        residual byte times |POINT:SCALE|, NaN where occluded (0 means the system reported the
        sample as modelled or interpolated).

    Raises
    ------
    InputError
        Missing or unreadable file, missing or unknown POINT:UNITS, non-positive POINT:RATE.
    """
    import ezc3d

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing C3D file", "no such file")
    try:
        c = ezc3d.c3d(str(path))
    except (RuntimeError, ValueError, IndexError, OSError) as e:
        raise InputError(path, "file", "a readable C3D file", str(e).splitlines()[0] if str(e) else type(e).__name__) from None
    units = _param(c, "POINT", "UNITS")
    factor = unit_factor(path, "POINT:UNITS", units[0] if units else "")
    rate = _param(c, "POINT", "RATE")
    rate = float(rate[0]) if rate is not None and len(rate) else float(c["header"]["points"]["frame_rate"])
    if not rate > 0:
        raise InputError(path, "POINT:RATE", "a positive point rate in Hz", rate)
    pts = np.asarray(c["data"]["points"], dtype=np.float64)  # (4, M, F)
    n_markers, n_frames = pts.shape[1], pts.shape[2]
    used = _param(c, "POINT", "USED")
    labels = _labels(c, int(used[0]) if used is not None and len(used) else n_markers)[:n_markers]
    xyz = pts[:3].transpose(2, 1, 0) * factor  # (F, M, 3)

    scale = _param(c, "POINT", "SCALE")
    scale = float(scale[0]) if scale is not None and len(scale) else -1.0
    raw = path.read_bytes()
    if n_markers and n_frames:
        words = _fourth_words(raw, n_frames, is_float=scale < 0)[:, :n_markers]
        residual = (words & 0xFF).astype(np.float64) * abs(scale) * factor
        invalid = (words < 0) | np.isnan(xyz).any(axis=2)
        residual[invalid] = np.nan
        xyz[invalid] = np.nan
    else:
        residual = np.full((n_frames, n_markers), np.nan)
    first0 = int(c["header"]["points"]["first_frame"])  # ezc3d: 0-based
    t = (first0 + np.arange(n_frames)) / rate
    return MarkerTrajectories(t=t, xyz=xyz, labels=labels, rate_hz=rate, residual=residual)


def write_c3d(path: str | os.PathLike[str], markers: MarkerTrajectories) -> None:
    """Write marker trajectories as a C3D file (float storage, mm, POINT:SCALE = -0.01), atomically.

    Parameters
    ----------
    path : path-like
    markers : MarkerTrajectories
        Times must be uniform: ``t = (first + arange(T)) / rate_hz`` with an integer ``first >= 0``.
        Residuals (metres) are stored to 0.01 mm when all are at most 2.55 mm; otherwise the
        scale widens to max residual / 255 so that none is clipped. Samples without a residual
        are stored with residual 0.
    """
    import ezc3d

    rate = markers.rate_hz
    n_frames, n_markers = markers.xyz.shape[:2]
    frame_index = markers.t * rate
    first0 = int(np.round(frame_index[0])) if n_frames else 0
    if n_frames and (first0 < 0 or np.max(np.abs(frame_index - (first0 + np.arange(n_frames)))) > 1e-6):
        raise InputError(path, "t", f"uniform samples at {rate} Hz starting at a frame index >= 0",
                         "non-uniform or negative times", hint="resample before writing a C3D")
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

    res_byte = np.clip(np.round(res_mm / abs(np.float32(scale))), 0, 255)
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
