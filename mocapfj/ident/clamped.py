"""Joint stiffness with the end-effector clamped (Jubien, Abba and Gautier 2014).

With the end-effector fixed to the environment the link angles stay at q0 while the motors move a
little as the controller pushes: for each joint j (their eq. 4-6, 10-12, link side, SI)

    tau_m_j = k_j q_m_j + offkm_j          (motor torque: offkm = offm - k q0)
    tau_l_j = k_j q_m_j + offkl_j          (joint torque, offkl = -k q0 - G(q0))
    tau_l   = J(q0)^T F_e                  (from the wrench measured between tool and environment)

and each is one IDIM-LS problem of two parameters (their eq. 8 and 11), solved with the
statistics of their eq. 15-17 (:func:`.ls.ls_fit`) after the same zero-phase low-pass on both
sides and a parallel decimation (their section 4.3: 10 Hz Butterworth, 5 Hz decimation filter).
F_e here is the wrench the end-effector applies to the environment, [f; m] expressed in the tool
frame at its origin (a sensor's reading in that sign); J(q0) is Pinocchio's LOCAL frame Jacobian
at q0 = q_m0, the motor angles at (near) zero torque (their eq. 3).

Also: the modified Denavit-Hartenberg model of Khalil and Kleinfinger (their Table 1 for the
KUKA KR500) built in Pinocchio, and the forward model of the clamped experiment for planning and
testing (the force levels of their section 4.3, at the controller's and the sensor's rates).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..types import LSResult
from ..validate import check_array, check_scalar, freeze_arrays
from .conditioning import decimate_parallel, lowpass, resample_to
from .ls import ls_fit

__all__ = ["KR500_MDH", "KR500_CONFIGURATIONS", "KR500_TABLE7", "ClampedFit", "ClampedStiffness", "mdh_model",
           "external_torques", "fit_clamped", "identify_clamped", "ClampedExperiment", "simulate_clamped"]

KR500_MDH = (
    # alpha_j, d_j (m), theta offset (rad), r_j (m): Jubien et al. (2014), Table 1 (theta_j = q_mj + offset)
    (math.pi, 0.0, 0.0, -1.045),
    (math.pi / 2, 0.500, 0.0, 0.0),
    (0.0, 1.300, math.pi / 2, 0.0),
    (-math.pi / 2, -0.055, 0.0, -1.025),
    (math.pi / 2, 0.0, 0.0, 0.0),
    (-math.pi / 2, 0.0, -math.pi / 2, -0.290),
)
KR500_CONFIGURATIONS = {
    # Jubien et al. (2014), Table 2: configuration 1 for axis 1, 2 for axis 2 (rad)
    1: (1.62, -0.89, 1.84, 1.62, -math.pi / 2, 0.46),
    2: (1.48, -0.87, 1.37, math.pi, -1.05, 0.0),
}
KR500_TABLE7 = {
    # Jubien et al. (2014), Tables 3-7: k (N m/rad) and relative SD (%) by motor torques and by wrench
    "k1": {"motor": (6.09e6, 2.1), "wrench": (6.93e6, 0.77), "rel_diff_pct": 12.1},
    "k2": {"motor": (8.00e6, 2.0), "wrench": (7.81e6, 0.98), "rel_diff_pct": 2.43},
}


def mdh_model(table: Sequence[Sequence[float]], tool_name: str = "tool", masses=None):
    """A Pinocchio model of a serial revolute robot from its modified Denavit-Hartenberg table
    (Khalil and Kleinfinger 1986): rows (alpha_j, d_j, theta_offset_j, r_j), frame j-1 to j =
    Rot(x, alpha) Trans(x, d) Rot(z, theta_offset + q_j) Trans(z, r). Joint names j1..jn; a frame
    `tool_name` at the last joint's frame. `masses`: optional (n,) kg, point masses at each
    joint frame's origin shifted 0.3 m along x (for a gravity vector of the right size; the
    stiffness fit only sees it in its offsets). Gravity along -z of the base frame."""
    import pinocchio as pin

    rows = np.asarray(table, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 4 or not np.isfinite(rows).all():
        raise InputError(None, "table", "rows (alpha, d, theta_offset, r) of finite numbers", rows.shape)
    model = pin.Model()
    parent = 0
    for j, (alpha, d, off, r) in enumerate(rows):
        R = pin.utils.rotate("x", alpha) @ pin.utils.rotate("z", off)
        p = np.array([d, 0.0, 0.0]) + pin.utils.rotate("x", alpha) @ np.array([0.0, 0.0, r])
        parent = model.addJoint(parent, pin.JointModelRZ(), pin.SE3(R, p), f"j{j + 1}")
        m = 0.0 if masses is None else float(masses[j])
        inertia = pin.Inertia(m, np.array([0.3, 0.0, 0.0]), np.eye(3) * max(m, 1e-6) * 0.01) if m > 0 else \
            pin.Inertia.Zero()
        model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
    model.addFrame(pin.Frame(tool_name, parent, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    return model


def external_torques(model, q0, wrench, frame: str = "tool") -> np.ndarray:
    """tau_l (T, n) = J(q0)^T F_e (Jubien et al. 2014, eq. 12): F_e (T, 6) [fx fy fz mx my mz] in
    N, N m, the wrench the end-effector applies to the environment, in `frame` at its origin; J
    the frame's LOCAL Jacobian at q0 (n,) rad. Rows with NaN stay NaN (sensor gaps)."""
    import pinocchio as pin

    q0 = np.asarray(q0, dtype=np.float64)
    if q0.shape != (model.nq,):
        raise InputError(None, "q0", f"{model.nq} joint angles", q0.shape)
    if not model.existFrame(frame):
        raise InputError(None, "frame", f"a frame of the model ({', '.join(f.name for f in model.frames)})", frame)
    F = check_array(wrench, "wrench", (None, 6))
    data = model.createData()
    J = pin.computeFrameJacobian(model, data, q0, model.getFrameId(frame), pin.LOCAL)
    if np.linalg.cond(J) > 1e8:
        raise InputError(None, "q0", "a configuration away from singularities (the Jacobian's condition number "
                         "below 1e8)", f"{np.linalg.cond(J):.3g}")
    return F @ J


@dataclass(frozen=True)
class ClampedFit:
    """k_j q_m_j + offset fitted to one torque (Jubien et al. 2014, eq. 8 or 11).

    Attributes
    ----------
    joint : str
    source : "motor_torque" or "wrench"
    k, k_std : N m/rad; k_rel_std_pct : % (their eq. 17)
    offset, offset_std : N m (offkm or offkl); offset_rel_std_pct : %
    rel_error_pct : 100 ||Y - W chi|| / ||Y|| (their Tables 3-6)
    n_samples : rows after decimation
    ls : the full LSResult
    """

    joint: str
    source: str
    k: float
    k_std: float
    k_rel_std_pct: float
    offset: float
    offset_std: float
    offset_rel_std_pct: float
    rel_error_pct: float
    n_samples: int
    ls: LSResult = field(repr=False)

    def to_dict(self) -> dict:
        return {"joint": self.joint, "source": self.source, "k": self.k, "k_std": self.k_std,
                "k_rel_std_pct": self.k_rel_std_pct, "offset": self.offset, "offset_std": self.offset_std,
                "offset_rel_std_pct": self.offset_rel_std_pct, "rel_error_pct": self.rel_error_pct,
                "n_samples": self.n_samples}


@dataclass(frozen=True)
class ClampedStiffness:
    """One joint's stiffness by motor torques and/or by the wrench, and their relative difference
    100 |k_motor - k_wrench| / k_wrench (Jubien et al. 2014, Table 7)."""

    name: str
    motor: ClampedFit | None
    wrench: ClampedFit | None

    @property
    def rel_diff_pct(self) -> float:
        if self.motor is None or self.wrench is None:
            return float("nan")
        return 100.0 * abs(self.motor.k - self.wrench.k) / abs(self.wrench.k)

    def to_dict(self) -> dict:
        d = {"name": self.name}
        if self.motor is not None:
            d["motor_torque"] = self.motor.to_dict()
        if self.wrench is not None:
            d["wrench"] = self.wrench.to_dict()
        if self.motor is not None and self.wrench is not None:
            d["rel_diff_pct"] = self.rel_diff_pct
            d["diff_sd"] = abs(self.motor.k - self.wrench.k) / math.hypot(self.motor.k_std, self.wrench.k_std)
        return d


def fit_clamped(q_m, tau, fs_hz: float, *, joint: str = "j", source: str = "motor_torque",
                cutoff_hz: float = 10.0, decimate_cutoff_hz: float = 5.0, cov: str = "hac") -> ClampedFit:
    """IDIM-LS of tau = k q_m + offset for one joint (Jubien et al. 2014, eq. 8 / 11, 13-17).

    q_m, tau : (T,) rad, N m, link side, uniformly sampled at fs_hz (NaN rows, e.g. sensor gaps,
        are cut into runs: each run is filtered alone and runs too short to filter are dropped).
    cutoff_hz : the Butterworth low-pass on both (their 10 Hz); decimate_cutoff_hz : the parallel
        decimation's cut-off (their 5 Hz; factor fs / (2.5 x cut-off)).
    cov : "hac" (default, the residuals of filtered data are correlated) or "classic" (their eq. 16).
    """
    dims: dict = {}
    q_m = check_array(q_m, "q_m", ("T",), dims=dims)
    tau = check_array(tau, "tau", ("T",), dims=dims)
    fs_hz = check_scalar(fs_hz, "fs_hz", positive=True)
    factor = max(int(fs_hz / (2.5 * decimate_cutoff_hz)), 1)
    ok = np.isfinite(q_m) & np.isfinite(tau)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))
    W_parts, y_parts = [], []
    min_len = 3 * 9 + 1 + 2 * factor
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a < min_len:
            continue
        W = np.column_stack([lowpass(q_m[a:b], fs_hz, cutoff_hz), np.ones(b - a)])
        y = lowpass(tau[a:b], fs_hz, cutoff_hz)
        Wd, yd = decimate_parallel(W, y, factor, fs_hz=fs_hz, cutoff_hz=decimate_cutoff_hz)
        W_parts.append(Wd)
        y_parts.append(yd)
    if not W_parts:
        raise InputError(None, "q_m, tau", f"a run of at least {min_len} samples without gaps", "none",
                         hint="record longer")
    W, y = np.vstack(W_parts), np.concatenate(y_parts)
    if np.ptp(W[:, 0]) <= 0:
        raise InputError(None, "q_m", "motor angles that vary with the applied force", "a constant angle",
                         hint="apply several force levels")
    off = "offkm" if source == "motor_torque" else "offkl"
    ls = ls_fit(W, y, (f"k_{joint}", f"{off}_{joint}"), cov=cov)
    return ClampedFit(joint=joint, source=source, k=float(ls.values[0]), k_std=float(ls.std[0]),
                      k_rel_std_pct=float(ls.rel_std_pct[0]), offset=float(ls.values[1]), offset_std=float(ls.std[1]),
                      offset_rel_std_pct=float(ls.rel_std_pct[1]), rel_error_pct=float(ls.rel_error_pct),
                      n_samples=int(ls.n_samples), ls=ls)


def identify_clamped(t, q_m, *, tau_m=None, wrench=None, t_wrench=None, model=None, frame: str = "tool",
                     q0=None, joints: Sequence[int] | None = None, names: Sequence[str] | None = None,
                     cutoff_hz: float = 10.0, decimate_cutoff_hz: float = 5.0, cov: str = "hac"
                     ) -> list[ClampedStiffness]:
    """Stiffness of the chosen joints by motor torques and/or by the measured wrench.

    Parameters
    ----------
    t : (T,) s, the controller's uniform clock; q_m : (T, n) rad, motor angles (link side)
    tau_m : (T, n) N m or None, motor torques (link side: current x drive gain)
    wrench : (S, 6) or None, F_e [fx fy fz mx my mz] (N, N m; unmeasured components 0) in `frame`
    t_wrench : (S,) s or None: the sensor's clock (default t); the wrench is interpolated onto t
        (NaN outside its span and across NaN samples)
    model : Pinocchio model, URDF path or MDH table (rows alpha, d, theta_offset, r) for the wrench
    q0 : (n,) rad, the Jacobian's configuration; default the motor angles at the sample of smallest
        motor torques (their eq. 3), or the first sample without torques
    joints : indices of the joints to identify (default all); names : n joint names
    """
    dims: dict = {}
    t = check_array(t, "t", ("T",), dims=dims, finite=True)
    q_m = check_array(q_m, "q_m", ("T", "n"), dims=dims, finite=True)
    n = q_m.shape[1]
    if tau_m is None and wrench is None:
        raise InputError(None, "tau_m, wrench", "motor torques, a wrench or both", "neither")
    if tau_m is not None:
        tau_m = check_array(tau_m, "tau_m", ("T", "n"), dims=dims)
    dt = np.diff(t)
    if t.size < 2 or not (dt > 0).all() or np.ptp(dt) > 1e-3 * dt.mean():
        raise InputError(None, "t", "a uniform, strictly increasing clock", f"steps {dt.min():.3g}..{dt.max():.3g} s")
    fs = 1.0 / float(dt.mean())
    names = tuple(names) if names is not None else tuple(f"j{j + 1}" for j in range(n))
    if len(names) != n:
        raise InputError(None, "names", f"{n} joint names", len(names))
    joints = tuple(range(n)) if joints is None else tuple(int(j) for j in joints)
    if any(j < 0 or j >= n for j in joints):
        raise InputError(None, "joints", f"indices in 0..{n - 1}", joints)
    tau_l = None
    if wrench is not None:
        pm = _model(model)
        if pm.nq != n:
            raise InputError(None, "model", f"a robot with the {n} joints of q_m", f"{pm.nq} joints")
        F = check_array(wrench, "wrench", (None, 6))
        if t_wrench is not None:
            tw = check_array(t_wrench, "t_wrench", (F.shape[0],))
            F = resample_to(tw, F, t)
        elif F.shape[0] != t.size:
            raise InputError(None, "wrench", f"{t.size} rows (one per sample of t) or t_wrench", F.shape[0])
        if q0 is None:
            load = np.nansum(np.abs(tau_m), axis=1) if tau_m is not None else np.nansum(np.abs(F), axis=1)
            q0 = q_m[int(np.nanargmin(load))]
        tau_l = external_torques(pm, q0, F, frame)
    out = []
    for j in joints:
        fm = fw = None
        if tau_m is not None:
            fm = _named(lambda: fit_clamped(q_m[:, j], tau_m[:, j], fs, joint=names[j], source="motor_torque",
                                            cutoff_hz=cutoff_hz, decimate_cutoff_hz=decimate_cutoff_hz, cov=cov),
                        names[j], "motor torques")
        if tau_l is not None:
            fw = _named(lambda: fit_clamped(q_m[:, j], tau_l[:, j], fs, joint=names[j], source="wrench",
                                            cutoff_hz=cutoff_hz, decimate_cutoff_hz=decimate_cutoff_hz, cov=cov),
                        names[j], "wrench")
        out.append(ClampedStiffness(name=names[j], motor=fm, wrench=fw))
    return out


def _named(fn, joint, what):
    try:
        return fn()
    except InputError as e:
        raise InputError(e.file, f"joint {joint} ({what}): {e.field}", e.expected, e.got, e.hint) from None


def _model(model):
    import pinocchio as pin

    if model is None:
        raise InputError(None, "model", "the robot (URDF or MDH table) to compute J(q0)^T F_e", "none")
    if isinstance(model, pin.Model):
        return model
    if isinstance(model, (list, tuple, np.ndarray)):
        return mdh_model(model)
    from .regressor import load_pin_model

    return load_pin_model(model)


@dataclass(frozen=True)
class ClampedExperiment:
    """A simulated clamped-end-effector run (see :func:`simulate_clamped`).

    t : (T,) s controller clock; q_m, tau_m : (T, n) motor angles and torques as logged
    t_wrench : (S,) s sensor clock; wrench : (S, 6) as logged (NaN where not acquired)
    q0 : (n,) the clamped configuration; k : (n,) true stiffnesses; tau_l : (T, n) true joint torques
    """

    t: np.ndarray
    q_m: np.ndarray
    tau_m: np.ndarray
    t_wrench: np.ndarray
    wrench: np.ndarray
    q0: np.ndarray
    k: np.ndarray
    tau_l: np.ndarray

    def __post_init__(self) -> None:
        freeze_arrays(self)


def simulate_clamped(model, q0, k, rng: np.random.Generator, *, frame: str = "tool", fz_levels=(-1e3, -2e3, -3e3,
                     -4e3, -5e3, -6e3, -3e3, 0.0), hold_s: float = 6.0, ramp_s: float = 1.0, fs_hz: float = 500.0,
                     fs_wrench_hz: float = 83.3, torque_sd: float = 100.0, force_sd: float = 20.0,
                     encoder_sd: float = 1e-7, torque_drift_sd: float = 0.0, force_drift_sd: float = 0.0,
                     drift_hz: float = 1.0, offm=None, drive_gain_error=None, wrench_gaps=()) -> ClampedExperiment:
    """The clamped experiment of Jubien et al. (2014), section 4.3, forward: the end-effector held at
    q0, force control steps f_z along the tool's z through `fz_levels` (N, held `hold_s`, ramps of
    `ramp_s`), the links static: tau_l = G(q0) + J(q0)^T F_e, q_m = q0 + tau_l / k,
    tau_m = (1 + drive_gain_error) (tau_l + offm) logged at fs_hz with white noise `torque_sd` (N m;
    current ripple), q_m with `encoder_sd` (rad); f_z logged at fs_wrench_hz with `force_sd` (N),
    NaN during `wrench_gaps` ((start, stop) s; their sensor was not acquired all the time).
    `torque_drift_sd` (N m) and `force_drift_sd` (N): noise band-limited below `drift_hz`, which
    the filters do not remove (the force loop's fluctuation, gear friction: the residual levels of
    their Tables 3-6 need such noise)."""
    import pinocchio as pin

    q0 = np.asarray(q0, dtype=np.float64)
    n = model.nq
    k = np.broadcast_to(np.asarray(k, dtype=np.float64), (n,))
    levels = np.concatenate([[0.0], np.asarray(fz_levels, dtype=np.float64)])
    knots_t, knots_f = [0.0], [0.0]
    for f in levels[1:]:
        knots_t += [knots_t[-1] + hold_s, knots_t[-1] + hold_s + ramp_s]
        knots_f += [knots_f[-1], f]
    knots_t.append(knots_t[-1] + hold_s)
    knots_f.append(knots_f[-1])
    T_end = knots_t[-1]
    t = np.arange(0.0, T_end, 1.0 / fs_hz)
    tw = np.arange(0.0, T_end, 1.0 / fs_wrench_hz)
    fz, fzw = np.interp(t, knots_t, knots_f), np.interp(tw, knots_t, knots_f)
    F = np.zeros((t.size, 6))
    F[:, 2] = fz
    data = model.createData()
    G = pin.computeGeneralizedGravity(model, data, q0)
    tau_l = G + external_torques(model, q0, F, frame)
    q_m = q0 + tau_l / k
    offm = np.zeros(n) if offm is None else np.broadcast_to(np.asarray(offm, float), (n,))
    gain = 1.0 + (np.zeros(n) if drive_gain_error is None else np.broadcast_to(np.asarray(drive_gain_error), (n,)))
    tau_m = gain * (tau_l + offm) + torque_sd * rng.standard_normal(tau_l.shape) \
        + torque_drift_sd * _slow_noise(rng, tau_l.shape, fs_hz, drift_hz)
    q_log = q_m + encoder_sd * rng.standard_normal(q_m.shape)
    Fw = np.zeros((tw.size, 6))
    Fw[:, 2] = fzw + force_sd * rng.standard_normal(tw.size) \
        + force_drift_sd * _slow_noise(rng, (tw.size,), fs_wrench_hz, drift_hz)
    for a, b in wrench_gaps:
        Fw[(tw >= a) & (tw < b)] = np.nan
    return ClampedExperiment(t=t, q_m=q_log, tau_m=tau_m, t_wrench=tw, wrench=Fw, q0=q0, k=k.copy(), tau_l=tau_l)


def _slow_noise(rng, shape, fs_hz, band_hz):
    """Unit-SD Gaussian noise band-limited below band_hz (zero-phase Butterworth of white noise)."""
    from scipy import signal

    sos = signal.butter(2, band_hz, fs=fs_hz, output="sos")
    x = signal.sosfiltfilt(sos, rng.standard_normal(shape), axis=0)
    return x / x.std(axis=0)
