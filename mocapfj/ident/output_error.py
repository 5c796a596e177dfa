"""Output-error identification of one flexible joint: the link simulated on the recorded motor
motion and compared with both measured outputs, the mocap link angle and the motor torque.

Why. Every equation-error method has to put a measured link acceleration into a regressor: from
mocap (noise amplified twice by differentiation), or rebuilt from the motor-side spring torque
(which carries the torque noise into the inertia column, where it meets the same noise in the
output: an errors-in-variables bias that grows as the excitation slows and the torque gets
noisier, -18 % to -77 % on the link inertia in independent trials). Here no measured signal is
differentiated except the motor angle. This is the output-error idea of DIDIM (Gautier, Janot and
Vandanjon 2013) for a flexible joint: the motor angle is prescribed (its position loop is stiff),
the link is simulated, and the simulation is compared with what was measured. The Jacobian is the
link's sensitivity to its parameters along the simulated motion: the instruments of IDIM-IV
(Janot, Vandanjon and Gautier 2014), noise-free because they come from the simulation.

The model (Lightcap and Banks 2007, eq. 4; signs docs/conventions.md):

    I q'' + v q' + c s(q') + G(q) = k (q_m - q)             (link, simulated: q_sim)
    u = J q_m'' + b q_m' + k (q_m - q_sim)                    (motor torque)
    q_mocap = q_sim + z                                       (the mocap angle's zero z)

G(q) = -mglx sin q + mgly cos q; s the Coulomb law: sign(q') with sticking, or tanh(q' / eps),
eps fitted (from the best of a few starting values, :data:`FRICTION_SCALES`) when it fits better than the
neighbours. The link is integrated at the controller's rate by
:func:`mocapfj.dynamics.link_response` (second order, friction included) and taken at the mocap
instants by cubic Hermite interpolation.

Where the information is. The link and motor inertias are told apart by the joint's dynamics:
the torque's response to the motor's motion up to and around the resonances of the motor loop,
and the link's inertial deflection I q'' / k in the mocap angle. On a light joint the first
carries nearly all of it (comparing the torque only within three times the excitation band
raises the Cramer-Rao bound of I from 0.9 % to 7.8 % on one grid case), so the torque is compared
at the controller's rate, up to `band_hz` (default 0.4 x its rate, at most 60 Hz, decimated to
2.5 samples per period of the band), with a noise model instead of a narrow band: each output's
residual is whitened by an autoregressive filter fitted to it (Burg's method, order by AIC; the
torque's noise is white, coloured or quantised, and the motor angle's noise, differentiated twice
in J q_m'', rises as f^4), i.e. generalised least squares iterated to the fit. The mocap angle is
compared at every measured sample (gap-filled samples are left out).

The parameters minimise the whitened residuals' sum of squares (scipy's trust-region reflective
least squares; bounds I, J, k > 0 and c, v, b >= 0). The Jacobian of the simulation is by forward
differences of the kernel (six simulations of a few milliseconds each).

Uncertainty. Two covariances of the same estimate: the model's, (J^T J)^-1 of the whitened
Jacobian, and a sandwich with a Newey-West meat over time (:func:`.ls.sandwich_cov`: whatever
correlation or model error the whitened residuals still show). Each parameter's reported SD is the
larger of the two.
"""

from __future__ import annotations

import functools
import math
import os
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import lfilter, resample_poly

from ..dynamics.link_response import context_arrays, link_response, substeps
from ..errors import InputError
from ..types import LSResult
from .conditioning import check_signals, derivatives, lowpass, noise_floor_sd
from .determinacy import SPLIT_NOISE_CHI2
from .ls import sandwich_cov

__all__ = ["OE_NAMES", "FRICTION_SCALES", "OutputErrorResult", "identify_output_error",
           "excitation_bandwidth_hz", "burg_ar", "eiv_band_hz", "wiener_drive",
           "encoder_band_hz"]

OE_NAMES = ("I", "mglx", "mgly", "c", "v", "J", "b", "k", "z", "eps", "k3")
_LINK = ("I", "mglx", "mgly", "c", "v", "k")
_SENS = _LINK + ("eps", "k3")         # the kernel's sensitivities, in its order
_IDX = {n: i for i, n in enumerate(OE_NAMES)}
HYSTERESIS_CHI2 = 50.0
"""A hysteretic spring must lower the whitened cost by this much (seven SDs)..."""
HYSTERESIS_MIN_SHARE = 0.05
"""...with a hysteretic stiffness of at least this share of k."""
AR_ORDER_MAX = (4, 8)
"""Largest autoregressive orders of the mocap and torque noise models: enough for the broad
colours of the noise (a drive's filter, the encoder's differentiated noise, the band's edge), too
few to notch out the excitation's harmonics where a model error leaves structure."""
CUBIC_CHI2 = 25.0
"""The cubic spring term must lower the whitened cost by this much (five SDs) to be kept..."""
CUBIC_MIN_PCT = 5.0
"""...and change the stiffness by this many percent at the 95th percentile of the deflection."""
ENCODER_SHIFT_SDS = 2.0
"""The motor-angle noise's measured shift is removed when it exceeds this many SDs in some parameter."""
ENCODER_REFIT_SDS = 0.5
"""...measured by a refit when its Gauss-Newton estimate exceeds this many SDs."""
AMBIGUITY_CHI2 = 25.0
"""A second minimum within this much of the best's (whitened) cost widens the SDs: a quadratic
profile through both (five SDs apart at this cost) is what the data leave open."""
SPLIT_STARTS = (0.1, 0.3, 0.5, 0.7, 0.9)
"""Link shares I / (I + J) the searches over the inertia split start from."""
CLOCK_CHI2 = 25.0
"""An offset between the mocap and controller clocks, fitted with the dynamics, is reported when it
lowers the whitened cost by this much (five SDs) and is three of its SDs from zero."""
CLOCK_MIN_S = 1e-3
"""...and is at least this large: a quarter of a 250 Hz mocap frame, the accuracy of an ordinary
hardware sync. A mocap angle shifted by dt looks like the link's viscous lag v q' / k with
v = k dt, which only the torque tells apart; below a millisecond a small error of the link
model (pa10_joint2: an apparent -0.67 ms) shifts it as readily as the clocks do."""
CLOCK_MAX_S = 0.2
"""The largest clock offset the test fits, s."""
LINK_BAND_FRACTION = 0.6
"""The comparison band's upper limit as a fraction of the link's resonance sqrt(k / I) / 2 pi."""

_DEBUG = bool(os.environ.get("MOCAPFJ_OE_DEBUG"))


class _FitMemo:
    """A few recent linear-spring fits of identify_output_error by their inputs' content (thread-safe).
    `listeners`: callables told each new key once it is stored (discovery's worker starts the
    effect-free re-identification from it, mocapfj.discover.reident)."""

    def __init__(self, size: int = 4):
        import collections
        import threading

        self._d, self._size, self._lock = collections.OrderedDict(), size, threading.Lock()
        self.listeners = []

    def get(self, key):
        with self._lock:
            if key in self._d:
                self._d.move_to_end(key)
                return self._d[key]
        return None

    def put(self, key, value) -> None:
        with self._lock:
            self._d[key] = value
            while len(self._d) > self._size:
                self._d.popitem(last=False)
        for f in list(self.listeners):
            f(key)


LINEAR_FITS = _FitMemo()


def content_digest(*parts) -> bytes:
    """A digest of arrays, tuples, numbers and strings: the memo of steps 1-4 below is keyed by the
    arguments they depend on; discovery keys its re-identification started ahead the same way."""
    import hashlib

    h = hashlib.blake2b(digest_size=20)

    def feed(v):
        if v is None:
            h.update(b"N")
        elif isinstance(v, (tuple, list)):
            h.update(b"(%d" % len(v))
            for e in v:
                feed(e)
        elif isinstance(v, np.ndarray) or np.ndim(v) > 0:
            a = np.ascontiguousarray(v)
            h.update(str((a.dtype.str, a.shape)).encode())
            h.update(a.tobytes())
        else:
            h.update(repr(float(v) if isinstance(v, (int, float, np.number)) and not isinstance(v, bool) else v).encode())

    for v in parts:
        feed(v)
    return h.digest()
# A trial whose link resonance needs more than SUBSTEP_GROWTH x the substeps per sample of the
# problem's first simulation (and more than MIN_SUBSTEP_CAP) counts as diverged: 16 x the
# resonance is 256 x the stiffness-to-inertia ratio, far outside what the data can support.
SUBSTEP_GROWTH = 16
MIN_SUBSTEP_CAP = 64
FRICTION_SCALES = (0.003, 0.01, 0.03, 0.1)
"""Starting points of the tanh law's eps, as fractions of the motor velocity's RMS (each fitted
briefly, the best refined)."""
EPS_RANGE_RAD_S = (1e-4, 1.0)
"""Bounds of eps, rad/s."""


@dataclass(frozen=True, eq=False)
class OutputErrorResult:
    """Result of :func:`identify_output_error`.

    fit : LSResult of OE_NAMES (kg m^2, N m, N m, N m, N m s, kg m^2, N m s, N m/rad, rad); `cov`
        and `std` are the reported ones (per parameter the larger of the model's and the
        sandwich's; NaN for a parameter held at a bound); `residual_rms` is the torque
        residual's in its band, N m.
    cov_model, cov_sandwich : (9, 9) the two covariances (module docstring).
    at_bound : names of parameters held at a bound (c, v or b at 0): the data push them below.
    friction_scale : eps of the Coulomb law chosen (0: sign with sticking), rad/s.
    band_hz : the torque comparison band, Hz.
    sigma_q, sigma_u : the residuals' SDs: mocap angle (rad, per sample) and torque (N m, in band).
    ar_q, ar_u : the whitening filters' coefficients (1, a_1, ..., a_p) of the two residuals.
    t, delta_sim, tau_s, delta_mocap, tau_s_motor : on the mocap samples inside the trims: times
        (s), the simulated deflection (rad), the spring torque k delta_sim (N m), the measured
        deflection q_m - (q_mocap - z) and u - J q_m'' - b q_m' (the motor side's spring torque,
        N m), both low-passed at 10 Hz, for the spring model.
    scores : {eps: whitened cost} of every Coulomb law tried.
    n_iter : least-squares evaluations in all.
    hysteresis : the score test's finding of a hysteretic spring (:func:`_hysteresis_test`), or None.
    spring_r2 : the motor side's spring torque against the fitted spring along the simulated
        deflection (both low-passed at 10 Hz, offset removed): coefficient of determination.
    motor_noise_rad : the motor angle's white noise per controller sample (its spectrum's floor;
        0 at or below its quantisation), rad.
    split_noise_chi2 : how much that noise's expected share of the whitened cost changes over
        link shares I / (I + J) of 0.02-0.98 (:func:`drive_noise_cost`).
        Above SPLIT_NOISE_CHI2 the SDs of I and J are those of a split uniform over I + J.
    clock : the clock-offset test (:func:`_clock_offset_fit`): {"offset_s", "sd_s" (the fit's SD
        and CLOCK_MIN_S combined), "sd_fit_s" (the fit's alone), "chi2" (the cost's drop), "found",
        "applied", "moves" ({name: how far the offset moves it}), "per_ms"}, or None when not
        tested.
    """

    fit: LSResult
    cov_model: np.ndarray
    cov_sandwich: np.ndarray
    at_bound: tuple[str, ...]
    friction_scale: float
    band_hz: float
    sigma_q: float
    sigma_u: float
    ar_q: np.ndarray
    ar_u: np.ndarray
    t: np.ndarray
    delta_sim: np.ndarray
    tau_s: np.ndarray
    delta_mocap: np.ndarray
    tau_s_motor: np.ndarray
    scores: dict
    n_iter: int
    hysteresis: dict | None = None
    spring_r2: float = float("nan")
    motor_noise_rad: float = 0.0
    split_noise_chi2: float = 0.0
    clock: dict | None = None

    def __getitem__(self, name: str) -> float:
        return self.fit[name]


def excitation_bandwidth_hz(q_m: np.ndarray, fs_hz: float, share: float = 0.99,
                           core: float = 0.95, spread: float = 3.0) -> float:
    """Frequency below which `share` of the motor velocity's power lies, Hz (the excitation's
    bandwidth; the velocity weights the trajectory's harmonics as the inertia column does), at
    most `spread` x the frequency below which `core` of it lies.

    The cap: the motor also carries what the link does back to it. A transmission error whose
    tooth frequency met a heavy joint's resonance (12.5 Hz) put 1-5 % of the motor velocity's
    power near 15 Hz, and 99 % of it lay below 14.6 Hz for an excitation whose 95 % lay below
    0.62 Hz: the first fits ran in a 44 Hz band full of that ringing, and the spot identification
    took 350 s to collapse the total inertia from 269 to 7.9 kg m^2 (hinge grid seed 33000, case
    003; with the cap 67 s, to no better values: the ringing is the effect discovery names). A
    designed excitation's power rises to its top frequency: in the other 161 trials of hinge grid
    seeds 33000-35000 the two points are at most 1.8 x apart, and the cap changes none of them."""
    qd = np.gradient(np.asarray(q_m, dtype=np.float64)) * fs_hz
    P = np.abs(np.fft.rfft(qd - qd.mean())) ** 2
    f = np.fft.rfftfreq(qd.size, 1.0 / fs_hz)
    c = np.cumsum(P)

    def at(s):
        return float(f[min(int(np.searchsorted(c, s * c[-1])), f.size - 1)])

    return min(at(share), spread * at(core))


def burg_ar(x: np.ndarray, max_order: int) -> tuple[np.ndarray, float]:
    """An autoregressive model of x (n,) by Burg's method, its order chosen by AIC up to
    `max_order`: (a (p + 1,) with a[0] = 1, the innovation variance). lfilter(a, 1, x) whitens x."""
    x = np.asarray(x, dtype=np.float64) - np.mean(x)
    n = x.size
    f, b = x[1:].copy(), x[:-1].copy()
    a = np.array([1.0])
    E = float(x @ x) / n
    best = (n * math.log(max(E, 1e-300)), a.copy(), E)
    for m in range(1, max_order + 1):
        den = float(f @ f + b @ b)
        if den <= 0:
            break
        k = -2.0 * float(b @ f) / den
        a = np.concatenate([a, [0.0]])
        a = a + k * a[::-1]
        E *= 1.0 - k * k
        aic = n * math.log(max(E, 1e-300)) + 2 * m
        if aic < best[0]:
            best = (aic, a.copy(), E)
        f, b = f[1:] + k * b[1:], b[:-1] + k * f[:-1]
        if f.size < 2:
            break
    return best[1], best[2]


def wiener_drive(q_m: np.ndarray, fs_hz: float) -> np.ndarray:
    """The motor angle with its white noise filtered out where the noise dominates, for driving
    the simulated link: the zero-phase Wiener gain max(0, 1 - N / P(f)), P the angle's Welch
    spectrum (4 s Hann windows) and N the white floor (:func:`.conditioning.noise_floor_sd`),
    applied by FFT after removing the straight line through the ends and mirroring (no edge step).
    The link's resonance amplifies what drives it by its quality factor (k / (v omega), 10-100):
    an encoder's noise of a few 1e-5 rad, raw, rings the simulated link where the real one, driven
    by the true motion, does not, and the fit moves the inertia split to damp that ringing (about
    -50 % on I in grid cases). The unchanged angle when it shows no noise above its quantisation."""
    from scipy.signal import welch

    q_m = np.asarray(q_m, dtype=np.float64)
    sm = noise_floor_sd(q_m, fs_hz)
    n = q_m.size
    if not sm > 0 or n < 64:
        return q_m
    nper = int(min(n, max(64, 4 * fs_hz)))
    f, P = welch(q_m, fs=fs_hz, nperseg=nper)
    N = sm ** 2 / (fs_hz / 2)
    gain = np.clip(1.0 - N / np.maximum(P, 1e-300), 0.0, 1.0)
    line = q_m[0] + (q_m[-1] - q_m[0]) * np.arange(n) / max(n - 1, 1)
    r = q_m - line
    ext = np.concatenate([r, -r[::-1]])             # odd mirror: continuous at the joins (both ends 0)
    F = np.fft.rfft(ext)
    fe = np.fft.rfftfreq(ext.size, 1.0 / fs_hz)
    F *= np.interp(fe, f, gain)
    return np.fft.irfft(F, ext.size)[:n] + line


class _Data:
    """The measurements on their own instants: the controller's (t_c uniform at fs_c: q_m, its
    derivatives, u) and the mocap's (q at t_q, measured mask), and the Hermite weights that take
    a controller-rate simulation to the mocap instants."""

    def __init__(self, t_c, q_m, u, fs_c, t_q, q, measured, trim_s, band_hz, drive=None, context=None):
        self.fs = fs_c
        # a robot's joint: its context (I_t, mglx_t, mgly_t, tau_t) at the controller's samples
        self.context = context
        self.I_ctx = (float(np.min(context[0])), float(np.mean(context[0]))) if context is not None else (0.0, 0.0)
        self.q_m, self.u = q_m, u
        self.qd_m, self.qdd_m = derivatives(q_m, fs_c)
        # the simulated link's drive: the motor angle without the noise that would ring it
        self.q_drive = q_m if drive is None else drive
        self.qd_drive = self.qd_m if drive is None else derivatives(drive, fs_c)[0]
        trim = int(round(trim_s * fs_c))
        self.trim = trim
        # the torque channel: band-limited and decimated (none when the band is the whole rate)
        self.band = min(float(band_hz), 0.45 * fs_c)
        stride = max(1, int(fs_c // (2.5 * self.band)))
        # the band is taken in two stages: a polyphase FIR decimation by m (to about twice the final
        # rate), then the zero-phase Butterworth at that rate (the same linear filter on data and
        # model, so the comparison is consistent; 10x cheaper than filtering at the full rate)
        self.m = max(1, stride // 2)
        self.stride = self.m * max(1, stride // self.m)
        edge = trim + (int(np.ceil(2.0 * fs_c / self.band)) if self.stride > 1 else 0)
        edge = self.m * int(np.ceil(edge / self.m))
        self.iu = np.arange(edge, t_c.size - edge, self.stride)
        self.iu_m = self.iu // self.m
        self.u_b, self.qdd_b, self.qd_b, self.qm_b = (self.band_of(x) for x in (u, self.qdd_m, self.qd_m, q_m))
        # the mocap channel: samples inside the trims, each between two controller samples; in
        # the same band as the torque (low-passed and decimated) when that is below its rate
        pos = (t_q - t_c[0]) * fs_c
        inside = (pos >= trim) & (pos <= t_c.size - 1 - trim)
        i = np.minimum(np.floor(pos[inside]).astype(np.int64), t_c.size - 2)
        s = pos[inside] - i
        self.i0 = i
        self.pos = pos[inside]
        self.h = self._hermite(s)
        self.fs_q = 1.0 / float(np.median(np.diff(t_q)))
        self.stride_q = max(1, int(self.fs_q // (2.5 * self.band))) if self.band < 0.4 * self.fs_q else 1
        edge_q = int(np.ceil(2.0 * self.fs_q / self.band)) if self.stride_q > 1 else 0
        self.iq = np.arange(edge_q, i.size - edge_q, self.stride_q)
        self.q = self.q_band(q[inside])
        filled = ~measured[inside]
        if self.stride_q > 1:
            # a decimated sample is measured unless a gap fills much of its span; the low-pass
            # spreads a long gap's straight line over a period of the band on either side
            frac = np.convolve(filled.astype(float), np.ones(self.stride_q) / self.stride_q, mode="same")
            reach = int(np.ceil(self.fs_q / self.band))
            run = np.convolve(filled.astype(float), np.ones(reach), mode="same") >= reach   # inside a long gap
            near = np.convolve(run.astype(float), np.ones(4 * reach + 1), mode="same") > 0
            filled = (frac > 0.5) | near
        self.filled = filled[self.iq]
        self.t_c = t_c

    def q_band(self, x):
        """A mocap-instant series (inner samples) in the band, at the kept rows."""
        if self.stride_q == 1:
            return np.asarray(x)[self.iq]
        return lowpass(x, self.fs_q, self.band)[self.iq]

    def band_of(self, x):
        if self.stride == 1:
            return np.asarray(x)[self.iu]
        if self.m > 1:
            x = resample_poly(x, 1, self.m, axis=0, window=_decimation_fir(self.m))
        return lowpass(x, self.fs / self.m, self.band)[self.iu_m]

    def _hermite(self, s):
        fs_c = self.fs
        return np.column_stack([2 * s**3 - 3 * s**2 + 1, (s**3 - 2 * s**2 + s) / fs_c, -2 * s**3 + 3 * s**2,
                                (s**3 - s**2) / fs_c])

    def at_mocap(self, q, w, dt: float = 0.0):
        """q (T_c, ...) and w its derivative at the mocap instants (cubic Hermite), or at those
        instants + dt s on the controller's clock (an undeclared clock offset)."""
        if dt == 0.0:
            i, h = self.i0, self.h
        else:
            pos = self.pos + dt * self.fs
            i = np.clip(np.floor(pos).astype(np.int64), 0, q.shape[0] - 2)
            h = self._hermite(np.clip(pos - i, 0.0, 1.0))
        if q.ndim > 1:
            h = h[:, :, None]
        return h[:, 0] * q[i] + h[:, 1] * w[i] + h[:, 2] * q[i + 1] + h[:, 3] * w[i + 1]


@functools.lru_cache(maxsize=32)
def _decimation_fir(m: int) -> np.ndarray:
    """The anti-alias FIR of scipy's resample_poly(x, 1, m), designed once per m (it designs it
    on every call otherwise): firwin(20 m + 1, 1 / m, Kaiser beta 5); shared, not to be modified."""
    from scipy.signal import firwin

    h = firwin(2 * 10 * m + 1, 1.0 / m, window=("kaiser", 5.0))
    return h


class _Problem:
    """The whitened residuals of one joint under one Coulomb law ("sign" or "tanh"), and their
    Jacobian, as functions of the free parameters (eps is fixed at 0 under the sign law)."""

    def __init__(self, data: _Data, law: str, scale: np.ndarray, noise=None, max_phase: float = 0.05,
                 cubic: bool = False, dt: float = 0.0, omega_cap: float = math.inf):
        self.d, self.law, self.scale, self.max_phase = data, law, scale, max_phase
        self.free = np.ones(len(OE_NAMES), bool)
        self.cubic = cubic
        if law == "sign":
            self.free[_IDX["eps"]] = False
        if not cubic:
            self.free[_IDX["k3"]] = False
        self.set_noise(noise or ((np.array([1.0]), 1.0), (np.array([1.0]), 1.0)))
        self._cache = (None, None)
        self._x = np.zeros(len(OE_NAMES))
        self.dt = float(dt)           # the mocap instants' offset on the controller clock, s
        self._n_first = None          # substeps per sample of the first simulation (_link)
        self.omega_cap = omega_cap    # the highest link resonance simulated, rad/s (_link)

    def sibling(self, data: _Data | None = None, noise=None, max_phase: float = 0.05, dt: float | None = None,
                omega_cap: float | None = None):
        """A problem of the same identification (law, scale, spring terms, resonance cap) on `data`
        (default this one's), under `noise`, at the clock offset `dt` and resonance cap `omega_cap`
        (default this one's)."""
        return _Problem(self.d if data is None else data, self.law, self.scale, noise, max_phase=max_phase,
                        cubic=self.cubic, dt=self.dt if dt is None else dt,
                        omega_cap=self.omega_cap if omega_cap is None else omega_cap)

    def set_noise(self, noise):
        """noise = ((a_q, sd_q), (a_u, sd_u)): the whitening filters and innovation SDs."""
        (self.a_q, self.s_q), (self.a_u, self.s_u) = noise
        p = self.a_q.size - 1
        bad = np.convolve(self.d.filled.astype(float), np.ones(p + 1))[:self.d.filled.size] > 0
        self.keep_q = ~bad
        self.keep_q[:p] = False

    def full(self, xf) -> np.ndarray:
        x = self._x.copy()
        x[self.free] = xf
        if self.law == "sign":
            x[_IDX["eps"]] = 0.0
        if not self.cubic:
            x[_IDX["k3"]] = 0.0
        return x

    def _link(self, x, sens=False):
        p = dict(zip(OE_NAMES, x))
        # A trial step towards a vanishing inertia or a huge stiffness raises the resonance, and the
        # kernel's substeps with it, without bound (an hour for one simulation of a light joint):
        # a resonance more than SUBSTEP_GROWTH x the first one simulated is treated as diverged.
        # The first simulation of each problem sets its cap, and the identification's start sets
        # `omega_cap` for all its problems: without it, each fit starting where the last one stopped
        # ratcheted the inertia down by 256 x per fit, to 2e-10 kg m^2 on a light cobot whose link
        # inertia its data barely determine (178 000 substeps per sample: a re-identification still
        # running after 27 minutes; hinge grid seed 23000).
        I_min = p["I"] + self.d.I_ctx[0]
        n = substeps(I_min, p["k"], 1.0 / self.d.fs, self.max_phase) if I_min > 0 and p["k"] > 0 else 1
        if self._n_first is None:
            self._n_first = n
        too_fast = I_min > 0 and p["k"] > 0 and math.sqrt(p["k"] / I_min) > self.omega_cap
        if too_fast or n > max(MIN_SUBSTEP_CAP, SUBSTEP_GROWTH * self._n_first):
            T = self.d.q_drive.size
            nan = np.full(T, np.nan)
            return (nan, nan, np.full((T, 8), np.nan), np.full((T, 8), np.nan)) if sens else (nan, nan)
        return link_response(self.d.q_drive, self.d.fs, eps=p["eps"], k3=p["k3"], qd_m=self.d.qd_drive, sensitivities=sens,
                             max_phase=self.max_phase, context=self.d.context, **{n: p[n] for n in _LINK})

    def simulate(self, x):
        x = np.asarray(x, dtype=np.float64)
        key = x.tobytes()
        if self._cache[0] != key:
            self._cache = (key, self._link(x))
        return self._cache[1]

    def raw(self, x):
        """Unwhitened residuals at the full parameter vector x: mocap angle (rad) and torque
        (N m), each in the band at its kept rows."""
        x = np.asarray(x, dtype=np.float64)
        q_s, w_s = self.simulate(x)
        if not (np.isfinite(q_s).all() and np.isfinite(w_s).all()):
            # the simulation diverged at a trial step (a stiff, light link at the edge of the
            # kernel's stability): a residual the optimiser rejects, not a crash
            return np.full(self.d.q.shape, 1.0), np.full(self.d.u_b.shape, 1e3 * (np.abs(self.d.u_b).max() + 1.0))
        r_q = self.d.q - self.d.q_band(self.d.at_mocap(q_s, w_s, self.dt)) - x[_IDX["z"]]
        r_u = self.d.u_b - (x[_IDX["J"]] * self.d.qdd_b + x[_IDX["b"]] * self.d.qd_b + self._spring_b(x, q_s))
        return r_q, r_u

    def _spring_b(self, x, q_s):
        """The spring torque k delta + k3 delta^3 (delta = q_m - q_sim) in the band."""
        tau = x[_IDX["k"]] * (self.d.qm_b - self.d.band_of(q_s))
        if x[_IDX["k3"]] != 0.0:
            tau = tau + x[_IDX["k3"]] * self.d.band_of((self.d.q_m - q_s) ** 3)
        return tau

    def _white(self, r_q, r_u):
        wq = lfilter(self.a_q, [1.0], r_q, axis=0)[self.keep_q] / self.s_q
        wu = lfilter(self.a_u, [1.0], r_u, axis=0)[self.a_u.size - 1:] / self.s_u
        return wq, wu

    def fun(self, xf):
        return np.concatenate(self._white(*self.raw(self.full(xf))))

    def jac_full(self, x):
        """The whitened Jacobian with respect to every parameter (rows as fun's)."""
        x = np.asarray(x, dtype=np.float64)
        q_s, w_s, Sq, Sw = self._link(x, sens=True)           # d q_sim / d (link parameters, eps, k3)
        if not (np.isfinite(Sq).all() and np.isfinite(Sw).all() and np.isfinite(q_s).all()):
            raise FloatingPointError("the link's simulation diverged")
        Sm = self.d.q_band(self.d.at_mocap(Sq, Sw, self.dt))
        delta = self.d.q_m - q_s
        k, k3 = x[_IDX["k"]], x[_IDX["k3"]]
        cols = [j for j, n in enumerate(_SENS) if self.free[_IDX[n]]]         # only what is fitted
        Sc = Sq[:, cols]
        Sb = self.d.band_of(Sc * (k + 3.0 * k3 * delta ** 2)[:, None] if k3 != 0.0 else k * Sc)
        Jq = np.zeros((Sm.shape[0], len(OE_NAMES)))
        Ju = np.zeros((Sb.shape[0], len(OE_NAMES)))
        for i, j in enumerate(cols):
            n = _SENS[j]
            Jq[:, _IDX[n]] = -Sm[:, j]
            Ju[:, _IDX[n]] = Sb[:, i]
        Ju[:, _IDX["k"]] -= self.d.qm_b - self.d.band_of(q_s)
        if self.free[_IDX["k3"]]:
            Ju[:, _IDX["k3"]] -= self.d.band_of(delta ** 3)
        Ju[:, _IDX["J"]] = -self.d.qdd_b
        Ju[:, _IDX["b"]] = -self.d.qd_b
        Jq[:, _IDX["z"]] = -1.0
        return np.vstack(self._white(Jq, Ju))

    def jac(self, xf):
        try:
            return self.jac_full(self.full(xf))[:, self.free]
        except FloatingPointError:      # only at a step the optimiser will reject (raw's residual)
            return np.zeros((self.fun(xf).size, int(self.free.sum())))

    def time_index(self) -> np.ndarray:
        """Each whitened row's controller sample (for the sandwich's autocovariances)."""
        iq = self.d.i0[self.d.iq][self.keep_q]
        iu = self.d.iu[self.a_u.size - 1:]
        return np.concatenate([iq, iu])


def _bounds(d: _Data | None = None):
    """(lower, upper) bounds in OE_NAMES order. A robot's joint (`d` with a context): its own
    inertia, added to the robot's, may be negative (the URDF's link heavier than the real one),
    the total kept above a tenth of the robot's least."""
    lo = np.full(len(OE_NAMES), -np.inf)
    hi = np.full(len(OE_NAMES), np.inf)
    for n in ("I", "J", "k"):
        lo[_IDX[n]] = 0.0
    if d is not None and d.context is not None:
        lo[_IDX["I"]] = -0.9 * d.I_ctx[0]
    for n in ("c", "v", "b"):
        lo[_IDX[n]] = 0.0
    lo[_IDX["eps"]], hi[_IDX["eps"]] = EPS_RANGE_RAD_S
    return lo, hi


def _inside(prob: _Problem, x) -> np.ndarray:
    """The free parameters of x strictly inside the bounds (I, J, k > 0; one at 0 just above it)."""
    lo, hi = _bounds(prob.d)
    f = prob.free
    return np.minimum(np.maximum(x[f], lo[f] + 1e-6 * prob.scale[f]), np.where(np.isfinite(hi[f]), 0.999 * hi[f], np.inf))


def _solve(prob: _Problem, x0, max_nfev: int, ftol: float = 1e-10):
    """Trust-region reflective least squares from x0 (full vector) over the free parameters:
    (x, cost, evaluations)."""
    from scipy.optimize import least_squares

    lo, hi = _bounds(prob.d)
    x0 = np.array(x0, dtype=np.float64)
    prob._x = x0.copy()
    f = prob.free
    xf = _inside(prob, x0)
    res = least_squares(prob.fun, xf, jac=prob.jac, bounds=(lo[f], hi[f]), method="trf", x_scale="jac",
                        ftol=ftol, xtol=1e-9, gtol=1e-10, max_nfev=max_nfev)
    return prob.full(res.x), float(res.fun @ res.fun), int(res.nfev)


START_INERTIA_SHARE = 0.05
"""When the start's rigid regression gives a negative total inertia on a torque that puts power into
the joint, its inertia's torque is held at least at this share of the torque's RMS (:func:`_initial`)."""


def _initial(q, q_m, u, fs_hz, band_hz, trim, context=None):
    """A consistent start without simulation, linear in both steps, no noisy regressor.

    1. The sum of the two equations with q ~ q_m (the rigid joint; no mocap in it) gives the
       total inertia A = I + J and damping B = b + v, the Coulomb level c and gravity from the
       torque: u = A q_m'' + B q_m' + c s(q_m') + G(q_m).
    2. The link equation solved for the deflection, quasi-statically (q'' ~ q_m''):
       q_m - q_mocap = (I q_m'' + v q_m' + [c s + G]) / k - z, with [c s + G] from step 1: linear
       in (I / k, v / k, 1 / k, z), the mocap noise in the output only.
    J = A - I, b = B - v, each of I, v kept within 5-95 % of its total.

    A robot's joint (`context` (I_t, mglx_t, mgly_t, tau_t) at the samples of q): the robot's
    terms are known, so they are taken out of the torque in step 1 and put in the deflection's
    known part in step 2; I, mglx, mgly are then the joint's own, added to the robot's, and I is
    kept within -0.9 min(I_t) and 0.95 A.
    """
    qd, qdd = derivatives(lowpass(q_m, fs_hz, min(0.4 * fs_hz, max(4.0 * band_hz, 20.0))), fs_hz)
    sl = slice(trim, q.size - trim)

    def lp(x):
        return lowpass(x, fs_hz, band_hz)[sl]

    sgn = np.tanh(qd / (0.02 * max(float(np.std(qd)), 1e-9)))
    Ws = lp(np.column_stack([qdd, qd, sgn, -np.sin(q_m), np.cos(q_m)]))
    robot = 0.0
    if context is not None:
        # the robot's inertial, gravity and coupling torque on the link, with q ~ q_m
        I_t, gx, gy, tau_t = context
        robot = lp(I_t * qdd - gx * np.sin(q_m) + gy * np.cos(q_m) - tau_t)
    ub = lp(u) - robot
    from .ls import ls_fit

    # ls_fit names the columns the motion does not excite (a motor standing still: all of them)
    A, B, c, mglx, mgly = ls_fit(Ws, ub, ("I + J", "b + v", "c", "mglx", "mgly")).values
    if not A > 0:
        # a sign error in q_m or u makes the torque put power out of a joint that dissipates it;
        # a torque that puts power in with a negative inertia is a friction the start's
        # Coulomb-viscous law lacks (a heavy joint whose breakaway friction equals its Coulomb
        # level sticks at each reversal, where the motor decelerates: I + J = -50.8 kg m^2 for 202;
        # hinge grid seed 39000, case 004): the start then holds the inertia's torque at
        # START_INERTIA_SHARE of the torque's RMS, the least the fits below refine
        power = float(np.mean(ub * Ws[:, 1]))
        if not power > 0:
            raise InputError(None, "u, q_m", "a motor torque that accelerates the joint (positive total inertia) "
                             "and puts power into it", f"I + J = {A:.4g} kg m2, mean power {power:.3g} W",
                             hint="check the signs of q_m and u (docs/conventions.md)")
        from scipy.optimize import lsq_linear

        lo = np.full(Ws.shape[1], -np.inf)
        lo[0] = START_INERTIA_SHARE * float(np.sqrt(np.mean(ub ** 2)) / max(np.sqrt(np.mean(Ws[:, 0] ** 2)), 1e-300))
        A, B, c, mglx, mgly = lsq_linear(Ws, ub, bounds=(lo, np.inf)).x
    known = Ws[:, 2:] @ np.array([c, mglx, mgly]) + robot
    Wd = np.column_stack([Ws[:, 0], Ws[:, 1], known, np.ones(known.size)])
    a_I, a_v, a_k, mz = np.linalg.lstsq(Wd, lp(q_m - q), rcond=None)[0]
    if not a_k > 0:
        # without gravity 1/k rests on the Coulomb column alone, which a deflection of other
        # origin can reverse (a transmission error's 1 mrad swings on a joint without gravity:
        # hinge grid seed 38000, case 005); the deflection's slope on the whole torque, the
        # inertia and the viscous friction split at half, is then the start the fits refine
        a_k, mz = np.linalg.lstsq(np.column_stack([ub + robot, np.ones(ub.size)]), lp(q_m - q), rcond=None)[0]
        a_I, a_v = 0.5 * A * a_k, 0.5 * max(float(B), 0.0) * a_k
    if not a_k > 0:
        raise InputError(None, "k", "a positive stiffness: the deflection q_m - q growing with the torque",
                         f"1/k = {a_k:.4g} rad/(N m)",
                         hint="check the signs of q, q_m and u (docs/conventions.md) and the deflection")
    k = 1.0 / a_k
    I = float(np.clip(a_I * k, 0.05 * A, 0.95 * A) if context is None else
              np.clip(a_I * k, -0.9 * float(np.min(context[0])), 0.95 * A))
    B = max(float(B), 0.0)
    v = float(np.clip(a_v * k, 0.05 * B, 0.95 * B)) if B > 0 else 0.0
    return np.array([I, mglx, mgly, max(float(c), 0.0), v, A - I, B - v, k, -mz])


def eiv_band_hz(q_m: np.ndarray, fs_hz: float, max_share: float = 1e-3) -> float:
    """The widest torque band in which the motor angle's own noise, differentiated twice, is a
    negligible part of the J q_m'' column: the largest f with  int_0^f N <= max_share int_0^f P,
    N the noise's spectrum after the two central differences (white noise of the SD that the top
    quarter of q_m's spectrum shows) and P the measured q_m'' spectrum (Welch, 2 s windows). An
    errors-in-variables regressor biases its parameter by about that share. Hz."""
    from scipy.signal import welch

    sm = noise_floor_sd(q_m, fs_hz)
    _, qdd = derivatives(q_m, fs_hz)
    nper = int(min(q_m.size, max(64, 2 * fs_hz)))
    f, P = welch(qdd, fs=fs_hz, nperseg=nper)
    h = 1.0 / fs_hz
    N = sm ** 2 / (fs_hz / 2) * np.sin(2 * np.pi * f * h) ** 4 / h ** 4
    bad = np.flatnonzero(np.cumsum(N) > max_share * np.cumsum(P))
    bad = bad[bad > 0]
    return float(f[bad[0] - 1]) if bad.size else float(f[-1])


def encoder_band_hz(q_m: np.ndarray, fs_hz: float, ratio: float = 10.0) -> float:
    """The frequency above which the motor angle's spectrum stays within `ratio` x its white noise
    floor (the encoder's noise, :func:`.conditioning.noise_floor_sd`): beyond it q_m is mostly
    noise. Welch spectrum with 4 s windows, Hz (fs / 2 when it never sinks that low)."""
    from scipy.signal import welch

    sm = noise_floor_sd(q_m, fs_hz)
    nper = int(min(q_m.size, max(64, 4 * fs_hz)))
    f, P = welch(q_m, fs=fs_hz, nperseg=nper)
    high = np.flatnonzero(P > ratio * sm ** 2 / (fs_hz / 2))
    return float(f[high[-1] + 1]) if high.size and high[-1] + 1 < f.size else float(fs_hz / 2)


def _encoder_noise_shift(q_m_c, fs_c, u_c, t_c, t, q, measured, trim_s, band, prob, x, free,
                         replicates: int = 2):
    """The Gauss-Newton step from x that a second dose of the motor angle's white noise (its SD
    from the spectrum's floor, :func:`.conditioning.noise_floor_sd`) causes, averaged over
    `replicates` fixed-seed draws: (n,) with zeros for parameters not in `free`, or None when the
    angle shows no noise above its quantisation."""

    sm = noise_floor_sd(q_m_c, fs_c)
    if not sm > 0:
        return None
    rng = np.random.default_rng(20261124)
    noise = ((prob.a_q, prob.s_q), (prob.a_u, prob.s_u))
    steps = []
    for _ in range(replicates):
        d2 = _Data(t_c, q_m_c + rng.normal(0.0, sm, q_m_c.size), u_c, fs_c, t, q, measured, trim_s, band,
                   context=prob.d.context)
        p2 = prob.sibling(d2, noise)
        J = p2.jac_full(x)[:, free]
        r = p2.fun(x[p2.free])
        sc = np.linalg.norm(J, axis=0)
        sc[sc == 0] = 1.0
        steps.append(-np.linalg.lstsq(J / sc, r, rcond=None)[0] / sc)
    out = np.zeros(x.size)
    out[free] = np.mean(steps, axis=0)
    return out


def _split_at(x, share: float) -> np.ndarray:
    """x with the inertia I + J split as I = share (I + J), J the rest (a copy)."""
    xs = np.array(x, dtype=np.float64)
    A = xs[_IDX["I"]] + xs[_IDX["J"]]
    xs[_IDX["I"]], xs[_IDX["J"]] = share * A, (1 - share) * A
    return xs


def _search_split(x, run, best=None) -> tuple:
    """The best (cost, x) of run(start) -> (x, cost) from each share of SPLIT_STARTS, and from x
    itself unless `best` = (cost, x) is already known for it."""
    for share in (SPLIT_STARTS if best is not None else (None,) + SPLIT_STARTS):
        xs, c = run(np.array(x, dtype=np.float64) if share is None else _split_at(x, share))
        if best is None or c < best[0]:
            best = (c, xs)
    return best


def _wiener_drive_shift(q_m_c, fs_c, u_c, t_c, t, q, measured, trim_s, band, prob, x, free):
    """How far the fit moves when the simulated link is driven by the Wiener-filtered motor angle
    (:func:`wiener_drive`) instead of the raw one: the inertia split searched again from x and from
    SPLIT_STARTS (short coarse fits), the best refined (up to 20 evaluations). (n,), zeros for
    parameters not in `free`. The split is searched because the two drives can put the cost's
    minimum at very different splits (grid case: I 0.07 raw, 0.38 Wiener-driven, true 0.32)."""
    d2 = _Data(t_c, q_m_c, u_c, fs_c, t, q, measured, trim_s, band, drive=wiener_drive(q_m_c, fs_c),
               context=prob.d.context)
    noise = ((prob.a_q, prob.s_q), (prob.a_u, prob.s_u))
    search = prob.sibling(d2, noise, max_phase=0.15)
    search.free = prob.free & free
    best = _search_split(x, lambda xs: _solve(search, xs, 8, 1e-6)[:2])
    p2 = prob.sibling(d2, noise)
    p2.free = search.free
    x2, _, _ = _solve(p2, best[1], 20, 1e-8)
    return np.where(free, x2 - x, 0.0)


def drive_noise_cost(prob: _Problem, x, sigma_m: float) -> float:
    """The expected share of the whitened torque cost (half the sum of squares) that white noise of
    SD sigma_m (rad per controller sample) on the motor angle adds at the parameters x.

    The angle drives the simulated link and enters the torque model directly, so the noise n adds
    N(f) n to the torque residual with N = J D(f)^2 + b D(f) + k (1 - H(f)), D the central
    difference's response i sin(2 pi f h) / h and H = k / (k - I w^2 + i d w) the link's linear
    response to its drive (d = v, plus c / eps under a smooth Coulomb law). Below the link's
    resonance N ~ -(J + I H) w^2: near it the link amplifies the noise, so the cost depends on how
    the inertia splits between link and motor, and a fit that minimises it moves the split toward
    the motor (a light link resonates above the band). The expectation is the integral over the
    band of |A|^2 |B|^2 |N|^2 2 sigma_m^2 / fs, A the whitening filter, B the band's low-pass,
    times the number of whitened rows / 2. Linear in the link (the friction's sticking left out)."""
    from scipy.signal import freqz

    d = prob.d
    if not sigma_m > 0:
        return 0.0
    h = 1.0 / d.fs
    fs_d = d.fs / d.stride
    f = np.linspace(0.0, fs_d / 2, 2001)[1:]
    w = 2 * np.pi * f
    p = dict(zip(OE_NAMES, x))
    damping = p["v"] + (p["c"] / p["eps"] if p["eps"] > 0 else 0.0)
    H = p["k"] / (p["k"] - (p["I"] + d.I_ctx[1]) * w ** 2 + 1j * damping * w)
    D = 1j * np.sin(w * h) / h
    N = p["J"] * D ** 2 + p["b"] * D + p["k"] * (1.0 - H)
    B2 = (1.0 / (1.0 + (f / d.band) ** 8)) ** 2 if d.stride > 1 else np.ones_like(f)
    _, A = freqz(prob.a_u, [1.0], worN=f, fs=fs_d)
    rows = d.u_b.size - (prob.a_u.size - 1)
    density = np.abs(A) ** 2 / prob.s_u ** 2 * B2 * np.abs(N) ** 2 * 2.0 * sigma_m ** 2 / d.fs
    return float(0.5 * rows * np.trapezoid(density, f))


def split_noise_chi2(prob: _Problem, x, sigma_m: float) -> float:
    """The range of :func:`drive_noise_cost` over link shares I / (I + J) of 0.02-0.98 (the other
    parameters at x): how strongly the motor angle's noise pulls on the inertia split. Above
    SPLIT_NOISE_CHI2 the noise, not the motion, can set the split (grid cases: I -47 % and -10 %
    with the noise, within 0.5 % without it); the pull's size depends on how flat the cost is
    along the split, which a quadratic model at the fit does not capture, so the split is then
    reported as not determined."""
    costs = [drive_noise_cost(prob, _split_at(x, share), sigma_m) for share in np.linspace(0.02, 0.98, 25)]
    return float(max(costs) - min(costs))


def _hysteresis_test(prob: _Problem, x, threshold: float = HYSTERESIS_CHI2) -> dict | None:
    """A score test for a hysteretic spring at the fitted linear one: the Bouc-Wen spring
    alpha k delta + (1 - alpha) k z(delta; beta = gamma) adds k_h (z - delta) (k_h = (1 - alpha) k)
    to the motor torque; its whitened column along the simulated (noise-free) deflection, made
    orthogonal to the fit's Jacobian, is regressed on the whitened residual for a few loop widths.
    Found when the best lowers the cost by HYSTERESIS_CHI2 with a positive k_h that is at least
    HYSTERESIS_MIN_SHARE of k: {alpha, beta, gamma, k_h, chi2}; else None. Below the link's
    resonance its load fixes the spring torque, so a loop shows in the deflection, not in the
    motor torque: the column is the mocap angle's shift (z - delta) k_h / k. (A test, not a fit.)"""
    from .springs import bouc_wen_path

    d = prob.d
    q_s, _ = prob.simulate(x)
    delta = d.q_m - q_s
    span = float(np.percentile(delta, 99) - np.percentile(delta, 1))
    if not span > 0:
        return None
    stride = max(1, int(d.fs // (8.0 * d.band)))
    k = x[_IDX["k"]]
    J = prob.jac_full(x)[:, prob.free]
    r = prob.fun(x[prob.free])
    Q, _ = np.linalg.qr(J / np.maximum(np.linalg.norm(J, axis=0), 1e-300))
    best = None
    for width in (0.03, 0.1, 0.3, 1.0):                     # the loop saturates over this share of the span
        bg = 0.5 / (width * span)
        z = bouc_wen_path(delta, 1.0, bg, bg, stride)
        # with the link's load fixed (below its resonance) the spring torque does not change: a
        # loop shifts the deflection instead, q by (z - delta) k_h / k, seen by the mocap
        w = (z - delta) / k
        col_q = -d.q_band(d.at_mocap(w, np.gradient(w) * d.fs))
        c = np.concatenate(prob._white(col_q, np.zeros(d.iu.size)))
        c = c - Q @ (Q.T @ c)
        cc = float(c @ c)
        if cc <= 0:
            continue
        coef = -float(c @ r) / cc                          # r(x + coef e) ~ r + coef c
        gain = float(c @ r) ** 2 / cc
        if best is None or gain > best["chi2"]:
            best = {"chi2": gain, "k_h": coef, "beta": bg, "gamma": bg}
    k = x[_IDX["k"]]
    if _DEBUG:
        print("hysteresis test", best, "k", k)
    if best is None or not (best["chi2"] > threshold and best["k_h"] > HYSTERESIS_MIN_SHARE * k):
        return None
    best["alpha"] = float(max(0.0, 1.0 - best["k_h"] / k))
    return best


def _clock_scan(prob: _Problem, x, coarse_s: float = 4e-3, fine_s: float = 2.5e-4) -> float:
    """The offset dt (|dt| <= CLOCK_MAX_S) that best aligns the simulated link at x with the mocap
    angle (least squares over the measured samples, the zero refitted): one simulation, the
    comparison shifted over a grid of `coarse_s`, then of `fine_s` around the best, refined by a
    parabola (the misfit varies over the motion's fastest period, a few tenths of a second)."""
    d = prob.d
    q_s, w_s = prob.simulate(np.asarray(x, dtype=np.float64))
    keep = ~d.filled

    def ssr(dt):
        r = (d.q - d.q_band(d.at_mocap(q_s, w_s, float(dt))))[keep]
        return float(np.sum((r - r.mean()) ** 2))

    grid = np.arange(-CLOCK_MAX_S, CLOCK_MAX_S + coarse_s / 2, coarse_s)
    best = grid[int(np.argmin([ssr(dt) for dt in grid]))]
    grid = best + np.arange(-coarse_s, coarse_s + fine_s / 2, fine_s)
    cost = np.array([ssr(dt) for dt in grid])
    k = int(np.argmin(cost))
    if 0 < k < grid.size - 1:
        a, b, c = cost[k - 1], cost[k], cost[k + 1]
        den = a - 2 * b + c
        if den > 0:
            return float(grid[k] + 0.5 * fine_s * (a - c) / den)
    return float(grid[k])


def _clock_offset_fit(prob: _Problem, x, budget: int = 30) -> tuple:
    """The fit with an offset dt between the two clocks free: the mocap angle at t is the link's
    at t + dt on the controller's clock (the link lags the motor physically, so a stream that
    lags or leads shows as a phase the dynamics cannot make). From x, all of prob's free parameters
    refitted with it, dt starting at prob.dt: (x with dt, dt s, its SD s, the whitened cost's drop,
    d x / d dt (n,): how the other parameters move with the offset, from the joint covariance)."""
    from scipy.optimize import least_squares

    d = prob.d
    p2 = prob.sibling(noise=((prob.a_q, prob.s_q), (prob.a_u, prob.s_u)), dt=0.0)
    p2.free = prob.free.copy()
    f = p2.free
    lo, hi = _bounds(d)
    x = np.asarray(x, dtype=np.float64)
    xf = _inside(prob, x)
    p2._x = x.copy()
    zeros_u = np.zeros(d.u_b.shape)

    def fun(v):
        p2.dt = float(v[-1])
        return p2.fun(v[:-1])

    def jac(v):
        p2.dt = float(v[-1])
        J = p2.jac(v[:-1])
        q_s, w_s = p2.simulate(p2.full(v[:-1]))
        col_q = -d.q_band(d.at_mocap(w_s, np.gradient(w_s) * d.fs, p2.dt))
        return np.column_stack([J, np.concatenate(p2._white(col_q, zeros_u))])

    dt0 = float(prob.dt)
    r0 = fun(np.concatenate([xf, [dt0]]))
    res = least_squares(fun, np.concatenate([xf, [dt0]]), jac=jac, method="trf", x_scale="jac",
                        bounds=(np.concatenate([lo[f], [dt0 - CLOCK_MAX_S]]), np.concatenate([hi[f], [dt0 + CLOCK_MAX_S]])),
                        ftol=1e-8, xtol=1e-10, gtol=1e-10, max_nfev=budget)
    Jm = jac(res.x)
    sc = np.linalg.norm(Jm, axis=0)
    sc[sc == 0] = 1.0
    s2 = max(float(res.fun @ res.fun) / max(res.fun.size - res.x.size, 1), 1.0)
    cov = np.linalg.pinv((Jm / sc).T @ (Jm / sc)) / np.outer(sc, sc) * s2
    slope = np.zeros(len(OE_NAMES))
    if cov[-1, -1] > 0:
        slope[f] = cov[:-1, -1] / cov[-1, -1]
    return p2.full(res.x[:-1]), float(res.x[-1]), float(np.sqrt(max(cov[-1, -1], 0.0))), \
        float(r0 @ r0 - res.fun @ res.fun), slope


def _noise_models(prob: _Problem, x) -> tuple:
    """Whitening filters and innovation SDs of both residuals at x."""
    r_q, r_u = prob.raw(x)
    keep = ~prob.d.filled
    a_q, v_q = burg_ar(_bridge(r_q, keep), AR_ORDER_MAX[0])
    a_u, v_u = burg_ar(r_u, AR_ORDER_MAX[1])
    return (a_q, math.sqrt(max(v_q, 1e-300))), (a_u, math.sqrt(max(v_u, 1e-300)))


def _bridge(r, keep):
    """r with its unmeasured samples interpolated (for the autoregressive fit only)."""
    if keep.all():
        return r
    idx = np.arange(r.size)
    return np.interp(idx, idx[keep], r[keep])


def identify_output_error(t, q, q_m, u, *, fs_hz: float, measured=None, controller=None,
                          band_hz: float | None = None, trim_s: float = 1.0,
                          friction_scales=FRICTION_SCALES, x0=None, max_nfev: int = 40,
                          link_band_fraction: float = LINK_BAND_FRACTION, test_cubic: bool = True,
                          test_hysteresis: bool = True, test_clock: bool = True,
                          fit_clock_offset: bool = False, clock_offset_s: float = 0.0,
                          context=None) -> OutputErrorResult:
    """Identify I, mglx, mgly, c, v, J, b, k (and the mocap zero z) by output error (module
    docstring).

    Parameters
    ----------
    t, q, q_m, u : (T,) float
        Times (s, uniform at fs_hz), link angle from mocap (rad), motor angle / gear ratio (rad),
        motor torque x gear ratio (N m), on one clock: the link side (docs/conventions.md).
    fs_hz : float
    measured : (T,) bool, optional
        True where q was measured (False where a gap was filled); default all.
    controller : (t_c, q_m_c, u_c, fs_c_hz), optional
        The controller's own samples over the same span (uniform at fs_c_hz, same clock as t):
        the simulation and the torque comparison then run at that rate, and (t, q) are the mocap
        samples. Default: everything on t.
    band_hz : float, optional
        The torque comparison band; default 0.4 x the torque's rate, at most 60 Hz.
    trim_s : float
        Seconds at each end left out of the comparison (the simulation's start, filter edges).
    friction_scales : starting values of the tanh law's eps / RMS motor velocity (FRICTION_SCALES).
    x0 : (9,) start in OE_NAMES order; default from a rigid sum equation and the deflection.
    max_nfev : least-squares evaluations per fit.
    test_clock : fit an undeclared offset between the two clocks with the dynamics (the mocap
        angle at t taken as the link's at t + dt): reported in ``clock``; when it is found (cost
        drop CLOCK_CHI2, three SDs from zero) the parameters it moves by more than their SD are
        listed in ``clock["moves"]`` (not determined under the declared synchronisation).
    fit_clock_offset : apply the fitted offset when found: the result is the identification with it.
    clock_offset_s : an offset (s) applied throughout: the mocap angle at t is the link's at
        t + clock_offset_s on the controller's clock.
    context : (I_t, mglx_t, mgly_t, tau_t), each (T,) at t, or None: a joint of a robot, simulated
        in the recorded motion of the others (:mod:`mocapfj.discover.context`): its link's inertia
        is I + I_t, its gravity terms mglx + mglx_t and mgly + mgly_t, and tau_t (N m, the other
        links' inertial and Coriolis torque) acts on it besides. The identified I, mglx, mgly are
        then the joint's own terms added to the robot's (I may be negative: the robot's model
        heavier than the link).

    Raises
    ------
    InputError
        Bad signals, a recording too short, signs that make the joint non-physical.
    """
    t, q, q_m, u = check_signals(t, q, q_m, u, fs_hz)
    measured = np.ones(t.size, bool) if measured is None else np.asarray(measured, bool)
    if measured.shape != t.shape:
        raise InputError(None, "measured", f"a (T,) = {t.shape} bool mask", measured.shape)
    trim = int(round(trim_s * fs_hz))
    need = 2 * trim + int(5 * fs_hz)
    if t.size < need:
        raise InputError(None, "t", f"at least {need} samples ({need / fs_hz:.1f} s) for output error (the trims and "
                         "5 s to compare)", f"{t.size} samples ({t.size / fs_hz:.2f} s)", hint="record longer")
    if controller is None:
        t_c, q_m_c, u_c, fs_c = t, q_m, u, fs_hz
    else:
        t_c, q_m_c, u_c, fs_c = controller
        fs_c = float(fs_c)
        t_c, q_m_c, _, u_c = check_signals(t_c, q_m_c, q_m_c, u_c, fs_c)
        if t[0] < t_c[0] - 1e-9 or t[-1] > t_c[-1] + 1e-9:
            raise InputError(None, "controller", "controller samples covering the mocap span",
                             f"[{t_c[0]:.4f}, {t_c[-1]:.4f}] s for [{t[0]:.4f}, {t[-1]:.4f}] s")
    ctx_c = None
    if context is not None:
        context = context_arrays(context, t.shape, 0.0)[0]
        ctx_c = context if t_c is t else tuple(np.interp(t_c, t, a) for a in context)
    I_mean = float(np.mean(context[0])) if context is not None else 0.0
    f_exc = excitation_bandwidth_hz(q_m, fs_hz)
    band0 = float(np.clip(3.0 * f_exc, 1.0, fs_hz / 5.0))
    x = (_initial(q, q_m, u, fs_hz, band0, trim, context) if x0 is None else np.asarray(x0, dtype=np.float64))
    f_eiv = eiv_band_hz(q_m_c, fs_c)
    f_max = min(0.4 * fs_c, 60.0, max(f_eiv, band0))
    u_rms = float(np.sqrt(np.mean(u ** 2)))
    v_rms = max(float(np.std(np.gradient(q_m_c) * fs_c)), 1e-9)
    d_ref = max(u_rms / x[7], 1e-9)                     # a deflection's size, rad
    scale = np.array([x[0] + I_mean, 1e-3 * u_rms, 1e-3 * u_rms, 1e-3 * u_rms, 1e-3 * u_rms / v_rms, x[5],
                      1e-3 * u_rms / v_rms, x[7], 1e-6, 1e-3, 1e-3 * x[7] / d_ref ** 2])
    x = np.concatenate([x, [0.0, 0.0]])
    nfev = 0
    datas = {}
    # the link resonance no fit may pass: SUBSTEP_GROWTH x the start's (256 x its stiffness-to-
    # inertia ratio, far outside what the data can support)
    I_start = x[_IDX["I"]] + I_mean
    omega_cap = (SUBSTEP_GROWTH * math.sqrt(x[_IDX["k"]] / I_start) if I_start > 0 and x[_IDX["k"]] > 0
                 else math.inf)

    def data_at(b_hz):
        if b_hz not in datas:
            datas[b_hz] = _Data(t_c, q_m_c, u_c, fs_c, t, q, measured, trim_s, b_hz, context=ctx_c)
        return datas[b_hz]

    def fit(b_hz, law, x_start, noise=None, budget=max_nfev, coarse=False, cubic=False, search=False,
            dt=clock_offset_s):
        """One fit in band b_hz under `law`. noise None: weighted by the residuals' SDs (no
        whitening); "white": that, then whitened by the residuals' autoregressive models; or the
        given models. coarse or search: a 3x coarser simulation and a looser tolerance (the
        searches before the final fit)."""
        nonlocal nfev
        prob = _Problem(data_at(b_hz), law, scale, max_phase=0.15 if coarse or search else 0.05, cubic=cubic, dt=dt,
                        omega_cap=omega_cap)
        ftol = 1e-6 if coarse or search else 1e-10
        if noise is None or noise == "white":
            r_q, r_u = prob.raw(x_start)
            prob.set_noise(((np.array([1.0]), max(float(np.std(r_q)), 1e-12)),
                            (np.array([1.0]), max(float(np.std(r_u)), 1e-12))))
            if noise is None:
                xs, cost, n = _solve(prob, x_start, budget, ftol)
                nfev += n
                return prob, xs, cost
            x_start, _, n = _solve(prob, x_start, budget, ftol)
            nfev += n
            noise = _noise_models(prob, x_start)
        prob.set_noise(noise)
        tic = time.perf_counter()
        xs, cost, n = _solve(prob, x_start, budget, ftol)
        nfev += n
        if _DEBUG:
            print(f"  fit band {b_hz:.2f} {law} {'search' if search else ('coarse' if coarse else 'fine')} "
                  f"cost {cost:.1f} n {n} {time.perf_counter() - tic:.2f}s", " ".join(f"{v:.4g}" for v in xs))
        return prob, xs, cost

    x_init = x

    def _linear_fit():
        nonlocal nfev
        x = x_init
        # 1. the split of the total inertia I + J: the cost in the excitation's band can have a second
        #    minimum at a light, stiff link; short fits from several splits, the best kept
        b0 = min(band0, f_max) if band_hz is None else float(band_hz)
        prob0, _, _ = fit(b0, "sign", x, None, 1, search=True)
        noise0 = ((prob0.a_q, prob0.s_q), (prob0.a_u, prob0.s_u))
        x = _search_split(x, lambda xs: fit(b0, "sign", xs, noise0, 8, search=True)[1:])[1]
        # 2. the Coulomb law in that band: sign with sticking, or tanh with eps fitted from the best
        #    of a few starting values
        prob_s, x_s, cost_s = fit(b0, "sign", x, None, 25, search=True)
        noise0 = ((prob_s.a_q, prob_s.s_q), (prob_s.a_u, prob_s.s_u))
        tanh_fits = []
        for e in friction_scales:
            xe = x_s.copy()
            xe[_IDX["eps"]] = float(np.clip(e * v_rms, *EPS_RANGE_RAD_S))
            tanh_fits.append(fit(b0, "tanh", xe, noise0, 6, search=True))
        prob_t, x_t, cost_t = fit(b0, "tanh", min(tanh_fits, key=lambda f: f[2])[1], noise0, 25, search=True)
        scores = {0.0: cost_s, float(x_t[_IDX["eps"]]): cost_t}
        law, x = ("tanh", x_t) if cost_t < cost_s - 2.0 else ("sign", x_s)
        # 3. the band widened with it, in steps of 3, up to a fraction of the link's resonance (above
        #    it the torque rings after every stick and slip of the friction, whose fine shape the model
        #    cannot be trusted with), the motor angle's noise limit and 60 Hz
        band = b0
        if band_hz is None:
            for _ in range(4):
                f_link = math.sqrt(x[_IDX["k"]] / (x[_IDX["I"]] + I_mean)) / (2 * math.pi)
                target = max(b0, min(f_max, link_band_fraction * f_link))
                if target <= band * 1.05:
                    break
                band = min(target, 3.0 * band)
                prob_b, x, cost_b = fit(band, law, x, None, 25, search=True)
            # the split again in the final band: in the excitation's band the cost is nearly flat along
            # I + J = const, and in the wider one it is rugged (each stick and slip of the friction), so
            # a local fit from the first band's split can stop far from the best
            if band > 1.05 * b0:
                noise_b = ((prob_b.a_q, prob_b.s_q), (prob_b.a_u, prob_b.s_u))
                x = _search_split(x, lambda xs: fit(band, law, xs, noise_b, 8, search=True)[1:], (cost_b, x))[1]
        # 4. the final fit, whitened by the noise models of the last residuals; then a look at the
        #    inertia split from either side (the cost can have a second minimum there)
        prob, x, cost = fit(band, law, x, "white")
        noise = (prob.a_q, prob.s_q), (prob.a_u, prob.s_u)
        A = x[_IDX["I"]] + x[_IDX["J"]]
        found = [(cost, x, prob)]
        for frac in (0.6, 1.5):
            xs = x.copy()
            # the link's inertia scaled (a robot's: its total, the robot's part included)
            xs[_IDX["I"]] = min(frac * (x[_IDX["I"]] + I_mean) - I_mean, 0.97 * A)
            xs[_IDX["J"]] = A - xs[_IDX["I"]]
            _, xs, c = fit(band, law, xs, noise, 10)
            if c < cost + AMBIGUITY_CHI2:
                p2, xs, c = fit(band, law, xs, noise, 25)
                found.append((c, xs, p2))
        cost, x, prob = min(found, key=lambda f: f[0])
        others = [(c - cost, xs) for c, xs, _ in found
                  if c - cost < AMBIGUITY_CHI2 and np.abs(xs[_IDX["I"]] - x[_IDX["I"]]) > 1e-6 * A]
        return law, x, band, scores, noise, cost, others, prob

    # steps 1-4, the linear-spring fit, depend only on the signals and these settings: a second
    # identification of the same signals (discovery's effect-free re-identification after the
    # one with every spring model) takes them from the first (LINEAR_FITS), not again
    key = content_digest(t, q, q_m, u, measured, controller, band_hz, trim_s, friction_scales, x0, max_nfev,
                          link_band_fraction, clock_offset_s, context)
    hit = LINEAR_FITS.get(key)
    if hit is not None:
        law, x, band, scores, noise, cost, others, nfev = hit
        x, scores, others = x.copy(), dict(scores), [(c, xs.copy()) for c, xs in others]
        prob = _Problem(data_at(band), law, scale, noise, dt=clock_offset_s, omega_cap=omega_cap)
    else:
        law, x, band, scores, noise, cost, others, prob = _linear_fit()
        LINEAR_FITS.put(key, (law, x.copy(), band, dict(scores), noise, cost,
                               [(c, xs.copy()) for c, xs in others], nfev))

    # 5b. a stiffening (or softening) spring: k delta + k3 delta^3, kept when the data want it by far
    #    (a likelihood ratio of CUBIC_CHI2) and it changes the stiffness by CUBIC_MIN_PCT over the
    #    deflections the recording reaches
    # 5a. a hysteretic spring first (a loop is otherwise read as a stiffening curve): the score
    #     test at the linear spring; when it finds one, no cubic term
    hysteresis = _hysteresis_test(prob, x) if test_hysteresis else None
    # a weaker loop (down to the cubic's threshold) wins over a cubic term that gains less
    weak = _hysteresis_test(prob, x, CUBIC_CHI2) if test_hysteresis and hysteresis is None else None
    if test_cubic and hysteresis is None:
        d_lin = q_m_c - prob.simulate(x)[0]
        x3 = x.copy()
        x3[_IDX["k3"]] = 0.3 * x[_IDX["k"]] / (3.0 * float(np.percentile(np.abs(d_lin), 95)) ** 2)
        pc, xc, cc = fit(band, law, x3, noise, 25, cubic=True)       # from 30 % stiffening: the
        #                                                          k3 column is tiny near zero
        if cc > cost:
            # stopped in another valley: from the same stiffening with the linear fit's
            # equivalent stiffness kept (k1 + k3 E[d^4] / E[d^2] = k, the least-squares line of the
            # cubic over the deflections met), where the cubic starts as good as the line
            x3[_IDX["k"]] = x[_IDX["k"]] - x3[_IDX["k3"]] * float(np.mean(d_lin ** 4) / np.mean(d_lin ** 2))
            if x3[_IDX["k"]] > 0.2 * x[_IDX["k"]]:
                p2, x2, c2 = fit(band, law, x3, noise, 25, cubic=True)
                if c2 < cc:
                    pc, xc, cc = p2, x2, c2
        d95 = float(np.percentile(np.abs(q_m_c - pc.simulate(xc)[0]), 95))
        change = 300.0 * xc[_IDX["k3"]] * d95 ** 2 / xc[_IDX["k"]]
        if _DEBUG:
            print(f"cubic test: chi2 {cost - cc:.1f} change {change:.1f} % k3 {xc[_IDX['k3']]:.4g} d95 {d95:.3g}")
        nonlinear = cost - cc > CUBIC_CHI2 and abs(change) > CUBIC_MIN_PCT
        if nonlinear and weak is not None and weak["chi2"] > cost - cc:
            hysteresis = weak                  # the spring is nonlinear, and a loop explains it better
        elif nonlinear:
            prob, x, cost = pc, xc, cc
            others = []
    clock = None
    if test_clock:
        # an undeclared offset between the clocks: the best alignment of the simulated link with
        # the mocap angle (a scan, robust to a large offset), every parameter refitted locally
        # with it and the offset fitted jointly for its SD; the cost drop under one noise model
        dt0 = _clock_scan(prob, x)
        if abs(dt0) < CLOCK_MIN_S / 2:
            # aligned already: the joint fit from here, under this fit's noise model
            _, dt_abs, sd_dt, chi2, slope = _clock_offset_fit(prob, x)
        else:
            p_dt, x_loc, _ = fit(band, law, x, "white", 40, cubic=prob.cubic, dt=clock_offset_s + dt0)
            x_loc, dt_abs, sd_dt, _, slope = _clock_offset_fit(p_dt, x_loc)
            p_dt.dt = dt_abs
            cost_dt = float(np.sum(p_dt.fun(x_loc[p_dt.free]) ** 2))
            p_0 = _Problem(data_at(band), law, scale, ((p_dt.a_q, p_dt.s_q), (p_dt.a_u, p_dt.s_u)), cubic=prob.cubic,
                           dt=clock_offset_s, omega_cap=omega_cap)
            p_0.free = p_dt.free.copy()
            _, cost_0, n = _solve(p_0, x, 20, 1e-8)
            nfev += n
            chi2 = cost_0 - cost_dt
        dt = dt_abs - clock_offset_s
        # the reported SD adds the link model's accuracy in time (CLOCK_MIN_S) to the fit's: on
        # eight hinge grid cases with 2.7-24 ms planted the fit's SD alone (0.005-0.11 ms) left
        # errors of up to 1.9 ms at 35 SDs
        clock = {"offset_s": dt, "sd_s": math.hypot(sd_dt, CLOCK_MIN_S), "sd_fit_s": sd_dt, "chi2": chi2,
                 "applied": False,
                 "found": bool(chi2 > CLOCK_CHI2 and abs(dt) > 3 * sd_dt and abs(dt) > CLOCK_MIN_S), "moves": {},
                 "per_ms": {}}
        if _DEBUG:
            print(f"clock offset scan {1e3 * dt0:+.2f} ms, fit {1e3 * dt:+.3f} +- {1e3 * sd_dt:.3f} ms, chi2 {chi2:.1f}")
        if clock["found"]:
            # the whole identification again with the offset (the friction law and the splits can
            # change with it; a local refit from here can stop in the declared fit's valley)
            again = identify_output_error(t, q, q_m, u, fs_hz=fs_hz, measured=measured, controller=controller,
                                          band_hz=band_hz, trim_s=trim_s, friction_scales=friction_scales, x0=x0,
                                          max_nfev=max_nfev, link_band_fraction=link_band_fraction,
                                          test_cubic=test_cubic, test_hysteresis=test_hysteresis, test_clock=False,
                                          clock_offset_s=dt_abs, context=context)
            if fit_clock_offset:
                # the offset is known to about CLOCK_MIN_S (the link model's accuracy in time), and
                # the viscous split moves with it (v ~ k dt): that uncertainty joins the SDs
                sig = clock["sd_s"]
                f0 = again.fit
                add = np.nan_to_num(slope) * sig
                cov = f0.cov + np.outer(add, add)
                std = np.sqrt(f0.std ** 2 + add ** 2)
                with np.errstate(invalid="ignore", divide="ignore"):
                    rel = np.where(f0.values != 0, 100.0 * std / np.abs(f0.values), np.nan)
                return replace(again, fit=replace(f0, std=std, cov=cov, rel_std_pct=rel),
                               clock=dict(clock, applied=True), n_iter=again.n_iter + nfev)
            shift = again.fit.values - x
    data = datas[band]
    eps = float(x[_IDX["eps"]])
    r = prob.fun(x[prob.free])
    Jm = prob.jac_full(x)
    r_q, r_u = prob.raw(x)

    # covariances: the model's and the Newey-West sandwich; the larger SD per parameter
    lo, _ = _bounds()
    at_bound = tuple(n for n in ("c", "v", "b") if x[_IDX[n]] <= lo[_IDX[n]] + 1e-6 * scale[_IDX[n]])
    free = prob.free & np.array([n not in at_bound for n in OE_NAMES])
    free &= np.linalg.norm(Jm, axis=0) > 0          # eps of a tanh law stiffer than the step: a sign law
    Jf = Jm[:, free]
    sc = np.linalg.norm(Jf, axis=0)
    sc[sc == 0] = 1.0
    inv = np.linalg.pinv((Jf / sc).T @ (Jf / sc)) / np.outer(sc, sc)
    n_obs, n_par = r.size, int(free.sum())
    s2 = float(r @ r) / max(n_obs - n_par, 1)
    cov_model = np.full((len(OE_NAMES), len(OE_NAMES)), np.nan)
    cov_sand = cov_model.copy()
    cov_model[np.ix_(free, free)] = inv * max(s2, 1.0)
    cov_sand[np.ix_(free, free)] = sandwich_cov(Jf, r, time_index=prob.time_index())
    var = np.fmax(np.diag(cov_model), np.diag(cov_sand))
    # a second minimum of nearly the same cost: the curvature at one of them understates what the
    # data leave open; the SD covers the other as a quadratic profile through both would
    for d_cost, xs in others:
        gap = (xs - x) ** 2 / max(d_cost, 1.0)
        var = np.where(free, np.fmax(var, gap), var)
    # the motor angle's own noise drives the simulated link (its resonance, through the friction):
    # the shift that twice that noise would cause is measured, removed once (a first-order
    # simulation-extrapolation, Cook and Stefanski 1994) and counted in the SD
    args = (q_m_c, fs_c, u_c, t_c, t, q, measured, trim_s, band, prob, x, free)
    try:
        encoder_shift = _encoder_noise_shift(*args)
    except FloatingPointError:
        # the re-noised drive rings the simulated link past the kernel's stability: the fit rests
        # on a knife's edge of the motor angle's noise, and the splits it sets are not measured
        encoder_shift = None
        split = np.isin(np.array(OE_NAMES), ("I", "J", "v", "b")) & free
        var = np.where(split, np.fmax(var, x ** 2), var)
    drive_spread = None
    if encoder_shift is not None:
        sig = np.abs(encoder_shift) > ENCODER_SHIFT_SDS * np.sqrt(var)
        # the shift can be far from linear (the cost is rugged along the inertia split): the fit
        # driven by the Wiener-filtered motor angle, which treats the noise the other way, shows
        # how far; the difference is counted in the SD (not corrected: neither drive is the truth)
        if (np.abs(encoder_shift) > ENCODER_REFIT_SDS * np.sqrt(var))[free].any():
            try:
                drive_spread = _wiener_drive_shift(*args)
                var = np.where(free, np.fmax(var, drive_spread ** 2), var)
            except FloatingPointError:
                drive_spread = None
            if _DEBUG:
                print("drive spread", dict(zip(OE_NAMES, np.round(drive_spread, 5))))
        if sig[free].any():
            # within the fit's bounds: a viscous friction fitted near zero (a light cobot whose
            # controller log was stamped 0.32 ms late, hinge grid seed 32000, case 004) was shifted
            # to -0.095 N m s/rad, which the link cannot be simulated with; the shift stays in the SD
            # I, J and k stay above zero as the fits keep them (_inside): a light cobot's motor
            # inertia shifted to exactly 0 made a model no simulation takes, and discovery
            # against it stopped with an error (hinge grid seed 35000, case 001, no model file)
            lo_x, hi_x = _bounds(prob.d)
            lo_x = np.where(np.isin(np.array(OE_NAMES), ("I", "J", "k")), lo_x + 1e-6 * prob.scale, lo_x)
            x = np.clip(np.where(free, x - encoder_shift, x), lo_x, hi_x)
            var = np.where(free, var + encoder_shift ** 2, var)
        else:
            encoder_shift = None
    # the motor angle's noise can set the inertia split by itself (drive_noise_cost): then the
    # split is not measured, and I and J get an SD spanning the splits (uniform over I + J)

    sigma_m = noise_floor_sd(q_m_c, fs_c)
    split_chi2 = split_noise_chi2(prob, x, sigma_m) if sigma_m > 0 else 0.0
    if split_chi2 > SPLIT_NOISE_CHI2:
        A = x[_IDX["I"]] + x[_IDX["J"]]
        split = np.isin(np.array(OE_NAMES), ("I", "J")) & free
        var = np.where(split, np.fmax(var, A ** 2 / 12.0), var)       # uniform over I + J
    # and it pulls every parameter a little (the cost's expected noise share has a slope at x):
    # the first-order shift (J'J)^-1 grad C is counted in the SD, not removed (the linear link
    # model of drive_noise_cost leaves the friction's sticking out)
    if sigma_m > 0:
        grad = np.zeros(x.size)
        for j in np.flatnonzero(free):
            e = 1e-4 * max(abs(x[j]), 1e-12)
            xp, xm = x.copy(), x.copy()
            xp[j] += e
            xm[j] -= e
            grad[j] = (drive_noise_cost(prob, xp, sigma_m) - drive_noise_cost(prob, xm, sigma_m)) / (2 * e)
        noise_pull = np.zeros(x.size)
        noise_pull[free] = inv @ grad[free]
        var = var + noise_pull ** 2
    if _DEBUG:
        print(f"motor noise {sigma_m:.3g} rad, split noise chi2 {split_chi2:.1f}")
        if sigma_m > 0:
            print("noise pull", dict(zip(OE_NAMES, np.round(noise_pull, 5))))
    if clock is not None and clock["found"]:
        # what the offset moves: the identification with it against this one, and what a
        # millisecond of it moves (it is known to about CLOCK_MIN_S: the link model's accuracy in time)
        moved = free & ((np.abs(shift) > np.sqrt(var)) | (np.abs(slope) * CLOCK_MIN_S > np.sqrt(var)))
        clock["moves"] = {n: float(shift[i]) for i, n in enumerate(OE_NAMES) if moved[i]}
        clock["per_ms"] = {n: float(slope[i] * 1e-3) for i, n in enumerate(OE_NAMES) if moved[i]}
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.sqrt(var / np.diag(cov_model))
        cov = cov_model * np.outer(d, d)
        std = np.sqrt(var)
        rel = np.where(x != 0, 100.0 * std / np.abs(x), np.nan)
    ub = data.u_b - data.u_b.mean()
    fit_ls = LSResult(names=OE_NAMES, values=x, std=std, rel_std_pct=rel, cov=cov,
                      cond=float(np.linalg.cond(Jf / sc)),
                      residual_rms=float(np.sqrt(np.mean(r_u ** 2))),
                      rel_error_pct=float(100 * np.linalg.norm(r_u) / np.linalg.norm(data.u_b)),
                      r2=float(1 - (r_u @ r_u) / (ub @ ub)), n_samples=int(n_obs))
    # the spring's samples, on the mocap clock. Simulated without the fits' resonance cap (_link):
    # the cap refuses an optimiser's trial step, and the result can lie beyond it once the encoder
    # noise's shift is removed (a heavy joint whose transmission error rings its link: I 1.41 ->
    # 1.38 kg m^2 past a cap of 945 rad/s, and every spring sample was NaN; hinge grid seed
    # 33000, case 003)
    q_s_c, w_s_c = prob.sibling(max_phase=prob.max_phase, omega_cap=math.inf).simulate(x)
    inner = slice(trim, t.size - trim)
    fc = min(10.0, 0.4 * fs_hz)
    q_s = np.interp(t, t_c, q_s_c)
    qd_m, qdd_m = derivatives(q_m, fs_hz)
    tau_s_motor = lowpass(u - x[_IDX["J"]] * qdd_m - x[_IDX["b"]] * qd_m, fs_hz, fc)[inner]
    d_sim = q_m - q_s
    tau_model = lowpass(x[_IDX["k"]] * d_sim + x[_IDX["k3"]] * d_sim ** 3, fs_hz, fc)[inner]
    res = tau_s_motor - tau_model
    res -= res.mean()
    dev = tau_s_motor - tau_s_motor.mean()
    spring_r2 = float(1.0 - (res @ res) / (dev @ dev)) if dev @ dev > 0 else float("nan")
    return OutputErrorResult(fit=fit_ls, cov_model=cov_model, cov_sandwich=cov_sand, at_bound=at_bound,
                             friction_scale=eps, band_hz=float(data.band), sigma_q=float(np.std(r_q)),
                             sigma_u=float(np.std(r_u)), ar_q=prob.a_q, ar_u=prob.a_u, t=t[inner],
                             delta_sim=(q_m - q_s)[inner], tau_s=x[_IDX["k"]] * (q_m - q_s)[inner],
                             delta_mocap=lowpass(q_m - (q - x[_IDX["z"]]), fs_hz, fc)[inner],
                             tau_s_motor=tau_s_motor, scores=scores, n_iter=nfev, hysteresis=hysteresis,
                             spring_r2=spring_r2, motor_noise_rad=sigma_m, split_noise_chi2=split_chi2,
                             clock=clock)
