"""Joint friction models: the term F(q, q') of the link equation (Lightcap and Banks (2007), eq. 4, docs/conventions.md).

Every model is a frozen dataclass with the same interface:

- ``torque(qd, q=None)``: friction torque in N m on the link side, any array shape, vectorised.
  It enters the link equation on the left, ``I q'' + G(q) + F(q, q') = tau_s``, so a dissipative
  model has ``F * qd >= 0``.
- ``smoothing``: a velocity eps in rad/s. With eps > 0 every ``sign(qd)`` becomes
  ``tanh(qd / eps)``, so a stiff integrator sees a smooth right-hand side; eps = 0 is the exact
  discontinuous model. ``with_smoothing(eps)`` returns a copy.
- ``params``: the coefficients as a dict ``{name: float}``.

Coulomb magnitudes are positive numbers on both sides of zero velocity, as the seed tables list
them (Oueslati et al. (2012), Table I, Bompos et al. (2007), Table II): for q' < 0 the Coulomb part is ``-c_neg``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import InputError
from ..validate import check_scalar

__all__ = [
    "Friction",
    "CoulombViscous",
    "AsymmetricCoulombViscous",
    "Stribeck",
    "AsymmetricStribeck",
    "ExtendedStribeck",
    "PositionDependent",
]


@runtime_checkable
class Friction(Protocol):
    """What the models and the simulator need from a friction model."""

    smoothing: float

    def torque(self, qd, q=None) -> np.ndarray: ...

    def with_smoothing(self, eps: float) -> "Friction": ...

    @property
    def params(self) -> dict[str, float]: ...


def _sgn(qd: np.ndarray, eps: float) -> np.ndarray:
    """sign(qd), or tanh(qd / eps) when eps > 0."""
    return np.tanh(qd / eps) if eps > 0 else np.sign(qd)


def _velocity(qd) -> np.ndarray:
    return np.asarray(qd, dtype=np.float64)


class _Scalars:
    """Shared behaviour of the models whose fields are all numbers."""

    smoothing: float

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            object.__setattr__(self, f.name, check_scalar(getattr(self, f.name), f.name))
        check_scalar(self.smoothing, "smoothing", nonneg=True)

    @property
    def params(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "smoothing"}  # type: ignore[arg-type]

    def with_smoothing(self, eps: float):
        return replace(self, smoothing=eps)  # type: ignore[type-var]


@dataclass(frozen=True)
class CoulombViscous(_Scalars):
    """Coulomb plus viscous friction, Lightcap and Banks (2007), eq. (4): ``F = c sign(q') + v q'``.

    Parameters
    ----------
    c : float
        Coulomb level, N m (Lightcap and Banks (2007), Table I column c).
    v : float
        Viscous coefficient, N m s / rad.
    smoothing : float
        eps in rad/s for ``tanh(q'/eps)``; 0 for the exact sign.
    """

    c: float
    v: float
    smoothing: float = 0.0

    def torque(self, qd, q=None) -> np.ndarray:
        """Friction torque, N m, same shape as `qd` (rad/s). `q` is not used."""
        qd = _velocity(qd)
        return self.c * _sgn(qd, self.smoothing) + self.v * qd


@dataclass(frozen=True)
class AsymmetricCoulombViscous(_Scalars):
    """Coulomb and viscous friction with different coefficients for q' > 0 and q' < 0.

    ``F = c_pos sign(q') + v_pos q'`` for q' >= 0 and ``F = c_neg sign(q') + v_neg q'`` for
    q' < 0 (both Coulomb magnitudes positive). Equal sides give :class:`CoulombViscous`.
    The asymmetry is the one seen in Oueslati et al. (2012), Table I and Bompos et al. (2007), Table II.
    """

    c_pos: float
    v_pos: float
    c_neg: float
    v_neg: float
    smoothing: float = 0.0

    def torque(self, qd, q=None) -> np.ndarray:
        """Friction torque, N m, same shape as `qd` (rad/s). `q` is not used."""
        qd = _velocity(qd)
        pos = qd >= 0
        return (np.where(pos, self.c_pos, self.c_neg) * _sgn(qd, self.smoothing)
                + np.where(pos, self.v_pos, self.v_neg) * qd)


def _stribeck(qd, s, fc, fs, vs, fv, exponent):
    return (fc + (fs - fc) * np.exp(-np.abs(qd / vs) ** exponent)) * s + fv * qd


@dataclass(frozen=True)
class Stribeck(_Scalars):
    """Stribeck friction, Oueslati et al. (2012), eq. (7):

        F = (fc + (fs - fc) exp(-|q'/vs|^exponent)) sign(q') + fv q'

    Parameters
    ----------
    fc, fs : float
        Coulomb and static (breakaway) levels, N m.
    vs : float
        Stribeck velocity, rad/s (> 0).
    fv : float
        Viscous coefficient, N m s / rad.
    exponent : float
        2 in Oueslati et al. (2012); 1 is also common.
    smoothing : float
        eps in rad/s for ``tanh(q'/eps)``; 0 for the exact sign.
    """

    fc: float
    fs: float
    vs: float
    fv: float
    exponent: float = 2.0
    smoothing: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_scalar(self.vs, "vs", positive=True)
        check_scalar(self.exponent, "exponent", positive=True)

    def torque(self, qd, q=None) -> np.ndarray:
        """Friction torque, N m, same shape as `qd` (rad/s). `q` is not used."""
        qd = _velocity(qd)
        return _stribeck(qd, _sgn(qd, self.smoothing), self.fc, self.fs, self.vs, self.fv,
                         self.exponent)


@dataclass(frozen=True)
class AsymmetricStribeck(_Scalars):
    """Stribeck friction (Oueslati et al. (2012), eq. 7) with its own coefficients on each side of q' = 0.

    Oueslati et al. (2012), Table I lists exactly this for the Staubli RX-170B axis 2 (positive velocity:
    fc 122.19, fs 148.54 N m, fv 336.73 N m s/rad, vs 0.009 rad/s; negative velocity: fc 87.02,
    fs 111.38, fv 294.44, vs 0.009). Magnitudes are positive on both sides.
    """

    fc_pos: float
    fs_pos: float
    vs_pos: float
    fv_pos: float
    fc_neg: float
    fs_neg: float
    vs_neg: float
    fv_neg: float
    exponent: float = 2.0
    smoothing: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("vs_pos", "vs_neg", "exponent"):
            check_scalar(getattr(self, name), name, positive=True)

    def torque(self, qd, q=None) -> np.ndarray:
        """Friction torque, N m, same shape as `qd` (rad/s). `q` is not used."""
        qd = _velocity(qd)
        s = _sgn(qd, self.smoothing)
        pos = _stribeck(qd, s, self.fc_pos, self.fs_pos, self.vs_pos, self.fv_pos, self.exponent)
        neg = _stribeck(qd, s, self.fc_neg, self.fs_neg, self.vs_neg, self.fv_neg, self.exponent)
        return np.where(qd >= 0, pos, neg)


def _six(name: str, f) -> tuple[float, ...]:
    t = tuple(float(x) for x in np.asarray(f, dtype=np.float64).ravel())
    if len(t) != 6 or not all(math.isfinite(x) for x in t):
        raise InputError(None, name, "six finite coefficients f1..f6", f)
    if t[3] <= 0 or t[5] < 0:
        raise InputError(None, name, "f4 > 0 (rad/s) and f6 >= 0 (s/rad)", f"f4={t[3]}, f6={t[5]}",
                         hint="a negative f6 makes exp(-1/(f6 |q'|)) diverge at rest")
    return t


def _extended(qd, s, f):
    f1, f2, f3, f4, f5, f6 = f
    a = np.abs(qd)
    x = f6 * a
    with np.errstate(divide="ignore", over="ignore"):
        drop = np.where(x > 0, np.exp(-1.0 / np.where(x > 0, x, 1.0)), 0.0)
    return f1 * qd + s * (f2 - f3 * np.exp(-a / f4) - f5 * drop)


@dataclass(frozen=True)
class ExtendedStribeck:
    """The six-coefficient friction model of Bompos et al. (2007), eq. (18) (Mitsubishi PA-10):

        F = f1 q' + f2 sign(q') - f3 sign(q') exp(-|q'| / f4) - f5 sign(q') exp(-1 / (f6 |q'|))

    Parameters
    ----------
    f : 6 floats
        (f1 N m s/rad, f2 N m, f3 N m, f4 rad/s > 0, f5 N m, f6 s/rad >= 0) for q' >= 0.
    f_neg : 6 floats or None
        The same for q' < 0 (Bompos et al. (2007), Table II gives both sides); None: symmetric.
    smoothing : float
        eps in rad/s for ``tanh(q'/eps)``; 0 for the exact sign.

    The last term vanishes as q' -> 0 and is 0 when f6 = 0 (Table II joint 6).
    """

    f: tuple[float, ...]
    f_neg: tuple[float, ...] | None = None
    smoothing: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "f", _six("f", self.f))
        if self.f_neg is not None:
            object.__setattr__(self, "f_neg", _six("f_neg", self.f_neg))
        check_scalar(self.smoothing, "smoothing", nonneg=True)

    @property
    def params(self) -> dict[str, float]:
        out = {f"f{i + 1}": v for i, v in enumerate(self.f)}
        if self.f_neg is not None:
            out.update({f"f{i + 1}_neg": v for i, v in enumerate(self.f_neg)})
        return out

    def with_smoothing(self, eps: float) -> "ExtendedStribeck":
        return replace(self, smoothing=eps)

    def torque(self, qd, q=None) -> np.ndarray:
        """Friction torque, N m, same shape as `qd` (rad/s). `q` is not used."""
        qd = _velocity(qd)
        s = _sgn(qd, self.smoothing)
        pos = _extended(qd, s, self.f)
        if self.f_neg is None:
            return pos
        return np.where(qd >= 0, pos, _extended(qd, s, self.f_neg))


@dataclass(frozen=True)
class PositionDependent:
    """Any friction model plus a Coulomb level that varies with the joint angle.

        F(q, q') = base.torque(q', q) + sign(q') sum_k a_k cos(n_k q + phi_k)

    Harmonic-drive friction ripple from manufacturing errors and misalignment (Lightcap and Banks (2007) sec. VI;
    docs methods "position-dependent friction": residual periodic in joint angle). Keep
    ``sum |a_k|`` below the base Coulomb level for a model that never drives the joint.

    Parameters
    ----------
    base : Friction
        The velocity-dependent part; its `smoothing` also smooths the ripple's sign.
    orders : K floats
        n_k, cycles per joint revolution.
    amplitudes : K floats
        a_k, N m.
    phases : K floats
        phi_k, rad.
    """

    base: Friction
    orders: tuple[float, ...]
    amplitudes: tuple[float, ...]
    phases: tuple[float, ...]

    def __post_init__(self) -> None:
        arrs = [np.atleast_1d(np.asarray(getattr(self, n), dtype=np.float64)).ravel()
                for n in ("orders", "amplitudes", "phases")]
        if not (arrs[0].shape == arrs[1].shape == arrs[2].shape) or not all(np.isfinite(a).all() for a in arrs):
            raise InputError(None, "orders/amplitudes/phases", "three finite sequences of equal length",
                             [a.shape for a in arrs])
        for n, a in zip(("orders", "amplitudes", "phases"), arrs):
            object.__setattr__(self, n, tuple(a.tolist()))
        if not isinstance(self.base, Friction):
            raise InputError(None, "base", "a friction model with torque(qd, q)", type(self.base).__name__)

    @property
    def smoothing(self) -> float:
        return self.base.smoothing

    def with_smoothing(self, eps: float) -> "PositionDependent":
        return replace(self, base=self.base.with_smoothing(eps))

    @property
    def params(self) -> dict[str, float]:
        out = {f"base.{k}": v for k, v in self.base.params.items()}
        for i, (n, a, p) in enumerate(zip(self.orders, self.amplitudes, self.phases), 1):
            out.update({f"order{i}": n, f"amplitude{i}": a, f"phase{i}": p})
        return out

    def ripple(self, q) -> np.ndarray:
        """Coulomb-level variation sum_k a_k cos(n_k q + phi_k), N m, same shape as `q` (rad)."""
        q = np.asarray(q, dtype=np.float64)
        arg = q[..., None] * np.asarray(self.orders) + np.asarray(self.phases)
        return np.cos(arg) @ np.asarray(self.amplitudes)

    def torque(self, qd, q=None) -> np.ndarray:
        """Friction torque, N m; `qd` (rad/s) and `q` (rad, required) broadcast together."""
        if q is None:
            raise InputError(None, "q", "the link angle (rad): this friction depends on position")
        qd = _velocity(qd)
        return self.base.torque(qd, q) + _sgn(qd, self.smoothing) * self.ripple(q)
