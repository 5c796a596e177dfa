"""Model elements to and from plain tables (TOML/JSON): ``{"model": "bouc_wen", "k": ..., ...}``.

Scenario files, model files and results all describe friction and spring elements this way.
The table's keys are the dataclass fields of the element; a nested element (the base friction of
a position-dependent model, the spring behind a backlash) is a nested table with its own
``model`` key; a list of numbers is a list.
"""

from __future__ import annotations

from dataclasses import fields, is_dataclass

from ..errors import InputError
from .friction import (AsymmetricCoulombViscous, AsymmetricStribeck, CoulombViscous, ExtendedStribeck,
                       PositionDependent, Stribeck)
from .hysteresis import BoucWen, Dahl, MaxwellSlip
from .springs import Backlash, CubicSpring, LinearSpring, PiecewiseSpring

__all__ = ["FRICTION_MODELS", "SPRING_MODELS", "element_from_table", "element_to_table"]

FRICTION_MODELS = {
    "coulomb_viscous": CoulombViscous,
    "asymmetric_coulomb_viscous": AsymmetricCoulombViscous,
    "stribeck": Stribeck,
    "asymmetric_stribeck": AsymmetricStribeck,
    "extended_stribeck": ExtendedStribeck,
    "position_dependent": PositionDependent,
}

SPRING_MODELS = {
    "linear": LinearSpring,
    "cubic": CubicSpring,
    "piecewise": PiecewiseSpring,
    "backlash": Backlash,
    "bouc_wen": BoucWen,
    "dahl": Dahl,
    "maxwell_slip": MaxwellSlip,
}

_ALL = {**FRICTION_MODELS, **SPRING_MODELS}
_NAME_OF = {cls: name for name, cls in _ALL.items()}


def register(name: str, cls, kind: str) -> None:
    """Add an element class under `name` (kind "friction" or "spring")."""
    (FRICTION_MODELS if kind == "friction" else SPRING_MODELS)[name] = cls
    _ALL[name] = cls
    _NAME_OF[cls] = name


def _value_from(value, source, where):
    if isinstance(value, dict) and "model" in value:
        return element_from_table(value, _ALL, source, where)
    if isinstance(value, list):
        return tuple(_value_from(v, source, f"{where}[{i}]") for i, v in enumerate(value))
    return value


def element_from_table(table: dict, registry: dict | None = None, source=None, where: str = "model"):
    """Build an element from its table.

    Parameters
    ----------
    table : dict
        ``{"model": name, field: value, ...}``.
    registry : dict, optional
        Allowed model names (default: every friction and spring model).
    source : path-like, optional
        The file the table came from, for error messages.
    where : str
        The table's place in that file, for error messages (e.g. ``"joints[j2].spring"``).
    """
    registry = _ALL if registry is None else registry
    if not isinstance(table, dict) or "model" not in table:
        got = f"a table without one ({len(table)} keys)" if isinstance(table, dict) else type(table).__name__
        raise InputError(source, where, f'a table with a "model" key, one of {sorted(registry)}', got)
    name = table["model"]
    if name not in registry:
        raise InputError(source, f"{where}.model", f"one of {sorted(registry)}", repr(name))
    cls = registry[name]
    names = [f.name for f in fields(cls) if f.init]
    unknown = sorted(set(table) - set(names) - {"model"})
    if unknown:
        raise InputError(source, f"{where}", f"parameters of {name}: {names}", f"unknown {unknown}")
    kwargs = {k: _value_from(v, source, f"{where}.{k}") for k, v in table.items() if k != "model"}
    try:
        return cls(**kwargs)
    except InputError as e:
        raise InputError(source, f"{where}.{e.field}", e.expected, e.got, e.hint) from None
    except TypeError as e:
        raise InputError(source, where, f"parameters of {name}: {names}", str(e)) from None


def _value_to(value):
    if is_dataclass(value) and type(value) in _NAME_OF:
        return element_to_table(value)
    if isinstance(value, (tuple, list)):
        return [_value_to(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # numpy scalar
        return value.item()
    return value


def element_to_table(element) -> dict:
    """The table of an element: ``{"model": name, field: value, ...}``; inverse of element_from_table."""
    cls = type(element)
    if cls not in _NAME_OF:
        raise InputError(None, "element", f"one of {sorted(_ALL)}", cls.__name__)
    out = {"model": _NAME_OF[cls]}
    for f in fields(element):
        if f.init:
            out[f.name] = _value_to(getattr(element, f.name))
    return out
