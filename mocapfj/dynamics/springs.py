"""Joint springs: the transmitted torque tau_s = f(delta, history) (Lightcap and Banks (2007), eq. 7, docs/conventions.md).

All spring elements, with or without internal state, share one protocol (:class:`SpringElement`)
so that the models and the simulator treat them alike:

- ``n_states``: number of internal states (0 for the stateless springs of this file).
- ``initial_state()``: (n_states,) virgin state.
- ``state_derivative(z, delta, delta_dot)``: dz/dt, same shape as `z`.
- ``torque(delta, z=None)``: tau_s in N m; `delta` any shape (...), `z` (..., n_states).
- ``run(delta, t)``: tau_s (T,) along a prescribed deflection history delta (T,) at times t (T,).
- ``params``: coefficients as ``{name: float}``.

Deflection delta = q_m - q in rad on the link side; a positive deflection gives a positive torque.
The stateful elements (Bouc-Wen, Dahl, Maxwell-slip) are in :mod:`.hysteresis`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np

from ..errors import InputError
from ..validate import check_scalar

__all__ = ["SpringElement", "LinearSpring", "CubicSpring", "PiecewiseSpring", "Backlash",
           "check_path"]


@runtime_checkable
class SpringElement(Protocol):
    """The spring protocol shared by stateless springs and hysteresis operators."""

    n_states: int

    def initial_state(self) -> np.ndarray: ...

    def state_derivative(self, z, delta, delta_dot) -> np.ndarray: ...

    def torque(self, delta, z=None) -> np.ndarray: ...

    def run(self, delta, t) -> np.ndarray: ...

    @property
    def params(self) -> dict[str, float]: ...


def check_path(delta, t) -> tuple[np.ndarray, np.ndarray]:
    """Validate a deflection history: delta (T,) rad and t (T,) s strictly increasing, finite."""
    d = np.asarray(delta, dtype=np.float64)
    tt = np.asarray(t, dtype=np.float64)
    if d.ndim != 1 or tt.shape != d.shape or d.size < 2:
        raise InputError(None, "delta, t", "two (T,) arrays with T >= 2", f"shapes {d.shape}, {tt.shape}")
    if not (np.isfinite(d).all() and np.isfinite(tt).all()):
        raise InputError(None, "delta, t", "finite values (no NaN)")
    if not (np.diff(tt) > 0).all():
        raise InputError(None, "t", "strictly increasing sample times")
    return d, tt


class _Stateless:
    """The spring protocol for springs without memory (n_states = 0)."""

    n_states: ClassVar[int] = 0

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            object.__setattr__(self, f.name, check_scalar(getattr(self, f.name), f.name))

    def initial_state(self) -> np.ndarray:
        return np.zeros(0)

    def state_derivative(self, z, delta, delta_dot) -> np.ndarray:
        return np.zeros(np.shape(z))

    def torque(self, delta, z=None) -> np.ndarray:
        """Spring torque, N m, same shape as `delta` (rad). `z` is ignored."""
        return self._torque(np.asarray(delta, dtype=np.float64))

    def run(self, delta, t) -> np.ndarray:
        """Torque (T,) N m along delta (T,) rad at times t (T,) s; memoryless, so just torque."""
        d, _ = check_path(delta, t)
        return self._torque(d)

    @property
    def params(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}  # type: ignore[arg-type]


@dataclass(frozen=True)
class LinearSpring(_Stateless):
    """Linear spring with a deflection offset, Lightcap and Banks (2007), eq. (7): ``tau_s = k (delta - offset)``.

    Parameters
    ----------
    k : float
        Stiffness, N m / rad (Lightcap and Banks (2007), Table I: 4.78e2 to 1.19e4).
    offset : float
        Deflection at zero torque, rad (e.g. a zero mismatch between resolver and mocap).
    """

    k: float
    offset: float = 0.0

    def _torque(self, d):
        return self.k * (d - self.offset)


@dataclass(frozen=True)
class CubicSpring(_Stateless):
    """Stiffening (k3 > 0) or softening (k3 < 0) spring: ``tau_s = k1 delta + k3 delta^3``.

    k1 in N m / rad, k3 in N m / rad^3. A common harmonic-drive fit (Taghirad 1997 style).
    """

    k1: float
    k3: float

    def _torque(self, d):
        return self.k1 * d + self.k3 * d**3


@dataclass(frozen=True)
class PiecewiseSpring(_Stateless):
    """Harmonic-drive stiffness as the manufacturers give it: three linear pieces.

    Stiffness k1 for |tau| <= tau1, k2 for tau1 < |tau| <= tau2, k3 beyond; odd in delta and
    continuous. The deflection breakpoints are ``theta1 = tau1 / k1`` and
    ``theta2 = theta1 + (tau2 - tau1) / k2`` (Harmonic Drive catalogue "torsional stiffness").

    Parameters
    ----------
    k1, k2, k3 : float
        Stiffnesses, N m / rad, positive (usually k1 < k2 < k3: soft wind-up).
    tau1, tau2 : float
        Torque limits of the first two pieces, N m, 0 < tau1 < tau2.
    """

    k1: float
    k2: float
    k3: float
    tau1: float
    tau2: float

    def __post_init__(self) -> None:
        super().__post_init__()
        for n in ("k1", "k2", "k3", "tau1"):
            check_scalar(getattr(self, n), n, positive=True)
        if not self.tau2 > self.tau1:
            raise InputError(None, "tau2", f"a torque above tau1 = {self.tau1}", self.tau2)

    @property
    def breakpoints(self) -> tuple[float, float]:
        """Deflections (theta1, theta2) in rad where the stiffness changes."""
        th1 = self.tau1 / self.k1
        return th1, th1 + (self.tau2 - self.tau1) / self.k2

    def _torque(self, d):
        th1, th2 = self.breakpoints
        a = np.abs(d)
        mag = np.where(a <= th1, self.k1 * a,
                       np.where(a <= th2, self.tau1 + self.k2 * (a - th1), self.tau2 + self.k3 * (a - th2)))
        return np.sign(d) * mag


@dataclass(frozen=True)
class Backlash:
    """Backlash / dead zone in front of any spring element: no torque within +-gap/2.

    The inner element sees the dead-zoned deflection
    ``d' = delta - gap/2`` (delta > gap/2), ``0`` (|delta| <= gap/2), ``delta + gap/2`` (delta < -gap/2),
    and its rate ``delta_dot`` outside the gap, 0 inside. Works with stateful elements too (the
    protocol is forwarded), e.g. lost motion in front of a hysteresis operator.

    Parameters
    ----------
    gap : float
        Total free play, rad (>= 0).
    spring : SpringElement
        The element engaged outside the gap.
    """

    gap: float
    spring: SpringElement

    def __post_init__(self) -> None:
        object.__setattr__(self, "gap", check_scalar(self.gap, "gap", nonneg=True))
        if not isinstance(self.spring, SpringElement):
            raise InputError(None, "spring", "a spring element (see SpringElement)", type(self.spring).__name__)

    @property
    def n_states(self) -> int:
        return self.spring.n_states

    @property
    def params(self) -> dict[str, float]:
        return {"gap": self.gap, **{f"spring.{k}": v for k, v in self.spring.params.items()}}

    def engaged(self, delta) -> np.ndarray:
        """The dead-zoned deflection d' (rad), same shape as `delta`."""
        d = np.asarray(delta, dtype=np.float64)
        h = 0.5 * self.gap
        return np.where(d > h, d - h, np.where(d < -h, d + h, 0.0))

    def initial_state(self) -> np.ndarray:
        return self.spring.initial_state()

    def state_derivative(self, z, delta, delta_dot) -> np.ndarray:
        inside = np.abs(np.asarray(delta, dtype=np.float64)) <= 0.5 * self.gap
        return self.spring.state_derivative(z, self.engaged(delta), np.where(inside, 0.0, delta_dot))

    def torque(self, delta, z=None) -> np.ndarray:
        """Torque, N m, same shape as `delta` (rad); `z` (..., n_states) for a stateful spring."""
        return self.spring.torque(self.engaged(delta), z)

    def run(self, delta, t) -> np.ndarray:
        """Torque (T,) N m along delta (T,) rad at times t (T,) s (the inner run on d')."""
        d, tt = check_path(delta, t)
        return self.spring.run(self.engaged(d), tt)
