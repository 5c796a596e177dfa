"""Two-step identification of one flexible joint (Lightcap and Banks (2007), §II.A, eq. 4-7).

Step 1 (Lightcap and Banks (2007), eq. 5-6): the sum of the link and motor equations has no stiffness term,

    I q'' - mglx sin q + mgly cos q + c sign(q') + v q' + J q_m'' + b q_m' = u,

linear in theta = (I, mglx, mgly, c, v, J, b); it is solved by least squares (Jubien, Abba and Gautier (2014), eq. 14-17).
Step 2 (Lightcap and Banks (2007), eq. 7): the spring torque is reconstructed from the link side,

    tau_s = I q'' - mglx sin q + mgly cos q + c sign(q') + v q',

and paired with the deflection delta = q_m - q; here the linear spring tau_s = k delta + tau0 is
fitted (other spring models: :mod:`mocapfj.ident.springs`). The one-step formulation (eq. 4, link
and motor equations stacked with k unknown) is solved too, as the baseline whose condition number
the two-step method lowers (Lightcap and Banks (2007), §II.A, §VI).

Signs and units: docs/conventions.md. Conditioning (Jubien, Abba and Gautier (2014), §3): q and q_m are low-passed
(zero-phase Butterworth, `cutoff_hz`) and differentiated by central differences; u and the
nonlinear columns (sin q, cos q, sign q') go through the same low-pass, so that the filtered step
of c sign(q') in u is matched by the column and not read as viscous friction; every column of
the observation matrix and the torque then go through the same low-pass (`parallel_cutoff_hz`)
and are decimated together, so the linear relation between them is kept while the noise the
second derivative amplifies is removed.

The link-angle zero. The pipeline aligns the mocap angle so that the mean deflection is zero
(`mocapfj.joints.sync.deflection`), so the q it gives is q_true + e with e = mean(delta_true).
Step 1 cannot see e: the gravity pair it returns is rotated, (A, B) = R(e) (mglx, mgly). Step 2
can: tau_s = k (delta + e), so the spring offset tau0 = k e. With `rezero=True` (default) the
gravity pair of step 1 and of the one-step fit is rotated back by e = tau0 / k (its covariance
with it), and the reconstructed tau_s is unchanged (it does not depend on the zero).

Coulomb sign. sign(q') is taken from the filtered velocity. Where |q'| < `sign_eps` rad/s the
sign is unreliable (noise, and the true friction is smooth there), so those samples, widened by
the parallel filter's length, are left out of every fit (not set to zero: a wrong sign biases c).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..types import LSResult
from .conditioning import check_signals, lowpass
from .equations import link_regressor
from .ls import ls_fit

__all__ = ["STEP1_NAMES", "SPRING_NAMES", "ONE_STEP_NAMES", "TwoStepResult", "step1_regressor",
           "one_step_regressor", "identify_two_step"]

STEP1_NAMES = ("I", "mglx", "mgly", "c", "v", "J", "b")
SPRING_NAMES = ("k", "tau0")
ONE_STEP_NAMES = STEP1_NAMES + SPRING_NAMES


@dataclass(frozen=True, eq=False)
class TwoStepResult:
    """Result of :func:`identify_two_step`.

    Attributes
    ----------
    step1 : LSResult
        theta = (I, mglx, mgly, c, v, J, b) of eq. (6): kg m^2, N m, N m, N m, N m s, kg m^2, N m s
        (gravity pair referred to the corrected zero when `rezero`).
    spring : LSResult
        (k, tau0) of tau_s = k delta + tau0: N m / rad, N m.
    one_step : LSResult
        (I, mglx, mgly, c, v, J, b, k, tau0) of eq. (4), the baseline.
    cond_two_step, cond_one_step : float
        Condition numbers of the step-1 and one-step observation matrices (columns unscaled).
    torque_rms : float
        RMS of u - W theta in step 1 over the fitted rows, N m (Lightcap and Banks (2007), §V "RMS errors").
    q_zero_rad : float
        e = tau0 / k, the zero of the given link angle minus the true zero, rad.
    t : (N,) float
        Times of the step-2 pairs, s (decimated time base).
    tau_s : (N,) float
        Reconstructed spring torque, N m (Lightcap and Banks (2007), eq. 7), parallel-filtered and decimated.
    delta : (N,) float
        Deflection q_m - q of the given angles, rad, same filtering; NaN-free.
    """

    step1: LSResult
    spring: LSResult
    one_step: LSResult
    cond_two_step: float
    cond_one_step: float
    torque_rms: float
    q_zero_rad: float
    t: np.ndarray
    tau_s: np.ndarray
    delta: np.ndarray


def step1_regressor(q, qd, qdd, qd_m, qdd_m, sgn=None) -> np.ndarray:
    """Observation matrix (T, 7) of eq. (6), columns (q'', -sin q, cos q, sign q', q', q_m'', q_m').

    All inputs (T,) in rad, rad/s, rad/s^2; `sgn` (T,) replaces sign(q') when given (e.g. tanh).
    The link equation's columns come from :func:`.equations.link_regressor`.
    """
    return np.column_stack([link_regressor(q, qd, qdd, sgn), qdd_m, qd_m])


def one_step_regressor(W1: np.ndarray, delta: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stacked eq. (4) from the eq. (6) matrix W1 (T, 7), delta (T,) rad and u (T,) N m.

    Link rows  (I, mglx, mgly, c, v | 0, 0 | -delta, -1) theta = 0;
    motor rows (0, ..., 0 | q_m'', q_m' | delta, 1) theta = u. Returns W (2T, 9), y (2T,).
    """
    T = W1.shape[0]
    one = np.ones(T)
    link = np.column_stack([W1[:, :5], np.zeros((T, 2)), -delta, -one])
    motor = np.column_stack([np.zeros((T, 5)), W1[:, 5:], delta, one])
    return np.vstack([link, motor]), np.concatenate([np.zeros(T), u])


def _rezero(res: LSResult, e: float) -> LSResult:
    """Rotate the (mglx, mgly) estimates from a zero shifted by e back: (mglx, mgly) = R(-e) (A, B)."""
    i, j = res.names.index("mglx"), res.names.index("mgly")
    c, s = np.cos(e), np.sin(e)
    Rm = np.eye(res.values.size)
    Rm[np.ix_([i, j], [i, j])] = [[c, s], [-s, c]]
    values = Rm @ res.values
    cov = Rm @ res.cov @ Rm.T
    std = np.sqrt(np.diag(cov))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(values != 0, 100.0 * std / np.abs(values), np.nan)
    return replace(res, values=values, cov=cov, std=std, rel_std_pct=rel)


def identify_two_step(t, q, q_m, u, *, fs_hz: float, cutoff_hz: float = 30.0, decimate: int = 1,
                   parallel_cutoff_hz: float | None = None, sign_eps: float = 0.01,
                   rezero: bool = True, trim_s: float = 1.0) -> TwoStepResult:
    """Two-step identification of one joint, Lightcap and Banks (2007), eq. (5)-(7), with eq. (4) as the baseline.

    Parameters
    ----------
    t : (T,) float
        Sample times, s, uniform at `fs_hz` (one clock for all signals, e.g. the controller's).
    q : (T,) float
        Link angle, rad (from mocap; its zero may be off by a constant, see the module docstring).
    q_m : (T,) float
        Motor angle on the link side, rad.
    u : (T,) float
        Motor torque on the link side, N m.
    fs_hz : float
        Sampling rate of t, Hz.
    cutoff_hz : float
        Low-pass on q and q_m before differentiation, Hz (mocap q'' needs 5-10 Hz).
    decimate : int
        Parallel decimation factor (Jubien, Abba and Gautier (2014), §3).
    parallel_cutoff_hz : float, optional
        Cut-off of the parallel filter on W and u, Hz; default 0.8 x the decimated Nyquist rate,
        never above `cutoff_hz`.
    sign_eps : float
        Samples with |q'| below this (rad/s) are left out (Coulomb sign unreliable).
    rezero : bool
        Refer the gravity pair to the zero found by step 2 (e = tau0 / k).
    trim_s : float
        Seconds dropped at both ends after filtering (filter transients), s.

    Returns
    -------
    TwoStepResult

    Raises
    ------
    InputError
        Bad shapes, NaN, non-uniform time; a parameter the trajectory does not excite (named).
    """
    t, q, q_m, u = check_signals(t, q, q_m, u, fs_hz)
    if int(decimate) != decimate or decimate < 1:
        raise InputError(None, "decimate", "a positive whole factor", decimate)
    decimate = int(decimate)
    fc2 = min(0.8 * fs_hz / (2 * decimate), cutoff_hz) if parallel_cutoff_hz is None else parallel_cutoff_hz
    qf = lowpass(q, fs_hz, cutoff_hz)
    qmf = lowpass(q_m, fs_hz, cutoff_hz)
    uf = lowpass(u, fs_hz, cutoff_hz)      # the same filter as on q, q_m: linear terms stay consistent
    dt = 1.0 / fs_hz
    qd = np.gradient(qf, dt)
    qdd = np.gradient(qd, dt)
    qd_m = np.gradient(qmf, dt)
    qdd_m = np.gradient(qd_m, dt)
    W1 = step1_regressor(qf, qd, qdd, qd_m, qdd_m)
    # u went through the low-pass; so must the nonlinear terms it holds (gravity, Coulomb sign), or
    # the filtered step of c sign(q') at a reversal would be read as viscous friction
    W1[:, 1:4] = lowpass(W1[:, 1:4], fs_hz, cutoff_hz)
    delta = qmf - qf

    # rows to leave out: near-zero velocity, widened by the parallel filter, and the ends
    bad = np.abs(qd) < sign_eps
    half = int(np.ceil(fs_hz / fc2))
    bad = np.convolve(bad.astype(float), np.ones(2 * half + 1), mode="same") > 0
    n_trim = int(round(trim_s * fs_hz))
    bad[:n_trim] = True
    bad[t.size - n_trim:] = True

    def parallel(x):  # the same low-pass on every column, then 1 sample in `decimate`
        return lowpass(x, fs_hz, fc2)[::decimate]

    keep = ~bad[::decimate]
    Wd = parallel(np.column_stack([W1, delta, uf]))[keep]
    td = t[::decimate][keep]
    W1d, deltad, ud = Wd[:, :7], Wd[:, 7], Wd[:, 8]

    step1 = ls_fit(W1d, ud, STEP1_NAMES)
    tau_s = W1d[:, :5] @ step1.values[:5]                                     # eq. (7), filtered
    spring = ls_fit(np.column_stack([deltad, np.ones_like(deltad)]), tau_s, SPRING_NAMES)
    Wo, yo = one_step_regressor(W1d, deltad, ud)
    one = ls_fit(Wo, yo, ONE_STEP_NAMES)
    e = spring["tau0"] / spring["k"]
    if rezero:
        step1 = _rezero(step1, e)
        one = _rezero(one, one["tau0"] / one["k"])
    return TwoStepResult(step1=step1, spring=spring, one_step=one, cond_two_step=step1.cond,
                         cond_one_step=one.cond, torque_rms=step1.residual_rms, q_zero_rad=float(e),
                         t=td, tau_s=tau_s, delta=deltad)
