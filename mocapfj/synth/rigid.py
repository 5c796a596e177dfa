"""Synthetic rigid robots for the controller-log-only entry point: a spatial arm as a URDF and the
log a controller would record while it follows an exciting trajectory.

The arm (`arm_urdf`): n revolute joints (3 to 6) alternating between a vertical and a horizontal
axis through ``rpy = (+-pi/2, 0, 0)`` joint origins, as industrial arms are described, with links of
plausible mass and inertia. The log (`rigid_recording`): each joint follows a sum of sines
(Fourier, the usual exciting trajectory); the torque is Pinocchio's inverse dynamics (RNEA, with the
rotor inertia as armature) plus friction and white noise, i.e. what a perfectly tracking controller
logs. No integration is needed, so the truth is exact.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..types import ControllerLog, JointSpec, Recording

__all__ = ["arm_urdf", "rigid_recording", "rigid_truth"]


def arm_urdf(n_joints: int = 3, *, seed: int = 0) -> str:
    """A spatial arm of `n_joints` revolute joints (3..6) as URDF XML (SI units).

    Joint 1 turns about the vertical z; every next joint's origin is rotated by rpy = (-pi/2, 0, 0)
    or (+pi/2, 0, 0) alternately, so axes alternate between vertical and horizontal (the
    rotations that leave round-off columns in the regressor). Links: masses 2-12 kg, lengths
    0.2-0.5 m, centres of mass off the axes, full inertia tensors; `seed` varies them.
    """
    if not 3 <= int(n_joints) <= 6:
        raise InputError(None, "n_joints", "3 to 6 joints", n_joints)
    rng = np.random.default_rng(seed)
    parts = ['<?xml version="1.0"?>', '<robot name="arm">', '<link name="base"/>']
    parent, prev_L = "base", 0.3
    for j in range(1, n_joints + 1):
        m = float(rng.uniform(2.0, 12.0) / j ** 0.5)
        L = float(rng.uniform(0.2, 0.5))
        com = rng.uniform(-0.05, 0.05, 3) + np.array([0.0, 0.0, L / 2])
        A = rng.normal(0, 0.2, (3, 3))
        inertia = m * L * L * (np.diag(rng.uniform([0.05, 0.05, 0.01], [0.1, 0.1, 0.03])) + 0.01 * (A @ A.T))
        rpy = "0 0 0" if j == 1 else ("-1.5707963267948966 0 0" if j % 2 == 0 else "1.5707963267948966 0 0")
        xyz = f"0 0 {prev_L:.6f}"
        parts.append(f'<link name="l{j}"><inertial><origin xyz="{com[0]:.6f} {com[1]:.6f} {com[2]:.6f}" rpy="0 0 0"/>'
                     f'<mass value="{m:.6f}"/><inertia ixx="{inertia[0, 0]:.8f}" ixy="{inertia[0, 1]:.8f}" '
                     f'ixz="{inertia[0, 2]:.8f}" iyy="{inertia[1, 1]:.8f}" iyz="{inertia[1, 2]:.8f}" '
                     f'izz="{inertia[2, 2]:.8f}"/></inertial></link>')
        parts.append(f'<joint name="j{j}" type="revolute"><parent link="{parent}"/><child link="l{j}"/>'
                     f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="0 0 1"/>'
                     f'<limit lower="-3.1" upper="3.1" effort="500" velocity="5"/></joint>')
        parent, prev_L = f"l{j}", L
    parts.append("</robot>")
    return "\n".join(parts)


def rigid_truth(urdf: str, *, armature=0.05, coulomb=2.0, viscous=1.5) -> dict:
    """The parameters a rigid log is made with: armature Ia (kg m^2), Coulomb fc (N m), viscous fv
    (N m s/rad), scalars or per joint."""
    from ..ident.regressor import load_pin_model

    pm = load_pin_model(urdf)
    n = pm.nv
    as_n = lambda v: np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)).copy()  # noqa: E731
    return {"armature": as_n(armature), "coulomb": as_n(coulomb), "viscous": as_n(viscous)}


def rigid_recording(urdf: str, *, duration_s: float = 30.0, rate_hz: float = 500.0, seed: int = 0,
                    f0_hz: float = 0.1, harmonics: int = 5, amplitude_rad: float = 0.8, torque_noise_Nm: float = 0.05,
                    jitter_s: float = 0.0, truth: dict | None = None, name: str = "rigid") -> Recording:
    """A rigid robot's controller log following an exciting Fourier trajectory (module docstring).

    Each joint: q(t) = sum_k a_k sin(2 pi k f0 t + phi_k) with random phases and a_k ~ 1/k scaled
    to `amplitude_rad` peak. tau = RNEA(q, q', q'') + Ia q'' + fc sign(q') + fv q' + noise.
    `jitter_s` > 0 adds uniform jitter to the time stamps (a log without a hardware clock); the
    signals are evaluated at the jittered instants, so the log is exact at its own stamps.
    Returns a Recording without markers (a controller log and the URDF text in `spec`); write it
    with :func:`mocapfj.io.write_recording` after setting `urdf` to a file.
    """
    import pinocchio as pin

    from ..ident.regressor import load_pin_model

    pm = load_pin_model(urdf)
    data = pm.createData()
    n = pm.nv
    truth = rigid_truth(urdf) if truth is None else truth
    rng = np.random.default_rng(seed)
    N = int(round(duration_s * rate_hz)) + 1
    t = np.arange(N) / rate_hz
    if jitter_s > 0:
        t = t + rng.uniform(-jitter_s, jitter_s, N)
        t[0] = 0.0
        t = np.sort(t)
    k = np.arange(1, harmonics + 1)
    w = 2 * np.pi * f0_hz * k
    q = np.zeros((N, n))
    qd = np.zeros((N, n))
    qdd = np.zeros((N, n))
    for j in range(n):
        a = (1.0 / k) * rng.uniform(0.6, 1.0, harmonics)
        phi = rng.uniform(0, 2 * np.pi, harmonics)
        arg = t[:, None] * w[None] + phi[None]
        peak = np.abs((a * np.sin(arg)).sum(1)).max()
        a = a * amplitude_rad / peak
        q[:, j] = (a * np.sin(arg)).sum(1)
        qd[:, j] = (a * w * np.cos(arg)).sum(1)
        qdd[:, j] = -(a * w * w * np.sin(arg)).sum(1)
    tau = np.stack([pin.rnea(pm, data, q[i], qd[i], qdd[i]) for i in range(N)])
    tau = tau + truth["armature"] * qdd + truth["coulomb"] * np.sign(qd) + truth["viscous"] * qd
    tau = tau + rng.normal(0.0, torque_noise_Nm, tau.shape)
    names = tuple(pm.names[1:])
    log = ControllerLog(t=t, q_m=q, tau=tau, joint_names=names)
    joints = tuple(JointSpec(name=nm, motor_position=f"q_{nm}", motor_torque=f"tau_{nm}", gear_ratio=1.0,
                             link_markers=()) for nm in names)
    return Recording(name=name, markers=None, controller=log, joints=joints, controller_file="controller.csv",
                     spec={"synthetic": {"seed": seed, "duration_s": duration_s}})
