"""Numeric CSV tables: a header row of column names, one row per sample.

Used for the controller log and for per-joint outputs. Empty cells and ``nan`` read as NaN;
the writer writes ``nan``, so that a row is never blank. Values are written
as the shortest text that reads back to the same float64, so a table reads back bit-identical.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError, not_utf8
from .atomic import write_text_atomic

__all__ = ["read_csv_columns", "write_csv_columns", "check_increasing", "format_floats"]


def format_floats(a: np.ndarray, nan: str = "nan") -> np.ndarray:
    """Shortest text that reads back to the same float64 (Python repr); NaN becomes `nan`."""
    a = np.asarray(a, dtype=np.float64)
    out = np.array([repr(x) for x in a.ravel().tolist()], dtype=object).reshape(a.shape)
    out[np.isnan(a)] = nan
    return out


def read_csv_columns(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Read a numeric CSV into ``{column name: (T,) float array}`` in file order."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing CSV file", "no such file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise not_utf8(path, e) from None
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise InputError(path, "header", "a first row of column names", "an empty file")
    names = [s.strip().strip('"') for s in lines[0].split(",")]
    if any(not s for s in names):
        raise InputError(path, "header", "a non-empty name for every column",
                         f"column {names.index('') + 1} of {len(names)} without a name")
    if len(set(names)) != len(names):
        dup = sorted({s for s in names if names.count(s) > 1})
        raise InputError(path, "header", "unique column names", f"duplicates {dup}")
    body = [ln for ln in lines[1:] if ln.strip()]
    if not body:
        return {s: np.empty(0) for s in names}
    try:
        data = np.loadtxt(body, delimiter=",", ndmin=2, dtype=np.float64)
    except ValueError:
        data = _parse_slow(path, names, body)
    if data.shape[1] != len(names):
        raise InputError(path, "row 2", f"{len(names)} values per row", data.shape[1])
    return {s: data[:, i].copy() for i, s in enumerate(names)}


def _parse_slow(path, names, body) -> np.ndarray:
    """Cell by cell, for tables with empty cells; names the first bad cell."""
    out = np.full((len(body), len(names)), np.nan)
    for i, ln in enumerate(body):
        cells = ln.split(",")
        if len(cells) != len(names):
            raise InputError(path, f"row {i + 2}", f"{len(names)} comma-separated values", len(cells))
        for j, cell in enumerate(cells):
            cell = cell.strip()
            if cell:
                try:
                    out[i, j] = float(cell)
                except ValueError:
                    raise InputError(path, f"row {i + 2} column {names[j][:40]!r}", "a number",
                                     f"{len(cell)} characters of text") from None
    return out


def write_csv_columns(path: str | os.PathLike[str], columns: dict[str, np.ndarray]) -> None:
    """Write equal-length columns as CSV, atomically; NaN is written as ``nan``."""
    names = list(columns)
    arrays = [np.asarray(columns[s]).ravel() for s in names]
    n = {a.shape[0] for a in arrays}
    if len(n) > 1:
        raise InputError(path, "columns", "columns of equal length", sorted(n))
    for s in names:
        if "," in s or "\n" in s:
            raise InputError(path, "header", "column names without commas or newlines", repr(s))
    text = [a.astype(str).astype(object) if np.issubdtype(a.dtype, np.integer) else format_floats(a) for a in arrays]
    table = np.column_stack(text) if arrays and arrays[0].size else np.empty((0, len(names)), str)
    rows = [",".join(r) for r in table.tolist()]
    write_text_atomic(path, "\n".join([",".join(names)] + rows) + "\n")


def check_increasing(path, field: str, t: np.ndarray) -> None:
    """Times must be finite and strictly increasing; the error names the first bad row."""
    if t.size and not np.all(np.isfinite(t)):
        i = int(np.argmax(~np.isfinite(t)))
        raise InputError(path, field, "a finite time in every row", f"{t[i]} at row {i + 2}")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0])
        raise InputError(path, field, "strictly increasing times", f"{float(t[i + 1])!r} after {float(t[i])!r} at row {i + 3}")
