"""n-link flexible-joint identification through mocap: the motor equations first, then the links'
base parameters through Pinocchio (Lightcap and Banks (2007), eq. 1; :mod:`.motorfirst` for one joint).

With flexible joints (docs/conventions.md),

    M(q) q'' + C(q, q') q' + G(q) + F(q') = tau_s,          J q_m'' + b q_m' + tau_s = u,

each joint's motor equation involves that joint alone, so :func:`.motorfirst.motor_stage` gives
(J, b, k, tau0) per joint, its motor-side spring torque tau_s = u - J q_m'' - b q_m' and the link
angle rebuilt without differentiating mocap noise. The link equations are then linear in the base
parameters of the links (Pinocchio's joint torque regressor with Coulomb and viscous columns,
:func:`.regressor.nlink_regressor`; base parameters by pivoted QR, :func:`.regressor.base_parameters`),
solved by least squares on every joint's rows together. Every column of the observation matrix and
the torque get the same zero-phase low-pass (parallel filtering, Jubien, Abba and Gautier (2014), §3); rows where the
joint's speed is below `sign_eps` are left out (Coulomb sign ambiguous). Single-joint trials with
the other joints braked are the special case of one moving joint (``mocapfj.ident.motorfirst``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..types import LSResult
from .conditioning import derivatives, lowpass
from .ls import ls_fit
from .motorfirst import MotorStage, motor_stage
from .regressor import base_parameters, load_pin_model, nlink_regressor

__all__ = ["NLinkResult", "identify_nlink_motor_first", "identify_nlink_joints"]


@dataclass(frozen=True, eq=False)
class NLinkResult:
    """Result of :func:`identify_nlink_motor_first`.

    motors : per joint, the :class:`.motorfirst.MotorStage` (J, b, k, tau0 in ``.motor``).
    base : LSResult of the base parameters (names: the regrouped combinations, e.g.
        "Izz_j2 + 0.2025 m_j3"; kg, kg m, kg m^2, N m, N m s).
    base_idx, Kd : the regrouping (:func:`.regressor.base_parameters`): beta = phi[base_idx] + Kd phi[dep].
    names : the standard parameter names of the regressor.
    joint_names : the joints, in the model's order.
    """

    motors: tuple[MotorStage, ...]
    base: LSResult
    base_idx: np.ndarray
    Kd: np.ndarray
    names: tuple[str, ...]
    joint_names: tuple[str, ...]


def identify_nlink_motor_first(model, t, Q, Q_m, U, *, fs_hz: float, joint_names: Sequence[str] | None = None,
                               link_cutoff_hz: float = 20.0, sign_eps: float = 0.01, **motor_kw) -> NLinkResult:
    """Identify every joint's motor side and the links' base parameters.

    Parameters
    ----------
    model : pin.Model, URDF path or XML string
        The links (1-DoF joints, in the order of the columns below).
    t : (T,) float
        Sample times, s, uniform at fs_hz, one clock.
    Q, Q_m, U : (T, n) float
        Link angles from mocap (rad), motor angles / N (rad), motor torques x N (N m), link side.
    fs_hz : float
    joint_names : n str, optional (default the model's joint names)
    link_cutoff_hz : float
        Low-pass of the link equations (and of the rebuilt angles), Hz.
    sign_eps : float
        Rows with |q'_j| below this (rad/s) are left out.
    **motor_kw
        Passed to :func:`.motorfirst.motor_stage` (cutoff_hz, split_hz, decimate, trim_s, ...).
    """
    pm = load_pin_model(model)
    Q, Q_m, U = (np.asarray(a, dtype=np.float64) for a in (Q, Q_m, U))
    t = np.asarray(t, dtype=np.float64)
    n = pm.nq
    names_j = tuple(pm.names[1:]) if joint_names is None else tuple(joint_names)
    for label, a in (("Q", Q), ("Q_m", Q_m), ("U", U)):
        if a.shape != (t.size, n):
            raise InputError(None, label, f"shape ({t.size}, {n}): the model's {n} joints over the {t.size} samples",
                             a.shape)
    if len(names_j) != n:
        raise InputError(None, "joint_names", f"{n} names", len(names_j))
    motors = []
    for j in range(n):
        try:
            motors.append(motor_stage(t, Q[:, j], Q_m[:, j], U[:, j], fs_hz=fs_hz, link_cutoff_hz=link_cutoff_hz,
                                      **motor_kw))
        except InputError as e:
            raise InputError(e.file, f"joint {names_j[j]}: {e.field}", e.expected, e.got, e.hint) from None
    Qh = np.column_stack([m.q_hat for m in motors])
    tau_s = np.column_stack([m.tau_s for m in motors])
    Qd, Qdd = derivatives(Qh, fs_hz)
    W, names = nlink_regressor(pm, Qh, Qd, Qdd, friction="coulomb_viscous", armature=False)
    p = W.shape[1]
    # parallel filtering: the same low-pass on every column (per joint's rows) and on the torque
    W = lowpass(W.reshape(t.size, n, p), fs_hz, link_cutoff_hz).reshape(t.size * n, p)
    y = lowpass(tau_s, fs_hz, link_cutoff_hz).ravel()
    inner = np.logical_and.reduce([m.inner for m in motors])
    keep = (inner[:, None] & (np.abs(Qd) > sign_eps)).ravel()
    base_idx, Kd, base_names = base_parameters(W[keep], names)
    base = ls_fit(W[keep][:, base_idx], y[keep], base_names)
    return NLinkResult(motors=tuple(motors), base=base, base_idx=base_idx, Kd=Kd, names=tuple(names),
                       joint_names=names_j)


def identify_nlink_joints(model, signals, *, decimate: int = 2, recording: str = "", gear_ratios=None,
                          spring_models=None) -> tuple[list, dict]:
    """:func:`identify_nlink_motor_first` on the joints' :class:`~mocapfj.types.JointSignals` (one
    clock, one span, in the model's joint order), as :class:`~.result.IdentifiedJoint` per joint
    (J, b, k and the spring model) and the links' base parameters {base: {name: (value, std)},
    cond, torque_rms, r2}."""
    from ..dynamics import LinearSpring
    from .joint import spring_pairs
    from .result import IdentifiedJoint, Parameter, SpringResult
    from .springs import HYSTERETIC, SPRING_FITTERS, select_spring_model

    t = signals[0].t
    fs = signals[0].fs_hz
    Q, Q_m, U = (np.column_stack([getattr(s, k) for s in signals]) for k in ("q", "q_m", "u"))
    res = identify_nlink_motor_first(model, t, Q, Q_m, U, fs_hz=fs, decimate=decimate,
                                     joint_names=[s.name for s in signals])
    base = {name: (float(v), float(sd)) for name, v, sd in zip(res.base.names, res.base.values, res.base.std)}
    summary = {"base": base, "cond": res.base.cond, "torque_rms": res.base.residual_rms, "r2": res.base.r2}
    gears = gear_ratios or [1.0] * len(signals)
    models = tuple(spring_models or (k for k in SPRING_FITTERS if k not in HYSTERETIC))
    out = []
    for s, m, gear in zip(signals, res.motors, gears):
        if m.hysteresis is not None:
            from ..dynamics import BoucWen

            params = {k: m.hysteresis[k] for k in ("k", "alpha", "beta", "gamma")}
            spring = SpringResult("bouc_wen", params, BoucWen(**params), motor_rms_gain_pct=m.hysteresis["rms_gain_pct"])
        else:
            inner = m.inner
            sel = select_spring_model(*spring_pairs(m.delta[inner], m.tau_s[inner], m.t[inner], fs), models=models)
            c = sel.chosen
            spring = SpringResult(c.model, {k: float(v) for k, v in c.params.items()},
                                  LinearSpring(k=m.motor["k"]) if c.model == "linear" else c.element,
                                  r2=sel.r2, holdout_rms_Nm=sel.holdout_rms)
        params = {n: Parameter(n, m.motor[n], m.motor.std_of(n)) for n in ("J", "b", "k")}
        out.append(IdentifiedJoint(name=s.name, method="nlink_motor_first", params=params, model=None, spring=spring,
                                   stages={"motor": m.motor}, cond={"cond_motor": m.motor.cond},
                                   torque_rms=m.motor.residual_rms, q_zero_rad=m.q_zero_rad,
                                   frames_filled=s.n_filled, recording=recording,
                                   extra={"nlink": {"base": base, "cond": res.base.cond,
                                                    "torque_rms": res.base.residual_rms, "r2": res.base.r2}}))
    return out, summary
