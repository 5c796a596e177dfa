"""Stream synchronisation and joint deflection (Lightcap and Banks (2007), eq. 7: delta = q_m - q).

The mocap and controller clocks are put on one time base by the offset recording.toml declares
(from a hardware sync): t_controller = t_mocap + clock_offset_s. Nothing else is aligned: the
link lags the motor physically (viscous friction alone looks like a delay of v/k, about 1.5 ms
on PA-10 joint 2) and that lag is what identification measures, so no cross-correlation is used
here. An undeclared offset is estimated with the dynamics by discovery (`time_delay`).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..types import ControllerLog, Deflection, JointAngles

__all__ = ["deflection", "resolver_quantum"]


def resolver_quantum(q_m: np.ndarray) -> float:
    """The quantum of a logged angle: its smallest non-zero step, rad (0 if none is found)."""
    d = np.abs(np.diff(q_m[np.isfinite(q_m)]))
    d = d[d > 1e-15]
    if d.size == 0:
        return 0.0
    smallest = float(d.min())
    # a quantised signal steps by whole quanta: most steps are near-integer multiples
    k = d / smallest
    return smallest if np.mean(np.abs(k - np.round(k)) < 1e-3) > 0.9 else 0.0


def deflection(angles: JointAngles, controller: ControllerLog, joint: int | str, clock_offset_s: float = 0.0) -> Deflection:
    """Deflection of one joint at the mocap samples.

    Parameters
    ----------
    angles : JointAngles
        Link angles on the mocap clock.
    controller : ControllerLog
    joint : int or str
        Column (or name) of the joint in the controller log.
    clock_offset_s : float
        Declared offset, t_controller = t_mocap + offset (recording.toml ``markers.clock_offset_s``).
    """
    j = controller.joint_names.index(joint) if isinstance(joint, str) else int(joint)
    t = angles.t + clock_offset_s
    inside = (t >= controller.t[0]) & (t <= controller.t[-1])
    q_m = np.where(inside, np.interp(t, controller.t, controller.q_m[:, j]), np.nan)
    tau = np.where(inside, np.interp(t, controller.t, controller.tau[:, j]), np.nan)
    ok = np.isfinite(angles.q) & np.isfinite(q_m)
    if not ok.any():
        raise InputError(None, "deflection", "mocap frames with a link angle inside the controller log's time span",
                         "none", hint="check markers.clock_offset_s and that both streams cover the same trial")
    offset = float(np.mean(q_m[ok] - angles.q[ok]))
    q = angles.q + offset
    quantum = resolver_quantum(controller.q_m[:, j])
    sigma = np.sqrt(angles.sigma_q**2 + quantum**2 / 12.0)
    return Deflection(t=t, q=q, q_m=q_m, delta=q_m - q, sigma_delta=sigma, tau=tau, q_offset_rad=offset,
                      q_m_quantum_rad=quantum)
