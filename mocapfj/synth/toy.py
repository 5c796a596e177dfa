"""A small, deterministic one-joint recording bundle: the demo and the io tests use it.

A link turns about the world z axis through a known centre following q(t); four markers ride on
it at radii 80-140 mm; three more sit still on the base. The controller log holds the motor
angle q_m = q + tau / k (a linear spring, Lightcap and Banks (2007), eq. 7) and the torque of a rigid pendulum
free of gravity, I q'' + v q' (Lightcap and Banks (2007), eq. 4 with mgl = c = 0). Marker noise is Gaussian and
some samples drop out. The full simulator (issue 3) supersedes this for identification work; it
is kept because it is small, exact and fast.
"""

from __future__ import annotations

import numpy as np

from ..types import ControllerLog, JointSpec, MarkerTrajectories, Recording

__all__ = ["toy_recording", "TOY_TRUTH"]

TOY_TRUTH = {
    "axis": (0.0, 0.0, 1.0),
    "centre_m": (0.30, -0.20, 0.85),
    "I": 1.2,          # kg m^2
    "v": 2.5,          # N m s / rad
    "k": 5.0e3,        # N m / rad
    "amplitude_rad": 0.6,
}


def toy_recording(duration_s: float = 4.0, mocap_hz: float = 250.0, controller_hz: float = 1000.0,
                  noise_m: float = 2e-4, dropout: float = 0.01, seed: int = 0) -> Recording:
    """Build the toy recording in memory (write it with `mocapfj.io.write_recording`).

    Returns a Recording whose markers are on the mocap clock starting at 0 s and whose
    controller log starts at 0 s too (clock offset 0).
    """
    rng = np.random.default_rng(seed)
    T = TOY_TRUTH
    c = np.asarray(T["centre_m"])
    # link angle: two sines, zero mean
    w1, w2 = 2 * np.pi * 0.5, 2 * np.pi * 1.3
    def q_of(t):
        return T["amplitude_rad"] * (0.8 * np.sin(w1 * t) + 0.2 * np.sin(w2 * t))
    def qd_of(t):
        return T["amplitude_rad"] * (0.8 * w1 * np.cos(w1 * t) + 0.2 * w2 * np.cos(w2 * t))
    def qdd_of(t):
        return -T["amplitude_rad"] * (0.8 * w1**2 * np.sin(w1 * t) + 0.2 * w2**2 * np.sin(w2 * t))

    tm = np.arange(int(round(duration_s * mocap_hz)) + 1) / mocap_hz
    radii = np.array([0.08, 0.10, 0.12, 0.14])
    phase = np.array([0.0, 1.7, 3.3, 4.6])
    height = np.array([0.02, -0.03, 0.04, -0.01])
    ang = q_of(tm)[:, None] + phase[None, :]
    link = np.stack([c[0] + radii * np.cos(ang), c[1] + radii * np.sin(ang),
                     np.broadcast_to(c[2] + height, ang.shape)], axis=-1)  # (T, 4, 3)
    base = np.broadcast_to(np.array([[0.0, 0.0, 0.6], [0.2, 0.0, 0.6], [0.0, 0.25, 0.6]]), (tm.size, 3, 3))
    xyz = np.concatenate([link, base], axis=1) + rng.normal(0.0, noise_m, (tm.size, 7, 3))
    drop = rng.random((tm.size, 7)) < dropout
    xyz[drop] = np.nan
    residual = np.where(drop, np.nan, np.abs(rng.normal(0.0, noise_m, (tm.size, 7))))
    labels = ("L1_1", "L1_2", "L1_3", "L1_4", "B_1", "B_2", "B_3")
    markers = MarkerTrajectories(t=tm, xyz=xyz, labels=labels, rate_hz=mocap_hz, residual=residual)

    tc = np.arange(int(round(duration_s * controller_hz)) + 1) / controller_hz
    tau = T["I"] * qdd_of(tc) + T["v"] * qd_of(tc)
    q_m = q_of(tc) + tau / T["k"]
    tau_meas = tau + rng.normal(0.0, 0.05, tc.size)
    controller = ControllerLog(t=tc, q_m=q_m[:, None], tau=tau_meas[:, None], joint_names=("j1",))
    joint = JointSpec(name="j1", motor_position="qm_j1", motor_torque="tau_j1", gear_ratio=50.0,
                      link_markers=labels[:4], parent_markers=labels[4:])
    return Recording(name="toy_joint1", markers=markers, controller=controller, joints=(joint,))
