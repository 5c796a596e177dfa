"""Springs with memory: Bouc-Wen, Dahl and generalized Maxwell-slip hysteresis operators.

They follow the spring protocol of :mod:`.springs` (``n_states``, ``initial_state``,
``state_derivative``, ``torque``, ``run``), so the simulator integrates their states with the
rigid-body states. Each also gives its energy balance: ``stored_energy(delta, z)`` and
``dissipation_rate(z, delta, delta_dot)`` with ``tau_s delta_dot = d/dt stored + dissipation``,
so the area of a steady loop, the closed integral of tau_s d delta, equals the energy dissipated
over the cycle (docs methods: "a loop in spring torque vs deflection that stays as frequency
goes to 0").

``run(delta, t)`` integrates the state along a prescribed deflection path. Dahl (exponent 1)
and rate-independent Maxwell-slip take the path as linear between samples and have exact
per-interval solutions, composed with a parallel prefix scan (log2 T vectorised steps, no
per-sample Python loop); the others go through ``scipy.integrate.solve_ivp`` along the cubic
spline through the samples (:func:`integrate_states`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from ..errors import InputError
from ..validate import check_scalar
from .springs import check_path

__all__ = ["BoucWen", "Dahl", "MaxwellSlip", "integrate_states"]


def integrate_states(element, delta, t, z0=None, *, rtol: float = 1e-8, atol: float = 1e-10,
                     method: str = "LSODA", max_step: float = 4.0) -> np.ndarray:
    """States (T, n_states) of `element` along delta (T,) rad at t (T,) s, by solve_ivp.

    The path between samples is the interpolating cubic spline of `delta` (smooth, so the solver
    takes steps that span many samples); `z0` defaults to the virgin state. For Dahl and
    rate-independent Maxwell-slip prefer ``run_states(..., method="exact")``, which is exact for
    the piecewise-linear path; the two agree to the interpolation difference.
    """
    d, tt = check_path(delta, t)
    z0 = element.initial_state() if z0 is None else np.asarray(z0, dtype=np.float64)
    if element.n_states == 0:
        return np.zeros((tt.size, 0))
    c = CubicSpline(tt, d).c  # (4, T-1): d = sum_j c[j] (t - t_k)^(3-j) on interval k
    last = tt.size - 2

    def rhs(ti, z):
        k = min(max(int(np.searchsorted(tt, ti, side="right")) - 1, 0), last)
        h = ti - tt[k]
        c0, c1, c2, c3 = c[:, k]
        return element.state_derivative(z, ((c0 * h + c1) * h + c2) * h + c3, (3 * c0 * h + 2 * c1) * h + c2)

    sol = solve_ivp(rhs, (tt[0], tt[-1]), z0, method=method, t_eval=tt, rtol=rtol, atol=atol,
                    max_step=max_step * float(np.median(np.diff(tt))))
    if not sol.success:
        raise RuntimeError(f"state integration failed: {sol.message}")
    return sol.y.T


def _scan(first_a, first_b, compose):
    """Inclusive Hillis-Steele prefix scan of maps (a, b) along axis 0, in log2(T) steps.

    ``compose(a1, b1, a2, b2)`` returns the map "apply 1, then 2".
    """
    a, b = first_a.copy(), first_b.copy()
    s, T = 1, a.shape[0]
    while s < T:
        na, nb = compose(a[:-s], b[:-s], a[s:], b[s:])
        a[s:], b[s:] = na, nb
        s *= 2
    return a, b


def _compose_affine(a1, b1, a2, b2):
    return a2 * a1, a2 * b1 + b2


def _compose_clamp(lo1, hi1, lo2, hi2):
    # clamp(clamp(x, lo1, hi1), lo2, hi2) == clamp(x, clip(lo1, lo2, hi2), clip(hi1, lo2, hi2))
    return np.clip(lo1, lo2, hi2), np.clip(hi1, lo2, hi2)


class _Hysteretic:
    """Shared `run` for the stateful elements."""

    def run_states(self, delta, t, z0=None, *, method: str = "auto") -> np.ndarray:
        """States (T, n_states) along delta (T,) rad at times t (T,) s, starting from `z0`.

        method: "auto" (exact scan where the element has one, else ODE), "exact" or "ode".
        """
        if method not in ("auto", "exact", "ode"):
            raise InputError(None, "method", '"auto", "exact" or "ode"', repr(method))
        has_exact = hasattr(self, "_exact_states") and self._has_exact()  # type: ignore[attr-defined]
        if method == "exact" and not has_exact:
            raise InputError(None, "method", "an element with an exact solution (Dahl exponent 1, "
                             "Maxwell-slip without Stribeck)", type(self).__name__)
        if method == "ode" or not has_exact:
            return integrate_states(self, delta, t, z0)
        d, _ = check_path(delta, t)
        z0 = self.initial_state() if z0 is None else np.asarray(z0, dtype=np.float64)  # type: ignore[attr-defined]
        return self._exact_states(d, z0)  # type: ignore[attr-defined]

    def run(self, delta, t, z0=None) -> np.ndarray:
        """Torque (T,) N m along delta (T,) rad at times t (T,) s, from state `z0` (default virgin)."""
        d, tt = check_path(delta, t)
        return self.torque(d, self.run_states(d, tt, z0))  # type: ignore[attr-defined]


@dataclass(frozen=True)
class BoucWen(_Hysteretic):
    """Bouc-Wen hysteretic spring (Bouc 1967; Wen 1976; Ismail et al. 2009 review):

        tau_s = alpha k delta + (1 - alpha) k z
        z'    = A delta' - beta |delta'| |z|^(n-1) z - gamma delta' |z|^n

    Parameters
    ----------
    k : float
        Stiffness scale, N m / rad (> 0).
    alpha : float
        Share of the purely elastic part, in [0, 1].
    beta, gamma : float
        Loop shape, rad^-n; beta + gamma > 0 bounds z by (A / (beta + gamma))^(1/n).
    A : float
        Initial slope of z against delta (dimensionless, > 0).
    n : float
        Sharpness of the elastic-to-plastic transition (>= 1 keeps the ODE smooth at z = 0).

    The state z is in rad. Stored energy alpha k delta^2 / 2 + (1 - alpha) k z^2 / (2A).
    """

    k: float
    alpha: float
    beta: float
    gamma: float
    A: float = 1.0
    n: float = 1.0

    n_states = 1

    def __post_init__(self) -> None:
        check_scalar(self.k, "k", positive=True)
        check_scalar(self.alpha, "alpha", lo=0.0, hi=1.0)
        check_scalar(self.beta, "beta")
        check_scalar(self.gamma, "gamma")
        check_scalar(self.A, "A", positive=True)
        check_scalar(self.n, "n", positive=True)
        if self.beta + self.gamma <= 0:
            raise InputError(None, "beta + gamma", "a positive sum (bounded hysteresis)", self.beta + self.gamma)

    @property
    def params(self) -> dict[str, float]:
        return {"k": self.k, "alpha": self.alpha, "beta": self.beta, "gamma": self.gamma, "A": self.A, "n": self.n}

    def initial_state(self) -> np.ndarray:
        return np.zeros(1)

    def state_derivative(self, z, delta, delta_dot) -> np.ndarray:
        z = np.asarray(z, dtype=np.float64)
        dd = np.asarray(delta_dot, dtype=np.float64)[..., None]
        zn = np.abs(z) ** self.n
        return self.A * dd - self.beta * np.abs(dd) * zn * np.sign(z) - self.gamma * dd * zn

    def torque(self, delta, z=None) -> np.ndarray:
        """Torque, N m; delta (...) rad, z (..., 1) rad."""
        delta = np.asarray(delta, dtype=np.float64)
        z = np.zeros(delta.shape + (1,)) if z is None else np.asarray(z, dtype=np.float64)
        return self.alpha * self.k * delta + (1 - self.alpha) * self.k * z[..., 0]

    def stored_energy(self, delta, z) -> np.ndarray:
        """Elastic energy, J: alpha k delta^2/2 + (1-alpha) k z^2/(2A); delta (...), z (..., 1)."""
        z = np.asarray(z, dtype=np.float64)[..., 0]
        return 0.5 * self.k * (self.alpha * np.asarray(delta) ** 2 + (1 - self.alpha) * z**2 / self.A)

    def dissipation_rate(self, z, delta, delta_dot) -> np.ndarray:
        """Dissipated power, W: (1-alpha) k / A (beta |delta'| |z|^(n+1) + gamma delta' z |z|^n)."""
        z = np.asarray(z, dtype=np.float64)[..., 0]
        dd = np.asarray(delta_dot, dtype=np.float64)
        zn = np.abs(z) ** self.n
        return (1 - self.alpha) * self.k / self.A * (self.beta * np.abs(dd) * zn * np.abs(z) + self.gamma * dd * z * zn)


@dataclass(frozen=True)
class Dahl(_Hysteretic):
    """Dahl friction element (Dahl 1968) in parallel with a linear spring k0:

        tau_s = k0 delta + F
        F'    = sigma delta' |1 - F sign(delta') / fc|^i sign(1 - F sign(delta') / fc)

    Parameters
    ----------
    sigma : float
        Initial (rest) stiffness of the friction element, N m / rad (> 0).
    fc : float
        Coulomb level the element saturates at, N m (> 0).
    k0 : float
        Parallel linear stiffness, N m / rad.
    exponent : float
        i; with i = 1 the state ODE is linear on each monotone piece and `run` is exact.

    The state is F in N m. Stored energy k0 delta^2/2 + F^2/(2 sigma).
    """

    sigma: float
    fc: float
    k0: float = 0.0
    exponent: float = 1.0

    n_states = 1

    def __post_init__(self) -> None:
        check_scalar(self.sigma, "sigma", positive=True)
        check_scalar(self.fc, "fc", positive=True)
        check_scalar(self.k0, "k0", nonneg=True)
        check_scalar(self.exponent, "exponent", positive=True)

    @property
    def params(self) -> dict[str, float]:
        return {"sigma": self.sigma, "fc": self.fc, "k0": self.k0, "exponent": self.exponent}

    def initial_state(self) -> np.ndarray:
        return np.zeros(1)

    def state_derivative(self, z, delta, delta_dot) -> np.ndarray:
        z = np.asarray(z, dtype=np.float64)
        dd = np.asarray(delta_dot, dtype=np.float64)[..., None]
        r = 1.0 - z * np.sign(dd) / self.fc
        if self.exponent == 1.0:
            return self.sigma * dd * r
        return self.sigma * dd * np.abs(r) ** self.exponent * np.sign(r)

    def torque(self, delta, z=None) -> np.ndarray:
        """Torque, N m; delta (...) rad, z (..., 1) N m."""
        delta = np.asarray(delta, dtype=np.float64)
        z = np.zeros(delta.shape + (1,)) if z is None else np.asarray(z, dtype=np.float64)
        return self.k0 * delta + z[..., 0]

    def stored_energy(self, delta, z) -> np.ndarray:
        """Elastic energy, J: k0 delta^2/2 + F^2/(2 sigma)."""
        z = np.asarray(z, dtype=np.float64)[..., 0]
        return 0.5 * self.k0 * np.asarray(delta) ** 2 + 0.5 * z**2 / self.sigma

    def dissipation_rate(self, z, delta, delta_dot) -> np.ndarray:
        """Dissipated power, W: F (delta' - F'/sigma)."""
        F = np.asarray(z, dtype=np.float64)[..., 0]
        dd = np.asarray(delta_dot, dtype=np.float64)
        return F * (dd - self.state_derivative(z, delta, dd)[..., 0] / self.sigma)

    def _has_exact(self) -> bool:
        return self.exponent == 1.0

    def _exact_states(self, d: np.ndarray, z0: np.ndarray) -> np.ndarray:
        # On an interval with increment D (sign s): F -> s fc + (F - s fc) exp(-sigma |D| / fc).
        D = np.diff(d)
        a = np.exp(-self.sigma * np.abs(D) / self.fc)
        b = np.sign(D) * self.fc * (1.0 - a)
        A, B = _scan(a, b, _compose_affine)
        F = np.concatenate([[z0[0]], A * z0[0] + B])
        return F[:, None]


@dataclass(frozen=True)
class MaxwellSlip(_Hysteretic):
    """Generalized Maxwell-slip operator: N elasto-slip elements in parallel with a spring k0.

    Lampaert, Al-Bender & Swevers 2003; Al-Bender, Lampaert & Swevers 2005 (GMS); used for
    harmonic-drive hysteresis by Ruderman & Bertram. Element i has stiffness k_i and slip level
    f_i s(delta'), with the normalised Stribeck curve
    ``s(v) = 1 + (stribeck_ratio - 1) exp(-(v / stribeck_velocity)^2)``. Its state is its torque F_i:

        sticking  (F_i delta' <= 0 or |F_i| < f_i s):  F_i' = k_i delta'
        slipping  (otherwise):                         F_i' = attraction (sign(delta') f_i - F_i / s)

        tau_s = k0 delta + sum_i F_i

    With ``stribeck_ratio = 1`` (the default) the operator is rate independent (the classical
    Maxwell-slip / Iwan model, a sum of play operators with thresholds r_i = f_i / k_i); `run`
    is then exact. The attraction rate (1/s) matters for a Stribeck curve; without one it only
    pulls an element that a solver stepped past its level back onto it.

    In `state_derivative` (what the simulator integrates) the switch from stick to slip is made
    continuous: over the band (1 - slip_band) f_i s < |F_i| < f_i s the derivative blends
    linearly from sticking to slipping. A discontinuous switch (slip_band = 0) makes the
    right-hand side discontinuous in the state and stalls implicit solvers (LSODA, Radau).

    Parameters
    ----------
    k : N floats
        Element stiffnesses, N m / rad (> 0).
    f : N floats
        Element slip torques, N m (> 0).
    k0 : float
        Parallel linear stiffness, N m / rad.
    stribeck_ratio, stribeck_velocity : float
        Static-to-Coulomb ratio and Stribeck velocity (rad/s) of the slip level.
    attraction : float
        GMS attraction rate C, 1/s.
    slip_band : float
        Relative width of the stick-to-slip blend of the ODE form (see below), in [0, 0.5].
    """

    k: tuple[float, ...]
    f: tuple[float, ...]
    k0: float = 0.0
    stribeck_ratio: float = 1.0
    stribeck_velocity: float = 1e-3
    attraction: float = 1e3
    slip_band: float = 1e-3

    def __post_init__(self) -> None:
        k = np.atleast_1d(np.asarray(self.k, dtype=np.float64)).ravel()
        f = np.atleast_1d(np.asarray(self.f, dtype=np.float64)).ravel()
        if k.shape != f.shape or k.size == 0 or not (np.all(k > 0) and np.all(f > 0)):
            raise InputError(None, "k, f", "two equal-length sequences of positive numbers",
                             f"k {k.tolist()}, f {f.tolist()}")
        object.__setattr__(self, "k", tuple(k.tolist()))
        object.__setattr__(self, "f", tuple(f.tolist()))
        check_scalar(self.k0, "k0", nonneg=True)
        check_scalar(self.stribeck_ratio, "stribeck_ratio", positive=True)
        check_scalar(self.stribeck_velocity, "stribeck_velocity", positive=True)
        check_scalar(self.attraction, "attraction", positive=True)
        check_scalar(self.slip_band, "slip_band", lo=0.0, hi=0.5)

    @property
    def n_states(self) -> int:
        return len(self.k)

    @property
    def params(self) -> dict[str, float]:
        out = {"k0": self.k0}
        for i, (k, f) in enumerate(zip(self.k, self.f), 1):
            out.update({f"k{i}": k, f"f{i}": f})
        out.update({"stribeck_ratio": self.stribeck_ratio, "stribeck_velocity": self.stribeck_velocity,
                    "attraction": self.attraction, "slip_band": self.slip_band})
        return out

    @cached_property
    def _arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.k), np.asarray(self.f)

    @property
    def thresholds(self) -> np.ndarray:
        """Slip deflections r_i = f_i / k_i, (N,) rad."""
        return np.asarray(self.f) / np.asarray(self.k)

    def initial_state(self) -> np.ndarray:
        return np.zeros(self.n_states)

    def _s(self, v):
        if self.stribeck_ratio == 1.0:
            return np.ones_like(v)
        return 1.0 + (self.stribeck_ratio - 1.0) * np.exp(-(v / self.stribeck_velocity) ** 2)

    def state_derivative(self, z, delta, delta_dot) -> np.ndarray:
        z = np.asarray(z, dtype=np.float64)
        v = np.asarray(delta_dot, dtype=np.float64)[..., None]
        k, f = self._arrays
        s = self._s(v)
        level = f * s
        if self.slip_band > 0:  # continuous stick -> slip transition over the band below the level
            g = np.clip((level - np.abs(z)) / (self.slip_band * level), 0.0, 1.0)
        else:
            g = (np.abs(z) < level).astype(np.float64)
        g = np.where(z * v > 0, g, 1.0)
        slip = self.attraction * (np.sign(v) * f - z / s)
        return g * k * v + (1.0 - g) * slip

    def torque(self, delta, z=None) -> np.ndarray:
        """Torque, N m; delta (...) rad, z (..., N) N m."""
        delta = np.asarray(delta, dtype=np.float64)
        z = np.zeros(delta.shape + (self.n_states,)) if z is None else np.asarray(z, dtype=np.float64)
        return self.k0 * delta + z.sum(axis=-1)

    def stored_energy(self, delta, z) -> np.ndarray:
        """Elastic energy, J: k0 delta^2/2 + sum F_i^2/(2 k_i)."""
        z = np.asarray(z, dtype=np.float64)
        return 0.5 * self.k0 * np.asarray(delta) ** 2 + (0.5 * z**2 / np.asarray(self.k)).sum(axis=-1)

    def dissipation_rate(self, z, delta, delta_dot) -> np.ndarray:
        """Dissipated power, W: sum_i F_i (delta' - F_i'/k_i), the slip work rate."""
        z = np.asarray(z, dtype=np.float64)
        dd = np.asarray(delta_dot, dtype=np.float64)
        slip_rate = dd[..., None] - self.state_derivative(z, delta, dd) / np.asarray(self.k)
        return (z * slip_rate).sum(axis=-1)

    def _has_exact(self) -> bool:
        return self.stribeck_ratio == 1.0

    def _exact_states(self, d: np.ndarray, z0: np.ndarray) -> np.ndarray:
        # Play operator per element: slip position w_i -> clamp(w_i, d - r_i, d + r_i); F_i = k_i (d - w_i).
        k, r = np.asarray(self.k), self.thresholds
        lo = d[1:, None] - r
        hi = d[1:, None] + r
        L, H = _scan(lo, hi, _compose_clamp)
        w0 = d[0] - z0 / k
        w = np.concatenate([w0[None, :], np.clip(w0, L, H)])
        return k * (d[:, None] - w)
