"""Drivetrain effects that simple flexible-joint models leave out (docs methods, "Effects").

- :class:`TransmissionError`: harmonic-drive kinematic error, periodic in the motor angle.
- :class:`GravityBalancer`: a spring balancer's torque as a function of the joint angle.
- :class:`PositionTorque`: any smooth torque of the joint angle (a Fourier series): what a
  gravity model leaves out, fitted from data when its physical cause is unknown.
- :class:`JointCoupling`: torques on one joint from the others' accelerations or deflections.
- :func:`shift_signal`: a sampled signal delayed by a clock offset, with interpolation.
- :class:`Drivetrain`: the per-joint bundle a model takes (transmission error, balancer and the
  drive-gain error ``torque_gain``: physical motor torque = torque_gain x commanded torque).

All on the link side, SI units (docs/conventions.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import make_interp_spline

from ..errors import InputError

__all__ = ["TransmissionError", "GravityBalancer", "PositionTorque", "JointCoupling", "Drivetrain", "shift_signal"]


def _tuple(name: str, x) -> tuple[float, ...]:
    a = np.atleast_1d(np.asarray(x, dtype=np.float64)).ravel()
    if not np.isfinite(a).all():
        raise InputError(None, name, "finite numbers", x)
    return tuple(a.tolist())


def _pos(name: str, value) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise InputError(None, name, "a positive number", value)
    return v


@dataclass(frozen=True)
class TransmissionError:
    """Kinematic transmission error of a harmonic drive, periodic in the wave-generator angle.

    The flexspline output lags or leads the ideal ``q_m`` (motor angle / N) by

        e(q_m) = sum_k a_k sin(n_k theta_wg + phi_k),   theta_wg = N q_m  (wave-generator angle)

    with the dominant orders n = 1 and 2 per wave-generator turn (docs methods, "kinematic
    transmission error"). The spring then sees ``delta = q_m + e(q_m) - q`` and the motor feels
    the spring torque times ``1 + e'(q_m)`` (the instantaneous gear ratio; power balance).

    Parameters
    ----------
    gear_ratio : float
        N (> 0).
    amplitudes : K floats
        a_k, rad on the link side (typically 1e-5 to 1e-4).
    phases : K floats
        phi_k, rad.
    orders : K floats
        n_k, cycles per wave-generator revolution; default (1, 2).
    """

    gear_ratio: float
    amplitudes: tuple[float, ...] = (0.0, 0.0)
    phases: tuple[float, ...] = (0.0, 0.0)
    orders: tuple[float, ...] = (1.0, 2.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "gear_ratio", _pos("gear_ratio", self.gear_ratio))
        vals = [_tuple(n, getattr(self, n)) for n in ("amplitudes", "phases", "orders")]
        if len({len(v) for v in vals}) != 1:
            raise InputError(None, "amplitudes/phases/orders", "sequences of equal length", [len(v) for v in vals])
        for n, v in zip(("amplitudes", "phases", "orders"), vals):
            object.__setattr__(self, n, v)

    @property
    def params(self) -> dict[str, float]:
        out = {"gear_ratio": self.gear_ratio}
        for i, (n, a, p) in enumerate(zip(self.orders, self.amplitudes, self.phases), 1):
            out.update({f"order{i}": n, f"amplitude{i}": a, f"phase{i}": p})
        return out

    def _arg(self, q_m):
        q_m = np.asarray(q_m, dtype=np.float64)
        return (self.gear_ratio * q_m)[..., None] * np.asarray(self.orders) + np.asarray(self.phases)

    def error(self, q_m) -> np.ndarray:
        """e(q_m) in rad (link side), same shape as `q_m` (rad, link side)."""
        return np.sin(self._arg(q_m)) @ np.asarray(self.amplitudes)

    def derivative(self, q_m) -> np.ndarray:
        """de/dq_m (dimensionless), same shape as `q_m`."""
        w = np.asarray(self.amplitudes) * np.asarray(self.orders) * self.gear_ratio
        return np.cos(self._arg(q_m)) @ w


@dataclass(frozen=True)
class GravityBalancer:
    """Spring gravity balancer between the base and the link.

    A spring of stiffness `k` and free length `free_length` joins a point at distance `b` from
    the joint on the base to a point at distance `a` on the link; the two arms make the angle
    ``phi = q - q0``. Spring length ``L = sqrt(a^2 + b^2 - 2 a b cos phi)``, potential
    ``U = k (L - free_length)^2 / 2`` and the torque it applies to the link

        tau_bal(q) = -dU/dq = -k (L - free_length) a b sin(phi) / L.

    It enters the link equation on the right: ``I q'' + G(q) + F = tau_s + tau_bal(q)``.
    Its signature in residuals: smooth, position-only, not of the m g l sin q form.

    Parameters
    ----------
    k : float
        Spring stiffness, N / m (> 0).
    a, b : float
        Arm lengths on the link and on the base, m (> 0, a != b).
    free_length : float
        Unstretched spring length, m (>= 0).
    q0 : float
        Joint angle at which the arms are aligned (spring shortest), rad.
    """

    k: float
    a: float
    b: float
    free_length: float = 0.0
    q0: float = 0.0

    def __post_init__(self) -> None:
        for n in ("k", "a", "b"):
            object.__setattr__(self, n, _pos(n, getattr(self, n)))
        if not (math.isfinite(self.free_length) and self.free_length >= 0 and math.isfinite(self.q0)):
            raise InputError(None, "free_length, q0", "a non-negative length and a finite angle",
                             (self.free_length, self.q0))
        if self.a == self.b:
            raise InputError(None, "a, b", "different arm lengths (a = b gives zero length at q0)", self.a)

    @property
    def params(self) -> dict[str, float]:
        return {"k": self.k, "a": self.a, "b": self.b, "free_length": self.free_length, "q0": self.q0}

    def length(self, q) -> np.ndarray:
        """Spring length L(q), m, same shape as `q` (rad)."""
        phi = np.asarray(q, dtype=np.float64) - self.q0
        return np.sqrt(self.a**2 + self.b**2 - 2 * self.a * self.b * np.cos(phi))

    def potential(self, q) -> np.ndarray:
        """Spring energy U(q), J."""
        return 0.5 * self.k * (self.length(q) - self.free_length) ** 2

    def torque(self, q) -> np.ndarray:
        """Torque on the link, N m, same shape as `q` (rad)."""
        phi = np.asarray(q, dtype=np.float64) - self.q0
        L = self.length(q)
        return -self.k * (L - self.free_length) * self.a * self.b * np.sin(phi) / L


@dataclass(frozen=True)
class PositionTorque:
    """A torque on the link that depends on the joint angle only: a Fourier series plus a
    Chebyshev series over an angle range,

        tau(q) = sum_k c_k cos(n_k q) + s_k sin(n_k q) + sum_j a_j T_j((q - center) / half_range)

    (N m; n_k cycles per revolution; T_j the Chebyshev polynomials, j = 1, 2, ...; the Chebyshev
    part describes the range it was fitted on and is not meant far outside it). It enters the link
    equation on the right like a balancer (``Drivetrain.balancer`` takes it): ``I q'' + G(q) + F
    = tau_s + tau(q)``: the generic form of a gravity-model error (a balancer, a cable, a wrong
    mass or centre of mass) when its physical cause is unknown.
    """

    orders: tuple[float, ...] = ()
    cos_Nm: tuple[float, ...] = ()
    sin_Nm: tuple[float, ...] = ()
    chebyshev_Nm: tuple[float, ...] = ()
    center_rad: float = 0.0
    half_range_rad: float = 1.0

    def __post_init__(self) -> None:
        o, c, s, ch = (_tuple(n, getattr(self, n)) for n in ("orders", "cos_Nm", "sin_Nm", "chebyshev_Nm"))
        if not (len(o) == len(c) == len(s)):
            raise InputError(None, "orders, cos_Nm, sin_Nm", "three sequences of equal length", (len(o), len(c), len(s)))
        for n, v in (("orders", o), ("cos_Nm", c), ("sin_Nm", s), ("chebyshev_Nm", ch)):
            object.__setattr__(self, n, v)
        object.__setattr__(self, "half_range_rad", _pos("half_range_rad", self.half_range_rad))
        if not math.isfinite(self.center_rad):
            raise InputError(None, "center_rad", "a finite angle", self.center_rad)

    @property
    def params(self) -> dict:
        return {"orders": list(self.orders), "cos_Nm": list(self.cos_Nm), "sin_Nm": list(self.sin_Nm),
                "chebyshev_Nm": list(self.chebyshev_Nm), "center_rad": self.center_rad,
                "half_range_rad": self.half_range_rad}

    def torque(self, q) -> np.ndarray:
        """Torque on the link, N m, same shape as `q` (rad)."""
        q = np.asarray(q, dtype=np.float64)
        out = np.zeros_like(q)
        for n, c, s in zip(self.orders, self.cos_Nm, self.sin_Nm):
            out = out + c * np.cos(n * q) + s * np.sin(n * q)
        if self.chebyshev_Nm:
            x = (q - self.center_rad) / self.half_range_rad
            out = out + np.polynomial.chebyshev.chebval(x, (0.0,) + self.chebyshev_Nm)
        return out


@dataclass(frozen=True, eq=False)
class JointCoupling:
    """Coupling torques between joints: ``tau_c = matrix @ x`` on the link side.

    kind = "acceleration": x is the link accelerations q'' (T, m); a model moves the term to
    the left, ``(M(q) - matrix) q'' = ...`` (square matrix only).
    kind = "deflection": x is the deflections delta (T, m); the torque adds to the spring torque
    reaching each link (a cross-stiffness).
    The matrix (n, m) maps m source joints onto n target joints, N m per unit of x; within one
    model it is square with a zero diagonal (the diagonal belongs to M or to the spring).
    Signature in residuals: correlation with the neighbours' accelerations (docs methods).
    """

    matrix: np.ndarray
    kind: str = "acceleration"

    def __post_init__(self) -> None:
        m = np.atleast_2d(np.asarray(self.matrix, dtype=np.float64))
        if m.ndim != 2 or not np.isfinite(m).all():
            raise InputError(None, "matrix", "a finite (n, m) matrix", f"shape {m.shape}")
        if self.kind not in ("acceleration", "deflection"):
            raise InputError(None, "kind", '"acceleration" or "deflection"', repr(self.kind))
        m = m.copy()
        m.setflags(write=False)
        object.__setattr__(self, "matrix", m)

    def torque(self, x) -> np.ndarray:
        """Coupling torque (..., n) N m from x (..., m) (rad/s^2 or rad)."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape[-1:] != (self.matrix.shape[1],):
            raise InputError(None, "x", f"an array with last axis {self.matrix.shape[1]}", f"shape {x.shape}")
        return x @ self.matrix.T

    def check_square(self, n: int) -> None:
        """Raise InputError unless the matrix is (n, n) with a zero diagonal."""
        if self.matrix.shape != (n, n) or np.any(np.diag(self.matrix) != 0):
            raise InputError(None, "coupling.matrix", f"a ({n}, {n}) matrix with zero diagonal",
                             f"shape {self.matrix.shape}")


@dataclass(frozen=True)
class Drivetrain:
    """Optional drivetrain effects of one joint.

    Attributes
    ----------
    transmission_error : TransmissionError or None
    balancer : GravityBalancer, PositionTorque or None (anything with ``torque(q)``, N m)
    torque_gain : float
        Drive-gain error: the motor produces ``torque_gain * u`` when the controller commands
        (and logs) u. 1 is a correct gain; its residual is proportional to the commanded torque.
    """

    transmission_error: TransmissionError | None = None
    balancer: GravityBalancer | None = None
    torque_gain: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "torque_gain", _pos("torque_gain", self.torque_gain))


def shift_signal(t, x, delay_s: float, *, kind: str = "cubic") -> np.ndarray:
    """The signal x delayed by `delay_s`: y(t_i) = x(t_i - delay_s), by interpolation.

    Use it to put a stream on another clock: with ``t_controller = t_mocap + offset`` (DESIGN),
    a mocap signal sampled at t_mocap, shifted by ``delay_s = offset``, reads as a function of
    the controller time at the same sample instants. Samples whose source time falls outside
    [t[0], t[-1]] are NaN (never extrapolated).

    Parameters
    ----------
    t : (T,) float
        Strictly increasing sample times, s.
    x : (T, ...) float
        Signal, time first. With kind "cubic" it must be finite; "linear" keeps NaN local.
    delay_s : float
        Delay in s; negative advances the signal.
    kind : {"cubic", "linear"}

    Returns
    -------
    (T, ...) float
    """
    t = np.asarray(t, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    if t.ndim != 1 or x.shape[:1] != t.shape or t.size < 4 or not (np.diff(t) > 0).all():
        raise InputError(None, "t, x", "increasing t (T,) with T >= 4 and x (T, ...)",
                         f"shapes {t.shape}, {x.shape}")
    if kind not in ("cubic", "linear"):
        raise InputError(None, "kind", '"cubic" or "linear"', repr(kind))
    if kind == "cubic" and not np.isfinite(x).all():
        raise InputError(None, "x", 'finite values for kind="cubic"', hint='use kind="linear" with NaN')
    ts = t - float(delay_s)
    inside = (ts >= t[0]) & (ts <= t[-1])
    spline = make_interp_spline(t, x, k=3 if kind == "cubic" else 1, axis=0)
    y = spline(np.clip(ts, t[0], t[-1]))
    y[~inside] = np.nan
    return y
