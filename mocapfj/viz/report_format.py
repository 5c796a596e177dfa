"""Numbers as the report prints them, and the reading of a run's files with errors that name them.

- :func:`fmt` a value to significant digits; :func:`pm` a value with its SD, both rounded at the
  SD's second significant digit ("11166 ± 79"); :func:`parse_pm` reads that back (tests).
- :func:`read_result_json`, :func:`read_toml`, :func:`read_columns`: the run's files, each
  failure an :class:`~mocapfj.errors.InputError` naming the file.
"""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path

import numpy as np

from ..errors import InputError, not_utf8

__all__ = ["fmt", "pm", "parse_pm", "UNITS", "read_result_json", "read_toml", "read_columns", "field"]

# Units of the identified parameters (docs/identification.md; link side).
UNITS = {"I": "kg m²", "J": "kg m²", "k": "N m/rad", "g": "N m/rad", "k1": "N m/rad", "k3": "N m/rad³", "c": "N m",
         "v": "N m s/rad", "b": "N m s/rad", "d": "N m s/rad", "mglx": "N m", "mgly": "N m", "tau0": "N m",
         "loop_half_height_Nm": "N m", "gap_rad": "rad", "delay_s": "s", "tau1": "N m",
         "tau2": "N m", "k2": "N m/rad"}


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def fmt(x, sig: int = 4) -> str:
    """`x` to `sig` significant digits ("n/a" for None or non-finite; integers as they are)."""
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    if not _finite(x):
        return "n/a"
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 1e6:
        s = f"{x:.{sig}g}"
        return s if "e" not in s else f"{x:.0f}"
    return f"{x:.{sig - 1}e}"


def pm(value, sd, unit: str = "") -> str:
    """`value ± sd`, both rounded at the SD's second significant digit (GUM practice); the value
    alone to 4 digits when the SD is missing. Values below 1e-3 or from 1e6 share an exponent."""
    u = f" {unit}" if unit else ""
    if not _finite(value):
        return "n/a"
    if not _finite(sd) or sd <= 0:
        return fmt(value) + u
    scale = 0
    if abs(value) >= 1e6 or (0 < abs(value) < 1e-3 and sd < 1e-3):
        scale = int(math.floor(math.log10(max(abs(value), sd))))
    v, s = value / 10.0 ** scale, sd / 10.0 ** scale
    e = int(math.floor(math.log10(s))) - 1
    d = max(0, -e)
    if e > 0:
        v, s = round(v / 10 ** e) * 10 ** e, round(s / 10 ** e) * 10 ** e
    vs = f"{v:.{d}f}"
    if float(vs) == 0:
        vs = vs.lstrip("-")                           # no "-0.0"
    body = f"{vs} ± {s:.{d}f}"
    return (f"({body})e{scale:+03d}" if scale else body) + u


_PM = re.compile(r"\(?(-?[0-9.]+) ± ([0-9.]+)\)?(?:e([+-][0-9]+))?")


def parse_pm(text: str) -> tuple[float, float, float]:
    """(value, sd, half of the last printed digit) of the first `pm` string in `text`."""
    m = _PM.search(text)
    if m is None:
        raise ValueError(f"no 'value ± sd' in {text!r}")
    scale = 10.0 ** int(m.group(3) or 0)
    dec = len(m.group(1).split(".")[1]) if "." in m.group(1) else 0
    return float(m.group(1)) * scale, float(m.group(2)) * scale, 0.5 * 10.0 ** -dec * scale


def read_result_json(path: Path) -> dict:
    """A results JSON (an object at the top), or InputError naming the file."""
    from ..io import read_json

    d = read_json(path)
    if not isinstance(d, dict):
        raise InputError(path, "top level", "a JSON object (the results mocapfj writes)", type(d).__name__)
    return d


def read_toml(path: Path) -> dict:
    try:
        return tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(path, "file", "an existing TOML file", "no such file") from None
    except UnicodeDecodeError as e:
        raise not_utf8(path, e) from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(path, "syntax", "valid TOML", " ".join(str(e).split())) from None


def read_columns(path: Path) -> dict[str, np.ndarray]:
    from ..io.csvio import read_csv_columns

    return read_csv_columns(path)


def field(d: dict, key: str, file: Path, expected: str = "a value"):
    """d[key], or InputError naming the file and the key."""
    if not isinstance(d, dict) or key not in d:
        raise InputError(file, key, expected, "missing")
    return d[key]
