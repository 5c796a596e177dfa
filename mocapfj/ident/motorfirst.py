"""Motor-first identification of one joint: a variant of seed 000 §II.A for mocap link angles.

Seed 000's step 1 solves the stiffness-free sum of the link and motor equations, in which the
link inertia I and the motor inertia J are told apart only by the deflection's acceleration
delta''. With mocap link angles (0.43 mrad noise at 250 Hz on pa10_joint2) delta'' is buried in
noise and I, J, v, b come out tens of percent off (tests/ident/test_twostep.py records it).

Here the motor equation comes first. J q_m'' + b q_m' + k (q_m - q) + tau0 = u uses only the
motor's clean derivatives; the noisy link angle enters undifferentiated through the deflection.
It gives J, b and a linear stiffness k. The link equation then follows,
I q'' - mglx sin q + mgly cos q + c sign(q') + v q' = k (q_m - q) + tau0, which gives I, mglx,
mgly, c and v, with the gravity pair referred to the link-angle zero that tau0 reveals
(e = -tau0 / k: the mocap angle's zero was aligned by the mean deflection). The spring torque
then feeds the spring models of `springs` as in seed 000's step 2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..types import LSResult
from .conditioning import decimate_parallel, derivatives, lowpass
from .ls import ls_fit
from .twostep import _check_inputs

__all__ = ["MotorFirstResult", "identify_joint_motor_first"]


@dataclass(frozen=True, eq=False)
class MotorFirstResult:
    """motor: LSResult of (J, b, k, tau0); link: LSResult of (I, mglx, mgly, c, v); q_zero_rad: the
    correction added to the link angle; t, tau_s (k delta + tau0), delta: the spring's samples."""

    motor: LSResult
    link: LSResult
    q_zero_rad: float
    t: np.ndarray
    tau_s: np.ndarray
    delta: np.ndarray

    def __getitem__(self, name: str) -> float:
        return self.motor[name] if name in self.motor.names else self.link[name]


def identify_joint_motor_first(t, q, q_m, u, *, fs_hz: float, cutoff_hz: float = 5.0, decimate: int = 2,
                               sign_eps: float = 0.03, trim_s: float = 1.0) -> MotorFirstResult:
    """Identify J, b, k from the motor equation, then I, mglx, mgly, c, v from the link equation.

    Parameters as `twostep.identify_joint`: t (T,) s uniform at fs_hz on one clock; q link angle
    (mocap), q_m motor angle / N, u motor torque x N (link side); `cutoff_hz` the zero-phase
    low-pass before differentiation (5 Hz suits 250 Hz mocap with 0.2 mm marker noise);
    `decimate` the parallel decimation of the motor equation; samples with |q'| < `sign_eps`
    are left out of the link equation; `trim_s` dropped at both ends.
    """
    t, q, q_m, u = _check_inputs(t, q, q_m, u, fs_hz)
    qf, qmf, uf = lowpass(q, fs_hz, cutoff_hz), lowpass(q_m, fs_hz, cutoff_hz), lowpass(u, fs_hz, cutoff_hz)
    qd, qdd = derivatives(qf, fs_hz)
    qmd, qmdd = derivatives(qmf, fs_hz)
    n_trim = int(round(trim_s * fs_hz))
    inner = np.zeros(t.size, bool)
    inner[n_trim:t.size - n_trim] = True
    delta = qmf - qf
    Wm = np.column_stack([qmdd, qmd, delta, np.ones_like(delta)])[inner]
    Wm, ym = decimate_parallel(Wm, uf[inner], decimate, fs_hz, min(cutoff_hz, 0.8 * fs_hz / (2 * decimate)))
    motor = ls_fit(Wm, ym, ["J", "b", "k", "tau0"])
    e = -motor["tau0"] / motor["k"]
    tau_s = motor["k"] * delta + motor["tau0"]
    qz = qf + e
    # parallel filtering (seed 003 §3): the sign and gravity columns get the low-pass the spring
    # torque (from filtered angles) already had, so a Coulomb step is smoothed alike on both sides
    Wl = lowpass(np.column_stack([qdd, -np.sin(qz), np.cos(qz), np.sign(qd), qd]), fs_hz, cutoff_hz)
    keep = inner & (np.abs(qd) > sign_eps)
    link = ls_fit(Wl[keep], tau_s[keep], ["I", "mglx", "mgly", "c", "v"])
    return MotorFirstResult(motor=motor, link=link, q_zero_rad=float(e), t=t[inner], tau_s=tau_s[inner],
                            delta=delta[inner] - e)
