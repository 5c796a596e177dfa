"""TOML reading with errors that name the file, and versioned ``format`` keys."""

from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path

import tomli_w

from ..errors import InputError, not_utf8
from .atomic import write_text_atomic

__all__ = ["read_toml", "write_toml", "check_format", "require", "describe"]


def read_toml(path: str | os.PathLike[str]) -> dict:
    """Parse a TOML file; missing files and syntax errors become InputError."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file", "an existing TOML file", "no such file")
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise InputError(path, "syntax", "valid TOML", str(e)) from None
    except UnicodeDecodeError as e:
        raise not_utf8(path, e) from None


def write_toml(path: str | os.PathLike[str], doc: dict) -> None:
    """Write `doc` as TOML, atomically."""
    write_text_atomic(path, tomli_w.dumps(doc))


def check_format(path, doc: dict, kind: str, supported: int) -> int:
    """Check ``format = "mocapfj.<kind>/<N>"``; return N. Newer N than `supported` is an error."""
    want = f"mocapfj.{kind}/{supported}"
    fmt = doc.get("format")
    m = re.fullmatch(rf"mocapfj\.{re.escape(kind)}/(\d{{1,6}})", fmt) if isinstance(fmt, str) else None
    if m is None:
        raise InputError(path, "format", f'format = "{want}"', describe(fmt))
    version = int(m.group(1))
    if version > supported:
        raise InputError(
            path, "format", f"version {supported} or older", f"version {version}",
            hint="the file was written by a newer mocapfj: upgrade mocapfj to read it",
        )
    return version


_MISSING = object()


def require(path, table: dict, key: str, kind: type | tuple[type, ...], where: str = "", default=_MISSING):
    """Fetch ``table[key]`` checking its type; the error names ``where.key``."""
    name = f"{where}.{key}" if where else key
    if key not in table:
        if default is not _MISSING:
            return default
        raise InputError(path, name, f"a value of type {_type_name(kind)}", "nothing (key missing)")
    value = table[key]
    if isinstance(value, bool) and bool not in (kind if isinstance(kind, tuple) else (kind,)):
        raise InputError(path, name, f"a value of type {_type_name(kind)}", describe(value))
    if not isinstance(value, kind):
        raise InputError(path, name, f"a value of type {_type_name(kind)}", describe(value))
    return value


def describe(value, width: int = 40) -> str:
    """A short account of a TOML value for a message: its type for tables and arrays, a string or
    number cut to `width` characters (a message never reprints a file's content)."""
    if isinstance(value, dict):
        return f"a table of {len(value)} keys"
    if isinstance(value, list):
        return f"an array of {len(value)} items"
    text = repr(value)
    return text if len(text) <= width else text[:width - 3] + "..."


def _type_name(kind) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {str: "string", int: "integer", float: "number", list: "array", dict: "table", bool: "boolean"}
    return " or ".join(dict.fromkeys(names.get(k, k.__name__) for k in kinds))
