"""TRC marker files (OpenSim / Motion Analysis tab-separated text), converted to metres.

Layout: line 1 ``PathFileType``; line 2 header keys; line 3 their values (``DataRate``,
``NumFrames``, ``NumMarkers``, ``Units``, ...); line 4 ``Frame#``, ``Time`` and one label per
marker (three columns each); line 5 the X/Y/Z sub-headers; then one row per frame. Empty
fields are missing samples (NaN).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import MarkerTrajectories
from .atomic import write_text_atomic
from .c3d import unit_factor
from .csvio import format_floats

__all__ = ["read_trc", "write_trc"]


def read_trc(path: str | os.PathLike[str]) -> MarkerTrajectories:
    """Read a TRC file. Times come from the ``Time`` column and must increase strictly."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing TRC file", "no such file")
    lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise InputError(path, "line 1", "a TRC header starting with 'PathFileType'", "another first line" if lines else "an empty file")
    keys = [k.strip() for k in lines[1].split("\t")]
    vals = [v.strip() for v in lines[2].split("\t")]
    header = dict(zip(keys, vals + [""] * (len(keys) - len(vals))))
    factor = unit_factor(path, "Units", header.get("Units", ""))
    try:
        rate = float(header.get("DataRate", "nan"))
    except ValueError:
        rate = float("nan")
    if not rate > 0:
        raise InputError(path, "DataRate", "a positive rate in Hz", repr(header.get("DataRate")))
    names = lines[3].split("\t")
    labels = [s.strip() for s in names[2::3]]
    labels = [s for s in labels if s]
    n_markers = len(labels)
    n_cols = 2 + 3 * n_markers
    body = [ln.rstrip("\r") for ln in lines[5:] if ln.strip()]
    table = _parse_rows(path, body, n_cols)
    t = table[:, 1]
    if np.any(~np.isfinite(t)):
        raise InputError(path, "Time", "a time in every row", f"missing at data row {int(np.argmax(~np.isfinite(t))) + 1}")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise InputError(path, "Time", "strictly increasing times",
                         f"{float(t[bad[0] + 1])!r} after {float(t[bad[0]])!r} at data row {bad[0] + 2}")
    xyz = table[:, 2:].reshape(len(table), n_markers, 3) * factor
    xyz[np.isnan(xyz).any(axis=2)] = np.nan
    try:
        return MarkerTrajectories(t=t, xyz=xyz, labels=tuple(labels), rate_hz=rate)
    except InputError as e:                 # the container's own checks: name this file
        raise InputError(path, e.field, e.expected, e.got, e.hint) from None


_EMPTY = re.compile(r"(?<![^\t])(?=\t|$)")  # an empty cell: at line start or after a tab, before a tab or the end


def _parse_rows(path, body: list[str], n_cols: int) -> np.ndarray:
    """Rows of tab-separated numbers into (N, n_cols); empty or absent trailing cells are NaN."""
    if not body:
        return np.empty((0, n_cols))
    filled = [_EMPTY.sub("nan", ln) for ln in body]
    counts = np.fromiter((ln.count("\t") + 1 for ln in filled), dtype=np.int64, count=len(filled))
    filled = [ln + "\tnan" * (n_cols - c) if c < n_cols else ln for ln, c in zip(filled, counts)]
    try:
        return np.loadtxt(filled, delimiter="\t", ndmin=2, usecols=range(n_cols), dtype=np.float64)
    except ValueError:
        for i, ln in enumerate(filled):  # name the first bad cell
            for j, cell in enumerate(ln.split("\t")[:n_cols]):
                try:
                    float(cell)
                except ValueError:
                    raise InputError(path, f"row {i + 6} column {j + 1}", "a number",
                                     f"{len(cell.strip())} characters of text") from None
        raise


def write_trc(path: str | os.PathLike[str], markers: MarkerTrajectories, units: str = "mm") -> None:
    """Write marker trajectories as TRC in `units` (``"mm"`` or ``"m"``), atomically.

    Values are written as the shortest text that reads back to the same float, so reading back gives the same numbers up to
    the unit conversion's rounding (below 1e-15 m).
    """
    factor = unit_factor("<argument>", "units", units)
    path = Path(path)
    n_frames, n_markers = markers.xyz.shape[:2]
    head = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{markers.rate_hz!r}\t{markers.rate_hz!r}\t{n_frames}\t{n_markers}\t{units}\t{markers.rate_hz!r}\t1\t{n_frames}",
        "Frame#\tTime\t" + "\t".join(f"{s}\t\t" for s in markers.labels),
        "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(n_markers)),
        "",
    ]
    vals = format_floats(markers.xyz.reshape(n_frames, -1) / factor, nan="")
    frames = np.arange(1, n_frames + 1).astype(str).astype(object)
    body = ["\t".join(r) for r in np.column_stack([frames, format_floats(markers.t), vals]).tolist()]
    write_text_atomic(path, "\n".join(head + body) + "\n")
