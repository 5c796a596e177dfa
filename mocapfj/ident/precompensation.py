"""Model-based pre-compensation of an elastic joint's deflection (Oueslati, Bearee, Gibaru and
Moraru 2012, eq. 17), and the jerk-limited reference it is shown on.

The motor command anticipates the link's deflection predicted by the identified model:

    theta_command(t) = theta_reference(t) - Delta_theta_simulated(t),
    Delta_theta_simulated = theta_l_sim - theta_reference

with theta_l_sim the link of y'' + 2 zeta omega0 y' + omega0^2 (y - u) = 0 driven by u =
theta_reference (their eq. 9-10, the model of :mod:`.algebraic`). In this package's sign
(delta = q_m - q, docs/conventions.md) the command is reference + delta_predicted. One pass is
their law; with ``iterations`` > 1 the correction is repeated on the model
(command <- command - (y_sim(command) - reference)), which converges to the model inverse below
the resonance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..validate import check_array, check_int, check_scalar, freeze_arrays
from .algebraic import second_order_response

__all__ = ["Precompensation", "precompensate", "jerk_limited_profile", "deflection_amplitude"]


@dataclass(frozen=True)
class Precompensation:
    """A pre-compensated motor command and what the identified model predicts for it.

    Attributes
    ----------
    t : (T,) s
    reference : (T,) rad, the wanted link (and original motor) trajectory
    command : (T,) rad, the motor command (their eq. 17)
    predicted_error_before : (T,) rad, link - reference the model predicts for the plain reference
    predicted_error_after : (T,) rad, the same for the command
    omega0, zeta : the model used
    iterations : int (0 for the model inverse)
    damping : "link" or "spring" (:mod:`.algebraic`)
    method : "eq17" or "inverse" (:func:`precompensate`)
    """

    t: np.ndarray
    reference: np.ndarray
    command: np.ndarray
    predicted_error_before: np.ndarray
    predicted_error_after: np.ndarray
    omega0: float
    zeta: float
    iterations: int
    damping: str = "link"
    method: str = "eq17"

    def __post_init__(self) -> None:
        freeze_arrays(self)

    def to_dict(self) -> dict:
        b = deflection_amplitude(self.predicted_error_before)
        a = deflection_amplitude(self.predicted_error_after)
        return {"omega0": self.omega0, "zeta": self.zeta, "iterations": self.iterations, "damping": self.damping,
                "method": self.method,
                "n_samples": int(self.t.size), "predicted_peak_before": b["peak"],
                "predicted_peak_after": a["peak"], "predicted_rms_before": b["rms"], "predicted_rms_after": a["rms"],
                "predicted_peak_ratio": b["peak"] / a["peak"] if a["peak"] > 0 else float("inf"),
                "max_correction": float(np.max(np.abs(self.command - self.reference)))}


def deflection_amplitude(e) -> dict:
    """Peak |e| and RMS of a tracking error or deflection e (T,) rad."""
    e = np.asarray(e, dtype=np.float64)
    return {"peak": float(np.max(np.abs(e))), "rms": float(np.sqrt(np.mean(e ** 2)))}


def precompensate(t, reference, omega0: float, zeta: float, *, iterations: int = 1,
                  damping: str = "link", method: str = "eq17") -> Precompensation:
    """The pre-compensated command for `reference` (Oueslati et al. 2012, eq. 17).

    Their law leaves (1 - H) times the deflection, H the model's response: it shrinks what lies
    well below the resonance and amplifies what lies near it (a reference whose acceleration
    jumps). ``method="inverse"`` inverts the model instead: the command whose simulated link is
    the reference, u = r + (r'' + 2 zeta omega0 r') / omega0^2 (link damping), or the solution of
    2 zeta omega0 u' + omega0^2 u = r'' + 2 zeta omega0 r' + omega0^2 r (spring damping), with r'
    and r'' from the cubic spline through the reference.

    Parameters
    ----------
    t : (T,) s, increasing; reference : (T,) rad (link side), starting at rest
    omega0 : rad/s, zeta : 1, the identified model (e.g. :func:`.algebraic.algebraic_estimate`)
    iterations : 1 for their law; more repeat the correction on the model
    damping : "link" (their eq. 9) or "spring": the form the estimate was made with
        (``SecondOrderEstimate.damping``)
    method : "eq17" (their law, repeated `iterations` times) or "inverse"
    """
    dims: dict = {}
    t = check_array(t, "t", ("T",), dims=dims)
    r = check_array(reference, "reference", ("T",), dims=dims)
    if t.size < 4 or not (np.diff(t) > 0).all():
        raise InputError(None, "t", "at least 4 strictly increasing times", f"{t.size} samples")
    omega0 = check_scalar(omega0, "omega0", positive=True)
    zeta = check_scalar(zeta, "zeta", nonneg=True)
    iterations = check_int(iterations, "iterations", lo=1, hi=50)
    if damping not in ("link", "spring"):
        raise InputError(None, "damping", '"link" or "spring"', repr(damping))
    if method not in ("eq17", "inverse"):
        raise InputError(None, "method", '"eq17" or "inverse"', repr(method))

    def link(u):
        return second_order_response(t, omega0, zeta, u, y0=float(u[0]), damping=damping)

    before = link(r) - r
    if method == "inverse":
        from scipy import signal
        from scipy.interpolate import CubicSpline

        sp = CubicSpline(t, r)
        r1, r2 = sp(t, 1), sp(t, 2)
        l1, l2 = 2 * zeta * omega0, omega0 ** 2
        if damping == "link" or l1 == 0:
            cmd = r + (r2 + l1 * r1) / l2
        else:
            rhs = (r2 + l1 * r1 + l2 * r) / l1
            first = signal.StateSpace([[-l2 / l1]], [[1.0]], [[1.0]], [[0.0]])
            _, cmd, _ = signal.lsim(first, rhs, t - t[0], X0=[r[0]])
            cmd = np.asarray(cmd, dtype=np.float64)
        err = link(cmd) - r
        iterations = 0
    else:
        cmd = r.copy()
        err = before
        for _ in range(iterations):
            cmd = cmd - err
            err = link(cmd) - r
    return Precompensation(t=t, reference=r, command=cmd, predicted_error_before=before, predicted_error_after=err,
                           omega0=omega0, zeta=zeta, iterations=iterations, damping=damping, method=method)


def jerk_limited_profile(t, start: float, stop: float, v_max: float, a_max: float, j_max: float,
                         t0: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point-to-point move with bounded velocity, acceleration and jerk (the seven-phase profile of
    Oueslati et al. (2012), Fig. 13), sampled at t (T,) s: position, velocity, acceleration
    (rad, rad/s, rad/s^2). Starts at t0 at rest; the bounds are reduced where the move is too
    short to reach them."""
    t = np.asarray(t, dtype=np.float64)
    for n, v in (("v_max", v_max), ("a_max", a_max), ("j_max", j_max)):
        check_scalar(v, n, positive=True)
    L = abs(stop - start)
    sgn = 1.0 if stop >= start else -1.0
    a = min(a_max, np.sqrt(v_max * j_max))                 # the acceleration reached
    v = v_max
    # shrink v (then a) until the accelerate + decelerate distance fits the move
    def dist(v, a):
        tj = a / j_max
        ta = v / a - tj                                     # constant-acceleration time
        return v * (ta + 2 * tj)                            # accelerate and decelerate together
    if dist(v, a) > L:
        lo, hi = 0.0, v
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            am = min(a, np.sqrt(mid * j_max))
            lo, hi = (mid, hi) if dist(mid, am) <= L else (lo, mid)
        v = lo
        a = min(a, np.sqrt(v * j_max))
    tj = a / j_max
    ta = max(v / a - tj, 0.0)
    tv = max((L - dist(v, a)) / v, 0.0) if v > 0 else 0.0
    phases = [(tj, j_max), (ta, 0.0), (tj, -j_max), (tv, 0.0), (tj, -j_max), (ta, 0.0), (tj, j_max)]
    edges = np.concatenate([[0.0], np.cumsum([d for d, _ in phases])]) + t0
    # exact piecewise-cubic integration of the piecewise-constant jerk
    p = np.zeros(8)
    vel = np.zeros(8)
    acc = np.zeros(8)
    for k, (d, j) in enumerate(phases):
        acc[k + 1] = acc[k] + j * d
        vel[k + 1] = vel[k] + acc[k] * d + j * d ** 2 / 2
        p[k + 1] = p[k] + vel[k] * d + acc[k] * d ** 2 / 2 + j * d ** 3 / 6
    k = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, 7)
    jj = np.array([j for _, j in phases] + [0.0])[k]
    tau = np.clip(t - edges[k], 0.0, None)
    before = t < t0
    pos = p[k] + vel[k] * tau + acc[k] * tau ** 2 / 2 + jj * tau ** 3 / 6
    vv = vel[k] + acc[k] * tau + jj * tau ** 2 / 2
    aa = acc[k] + jj * tau
    at_end = k == 7
    pos = np.where(at_end, p[7], pos)
    vv = np.where(at_end | before, 0.0, vv)
    aa = np.where(at_end | before, 0.0, aa)
    pos = np.where(before, 0.0, pos)
    return start + sgn * pos, sgn * vv, sgn * aa
