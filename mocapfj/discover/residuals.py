"""Equation-error residuals of a joint model against a recording, split where the physics splits.

With the motor-side spring torque tau_s = u - J q_m'' - b q_m' (as clean as the motor signals;
:mod:`mocapfj.ident.motorfirst`):

- the spring residual  r_s = tau_s - f(delta)            (spring, transmission, clock, drive gain)
- the link residual    r_l = tau_s - [I q'' + G(q) + F(q, q') - tau_pos(q) + coupling]   (friction,
  gravity, neighbours)

The spring relation holds whatever the friction and gravity are, and the link equation whatever
the spring is, so an effect shows in one of the two. The link angle of the link residual is
rebuilt without differentiating mocap noise (below 2 Hz the mocap deflection, above it the
spring's, tau_s / k). Both residuals are low-passed at 10 Hz (every term at full band first, so
the filter is the same on both sides of each equation) and trimmed at the ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from ..dynamics import BoucWen, LinearSpring, shift_signal
from ..errors import InputError
from ..ident.conditioning import complementary, derivatives, lowpass
from ..ident.springs import bouc_wen_path
from ..dynamics import JointModel

__all__ = ["Families", "families", "spring_torque_of", "RESIDUAL_HZ"]

RESIDUAL_HZ = 10.0     # low-pass of both residuals
LINK_HZ = 20.0         # low-pass of the signals before differentiation
SPLIT_HZ = 2.0         # mocap / spring cross-over of the rebuilt deflection


def spring_torque_of(model: JointModel, delta: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The model spring's torque along the deflection path delta (T,) rad at t (T,) s, N m.

    A Bouc-Wen spring with n = 1 runs along the path exactly (linear between samples, at most
    100 Hz: `ident.springs.bouc_wen_path`); other hysteretic springs by their own `run`."""
    sp = model.spring
    if isinstance(sp, BoucWen) and sp.n == 1.0:
        step = max(1, int(round(1.0 / (100.0 * float(np.median(np.diff(t)))))))
        z = bouc_wen_path(delta, sp.A, sp.beta, sp.gamma, step)
        return sp.alpha * sp.k * delta + (1 - sp.alpha) * sp.k * z
    if getattr(sp, "n_states", 0):
        return np.asarray(sp.run(delta, t), dtype=np.float64)
    return np.asarray(sp.torque(delta), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Families:
    """The residuals and the signals the effect library regresses them on (all (T,), one clock).

    t, q_m (rad), u (logged torque, N m, low-passed at LINK_HZ), tau_s (motor-side spring
    torque), delta (recorded deflection q_m - q, zero-corrected, full band), d_hat (rebuilt
    deflection), q_hat, qd_hat, qdd_hat (rebuilt link angle and its derivatives), r_s, r_l (the
    two residuals, N m, low-passed at RESIDUAL_HZ), keep_s, keep_l (samples used: inside the trims;
    the link residual also leaves out |q'| < 0.005 rad/s), q_zero_rad (zero correction added to
    the recorded deflection), k (the spring's linear equivalent), fs_hz, model, motor ((T, 2): the
    motor's acceleration and velocity as r_s carries them, low-passed at RESIDUAL_HZ: how an error
    of the nominal J and b enters the spring residual, -dJ q_m'' - db q_m'; None unless asked for,
    :func:`families`' `motor_free`).
    """

    t: np.ndarray
    q: np.ndarray
    q_m: np.ndarray
    u: np.ndarray
    tau_s: np.ndarray
    delta: np.ndarray
    d_hat: np.ndarray
    q_hat: np.ndarray
    qd_hat: np.ndarray
    qdd_hat: np.ndarray
    r_s: np.ndarray
    r_l: np.ndarray
    keep_s: np.ndarray
    keep_l: np.ndarray
    q_zero_rad: float
    k: float
    fs_hz: float
    model: JointModel
    motor: np.ndarray | None

    def lp(self, x: np.ndarray) -> np.ndarray:
        """The residuals' low-pass (RESIDUAL_HZ), for a regressor formed at full band."""
        return lowpass(x, self.fs_hz, RESIDUAL_HZ)

    def residual(self, family: str) -> tuple[np.ndarray, np.ndarray]:
        """(the residual, the samples it keeps) of `family`: "spring" or "link"."""
        return (self.r_s, self.keep_s) if family == "spring" else (self.r_l, self.keep_l)

    def spring_residual_for(self, delta: np.ndarray) -> np.ndarray:
        """r_s with another recorded deflection (e.g. the link angle on a shifted clock)."""
        return self.lp(self.tau_s - spring_torque_of(self.model, delta + self.q_zero_rad, self.t))


def _link_torque(model: JointModel, q, qd, qdd, context=None) -> np.ndarray:
    """I q'' + G(q) + F(q, q') - tau_pos(q), N m (docs/conventions.md signs); a robot's joint
    (context: its :class:`.context.LinkContext`) adds the robot's inertia and gravity and takes off
    the other links' torque."""
    if context is None:
        tau = model.I * qdd + model.single_joint().gravity(q) + model.friction.torque(qd, q)
    else:      # the joint's own I (>= 0), mglx, mgly are added to the robot's
        tau = ((model.I + context.I) * qdd - (model.mglx + context.mglx) * np.sin(q)
               + (model.mgly + context.mgly) * np.cos(q) + model.friction.torque(qd, q) - context.tau)
    if model.position_torque is not None:
        tau = tau - model.position_torque.torque(q)
    return tau


def families(model: JointModel, t, q, q_m, u, *, fs_hz: float, others_qdd: dict | None = None,
             trim_s: float = 1.0, motor_free: bool = False) -> Families:
    """The spring and link residuals of `model` on one joint's recorded signals (mocap clock).
    others_qdd : {joint: (T,) rad/s^2} the other joints' accelerations (the model's coupling
    terms) and, for a robot's joint, the robot's context (:data:`.context.ROBOT_KEY`). motor_free:
    keep the motor's columns (Families.motor) for the spring effects' fits."""
    t, q, q_m, u = (np.asarray(a, dtype=np.float64) for a in (t, q, q_m, u))
    if not (t.shape == q.shape == q_m.shape == u.shape and t.ndim == 1):
        raise InputError(None, "t, q, q_m, u", "four (T,) arrays", [a.shape for a in (t, q, q_m, u)])
    n_trim = int(round(trim_s * fs_hz))
    if t.size < 2 * n_trim + int(4 * fs_hz / SPLIT_HZ):
        raise InputError(None, "t", f"at least {2 * n_trim + int(4 * fs_hz / SPLIT_HZ)} samples for the residual filters",
                         t.size, hint="record longer")
    if model.delay_s:
        q = shift_signal(t, q, model.delay_s)             # the model's clock correction
        ok = np.isfinite(q)
        q = np.interp(t, t[ok], q[ok])
    qmf = lowpass(q_m, fs_hz, LINK_HZ)
    uf = lowpass(u, fs_hz, LINK_HZ)
    qmd, qmdd = derivatives(qmf, fs_hz)
    tau_s = model.torque_gain * uf - model.J * qmdd - model.b * qmd
    if model.transmission_error is not None:             # the motor feels tau_s (1 + e'(q_m))
        tau_s = tau_s / (1.0 + model.transmission_error.derivative(qmf))
    delta = lowpass(q_m - q, fs_hz, LINK_HZ)
    if model.transmission_error is not None:
        delta = delta + model.transmission_error.error(qmf)
    k = model.stiffness()
    inner = np.zeros(t.size, bool)
    inner[n_trim:t.size - n_trim] = True

    # the zero of the recorded deflection (the joints stage aligned its mean to 0)
    def cost(e):
        r = tau_s - spring_torque_of(model, delta + e, t)
        return float(np.mean((r[inner] - np.median(r[inner])) ** 2)) + float(np.median(r[inner]) ** 2)

    if getattr(model.spring, "n_states", 0) or not isinstance(model.spring, LinearSpring):
        span = max(5e-3, 5 * float(np.std(delta)))
        e = float(minimize_scalar(cost, bounds=(-span, span), method="bounded", options={"xatol": 1e-7}).x)
    else:   # linear: tau_s = k (delta + e - offset), e from the means
        e = float(np.mean(tau_s[inner]) / model.spring.k - np.mean(delta[inner]) + model.spring.offset)
    r_s_full = tau_s - spring_torque_of(model, delta + e, t)
    d_lin = tau_s / k
    d_hat = complementary(delta + e, d_lin, fs_hz, SPLIT_HZ)
    q_hat = qmf - d_hat
    qd, qdd = derivatives(q_hat, fs_hz)
    from .model import link_context

    link = _link_torque(model, q_hat, qd, qdd, link_context(model, others_qdd))
    for src, c in model.coupling.items():
        if others_qdd is None or src not in others_qdd:
            raise InputError(None, f"joints[{model.name}].coupling", "source joints in the recording", src)
        link = link + c * others_qdd[src]
    r_l_full = tau_s - link
    moving = np.abs(qd) > 0.005
    moving = np.convolve(moving.astype(float), np.ones(5), mode="same") >= 5
    return Families(t=t, q=q, q_m=qmf, u=uf, tau_s=tau_s, delta=delta + e, d_hat=d_hat, q_hat=q_hat, qd_hat=qd,
                    qdd_hat=qdd, r_s=lowpass(r_s_full, fs_hz, RESIDUAL_HZ), r_l=lowpass(r_l_full, fs_hz, RESIDUAL_HZ),
                    keep_s=inner, keep_l=inner & moving, q_zero_rad=e, k=k, fs_hz=fs_hz, model=model,
                    motor=np.column_stack([lowpass(qmdd, fs_hz, RESIDUAL_HZ), lowpass(qmd, fs_hz, RESIDUAL_HZ)])
                    if motor_free else None)
