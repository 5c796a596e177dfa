"""Validators for values that cross a boundary: one family of ``check_*`` functions.

Each returns a clean value (a Python float, a float64 array) or raises :class:`InputError` naming
the argument, what was expected and what came (pytransform3d's ``check_*`` style). Frozen result
types validate their fields with these in ``__post_init__`` and then :func:`freeze` the arrays,
so code inside the package can trust them (docs/conventions.md).

Shapes are tuples whose entries are a size (int), ``None`` (any size) or a name (str): a named
size must agree across every array checked with the same ``dims`` dictionary, which records the
sizes it has seen::

    dims = {}
    t = check_array(t, "t", ("T",), dims=dims)
    xyz = check_array(xyz, "xyz", ("T", "M", 3), dims=dims)     # T must equal len(t)
"""

from __future__ import annotations

import math
from collections.abc import MutableMapping

import numpy as np

from .errors import InputError

__all__ = ["check_scalar", "check_int", "check_array", "check_unit_vector", "freeze", "freeze_arrays"]


def check_scalar(value, name: str, *, positive: bool = False, nonneg: bool = False, lo: float | None = None,
                 hi: float | None = None, allow_nan: bool = False, file=None) -> float:
    """A finite real number as a float (NaN only with `allow_nan`), with optional bounds.

    positive: > 0; nonneg: >= 0; lo, hi: inclusive bounds. `file` names the file the value came
    from, when it did (the message then points there).
    """
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = None
    if v is not None and math.isnan(v) and allow_nan:
        return v
    bad = (v is None or not math.isfinite(v) or (positive and v <= 0) or (nonneg and v < 0)
           or (lo is not None and v < lo) or (hi is not None and v > hi))
    if bad:
        want = "a positive" if positive else "a non-negative" if nonneg else "a finite"
        rng = ""
        if lo is not None and hi is not None:
            rng = f" in [{lo:g}, {hi:g}]"
        elif lo is not None:
            rng = f" >= {lo:g}"
        elif hi is not None:
            rng = f" <= {hi:g}"
        raise InputError(file, name, f"{want} number{rng}", repr(value))
    return v


def check_int(value, name: str, *, lo: int | None = None, hi: int | None = None, file=None) -> int:
    """A whole number (an int, or a float with no fraction) as an int, within [lo, hi]."""
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    if not ok and isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
        ok = True
    if not ok or (lo is not None and value < lo) or (hi is not None and value > hi):
        rng = f" in [{lo}, {hi}]" if lo is not None and hi is not None else f" >= {lo}" if lo is not None else ""
        raise InputError(file, name, f"a whole number{rng}", repr(value))
    return int(value)


def _shape_text(shape, dims) -> str:
    parts = []
    for s in shape:
        if isinstance(s, str) and s in dims:
            parts.append(f"{s}={dims[s]}")
        else:
            parts.append("any" if s is None else str(s))
    return "(" + ", ".join(parts) + ("," if len(parts) == 1 else "") + ")"


def check_array(x, name: str, shape: tuple | None = None, *, dims: MutableMapping | None = None,
                finite: bool = False, dtype=np.float64, file=None) -> np.ndarray:
    """`x` as an array of `dtype` (float64 by default) with the given shape (module docstring).

    finite: refuse NaN and infinities. `dims` (a dict) records and checks named sizes across
    calls. Returns a new array only when a conversion was needed.
    """
    try:
        a = np.asarray(x, dtype=dtype)
    except (TypeError, ValueError):
        raise InputError(file, name, f"an array of numbers{'' if shape is None else ' of shape ' + str(shape)}",
                         type(x).__name__) from None
    dims = {} if dims is None else dims
    if shape is not None:
        ok = a.ndim == len(shape)
        if ok:
            for s, n in zip(shape, a.shape):
                if s is None:
                    continue
                if isinstance(s, str):
                    if s in dims and dims[s] != n:
                        ok = False
                        break
                elif s != n:
                    ok = False
                    break
        if not ok:
            raise InputError(file, name, f"an array of shape {_shape_text(shape, dims)}", f"shape {a.shape}")
        for s, n in zip(shape, a.shape):
            if isinstance(s, str):
                dims.setdefault(s, n)
    if finite and a.dtype.kind == "f" and not np.isfinite(a).all():
        bad = int((~np.isfinite(a)).sum())
        raise InputError(file, name, "finite values", f"{bad} NaN or infinite of {a.size}")
    return a


def check_unit_vector(x, name: str, *, tol: float = 1e-6, file=None) -> np.ndarray:
    """A (3,) direction of unit length (within `tol`), as float64."""
    a = check_array(x, name, (3,), finite=True, file=file)
    n = float(np.linalg.norm(a))
    if abs(n - 1.0) > tol:
        raise InputError(file, name, "a unit vector", f"norm {n:.6g}")
    return a


def freeze(a: np.ndarray) -> np.ndarray:
    """A read-only copy of `a` (frozen dataclasses hold read-only arrays)."""
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def freeze_arrays(obj) -> None:
    """Replace every numpy array field of the frozen dataclass `obj` by a read-only copy (for its
    ``__post_init__``)."""
    from dataclasses import fields

    for f in fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray):
            object.__setattr__(obj, f.name, freeze(v))
