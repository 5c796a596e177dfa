"""Forward simulation of a flexible-joint model and the controller log it would produce.

``simulate(model, t, drive)`` integrates the model of :mod:`.flexjoint` (a :class:`SingleJoint`
or an :class:`NLinkModel`) with ``scipy.integrate.solve_ivp`` (stiff-capable LSODA by default,
step limited by `max_step`), the spring/hysteresis states riding in the state vector.
The drive says what moves the motor:

- :class:`PrescribedMotor`: q_m(t) is given; only the links and the spring states are
  integrated and u follows from the motor equation (Lightcap and Banks (2007), eq. 4, second line).
- :class:`PID`: a motor-position loop tracking q_ref(t) (PD when ki = 0).
- :class:`TorqueInput`: u(t) is given (open loop; u = 0 leaves the joint free).

Callables of time (trajectories, references, torques) are called with a float t, returning
(n,) arrays, and once with the (T,) output times, returning (T, n) (a (T,) result is accepted
for one joint). :func:`controller_log` samples a result like a robot controller: its own rate,
resolver quantisation of q_m, noise on the torque, randomness only from the Generator passed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from ..errors import InputError
from ..types import ControllerLog
from .flexjoint import FlexibleJointModel

__all__ = ["PrescribedMotor", "PID", "TorqueInput", "SimulationResult", "simulate", "resample",
           "controller_log"]


def _eval(fn: Callable, t, n: int) -> np.ndarray:
    """fn(t) as (n,) for a float t, (T, n) for t (T,)."""
    out = np.asarray(fn(t), dtype=np.float64)
    if np.ndim(t) == 0:
        if out.shape == (n,):
            return out
        return np.full(n, float(out)) if out.ndim == 0 else np.broadcast_to(out, (n,)).copy()
    T = np.shape(t)[0]
    if n == 1 and out.shape == (T,):
        return out[:, None]
    return np.broadcast_to(out, (T, n)).astype(np.float64)


@dataclass(frozen=True, eq=False)
class PrescribedMotor:
    """The motor follows q_m(t) exactly (a stiff position loop); u is computed, not simulated.

    trajectory : callable t -> (q_m, q_m', q_m'') in rad, rad/s, rad/s^2 (link side).
    """

    trajectory: Callable

    @classmethod
    def from_samples(cls, t, q_m) -> "PrescribedMotor":
        """Cubic-spline trajectory through samples t (T,) s, q_m (T,) or (T, n) rad."""
        t = np.asarray(t, dtype=np.float64)
        q_m = np.asarray(q_m, dtype=np.float64)
        if t.ndim != 1 or q_m.shape[:1] != t.shape or t.size < 4:
            raise InputError(None, "t, q_m", "t (T,) and q_m (T,) or (T, n), T >= 4", f"{t.shape}, {q_m.shape}")
        sp = CubicSpline(t, q_m, axis=0)
        d1, d2 = sp.derivative(1), sp.derivative(2)
        return cls(lambda tt: (sp(tt), d1(tt), d2(tt)))

    def evaluate(self, t, n: int):
        q, qd, qdd = self.trajectory(t)
        return tuple(_eval(lambda _t, a=a: a, t, n) for a in (q, qd, qdd))


@dataclass(frozen=True, eq=False)
class PID:
    """Motor-position loop: u = u_ff + kp (q_ref - q_m) + kd (q_ref' - q_m') + ki integral(q_ref - q_m).

    Parameters
    ----------
    reference : callable t -> (q_ref, q_ref') rad, rad/s (link side, like q_m)
    kp, kd, ki : float or (n,)
        Gains in N m/rad, N m s/rad, N m/(rad s). ki = 0 gives PD.
    feedforward : callable t -> (n,) N m, or None
    u_max : float or None
        Symmetric torque saturation, N m.
    """

    reference: Callable
    kp: float | np.ndarray
    kd: float | np.ndarray
    ki: float | np.ndarray = 0.0
    feedforward: Callable | None = None
    u_max: float | None = None

    def torque(self, t, q_m, qd_m, integral, n: int) -> np.ndarray:
        r, rd = (_eval(lambda _t, a=a: a, t, n) for a in self.reference(t))
        u = self.kp * (r - q_m) + self.kd * (rd - qd_m) + self.ki * integral
        if self.feedforward is not None:
            u = u + _eval(self.feedforward, t, n)
        return u if self.u_max is None else np.clip(u, -self.u_max, self.u_max)

    def error(self, t, q_m, n: int) -> np.ndarray:
        return _eval(lambda _t: self.reference(_t)[0], t, n) - q_m


@dataclass(frozen=True, eq=False)
class TorqueInput:
    """Open loop: the commanded motor torque u(t), callable t -> (n,) N m."""

    torque_fn: Callable


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """A simulated run, all arrays time first, joint axis last (docs/conventions.md).

    Attributes
    ----------
    t : (T,) s
    q, qd, qdd : (T, n) link angle rad, rad/s, rad/s^2 (the truth mocap would measure)
    q_m, qd_m, qdd_m : (T, n) motor angle / gear ratio, rad, rad/s, rad/s^2
    u : (T, n) commanded motor torque x gear ratio, N m (what the controller logs; the motor
        makes torque_gain x u)
    tau_s : (T, n) transmitted spring torque, N m
    delta : (T, n) deflection q_m + e(q_m) - q, rad
    z : (T, n_z) spring/hysteresis states (joint j: columns ``spring_slices[j]``)
    spring_slices : tuple of n slices
    joint_names : tuple of n str
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    q_m: np.ndarray
    qd_m: np.ndarray
    qdd_m: np.ndarray
    u: np.ndarray
    tau_s: np.ndarray
    delta: np.ndarray
    z: np.ndarray
    spring_slices: tuple[slice, ...]
    joint_names: tuple[str, ...]

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                v = np.array(v, dtype=np.float64)
                v.setflags(write=False)
                object.__setattr__(self, f.name, v)

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)


def _initial(x, default, n, name):
    if x is None:
        return np.asarray(default, dtype=np.float64)
    a = np.broadcast_to(np.asarray(x, dtype=np.float64), (n,)).copy() if np.ndim(x) == 0 else np.asarray(x, float)
    if a.shape != np.shape(default):
        raise InputError(None, name, f"shape {np.shape(default)}", f"shape {a.shape}")
    return a


def simulate(model: FlexibleJointModel, t, drive, *, q0=None, qd0=None, q_m0=None, qd_m0=None, z0=None,
             tau_ext: Callable | None = None, method: str = "LSODA", rtol: float = 1e-8, atol: float = 1e-10,
             max_step: float | None = None, max_evals: int | None = None) -> SimulationResult:
    """Simulate `model` driven by `drive`, returning the states and torques at times `t`.

    Parameters
    ----------
    model : SingleJoint or NLinkModel
        Smooth its friction (``with_friction_smoothing``) for stiff integration.
    t : (T,) s
        Output times, increasing; the run starts at t[0].
    drive : PrescribedMotor, PID or TorqueInput
    q0, qd0, q_m0, qd_m0 : (n,) or None
        Initial states. Defaults: q_m0 from the trajectory (PrescribedMotor), the reference (PID)
        or 0 (TorqueInput); qd_m0 likewise or 0; q0 the static link angle for q_m0
        (``model.static_link_angle``; pass q0 when the springs have no stiffness at state z0,
        e.g. Maxwell-slip without k0); qd0 = qd_m0.
    z0 : (n_z,) or None
        Spring states; default virgin (``model.initial_spring_state()``).
    tau_ext : callable t -> (n,) N m, or None
        External torque on the links (e.g. coupling from joints outside the model).
    method, rtol, atol : solve_ivp settings ('LSODA', 'Radau', 'BDF' for stiff models).
    max_step : float or None
        Largest step, s; default the median output interval.
    max_evals : int or None
        Right-hand-side evaluations allowed; beyond them (or at a non-finite derivative) a
        RuntimeError instead of an integration that does not end (a stiff or diverging model).
    """
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.size < 2 or not (np.diff(t) > 0).all():
        raise InputError(None, "t", "strictly increasing times (T,), T >= 2", f"shape {t.shape}")
    if not isinstance(model, FlexibleJointModel):
        raise InputError(None, "model", "a SingleJoint or NLinkModel", type(model).__name__)
    if not isinstance(drive, (PrescribedMotor, PID, TorqueInput)):
        raise InputError(None, "drive", "PrescribedMotor, PID or TorqueInput", type(drive).__name__)
    if max_step is not None and not max_step > 0:
        raise InputError(None, "max_step", "a positive step in s", max_step)
    n, nz = model.n_joints, model.n_spring_states
    z0 = _initial(z0, model.initial_spring_state(), nz, "z0")
    ext = (lambda tt: _eval(tau_ext, tt, n)) if tau_ext is not None else (lambda tt: None)
    max_step = float(np.median(np.diff(t))) if max_step is None else float(max_step)
    zeros = np.zeros(n)

    if isinstance(drive, PrescribedMotor):
        qm0, qdm0, _ = drive.evaluate(t[0], n)
    elif isinstance(drive, PID):
        qm0, qdm0 = (_eval(lambda _t, a=a: a, t[0], n) for a in drive.reference(t[0]))
    else:
        qm0, qdm0 = zeros, zeros
    qm0, qdm0 = _initial(q_m0, qm0, n, "q_m0"), _initial(qd_m0, qdm0, n, "qd_m0")
    if q0 is None:
        try:
            q0 = model.static_link_angle(qm0, z0)
        except RuntimeError:
            raise InputError(None, "q0", "an initial link angle", None,
                             hint="the springs at state z0 find no static equilibrium; pass q0") from None
    q0 = _initial(q0, zeros, n, "q0")
    qd0 = _initial(qd0, qdm0, n, "qd0")

    m = 4 * n + nz  # model states; a PID adds its n integrals after them
    if isinstance(drive, PrescribedMotor):
        def rhs(ti, x):
            qm, qdm, _ = drive.evaluate(ti, n)
            return model.link_state_derivative(x, qm, qdm, ext(ti))
        x0 = np.concatenate([q0, qd0, z0])
    elif isinstance(drive, PID):
        def rhs(ti, x):
            qm, qdm = x[2 * n:3 * n], x[3 * n:4 * n]
            u = drive.torque(ti, qm, qdm, x[m:], n)
            return np.concatenate([model.state_derivative(x[:m], u, ext(ti)), drive.error(ti, qm, n)])
        x0 = np.concatenate([q0, qd0, qm0, qdm0, z0, zeros])
    else:
        def rhs(ti, x):
            return model.state_derivative(x, _eval(drive.torque_fn, ti, n), ext(ti))
        x0 = np.concatenate([q0, qd0, qm0, qdm0, z0])

    if max_evals is not None:
        inner, count = rhs, [0]

        def rhs(ti, x):                      # noqa: F811 - the same derivative, with a budget
            count[0] += 1
            if count[0] > max_evals:
                raise RuntimeError(f"simulation stopped at t = {ti:.6g} s after {max_evals} derivative evaluations "
                                   "(a model too stiff or diverging under this drive)")
            dx = inner(ti, x)
            if not np.all(np.isfinite(dx)):
                raise RuntimeError(f"simulation left the finite numbers at t = {ti:.6g} s")
            return dx

    sol = solve_ivp(rhs, (t[0], t[-1]), x0, method=method, t_eval=t, rtol=rtol, atol=atol, max_step=max_step)
    if not sol.success:
        raise RuntimeError(f"simulation failed at t = {sol.t[-1] if sol.t.size else t[0]:.6g} s: {sol.message}")
    X = sol.y.T
    q, qd = X[:, :n], X[:, n:2 * n]
    te = ext(t)
    if isinstance(drive, PrescribedMotor):
        qm, qdm, qddm = drive.evaluate(t, n)
        z = X[:, 2 * n:2 * n + nz]
        tau_s, delta, _ = model.spring_torque(q, qd, qm, qdm, z)
        u = model.motor_torque(qm, qdm, qddm, tau_s)
    else:
        qm, qdm, z, c = X[:, 2 * n:3 * n], X[:, 3 * n:4 * n], X[:, 4 * n:4 * n + nz], X[:, 4 * n + nz:]
        tau_s, delta, _ = model.spring_torque(q, qd, qm, qdm, z)
        u = drive.torque(t, qm, qdm, c, n) if isinstance(drive, PID) else _eval(drive.torque_fn, t, n)
        qddm = model.motor_acceleration(qm, qdm, tau_s, u)
    qdd = model.link_acceleration(q, qd, tau_s, te)
    return SimulationResult(t=t, q=q, qd=qd, qdd=qdd, q_m=qm, qd_m=qdm, qdd_m=qddm, u=u, tau_s=tau_s,
                            delta=delta, z=z, spring_slices=model.spring_slices, joint_names=model.joint_names)


def resample(result: SimulationResult, t) -> SimulationResult:
    """The result linearly interpolated at times t (T2,) s within [result.t[0], result.t[-1]]."""
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.size == 0 or t.min() < result.t[0] or t.max() > result.t[-1]:
        raise InputError(None, "t", f"times within [{result.t[0]}, {result.t[-1]}] s", f"[{t.min()}, {t.max()}]")
    idx = np.clip(np.searchsorted(result.t, t, side="right") - 1, 0, result.t.size - 2)
    w = ((t - result.t[idx]) / (result.t[idx + 1] - result.t[idx]))[:, None]
    out = {}
    for f in fields(result):
        v = getattr(result, f.name)
        if f.name == "t":
            out["t"] = t
        elif isinstance(v, np.ndarray):
            out[f.name] = (1 - w) * v[idx] + w * v[idx + 1]
        else:
            out[f.name] = v
    return SimulationResult(**out)


def controller_log(result: SimulationResult, rate_hz: float, *, rng: np.random.Generator,
                   quantum_rad: float | None = None, resolver_bits: int | None = None,
                   gear_ratio: float | None = None, current_noise_sd: float = 0.0,
                   include_truth: bool = False) -> ControllerLog:
    """What the robot controller would log: q_m quantised, torque with noise, at its own rate.

    Parameters
    ----------
    result : SimulationResult
        Simulate on a grid at least as fine as the log; values are interpolated linearly.
    rate_hz : float
        Log rate; samples at t[0] + k / rate_hz up to t[-1].
    rng : numpy.random.Generator
        The only source of randomness.
    quantum_rad : float or None
        Resolution of the logged q_m, rad on the link side.
    resolver_bits, gear_ratio : int, float or None
        Alternative to `quantum_rad`: quantum = 2 pi / (2**bits * gear_ratio).
    current_noise_sd : float
        SD of white noise added to the logged torque, N m on the link side (current noise times
        motor constant times gear ratio).
    include_truth : bool
        Add ``extra`` columns ``q_true_<joint>`` and ``q_m_true_<joint>`` (rad) with the true link
        and motor angles at the log times. Off by default: a log written to a recording bundle
        must not carry the answer. ``resample(result, log.t)`` gives every true signal.
    """
    if not isinstance(rng, np.random.Generator):
        raise InputError(None, "rng", "a numpy.random.Generator", type(rng).__name__)
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(None, "rate_hz", "a positive rate in Hz", rate_hz)
    if quantum_rad is not None and resolver_bits is not None:
        raise InputError(None, "quantum_rad, resolver_bits", "one of the two, not both")
    if resolver_bits is not None:
        if gear_ratio is None or not gear_ratio > 0 or int(resolver_bits) != resolver_bits or resolver_bits < 1:
            raise InputError(None, "resolver_bits, gear_ratio", "a positive bit count and a positive gear ratio",
                             (resolver_bits, gear_ratio))
        quantum_rad = 2 * np.pi / (2.0 ** int(resolver_bits) * float(gear_ratio))
    if quantum_rad is not None and not (np.isfinite(quantum_rad) and quantum_rad > 0):
        raise InputError(None, "quantum_rad", "a positive quantum in rad", quantum_rad)
    if not (np.isfinite(current_noise_sd) and current_noise_sd >= 0):
        raise InputError(None, "current_noise_sd", "a non-negative SD in N m", current_noise_sd)
    t0, t1 = result.t[0], result.t[-1]
    t_log = np.minimum(t0 + np.arange(int(np.floor((t1 - t0) * rate_hz + 1e-9)) + 1) / rate_hz, t1)
    true = resample(result, t_log)
    q_m = true.q_m if quantum_rad is None else quantum_rad * np.round(true.q_m / quantum_rad)
    tau = true.u + (rng.normal(0.0, current_noise_sd, true.u.shape) if current_noise_sd > 0 else 0.0)
    extra = {}
    if include_truth:
        for j, name in enumerate(result.joint_names):
            extra[f"q_true_{name}"] = true.q[:, j]
            extra[f"q_m_true_{name}"] = true.q_m[:, j]
    return ControllerLog(t=t_log, q_m=q_m, tau=tau, joint_names=result.joint_names, extra=extra)
