"""The single-joint equations of Lightcap and Banks (2007), eq. (4), as observation matrices: the
one place the link and motor equations are written (signs: docs/conventions.md).

    link:   I q'' - mglx sin q + mgly cos q + c sgn(q') + v q' = tau_s
    motor:  J q_m'' + b q_m' + tau_s = u,      tau_s = k (q_m - q) (+ tau0 for a zero offset)
"""

from __future__ import annotations

import numpy as np

__all__ = ["LINK_NAMES", "MOTOR_NAMES", "link_regressor", "link_torque", "motor_regressor"]

LINK_NAMES = ("I", "mglx", "mgly", "c", "v")
MOTOR_NAMES = ("J", "b", "k", "tau0")


def link_regressor(q, qd, qdd, sgn=None) -> np.ndarray:
    """Columns (q'', -sin q, cos q, sgn q', q') (T, 5) of the link equation, in LINK_NAMES order.

    q, qd, qdd (T,) rad, rad/s, rad/s^2; `sgn` (T,) replaces sign(q') when given (a smoothed or
    low-passed Coulomb column, tanh(q'/eps))."""
    q, qd, qdd = (np.asarray(a, dtype=np.float64) for a in (q, qd, qdd))
    s = np.sign(qd) if sgn is None else np.asarray(sgn, dtype=np.float64)
    return np.column_stack([qdd, -np.sin(q), np.cos(q), s, qd])


def link_torque(p, q, qd, qdd, sgn=None) -> np.ndarray:
    """The link equation's torque (T,) N m for parameters `p` ({name: value} or 5 values in
    LINK_NAMES order)."""
    theta = np.array([p[n] for n in LINK_NAMES]) if isinstance(p, dict) else np.asarray(p, dtype=np.float64)
    return link_regressor(q, qd, qdd, sgn) @ theta


def motor_regressor(qd_m, qdd_m, spring) -> np.ndarray:
    """Columns (q_m'', q_m', f, 1) (T, 4) of the motor equation, in MOTOR_NAMES order: `spring` is
    the deflection (a linear spring, k its coefficient) or a spring shape f(delta) (T,)."""
    qd_m, qdd_m, spring = (np.asarray(a, dtype=np.float64) for a in (qd_m, qdd_m, spring))
    return np.column_stack([qdd_m, qd_m, spring, np.ones_like(spring)])
