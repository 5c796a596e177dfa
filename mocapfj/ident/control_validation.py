"""Validation of an identified joint model by model-based control (Bompos, Artemiadis,
Oikonomopoulos and Kyriakopoulos 2007, §III.C).

Bompos et al. (2007) prove their identified PA-10 model by tracking a trajectory with an inverse
dynamics controller built from it (their eq. 21) and showing that the error and the feedback share
of the torque stay small. Here the same test runs in simulation on one flexible joint: a
computed-torque controller built from a model (the identified flexible model, a nominal one, or
the rigid model that ignores the spring) drives the true plant, and the link tracking errors of
the controllers are compared.

The controller is what a lab runs on a joint whose motor side is measured: feedforward from the
model's inverse dynamics along the reference q*(t), plus PD feedback on the motor angle,

    u = u_ff(t) + kp (q_m*(t) - q_m) + kd (q_m*'(t) - q_m')

held constant over each control period (zero-order hold). Feedforward, by model kind
(Lightcap and Banks (2007), eq. 4, docs/conventions.md; G(q) = -mglx sin q + mgly cos q):

- flexible: tau_s* = I q*'' + G(q*) + F(q*'), the spring deflected by it,
  q_m* = q* + tau_s*/k (and its two time derivatives), and the motor equation
  u_ff = (J q_m*'' + b q_m*' + tau_s*) / g (g the drive's torque gain);
- rigid: the spring taken as infinitely stiff, q_m* = q* and
  u_ff = (I + J) q*'' + b q*' + G(q*) + F(q*').

k is the model spring's linear equivalent (``JointModel.stiffness``). The feedforward uses the
model's friction law smoothed as tanh(q'/friction_smoothing) (an exact Coulomb step would ask an
infinite motor acceleration of a flexible joint); its time derivatives are taken by a five-point
stencil on the analytic reference, the inertia and gravity terms analytically. The formulas are
written here, apart from the plant's code: the plant is :class:`mocapfj.dynamics.SingleJoint`
(its ``spring_torque``, ``link_acceleration`` and ``motor_acceleration``), integrated by fixed-step
RK4 with ``substeps`` steps per control period, all controllers at once as a batch.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace

import numpy as np

from ..dynamics.joint_model import JointModel
from ..dynamics.springs import LinearSpring
from ..errors import InputError
from ..validate import check_int, check_scalar, freeze

__all__ = ["WindowedSines", "ComputedTorque", "TrackingRun", "ControlValidation", "control_check",
           "lab_gains", "perturbed"]


# ---- reference trajectory ------------------------------------------------------------------------
def _smoothstep(t, ramp: float) -> np.ndarray:
    """s(t) = 35 x^4 - 84 x^5 + 70 x^6 - 20 x^7, x = t / ramp clipped to [0, 1], and its first four
    time derivatives, (5, T): 0 -> 1 with three zero derivatives at both ends."""
    x = np.clip(np.asarray(t, dtype=np.float64) / ramp, 0.0, 1.0)
    inside = (x > 0) & (x < 1)
    p = np.polynomial.Polynomial([0, 0, 0, 0, 35, -84, 70, -20])
    out = np.empty((5,) + x.shape)
    for k in range(5):
        out[k] = p.deriv(k)(x) / ramp ** k if k else p(x)
        if k:
            out[k] = np.where(inside, out[k], 0.0)
    return out


@dataclass(frozen=True)
class WindowedSines:
    """q*(t) = q0 + s(t) sum_i a_i sin(2 pi f_i t), s a septic ramp from 0 to 1 over ramp_s.

    Starts at rest at q0 with its first four derivatives zero, so a plant at rest follows it from
    t = 0. q0, amplitudes rad; frequencies Hz; ramp_s s.
    """

    q0: float
    amplitudes: tuple[float, ...]
    frequencies_hz: tuple[float, ...]
    ramp_s: float = 1.0

    def __post_init__(self) -> None:
        check_scalar(self.q0, "q0")
        check_scalar(self.ramp_s, "ramp_s", positive=True)
        a = tuple(float(check_scalar(v, "amplitudes")) for v in self.amplitudes)
        f = tuple(float(check_scalar(v, "frequencies_hz", positive=True)) for v in self.frequencies_hz)
        if len(a) != len(f) or not a:
            raise InputError(None, "amplitudes, frequencies_hz", "two non-empty sequences of one length",
                             f"{len(a)} and {len(f)}")
        object.__setattr__(self, "amplitudes", a)
        object.__setattr__(self, "frequencies_hz", f)

    def derivatives(self, t) -> np.ndarray:
        """(5, T): q*, q*', q*'', q*''', q*'''' at times t (T,) s (rad, rad/s, ... rad/s^4)."""
        t = np.asarray(t, dtype=np.float64)
        f = np.zeros((5,) + t.shape)
        for a, fr in zip(self.amplitudes, self.frequencies_hz):
            w = 2 * math.pi * fr
            s, c = np.sin(w * t), np.cos(w * t)
            f += a * np.stack([s, w * c, -w ** 2 * s, -w ** 3 * c, w ** 4 * s])
        s = _smoothstep(t, self.ramp_s)
        out = np.zeros_like(f)
        for n in range(5):                                  # Leibniz rule for (s f)^(n)
            for k in range(n + 1):
                out[n] += math.comb(n, k) * s[k] * f[n - k]
        out[0] += self.q0
        return out

    def to_dict(self) -> dict:
        return {"kind": "windowed_sines", "q0": self.q0, "amplitudes": list(self.amplitudes),
                "frequencies_hz": list(self.frequencies_hz), "ramp_s": self.ramp_s}


# ---- controllers ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class ComputedTorque:
    """A computed-torque controller built from `model`.

    name : label in the result; model : the JointModel the feedforward uses; flexible : True for
    the flexible feedforward (spring deflection compensated), False for the rigid one;
    friction_smoothing : rad/s, the tanh smoothing of the model's friction in the feedforward.
    """

    name: str
    model: JointModel
    flexible: bool = True
    friction_smoothing: float = 0.05

    def __post_init__(self) -> None:
        if not isinstance(self.model, JointModel):
            raise InputError(None, "model", "a mocapfj.dynamics.JointModel", type(self.model).__name__)
        check_scalar(self.friction_smoothing, "friction_smoothing", positive=True)

    def reference(self, traj, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Motor reference q_m*, q_m*' and feedforward u_ff, each (T,), at times t (T,) s."""
        m = self.model
        fric = m.friction.with_smoothing(self.friction_smoothing)
        q, qd, qdd, q3, q4 = traj.derivatives(t)
        sn, cs = np.sin(q), np.cos(q)
        grav = -m.mglx * sn + m.mgly * cs
        dgrav = -m.mglx * cs - m.mgly * sn                         # dG/dq
        ddgrav = m.mglx * sn - m.mgly * cs                          # d2G/dq2
        if not self.flexible:
            return q, qd, (m.I + m.J) * qdd + m.b * qd + grav + fric.torque(qd, q)
        # friction along the reference and its two time derivatives (five-point stencils)
        h = 1e-3 * self.friction_smoothing / max(float(np.max(np.abs(qdd))), 1e-9)
        h = min(h, 1e-4)
        Fs = [fric.torque(d[1], d[0]) for d in (traj.derivatives(t + j * h) for j in (-2, -1, 0, 1, 2))]
        F1 = (Fs[0] - 8 * Fs[1] + 8 * Fs[3] - Fs[4]) / (12 * h)
        F2 = (-Fs[0] + 16 * Fs[1] - 30 * Fs[2] + 16 * Fs[3] - Fs[4]) / (12 * h * h)
        tau = m.I * qdd + grav + Fs[2]
        tau1 = m.I * q3 + dgrav * qd + F1
        tau2 = m.I * q4 + ddgrav * qd ** 2 + dgrav * qdd + F2
        k = m.stiffness()
        qm, qmd, qmdd = q + tau / k, qd + tau1 / k, qdd + tau2 / k
        return qm, qmd, (m.J * qmdd + m.b * qmd + tau) / m.torque_gain


def lab_gains(model: JointModel, bandwidth_hz: float, zeta: float = 0.8) -> tuple[float, float]:
    """PD gains (kp N m/rad, kd N m s/rad) of a loop of `bandwidth_hz` and damping `zeta` on the
    joint's total inertia I + J, as labs tune a motor-position loop."""
    w = 2 * math.pi * check_scalar(bandwidth_hz, "bandwidth_hz", positive=True)
    M = model.I + model.J
    return M * w * w, 2 * check_scalar(zeta, "zeta", positive=True) * M * w


def perturbed(model: JointModel, rel_sd, rng: np.random.Generator) -> JointModel:
    """`model` with I, J, mglx, mgly, b, the friction coefficients and the linear spring's k each
    multiplied by (1 + s N(0, 1)) (independent draws from `rng`): a model with identification
    errors. `rel_sd` is one relative SD s for all, or {name: s} (names I, J, mglx, mgly, b, k and
    the friction's params, e.g. c, v; a missing name is left exact), e.g. an identification's
    reported SD / value."""
    if not isinstance(model.spring, LinearSpring):
        raise InputError(None, "spring", "a LinearSpring", type(model.spring).__name__)
    if isinstance(rel_sd, dict):
        sd = {str(n): check_scalar(v, f"rel_sd[{n}]", nonneg=True) for n, v in rel_sd.items()}
    else:
        one = check_scalar(rel_sd, "rel_sd", nonneg=True)
        sd = {n: one for n in ("I", "J", "mglx", "mgly", "b", "k", *model.friction.params)}

    def f(n):
        return 1.0 + sd.get(n, 0.0) * float(rng.standard_normal())
    changes = {n: getattr(model, n) * f(n) for n in ("I", "J", "mglx", "mgly", "b")}
    fr = replace(model.friction, **{n: v * f(n) for n, v in model.friction.params.items()})
    return model.with_(friction=fr, spring=LinearSpring(model.spring.k * f("k")), **changes)


# ---- result --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TrackingRun:
    """One controller on the plant. Errors are q* - q (link) and q_m* - q_m (motor), rad;
    feedback_share = RMS of the PD torque / RMS of the total torque (Bompos et al. (2007) judge
    the model by it being small)."""

    name: str
    flexible: bool
    rms_rad: float
    max_rad: float
    motor_rms_rad: float
    feedback_share: float
    u_rms: float

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class ControlValidation:
    """Controllers tracking one reference on one plant.

    t : (T,) s, the control instants; reference : (T,) rad, q*; q : (B, T) rad, the link angle under
    each controller (order of ``runs``); u : (B, T) N m, the torque each commanded from t[i] to
    t[i + 1]; runs : per controller; kp, kd, rate_hz, substeps : the loop.
    """

    t: np.ndarray
    reference: np.ndarray
    q: np.ndarray
    u: np.ndarray
    runs: tuple[TrackingRun, ...]
    kp: float
    kd: float
    rate_hz: float
    substeps: int
    trajectory: dict

    def __post_init__(self) -> None:
        for n in ("t", "reference", "q", "u"):
            object.__setattr__(self, n, freeze(np.asarray(getattr(self, n), dtype=np.float64)))

    def run(self, name: str) -> TrackingRun:
        for r in self.runs:
            if r.name == name:
                return r
        raise InputError(None, "name", f"one of {[r.name for r in self.runs]}", repr(name))

    def ratio(self, worse: str, better: str, stat: str = "rms") -> float:
        """Error of controller `worse` over that of `better` (stat "rms" or "max")."""
        a, b = self.run(worse), self.run(better)
        key = "rms_rad" if stat == "rms" else "max_rad"
        return getattr(a, key) / getattr(b, key)

    def to_dict(self) -> dict:
        return {"kp": self.kp, "kd": self.kd, "rate_hz": self.rate_hz, "substeps": self.substeps,
                "duration_s": float(self.t[-1] - self.t[0]), "trajectory": self.trajectory,
                "runs": [r.to_dict() for r in self.runs]}


# ---- the closed loop -----------------------------------------------------------------------------
def control_check(plant: JointModel, controllers: Sequence[ComputedTorque], trajectory: WindowedSines,
                  duration_s: float, *, kp: float, kd: float, rate_hz: float = 400.0, substeps: int = 4,
                  plant_smoothing: float = 1e-3) -> ControlValidation:
    """Simulate each controller tracking `trajectory` on `plant` and measure the link error.

    Parameters
    ----------
    plant : JointModel, the true joint (its ``single_joint(plant_smoothing)`` is integrated; a
        sign friction law becomes tanh(q'/plant_smoothing))
    controllers : ComputedTorque, distinct names
    trajectory : the link reference q*(t), starting at rest
    duration_s : s; kp, kd : N m/rad, N m s/rad, the motor-side PD gains (``lab_gains``)
    rate_hz : control rate (zero-order hold; default the 2.5 ms cycle of Bompos et al. (2007))
    substeps : RK4 steps per control period
    """
    if not isinstance(plant, JointModel):
        raise InputError(None, "plant", "a mocapfj.dynamics.JointModel", type(plant).__name__)
    controllers = tuple(controllers)
    if not controllers or not all(isinstance(c, ComputedTorque) for c in controllers):
        raise InputError(None, "controllers", "one or more ComputedTorque", repr(controllers)[:80])
    if len({c.name for c in controllers}) != len(controllers):
        raise InputError(None, "controllers", "distinct names", [c.name for c in controllers])
    if not hasattr(trajectory, "derivatives"):
        raise InputError(None, "trajectory", "a WindowedSines (a .derivatives(t) method)", type(trajectory).__name__)
    duration_s = check_scalar(duration_s, "duration_s", positive=True)
    kp, kd = check_scalar(kp, "kp", positive=True), check_scalar(kd, "kd", nonneg=True)
    rate_hz = check_scalar(rate_hz, "rate_hz", positive=True)
    substeps = check_int(substeps, "substeps", lo=1, hi=1000)
    n_ticks = int(round(duration_s * rate_hz))
    if n_ticks < 10:
        raise InputError(None, "duration_s", f"at least 10 control periods (1/{rate_hz:g} s)", duration_s)

    sj = plant.single_joint(plant_smoothing)
    t = np.arange(n_ticks + 1) / rate_hz
    refs = [c.reference(trajectory, t) for c in controllers]
    qm_ref = np.stack([r[0] for r in refs])                # (B, T)
    qmd_ref = np.stack([r[1] for r in refs])
    u_ff = np.stack([r[2] for r in refs])
    q_ref = trajectory.derivatives(t)[0]
    B = len(controllers)

    # the plant at rest holding q*(0)
    q0 = float(q_ref[0])
    qm0 = float(sj.static_motor_angle(np.array([q0]))[0])
    z = np.broadcast_to(sj.initial_spring_state(), (B, sj.n_spring_states)).copy()
    x = np.zeros((4, B, 1))
    x[0], x[2] = q0, qm0

    def deriv(x, z, u):
        q, qd, qm, qdm = x
        tau_s, delta, delta_dot = sj.spring_torque(q, qd, qm, qdm, z)
        dz = sj.spring_state_derivative(z, delta, delta_dot) if z.shape[-1] else z
        return np.stack([qd, sj.link_acceleration(q, qd, tau_s), qdm, sj.motor_acceleration(qm, qdm, tau_s, u)]), dz

    h = 1.0 / (rate_hz * substeps)
    q_out = np.empty((B, n_ticks + 1))
    u_all = np.empty((B, n_ticks + 1))
    u_fb = np.empty((B, n_ticks + 1))
    qm_out = np.empty((B, n_ticks + 1))
    for i in range(n_ticks + 1):
        q_out[:, i], qm_out[:, i] = x[0, :, 0], x[2, :, 0]
        fb = kp * (qm_ref[:, i] - x[2, :, 0]) + kd * (qmd_ref[:, i] - x[3, :, 0])
        u = (u_ff[:, i] + fb)[:, None]
        u_fb[:, i], u_all[:, i] = fb, u[:, 0]
        if i == n_ticks:
            break
        for _ in range(substeps):
            k1, l1 = deriv(x, z, u)
            k2, l2 = deriv(x + 0.5 * h * k1, z + 0.5 * h * l1, u)
            k3, l3 = deriv(x + 0.5 * h * k2, z + 0.5 * h * l2, u)
            k4, l4 = deriv(x + h * k3, z + h * l3, u)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            z = z + h / 6 * (l1 + 2 * l2 + 2 * l3 + l4)
        if not np.all(np.isfinite(x)) or np.max(np.abs(x[0])) > 1e3:
            raise InputError(None, "kp, kd", "gains the loop is stable with at this rate and step",
                             f"a closed loop diverging at t = {t[i]:.6g} s ({rate_hz:g} Hz, {substeps} substeps)",
                             hint="lower the bandwidth or raise rate_hz / substeps")

    e = q_ref[None, :] - q_out
    em = qm_ref - qm_out

    def rms(a):
        return np.sqrt(np.mean(a ** 2, axis=-1))
    runs = tuple(TrackingRun(name=c.name, flexible=c.flexible, rms_rad=float(rms(e[b])), max_rad=float(np.max(np.abs(e[b]))),
                             motor_rms_rad=float(rms(em[b])), feedback_share=float(rms(u_fb[b]) / rms(u_all[b])),
                             u_rms=float(rms(u_all[b])))
                 for b, c in enumerate(controllers))
    return ControlValidation(t=t, reference=q_ref, q=q_out, u=u_all, runs=runs, kp=kp, kd=kd, rate_hz=rate_hz,
                             substeps=substeps, trajectory=trajectory.to_dict())
