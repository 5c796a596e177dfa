"""Rig TOML (anipose-compatible ``[cam_N]`` tables) and board TOML (calibration targets).

Rig: one ``[cam_<number>]`` table per camera with ``name``, ``size`` [w, h], ``matrix`` (3x3),
``distortions``, ``rotation`` (Rodrigues vector, world to camera) and ``translation``, plus a
``[metadata]`` table. Translations are stored in ``metadata.units`` (metres when written by
mocapfj); anipose files without units need ``units=`` when read, because anipose stores them
in whatever unit its board was measured in.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import BOARD_TYPES, Board, Camera, Rig, Wand
from ..rotations import matrix_from_rotvec, rotvec_from_matrix
from .c3d import unit_factor
from .tomlio import check_format, read_toml, require, write_toml

__all__ = ["read_rig", "write_rig", "read_board", "board_from_table", "write_board", "read_wand", "write_wand"]


def _array(path, table, key, where, shape):
    value = require(path, table, key, list, where)
    try:
        a = np.asarray(value, dtype=np.float64)
    except (ValueError, TypeError):
        raise InputError(path, f"{where}.{key}", f"numbers in shape {shape}", repr(value)) from None
    if shape is not None and a.shape != shape:
        raise InputError(path, f"{where}.{key}", f"numbers in shape {shape}", f"shape {a.shape}")
    return a


def read_rig(path: str | os.PathLike[str], units: str | None = None) -> Rig:
    """Read a rig TOML. Cameras are ordered by their number (``cam_2`` before ``cam_10``).

    Parameters
    ----------
    units : str, optional
        Unit of the translations when the file's ``[metadata]`` does not say (anipose files).
    """
    path = Path(path)
    doc = read_toml(path)
    meta = dict(doc.get("metadata", {}))
    if "format" in doc:
        check_format(path, doc, "rig", 1)
    unit = meta.get("units", units)
    if unit is None:
        raise InputError(path, "metadata.units", "the unit of the camera translations (m or mm)", "nothing",
                         hint='add [metadata] units = "mm" to the file, or pass units=')
    factor = unit_factor(path, "metadata.units", unit)
    keys = [k for k in doc if re.fullmatch(r"cam_\d+", k)]
    if not keys:
        raise InputError(path, "cam_0", "at least one [cam_N] table", "none")
    cameras = []
    for key in sorted(keys, key=lambda k: int(k[4:])):
        tab = doc[key]
        if not isinstance(tab, dict):
            raise InputError(path, key, "a table", repr(tab))
        size = _array(path, tab, "size", key, (2,))
        cameras.append(Camera(
            name=str(require(path, tab, "name", (str, int), key, default=key)),
            size=(int(size[0]), int(size[1])),
            K=_array(path, tab, "matrix", key, (3, 3)),
            dist=_array(path, tab, "distortions", key, None).ravel(),
            R_cam_world=matrix_from_rotvec(_array(path, tab, "rotation", key, (3,))),
            t_cam_world=_array(path, tab, "translation", key, (3,)) * factor,
        ))
    meta["units"] = "m"
    return Rig(cameras=tuple(cameras), metadata=meta)


def _finite_metadata(value, where: str) -> None:
    """Refuse NaN or infinite numbers anywhere in the metadata: a rig file never carries them."""
    if isinstance(value, dict):
        for k, v in value.items():
            _finite_metadata(v, f"{where}.{k}")
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _finite_metadata(v, f"{where}[{i}]")
    elif isinstance(value, float) and not np.isfinite(value):
        raise InputError(None, where, "a finite number (a rig file never holds NaN or infinity)", value)


def write_rig(path: str | os.PathLike[str], rig: Rig) -> None:
    """Write a rig TOML (metres), atomically. Cameras are written as ``cam_0``, ``cam_1``, ... in
    their order; the metadata (units, residuals, SDs) must be finite (the cameras are, by type)."""
    _finite_metadata(dict(rig.metadata), "metadata")
    doc: dict = {}
    for i, cam in enumerate(rig.cameras):
        doc[f"cam_{i}"] = {
            "name": cam.name,
            "size": [int(cam.size[0]), int(cam.size[1])],
            "matrix": cam.K.tolist(),
            "distortions": cam.dist.tolist(),
            "rotation": rotvec_from_matrix(cam.R_cam_world).tolist(),
            "translation": cam.t_cam_world.tolist(),
        }
    meta = dict(rig.metadata)
    meta["units"] = "m"
    doc["metadata"] = meta
    write_toml(path, doc)


_BOARD_REQUIRED = {
    "chessboard": ("square_m",),
    "charuco": ("square_m", "marker_m", "dictionary"),
    "aprilgrid": ("tag_m", "spacing_m", "family"),
}


def read_board(path: str | os.PathLike[str]) -> Board:
    """Read a calibration target TOML (``[board]`` table; docs/formats.md)."""
    path = Path(path)
    doc = read_toml(path)
    if "format" in doc:
        check_format(path, doc, "board", 1)
    return board_from_table(require(path, doc, "board", dict), path, "board")


def board_from_table(tab: dict, path=None, where: str = "board") -> Board:
    """A Board from its table (the ``[board]`` table of a board file, or one inside another file)."""
    kind = require(path, tab, "type", str, where)
    if kind not in BOARD_TYPES:
        raise InputError(path, f"{where}.type", f"one of {list(BOARD_TYPES)}", repr(kind))
    cols = require(path, tab, "columns", int, where)
    rows = require(path, tab, "rows", int, where)
    if cols < 2 or rows < 2:
        raise InputError(path, f"{where}.columns/rows", "at least 2 x 2", f"{cols} x {rows}")
    values = {}
    for key in ("square_m", "marker_m", "tag_m", "spacing_m"):
        v = require(path, tab, key, (int, float), where, default=None)
        if v is not None and not v > 0:
            raise InputError(path, f"{where}.{key}", "a positive length in metres", v)
        values[key] = None if v is None else float(v)
    for key in ("dictionary", "family"):
        values[key] = require(path, tab, key, str, where, default=None)
    for key in _BOARD_REQUIRED[kind]:
        if values[key] is None:
            raise InputError(path, f"{where}.{key}", f"a value (required for a {kind})", "nothing (key missing)")
    return Board(type=kind, columns=cols, rows=rows, inverted=bool(require(path, tab, "inverted", bool, where, default=False)),
                 **values)


def write_board(path: str | os.PathLike[str], board: Board) -> None:
    """Write a calibration target TOML, atomically."""
    tab = {"type": board.type, "columns": board.columns, "rows": board.rows}
    for key in ("square_m", "marker_m", "dictionary", "tag_m", "spacing_m", "family"):
        v = getattr(board, key)
        if v is not None:
            tab[key] = v
    if board.inverted:
        tab["inverted"] = True
    write_toml(path, {"format": "mocapfj.board/1", "board": tab})


def read_wand(path: str | os.PathLike[str]) -> Wand:
    """Read a wand TOML (``calibration/wands/*.toml``; docs/formats.md): ``[wand]`` with
    ``markers_m`` (distances along the wand from its first marker, m) and an optional
    ``[lframe]`` with ``markers_m`` (L-frame marker positions in the world it defines, m)."""
    path = Path(path)
    doc = read_toml(path)
    if "format" in doc:
        check_format(path, doc, "wand", 1)
    tab = require(path, doc, "wand", dict)
    m = _array(path, tab, "markers_m", "wand", None)
    if m.ndim != 1:
        raise InputError(path, "wand.markers_m", "a list of distances in metres", f"shape {m.shape}")
    lframe = None
    if "lframe" in doc:
        lt = require(path, doc, "lframe", dict)
        lframe = _array(path, lt, "markers_m", "lframe", None)
        if lframe.ndim != 2 or lframe.shape[1] != 3:
            raise InputError(path, "lframe.markers_m", "a list of [x, y, z] positions in metres", f"shape {lframe.shape}")
    try:
        return Wand(markers_m=m, lframe_m=lframe,
                    name=str(require(path, tab, "name", str, "wand", default=path.stem)))
    except InputError as e:
        raise InputError(path, e.field.replace("wand ", "wand.").replace("lframe ", "lframe."), e.expected, e.got) from None


def write_wand(path: str | os.PathLike[str], wand: Wand) -> None:
    """Write a wand TOML, atomically."""
    doc = {"format": "mocapfj.wand/1", "wand": {"name": wand.name, "markers_m": wand.markers_m.tolist()}}
    if wand.lframe_m is not None:
        doc["lframe"] = {"markers_m": wand.lframe_m.tolist()}
    write_toml(path, doc)
