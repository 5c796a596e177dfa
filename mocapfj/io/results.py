"""Results as JSON for machines, and 2D detections as CSV."""

from __future__ import annotations

import json
import math
import os
from dataclasses import fields, is_dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, not_utf8
from ..types import Detections
from .atomic import write_text_atomic
from .csvio import read_csv_columns, write_csv_columns

__all__ = ["to_jsonable", "write_json", "read_json", "read_detections", "write_detections"]


def to_jsonable(obj):
    """Plain JSON types from numpy arrays, scalars, paths and dataclasses; NaN/inf become null."""
    if is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in fields(obj)}
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer, int)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def write_json(path: str | os.PathLike[str], obj) -> None:
    """Write `obj` as indented JSON, atomically."""
    write_text_atomic(path, json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n")


def read_json(path: str | os.PathLike[str]):
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing JSON file", "no such file")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise InputError(path, f"line {e.lineno}", "valid JSON", e.msg) from None
    except UnicodeDecodeError as e:
        raise not_utf8(path, e) from None


_DET_COLUMNS = ("frame", "camera", "x_px", "y_px")


def read_detections(path: str | os.PathLike[str]) -> Detections:
    """Read 2D detections: columns frame, camera, x_px, y_px and optionally point_id."""
    cols = read_csv_columns(path)
    for c in _DET_COLUMNS:
        if c not in cols:
            raise InputError(path, c, f"a column named {c!r} (columns: frame, camera, x_px, y_px[, point_id])", f"columns {list(cols)}")
    n = cols["frame"].shape[0]
    ids = cols.get("point_id", np.full(n, -1.0))
    for c in ("frame", "camera"):
        if np.any(np.isnan(cols[c])) or np.any(cols[c] != np.round(cols[c])) or np.any(cols[c] < 0):
            raise InputError(path, c, "non-negative integers in every row", "a missing or fractional value")
    ids = np.where(np.isnan(ids), -1, ids)
    return Detections(frame=cols["frame"].astype(np.int64), camera=cols["camera"].astype(np.int64),
                      xy_px=np.column_stack([cols["x_px"], cols["y_px"]]), point_id=ids.astype(np.int64))


def write_detections(path: str | os.PathLike[str], det: Detections) -> None:
    """Write 2D detections as CSV, atomically."""
    write_csv_columns(path, {"frame": det.frame, "camera": det.camera, "x_px": det.xy_px[:, 0],
                             "y_px": det.xy_px[:, 1], "point_id": det.point_id})
