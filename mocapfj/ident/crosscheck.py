"""Two identifications of one joint held against each other, parameter by parameter.

Every method of mocapfj is checked against the time-domain identification of the same joint
(``mocapfj identify``): the frequency-domain fit (Makarov et al. 2012), the algebraic estimator,
the clamped stiffness. Two estimates a and b of one parameter, with SDs s_a and s_b from
independent data or methods, agree when |a - b| <= Z_LIMIT sqrt(s_a^2 + s_b^2); otherwise they
disagree, and the report says so with the size of the difference in SDs and in percent. A
parameter one method did not determine (``determined`` false, with its reason) is not compared.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from ..errors import InputError

__all__ = ["Z_LIMIT", "ParameterCheck", "CrossCheck", "cross_check"]

Z_LIMIT = 3.0


@dataclass(frozen=True)
class ParameterCheck:
    """One parameter: both estimates, their difference in percent of b and in combined SDs, and
    the status "agree", "disagree" or "not_compared" (with the reason)."""

    name: str
    a: float
    a_std: float
    b: float
    b_std: float
    status: str
    diff_pct: float | None = None
    z: float | None = None
    reason: str | None = None

    def to_dict(self) -> dict:
        return {"name": self.name, "a": self.a, "a_std": self.a_std, "b": self.b, "b_std": self.b_std,
                "status": self.status, "diff_pct": self.diff_pct, "z": self.z, "reason": self.reason}


@dataclass(frozen=True)
class CrossCheck:
    """The parameters two methods share, compared (module docstring)."""

    method_a: str
    method_b: str
    joint: str
    params: tuple[ParameterCheck, ...]

    @property
    def disagree(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params if p.status == "disagree")

    @property
    def verdict(self) -> str:
        compared = [p for p in self.params if p.status != "not_compared"]
        if not compared:
            return "nothing compared"
        if self.disagree:
            return (f"{self.method_a} and {self.method_b} disagree on {', '.join(self.disagree)} "
                    f"(beyond {Z_LIMIT:g} combined SDs)")
        return f"{self.method_a} and {self.method_b} agree on {', '.join(p.name for p in compared)}"

    def lines(self) -> list[str]:
        """One line per parameter, for people."""
        out = []
        for p in self.params:
            if p.status == "not_compared":
                out.append(f"{p.name}: not compared ({p.reason})")
            else:
                out.append(f"{p.name}: {self.method_a} {p.a:.5g} +- {p.a_std:.2g}, {self.method_b} {p.b:.5g} +- "
                           f"{p.b_std:.2g} ({p.diff_pct:+.2f} %, {p.z:+.1f} SD): {p.status}")
        return out

    def to_dict(self) -> dict:
        return {"method_a": self.method_a, "method_b": self.method_b, "joint": self.joint, "z_limit": Z_LIMIT,
                "params": [p.to_dict() for p in self.params], "disagree": list(self.disagree),
                "verdict": self.verdict}


def _entry(where: str, name: str, p) -> tuple[float, float, bool, str | None]:
    if isinstance(p, Mapping):
        value, std = p.get("value", p.get("mean")), p.get("std")
        determined, reason = bool(p.get("determined", True)), p.get("reason")
    else:
        value, std, determined, reason = getattr(p, "value"), getattr(p, "std"), getattr(p, "determined", True), \
            getattr(p, "reason", None)
    try:
        value, std = float(value), float(std)
    except (TypeError, ValueError):
        raise InputError(where, f"params.{name}", "a value and a standard deviation", f"{value!r}, {std!r}") from None
    return value, std, determined, reason


def cross_check(a: Mapping, b: Mapping, *, method_a: str, method_b: str, joint: str = "",
                names=None) -> CrossCheck:
    """Compare the parameters `names` (default: those both `a` and `b` hold) of two identifications.

    `a`, `b`: {name: {"value", "std"[, "determined", "reason"]}} (the ``params`` of a result's
    JSON) or {name: Parameter}. Differences are given relative to `b` (the reference, usually the
    time-domain identification).
    """
    names = [n for n in (names or a) if n in a and n in b]
    checks = []
    for n in names:
        va, sa, da, ra = _entry(method_a, n, a[n])
        vb, sb, db, rb = _entry(method_b, n, b[n])
        if not (da and db):
            who = method_a if not da else method_b
            why = ra if not da else rb
            checks.append(ParameterCheck(n, va, sa, vb, sb, "not_compared",
                                         reason=f"{who} did not determine it" + (f": {why}" if why else "")))
            continue
        if not all(math.isfinite(x) for x in (va, sa, vb, sb)):
            checks.append(ParameterCheck(n, va, sa, vb, sb, "not_compared", reason="a value or an SD is not finite"))
            continue
        s = math.hypot(sa, sb)
        z = (va - vb) / s if s > 0 else (0.0 if va == vb else math.copysign(math.inf, va - vb))
        diff = 100.0 * (va - vb) / abs(vb) if vb != 0 else None
        checks.append(ParameterCheck(n, va, sa, vb, sb, "agree" if abs(z) <= Z_LIMIT else "disagree",
                                     diff_pct=diff, z=z))
    return CrossCheck(method_a, method_b, joint, tuple(checks))
