"""Motor-first identification of one joint: a variant of Lightcap and Banks (2007), §II.A for mocap link angles.

Lightcap and Banks' step 1 solves the stiffness-free sum of the link and motor equations, in which the
link inertia I and the motor inertia J are told apart only by the deflection's acceleration
delta''. With mocap link angles (0.43 mrad noise at 250 Hz on pa10_joint2) delta'' is buried in
noise and I, J, v, b come out tens of percent off (tests/ident/test_twostep.py records it).

Here the motor equation comes first (eq. 4, second row),

    J q_m'' + b q_m' + k (q_m - q) + tau0 = u,

which uses only the motor's clean derivatives; the noisy link angle enters undifferentiated
through the deflection. It is linear in its signals, so the low-pass (`cutoff_hz`) is the same on
both sides and only sets the noise; it gives J, b, k and tau0 (tau0 = k e: the mocap angle's
zero was aligned by the mean deflection, so it is off by e, reported as `q_zero_rad`).

The spring torque then comes from the motor side, tau_s = u - J q_m'' - b q_m' (as clean as the
motor signals), and the link angle is rebuilt without differentiating mocap noise by a
complementary split at `split_hz`: below it the deflection is the mocap one (whatever the spring
is), above it tau_s / k (the joint's vibration, which the mocap noise hides),

    q_hat = q_m - [L(delta) + (1 - L)((tau_s - tau0) / k)],   delta = q_m - q + e (mocap, zero-corrected).

The link equation (eq. 4, first row), I q'' - mglx sin q + mgly cos q + c sign(q') + v q' = tau_s,
is solved on q_hat at `link_cutoff_hz` (20 Hz keeps the Coulomb steps sharp: a lower cut-off
distorts the nonlinear columns and biases I). (tau_s, delta_mocap) then feed the spring models of
`springs` as in Lightcap and Banks' step 2.

Precision. What limits it is the mocap angle's noise below 1 Hz (and, with a moving parent
cluster, its shared and systematic error): on pa10_joint2 (60 s, 0.2 mm markers) J and b scatter
by about 0.6 % from trial to trial and I, which the data fix through I + J, by about twice that;
the mean of ten trials is within 0.2 % of the truth (benchmarks/bench_identify.py).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..types import LSResult
from .conditioning import (check_signals, complementary, decimate_parallel, derivatives, lowpass, noise_gain,
                           white_noise_sd)
from .equations import LINK_NAMES, MOTOR_NAMES, link_regressor, motor_regressor
from .ls import ls_fit

__all__ = ["MOTOR_NAMES", "LINK_NAMES", "MotorFirstResult", "MotorStage", "motor_stage", "identify_motor_first",
           "white_noise_sd"]



@dataclass(frozen=True, eq=False)
class MotorFirstResult:
    """Result of :func:`identify_motor_first`.

    motor : LSResult of (J, b, k, tau0): kg m^2, N m s, N m / rad, N m.
    link : LSResult of (I, mglx, mgly, c, v): kg m^2, N m, N m, N m, N m s (gravity pair referred
        to the corrected zero).
    q_zero_rad : tau0 / k, the zero of the given link angle minus the spring's zero, rad (as in
        `twostep`): the link angle referred to the spring is q - q_zero_rad.
    t, tau_s, delta : the spring's samples for step 2 (s, N m, rad): motor-side spring torque and
        mocap deflection (referred to the corrected zero), both low-passed at `link_cutoff_hz`.
    hysteresis : the Bouc-Wen spring found in the motor equation, {k, alpha, beta, gamma,
        rms_gain_pct} (N m/rad, 1, 1/rad, 1/rad, %), or None.
    """

    motor: LSResult
    link: LSResult
    q_zero_rad: float
    t: np.ndarray
    tau_s: np.ndarray
    delta: np.ndarray
    hysteresis: dict | None = None

    def __getitem__(self, name: str) -> float:
        return self.motor[name] if name in self.motor.names else self.link[name]

    @property
    def names(self) -> tuple[str, ...]:
        return LINK_NAMES[:3] + LINK_NAMES[3:] + MOTOR_NAMES

    def values(self, names=("I", "mglx", "mgly", "c", "v", "J", "b")) -> np.ndarray:
        return np.array([self[n] for n in names])


@dataclass(frozen=True, eq=False)
class MotorStage:
    """Result of :func:`motor_stage`: motor (LSResult of J, b, k, tau0), hysteresis (dict or None),
    q_zero_rad (tau0 / k, rad), inner ((T,) bool: the samples inside the trims), and on all T
    samples: t (s), tau_s (motor-side spring torque, N m), q_hat (rebuilt link angle, rad, referred
    to the spring's zero), delta (mocap deflection referred to that zero, rad), all low-passed at
    the link cut-off."""

    motor: LSResult
    hysteresis: dict | None
    q_zero_rad: float
    inner: np.ndarray
    t: np.ndarray
    tau_s: np.ndarray
    q_hat: np.ndarray
    delta: np.ndarray


def motor_stage(t, q, q_m, u, *, fs_hz: float, cutoff_hz: float = 5.0, link_cutoff_hz: float = 20.0,
                split_hz: float = 2.0, decimate: int = 2, trim_s: float = 1.0, spring=None, q_zero_rad: float = 0.0,
                hysteresis: bool = True, min_gain_pct: float = 2.0, bias_compensation: bool = True) -> MotorStage:
    """The motor equation of one joint (J, b, k, tau0), its spring torque and the rebuilt link angle.

    The first half of :func:`identify_motor_first`, whose docstring documents the
    parameters (all but `sign_eps`) and the errors; the n-link identification (:mod:`.nlink`)
    runs it per joint.
    """
    t, q, q_m, u = check_signals(t, q, q_m, u, fs_hz)
    n_trim = int(round(trim_s * fs_hz))
    need = 2 * n_trim + int(np.ceil(4 * fs_hz / min(cutoff_hz, split_hz)))
    if t.size < need:
        raise InputError(None, "t", f"at least {need} samples ({need / fs_hz:.1f} s) for the filters and the trim",
                         f"{t.size} samples ({t.size / fs_hz:.2f} s)", hint="record longer or lower trim_s")
    inner = np.zeros(t.size, bool)
    inner[n_trim:t.size - n_trim] = True

    # motor equation: linear in its signals, one low-pass on every column and on u
    qmf, delta = lowpass(q_m, fs_hz, cutoff_hz), lowpass(q_m - q, fs_hz, cutoff_hz)
    qmd, qmdd = derivatives(qmf, fs_hz)
    f_spring = delta if spring is None else spring(delta + q_zero_rad, t)
    Wm_full = motor_regressor(qmd, qmdd, f_spring)
    u_c = lowpass(u, fs_hz, cutoff_hz)
    Wm, ym = decimate_parallel(Wm_full[inner], u_c[inner], decimate, fs_hz, min(cutoff_hz, 0.8 * fs_hz / (2 * decimate)))
    motor = ls_fit(Wm, ym, MOTOR_NAMES)
    if bias_compensation and spring is None:
        # errors in variables: the mocap noise in the deflection column attenuates k, and J and b
        # (nearly collinear with it) take up the difference; remove the noise's share of W^T W
        fc2 = min(cutoff_hz, 0.8 * fs_hz / (2 * decimate)) if decimate > 1 else None
        var = white_noise_sd(q, fs_hz) ** 2 * (noise_gain(fs_hz, cutoff_hz, fc2) if fc2 else noise_gain(fs_hz, cutoff_hz))
        motor = _compensated(Wm, ym, motor, 2, var)
    if spring is not None:   # report k as the scale times the shape's mean slope (the linear equivalent)
        slope = float(np.polyfit(delta[inner], f_spring[inner], 1)[0])
        i = MOTOR_NAMES.index("k")
        gain = np.ones(len(MOTOR_NAMES))
        gain[i] = slope
        motor = replace(motor, values=motor.values * gain, std=motor.std * gain, cov=motor.cov * np.outer(gain, gain))
    J, b, k, tau0 = motor.values
    if not k > 0:
        raise InputError(None, "k", "a positive stiffness from the motor equation", f"{k:.4g} N m/rad",
                         hint="check the signs of q, q_m and u (docs/conventions.md) and the deflection")
    e = -tau0 / k if spring is None else -float(q_zero_rad)   # the correction added to q

    qmf, uf = lowpass(q_m, fs_hz, link_cutoff_hz), lowpass(u, fs_hz, link_cutoff_hz)
    qmd, qmdd = derivatives(qmf, fs_hz)
    d_mocap = lowpass(q_m - q, fs_hz, link_cutoff_hz) - e

    def rebuilt(J, b, k, tau0):
        """Spring torque from the motor side; deflection by the complementary split."""
        tau_s = uf - J * qmdd - b * qmd
        d_lin = (tau_s - tau0) / k
        return tau_s, complementary(d_mocap, d_lin, fs_hz, split_hz)

    tau_s, d_hat = rebuilt(J, b, k, tau0)
    hyst = None
    if hysteresis and spring is None:
        hyst = _hysteretic_motor(Wm_full, u_c, d_hat, inner, fs_hz, cutoff_hz, decimate, motor, min_gain_pct)
        if hyst is not None:
            motor, hyst = hyst
            J, b, tau0 = motor["J"], motor["b"], motor["tau0"]
            tau_s, d_hat = rebuilt(J, b, hyst["k"], tau0)
    return MotorStage(motor=motor, hysteresis=hyst, q_zero_rad=float(-e), inner=inner, t=t, tau_s=tau_s,
                      q_hat=qmf - d_hat, delta=d_mocap)


def identify_motor_first(t, q, q_m, u, *, fs_hz: float, cutoff_hz: float = 5.0, link_cutoff_hz: float = 20.0,
                               split_hz: float = 2.0, decimate: int = 2, sign_eps: float = 0.01,
                               trim_s: float = 1.0, spring=None, q_zero_rad: float = 0.0,
                               hysteresis: bool = True, min_gain_pct: float = 2.0,
                               bias_compensation: bool = True) -> MotorFirstResult:
    """Identify J, b, k from the motor equation, then I, mglx, mgly, c, v from the link equation.

    Parameters
    ----------
    t, q, q_m, u : (T,) float
        Times (s, uniform at fs_hz, one clock), link angle from mocap (rad), motor angle / N
        (rad), motor torque x N (N m): the link side, docs/conventions.md.
    fs_hz : float
        Sampling rate, Hz.
    cutoff_hz : float
        Zero-phase low-pass of the motor equation (linear: sets only the noise), Hz.
    link_cutoff_hz : float
        Low-pass of the link equation and of the spring samples, Hz; below the Nyquist rate.
    split_hz : float
        Cross-over of the rebuilt link angle between mocap deflection and tau_s / k, Hz.
    decimate : int
        Parallel decimation of the motor equation (Jubien, Abba and Gautier (2014), §3).
    sign_eps : float
        Samples with |q'| below this (rad/s) are left out of the link equation.
    trim_s : float
        Seconds dropped at both ends (filter transients).
    spring : callable, optional
        A nonlinear spring shape f(delta, t) -> N m (e.g. a fitted `springs.SpringFit.predict`,
        t in s) for the motor equation, which then reads J q_m'' + b q_m' + s f(delta) + tau0
        = u, with delta = q_m - q + e low-passed as the equation and e = `q_zero_rad` (found by a
        first, linear pass); the reported k is s times the shape's mean slope. Default: the
        linear spring k delta, and e = tau0 / k.
    q_zero_rad : float
        The link-angle zero e of a first pass, for `spring`, rad (ignored without it).
    hysteresis : bool
        Test the motor equation for a hysteretic spring (see the module docstring) and, when it
        is found, identify J, b and the Bouc-Wen spring together (ignored with `spring`).
    min_gain_pct : float
        The hysteretic spring is kept when it lowers the motor equation's residual RMS by at
        least this much, %.
    bias_compensation : bool
        Remove the mocap noise's share from the normal equations of the motor equation (its
        deflection column is noisy: errors in variables). The noise SD is read from the top
        quarter of the link angle's spectrum (:func:`white_noise_sd`).

    Raises
    ------
    InputError
        Bad shapes, NaN, non-uniform time, a recording too short for the filters, a parameter
        the trajectory does not excite (named), a spring that does not stiffen (k <= 0).
    """
    st = motor_stage(t, q, q_m, u, fs_hz=fs_hz, cutoff_hz=cutoff_hz, link_cutoff_hz=link_cutoff_hz,
                     split_hz=split_hz, decimate=decimate, trim_s=trim_s, spring=spring, q_zero_rad=q_zero_rad,
                     hysteresis=hysteresis, min_gain_pct=min_gain_pct, bias_compensation=bias_compensation)
    qh, tau_s, inner = st.q_hat, st.tau_s, st.inner
    qd, qdd = derivatives(qh, fs_hz)
    # the Coulomb step gets the low-pass that tau_s (from filtered u) already had
    Wl = link_regressor(qh, qd, qdd, sgn=lowpass(np.sign(qd), fs_hz, link_cutoff_hz))
    keep = inner & (np.abs(qd) > sign_eps)
    link = ls_fit(Wl[keep], tau_s[keep], LINK_NAMES)
    return MotorFirstResult(motor=st.motor, link=link, q_zero_rad=st.q_zero_rad, t=st.t[inner], tau_s=tau_s[inner],
                            delta=st.delta[inner], hysteresis=st.hysteresis)


def _compensated(W: np.ndarray, y: np.ndarray, ls: LSResult, col: int, var: float) -> LSResult:
    """Least squares with the noise variance `var` of column `col` taken out of W^T W (bias-
    compensated LS for errors in variables); statistics as ls_fit's with the new solution."""
    A = W.T @ W
    A[col, col] -= W.shape[0] * var
    if not np.all(np.linalg.eigvalsh(A) > 0):
        return ls                       # the noise estimate exceeds the column's spread: keep LS
    x = np.linalg.solve(A, W.T @ y)
    r = y - W @ x
    rss = float(r @ r)
    cov = rss / (W.shape[0] - W.shape[1]) * np.linalg.inv(A)
    std = np.sqrt(np.diag(cov))
    dev = y - y.mean()
    return replace(ls, values=x, cov=cov, std=std, rel_std_pct=100 * std / np.abs(x),
                   residual_rms=float(np.sqrt(rss / W.shape[0])), rel_error_pct=100 * np.sqrt(rss / float(y @ y)),
                   r2=1 - rss / float(dev @ dev))


def _hysteretic_motor(W, u_c, d_hat, inner, fs_hz, cutoff_hz, decimate, linear: LSResult, min_gain_pct):
    """The motor equation with a Bouc-Wen spring, alpha k delta + (1 - alpha) k z(delta; beta, gamma).

    Linear in (J, b, alpha k, tau0, (1 - alpha) k) for given (beta, gamma), which are found by
    variable projection: a grid over beta = gamma, then Nelder-Mead on (ln beta, ln gamma). z
    runs along the rebuilt deflection d_hat (the vibration's minor loops included, without the
    mocap noise) and gets the equation's low-pass. Returns (LSResult with the linear equivalent
    k = alpha k + (1 - alpha) k, parameters dict) when the residual RMS is min_gain_pct % below
    both the linear and the cubic spring's, with a positive hysteretic stiffness, else None.
    """
    from scipy.optimize import minimize

    from .springs import bouc_wen_path

    stride = max(1, int(fs_hz // (8 * cutoff_hz)))       # z along d_hat at >= 8x the cut-off
    fc2 = min(cutoff_hz, 0.8 * fs_hz / (2 * decimate))
    names = ("J", "b", "k_lin", "tau0", "k_hyst")

    def solve(x):
        z = bouc_wen_path(d_hat, 1.0, np.exp(x[0]), np.exp(x[1]), stride)
        Wz = np.column_stack([W, lowpass(z, fs_hz, cutoff_hz)])[inner]
        Wd, yd = decimate_parallel(Wz, u_c[inner], decimate, fs_hz, fc2)
        return ls_fit(Wd, yd, names)

    # the elastic alternative a hysteretic spring must beat: a cubic spring (a stiffening or
    # softening spring also lowers the linear residual, and a Bouc-Wen loop can mimic it)
    # (nonlinear columns are formed on the full-band deflection, vibration included, then filtered)
    cubic = lowpass(d_hat ** 3, fs_hz, cutoff_hz)
    Wc, yc = decimate_parallel(np.column_stack([W, cubic])[inner], u_c[inner], decimate, fs_hz, fc2)
    elastic = min(linear.residual_rms, ls_fit(Wc, yc, ("J", "b", "k1", "tau0", "k3")).residual_rms)
    span = float(np.ptp(d_hat[inner]))
    grid = [np.log([c / 2, c / 2]) for c in np.geomspace(2.0 / span, 200.0 / span, 7)]
    fits = [solve(x) for x in grid]
    i = int(np.argmin([f.residual_rms for f in fits]))
    if not (fits[i]["k_hyst"] > 0 and fits[i].residual_rms <= (1 - min_gain_pct / 100) * elastic):
        return None
    opt = minimize(lambda x: solve(x).residual_rms, grid[i], method="Nelder-Mead",
                   options={"xatol": 0.02, "fatol": 1e-6 * linear.residual_rms, "maxfev": 40})
    best = solve(opt.x)
    if not (best["k_hyst"] > 0 and best.residual_rms <= (1 - min_gain_pct / 100) * elastic):
        return None
    beta, gamma = np.exp(opt.x)
    k = best["k_lin"] + best["k_hyst"]
    # report in the linear model's names: J, b, k (the equivalent stiffness alpha k + (1 - alpha) k), tau0
    T = np.array([[1, 0, 0, 0, 0], [0, 1, 0, 0, 0], [0, 0, 1, 0, 1], [0, 0, 0, 1, 0]], float)
    cov = T @ best.cov @ T.T
    values = T @ best.values
    std = np.sqrt(np.diag(cov))
    motor = replace(best, names=MOTOR_NAMES, values=values, cov=cov, std=std,
                    rel_std_pct=100 * std / np.abs(values))
    params = {"k": float(k), "alpha": float(best["k_lin"] / k), "beta": float(beta), "gamma": float(gamma),
              "rms_gain_pct": float(100 * (1 - best.residual_rms / linear.residual_rms))}
    return motor, params
