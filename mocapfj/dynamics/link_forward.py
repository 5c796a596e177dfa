"""The link of one flexible joint under a prescribed motor motion, for any joint model discovery
builds: the compiled forward simulation behind :func:`mocapfj.discover.simulate_joint`.

:mod:`.link_response` integrates the plain joint (Coulomb-viscous friction, linear or cubic
spring) with parameter sensitivities for output-error identification. Discovery also simulates
the joint with the effects it names, and integrating those with LSODA and a Python right-hand
side took 20-60 s per 60 s recording, or, with a narrow Bouc-Wen loop whose stiff state equation
LSODA probes with wild trial steps, did not finish. This kernel runs the same scheme (Stormer-
Verlet with the friction law set-valued, module docstring of :mod:`.link_response`) with

- friction: Coulomb and viscous coefficients per direction of motion plus a Stribeck excess
  s exp(-(|q'|/vs)^x) per direction (:class:`.CoulombViscous`, :class:`.AsymmetricCoulombViscous`,
  :class:`.Stribeck`, :class:`.AsymmetricStribeck`), and a Coulomb level that ripples with the link
  angle, sum a_k cos(n_k q + phi_k) on both directions (:class:`.PositionDependent` over one of
  those, the ripple taken at each substep's mid angle). Under the sign law the link sticks while the
  net torque is below the breakaway level c + s of the direction it would move in; while it
  slides, the Stribeck excess is taken at the substep's mid speed (implicit midpoint, Newton from
  the explicit step). Taken at the starting speed, the scheme was first order in it: on a joint
  with twice its Coulomb level at rest and vs 0.04 rad/s (hinge grid seed 42000, case 001), the
  link driven by the true motor angle ended its stuck phases up to 0.89 mrad from the recording
  simulator's (110 urad RMS over 24 s; 891 and 398 urad at 4 and 20 x the substeps), so that the
  true model fitted its trial 14.7 noise SDs worse than the model without the Stribeck friction;
  at mid speed, 16 urad RMS (140 at most), and the scheme agrees with itself at 20 x the
  substeps to 8.6 urad;
- springs: linear with offset, cubic, three-piece (:class:`.PiecewiseSpring`), Bouc-Wen with
  n = 1 (:class:`.BoucWen`), each optionally behind free play (:class:`.Backlash`). The Bouc-Wen
  state is advanced exactly along the deflection's path between substep midpoints (the state
  equation is linear in z on each side of z = 0 when n = 1, so each piece is an exponential);
- a kinematic transmission error e(q_m) (:class:`.TransmissionError`), evaluated at every
  substep's motor angle: the spring sees q_m + e - q. Its fastest order advances at most 0.5 rad
  per substep (more substeps when the wave generator turns fast).

It returns q, q' and the spring torque at the samples; the motor equation then gives u.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from .drivetrain import TransmissionError
from .friction import AsymmetricCoulombViscous, AsymmetricStribeck, CoulombViscous, PositionDependent, Stribeck
from .hysteresis import BoucWen
from .link_response import context_arrays, substeps
from .springs import Backlash, CubicSpring, LinearSpring, PiecewiseSpring

__all__ = ["link_forward", "encode_friction", "encode_ripple", "encode_spring"]

_KERNEL = None
SPRING_POLY, SPRING_PIECEWISE, SPRING_BOUC_WEN = 0, 1, 2


def encode_friction(fr) -> np.ndarray | None:
    """(10,) c_pos, c_neg, v_pos, v_neg, s_pos, s_neg, vs_pos, vs_neg, exponent, eps of a friction
    law the kernel runs, or None. A :class:`.PositionDependent` law is its base's, the ripple
    apart (:func:`encode_ripple`), when the ripple never takes either Coulomb level below zero."""
    if type(fr) is PositionDependent:
        a = encode_friction(fr.base)
        if a is None or float(np.abs(fr.amplitudes).sum()) > min(a[0], a[1]):
            return None
        return a
    eps = float(getattr(fr, "smoothing", 0.0) or 0.0)
    t = type(fr)
    if t is CoulombViscous:
        a = (fr.c, fr.c, fr.v, fr.v, 0.0, 0.0, 1.0, 1.0, 2.0)
    elif t is AsymmetricCoulombViscous:
        a = (fr.c_pos, fr.c_neg, fr.v_pos, fr.v_neg, 0.0, 0.0, 1.0, 1.0, 2.0)
    elif t is Stribeck:
        a = (fr.fc, fr.fc, fr.fv, fr.fv, fr.fs - fr.fc, fr.fs - fr.fc, fr.vs, fr.vs, fr.exponent)
    elif t is AsymmetricStribeck:
        a = (fr.fc_pos, fr.fc_neg, fr.fv_pos, fr.fv_neg, fr.fs_pos - fr.fc_pos, fr.fs_neg - fr.fc_neg, fr.vs_pos,
             fr.vs_neg, fr.exponent)
    else:
        return None
    a = np.array(a + (eps,), dtype=np.float64)
    if not (np.isfinite(a).all() and (a[:4] >= 0).all() and (a[6:8] > 0).all() and a[8] >= 1.0 and eps >= 0
            and (a[:2] + a[4:6] >= 0).all()):
        return None
    return a


def encode_ripple(fr) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(orders, amplitudes, phases + pi / 2) of a :class:`.PositionDependent` law's ripple, each
    (K,), so that the kernel's sine sum (the transmission error's, with N = 1) gives its cosines;
    empty for any other law."""
    if type(fr) is PositionDependent:
        return (np.asarray(fr.orders, dtype=np.float64), np.asarray(fr.amplitudes, dtype=np.float64),
                np.asarray(fr.phases, dtype=np.float64) + 0.5 * math.pi)
    return np.zeros(0), np.zeros(0), np.zeros(0)


def encode_spring(sp) -> tuple[int, np.ndarray, float] | None:
    """(kind, params (6,), gap) of a spring the kernel runs, or None."""
    gap = 0.0
    if type(sp) is Backlash:
        gap, sp = float(sp.gap), sp.spring
    t = type(sp)
    if t is LinearSpring:
        kind, p = SPRING_POLY, (sp.k, 0.0, sp.offset)
    elif t is CubicSpring:
        kind, p = SPRING_POLY, (sp.k1, sp.k3, 0.0)
    elif t is PiecewiseSpring:
        kind, p = SPRING_PIECEWISE, (sp.k1, sp.k2, sp.k3, *sp.breakpoints)
    elif t is BoucWen and sp.n == 1.0:
        kind, p = SPRING_BOUC_WEN, (sp.k, sp.alpha, sp.beta, sp.gamma, sp.A)
    else:
        return None
    p = np.array(p + (0.0,) * (6 - len(p)), dtype=np.float64)
    if not (np.isfinite(p).all() and p[0] > 0 and math.isfinite(gap)):
        return None
    return kind, p, gap


def _engaged_py(d, gap):  # pragma: no cover - compiled
    if gap <= 0.0:
        return d
    hg = 0.5 * gap
    if d > hg:
        return d - hg
    if d < -hg:
        return d + hg
    return 0.0

def _bouc_wen_step_py(z, d0, d1, beta, gamma, A):  # pragma: no cover - compiled
    """z after the (engaged) deflection moves linearly from d0 to d1 (n = 1, exact)."""
    x = abs(d1 - d0)
    if x == 0.0:
        return z
    s = 1.0 if d1 > d0 else -1.0
    y = s * z                                    # the state in the direction of motion
    lam = beta + gamma
    kap = gamma - beta
    while x > 0.0:
        if y >= 0.0:                             # loading: dy/dx = A - lam y
            yi = A / lam
            y = yi + (y - yi) * math.exp(-lam * x)
            x = 0.0
        else:                                    # unloading: dy/dx = A + kap y, up to y = 0
            if abs(kap) * x < 1e-12:
                x0 = -y / A
            else:
                arg = A + kap * y
                x0 = math.log(A / arg) / kap if arg > 0.0 else np.inf
            if x0 >= x:
                if abs(kap) * x < 1e-12:
                    y = y + A * x
                else:
                    y = (y + A / kap) * math.exp(kap * x) - A / kap
                x = 0.0
            else:
                y = 0.0
                x -= x0
    return s * y

def _spring_torque_py(kind, P, gap, d, z):  # pragma: no cover - compiled
    e = _engaged(d, gap)
    if kind == 0:
        return P[0] * (e - P[2]) + P[1] * e * e * e
    if kind == 1:
        a = abs(e)
        sg = 1.0 if e >= 0.0 else -1.0
        th1 = P[3]
        th2 = P[4]
        if a <= th1:
            return sg * P[0] * a
        tau1 = P[0] * th1
        if a <= th2:
            return sg * (tau1 + P[1] * (a - th1))
        return sg * (tau1 + P[1] * (th2 - th1) + P[2] * (a - th2))
    return P[0] * (P[1] * e + (1.0 - P[1]) * z)

def _te_value_py(qm, N, amps, phases, orders):  # pragma: no cover - compiled
    s = 0.0
    for j in range(amps.shape[0]):
        s += amps[j] * math.sin(orders[j] * N * qm + phases[j])
    return s


def _run_py(q_m, qd_m, dt, n_sub, I, mglx, mgly, fr, kind, P, gap, N, amps, phases, orders, q0, w0,
            ctx, cI, cgx, cgy, cex, r_orders, r_amps, r_phases):  # pragma: no cover
    T = q_m.shape[0]
    q_out = np.empty(T)
    w_out = np.empty(T)
    tau_out = np.empty(T)
    h = dt / n_sub
    eps = fr[9]
    expo = fr[8]
    I_min = I
    if ctx:
        I_min = I + cI.min()
    rip = r_amps.shape[0] > 0                    # a Coulomb ripple with the link angle (encode_ripple)
    if eps > 0.0 and h * (max(fr[0] + fr[4], fr[1] + fr[5]) + np.abs(r_amps).sum()) > eps * I_min:
        eps = 0.0                                # stiffer than the step resolves: sign
    bw = kind == 2
    q = q0
    w = w0
    z = 0.0
    dl0 = q_m[0] + _te_value(q_m[0], N, amps, phases, orders) - q
    d_prev = _engaged(dl0, gap)
    q_out[0] = q
    w_out[0] = w
    tau_out[0] = _spring_torque(kind, P, gap, dl0, z)
    Ii = I
    gx = mglx
    gy = mgly
    tx = 0.0
    for i in range(1, T):
        a = q_m[i - 1]
        b = q_m[i]
        ma = qd_m[i - 1] * dt
        mb = qd_m[i] * dt
        for s in range(n_sub):
            x = (s + 0.5) / n_sub
            x2 = x * x
            x3 = x2 * x
            if ctx:                              # the robot's terms, linear within the sample
                Ii = I + cI[i - 1] + x * (cI[i] - cI[i - 1])
                gx = mglx + cgx[i - 1] + x * (cgx[i] - cgx[i - 1])
                gy = mgly + cgy[i - 1] + x * (cgy[i] - cgy[i - 1])
                tx = cex[i - 1] + x * (cex[i] - cex[i - 1])
            qm = ((2 * x3 - 3 * x2 + 1) * a + (x3 - 2 * x2 + x) * ma + (-2 * x3 + 3 * x2) * b + (x3 - x2) * mb)
            qmt = qm + _te_value(qm, N, amps, phases, orders)
            qmid = q + 0.5 * h * w
            dl = qmt - qmid
            if bw:
                de = _engaged(dl, gap)
                z = _bouc_wen_step(z, d_prev, de, P[2], P[3], P[4])
                d_prev = de
            F = _spring_torque(kind, P, gap, dl, z) + gx * math.sin(qmid) - gy * math.cos(qmid)
            if ctx:
                F += tx
            p = Ii * w + h * F                   # momentum without friction
            rp = _te_value(qmid, 1.0, r_amps, r_phases, r_orders) if rip else 0.0      # the Coulomb ripple
            if eps > 0.0:
                # Ii w1 + h fr((w + w1) / 2) = p, fr(x) = C(x) tanh(x / eps) + V(x) x: Newton
                w1 = w
                for _ in range(60):
                    wf = 0.5 * (w + w1)
                    j = 0 if wf >= 0.0 else 1
                    r = (abs(wf) / fr[6 + j]) ** expo
                    ex = math.exp(-r)
                    C = fr[j] + rp + fr[4 + j] * ex
                    dC = 0.0
                    if fr[4 + j] != 0.0 and wf != 0.0:
                        dC = -fr[4 + j] * ex * expo * r / wf
                    th = math.tanh(wf / eps)
                    g = Ii * w1 + h * (C * th + fr[2 + j] * wf) - p
                    dg = Ii + 0.5 * h * (C * (1.0 - th * th) / eps + fr[2 + j] + dC * th)
                    if dg < 0.5 * Ii:
                        dg = 0.5 * Ii
                    dw1 = g / dg
                    w1 -= dw1
                    if abs(dw1) <= 1e-12 * (abs(w1) + eps):
                        break
                q = qmid + 0.5 * h * w1
                w = w1
            elif w != 0.0:
                sg = 1.0 if w > 0.0 else -1.0
                j = 0 if w > 0.0 else 1
                C = fr[j] + rp + fr[4 + j] * math.exp(-(abs(w) / fr[6 + j]) ** expo)
                mass = Ii + 0.5 * h * fr[2 + j]
                rhs = p - 0.5 * h * fr[2 + j] * w
                w1 = (rhs - sg * h * C) / mass
                if fr[4 + j] != 0.0 and w1 * sg > 0.0:
                    # the Stribeck excess at the step's mid speed (implicit midpoint, as the
                    # smoothed law's): at the starting speed the scheme is first order in it, and
                    # a breakaway of twice the Coulomb level at 0.04 rad/s stuck the link 0.8 mrad
                    # away from where it sticks (module docstring)
                    for _ in range(30):
                        wm = 0.5 * (w + w1)
                        if wm * sg <= 0.0:
                            break
                        r = (abs(wm) / fr[6 + j]) ** expo
                        ex = math.exp(-r)
                        g = mass * w1 - rhs + sg * h * (fr[j] + rp + fr[4 + j] * ex)
                        dg = mass - 0.5 * h * sg * fr[4 + j] * ex * expo * r / wm
                        if dg < 0.5 * mass:
                            dg = 0.5 * mass
                        dw1 = g / dg
                        w1 -= dw1
                        if abs(dw1) <= 1e-12 * (abs(w1) + abs(w)):
                            break
                if w1 * sg >= 0.0:               # slides one way all along
                    q = qmid + 0.5 * h * w1
                    w = w1
                else:                            # reaches rest within the step
                    frac = w / (w - w1)
                    h2 = h * (1.0 - frac)
                    q_stop = q + 0.5 * h * frac * w
                    F2 = (_spring_torque(kind, P, gap, qmt - q_stop, z) + gx * math.sin(q_stop)
                          - gy * math.cos(q_stop))
                    if ctx:
                        F2 += tx
                    j2 = 0 if F2 > 0.0 else 1
                    static = fr[j2] + fr[4 + j2] + (_te_value(q_stop, 1.0, r_amps, r_phases, r_orders) if rip else 0.0)
                    if abs(F2) <= static:        # sticks
                        w = 0.0
                        q = q_stop
                    else:                        # turns: the friction flips at the stop
                        sg2 = 1.0 if F2 > 0.0 else -1.0
                        w = h2 * (F2 - sg2 * static) / (Ii + 0.5 * h2 * fr[2 + j2])
                        q = q_stop + 0.5 * h2 * w
            else:                                # at rest: sticks or breaks away
                j = 0 if F > 0.0 else 1
                static = fr[j] + rp + fr[4 + j]
                if abs(F) > static:
                    sg = 1.0 if F > 0.0 else -1.0
                    w = h * (F - sg * static) / (Ii + 0.5 * h * fr[2 + j])
                    q = q + 0.5 * h * w
        q_out[i] = q
        w_out[i] = w
        dl = b + _te_value(b, N, amps, phases, orders) - q
        zz = _bouc_wen_step(z, d_prev, _engaged(dl, gap), P[2], P[3], P[4]) if bw else z
        tau_out[i] = _spring_torque(kind, P, gap, dl, zz)
    return q_out, w_out, tau_out


_engaged = _bouc_wen_step = _spring_torque = _te_value = None    # compiled by _kernel()


def _kernel():
    """The compiled kernel (numba is imported on first use). The helpers are module globals
    compiled here, so that numba's on-disk cache holds (it misses on closures)."""
    global _KERNEL, _engaged, _bouc_wen_step, _spring_torque, _te_value
    if _KERNEL is not None:
        return _KERNEL
    from numba import njit

    _engaged = njit(cache=True, inline="always")(_engaged_py)
    _bouc_wen_step = njit(cache=True)(_bouc_wen_step_py)
    _spring_torque = njit(cache=True)(_spring_torque_py)
    _te_value = njit(cache=True)(_te_value_py)
    _KERNEL = njit(cache=True)(_run_py)
    return _KERNEL


def link_forward(q_m, fs_hz: float, *, I: float, mglx: float, mgly: float, friction, spring,
                 transmission_error: TransmissionError | None = None, qd_m=None, q0: float, w0: float | None = None,
                 d_span: float = 0.0, max_phase: float = 0.05, context=None):
    """(q (T,) rad, q' (T,) rad/s, tau_s (T,) N m) of the link under the motor angle q_m (T,) rad
    sampled at fs_hz, starting at q0 (a static equilibrium: ``SingleJoint.static_link_angle``)
    with velocity w0 (default the motor's) and a virgin spring state. `friction` and `spring` are
    elements of :mod:`.friction` and :mod:`.springs` / :mod:`.hysteresis` (module docstring for
    the ones it runs); `d_span` rad bounds the deflections met (the spring's largest slope
    up to it sets the substeps, :func:`.link_response.substeps`). Raises InputError for an element it does
    not run and RuntimeError when the integration leaves the finite numbers.

    context : (I_t, mglx_t, mgly_t, tau_t), each (T,) at the samples of q_m, or None: the link of a
    robot (:mod:`mocapfj.discover.context`). The link's inertia is then I + I_t (kg m^2), its
    gravity terms mglx + mglx_t, mgly + mgly_t (N m), and tau_t N m acts on it besides (the other
    links' inertial and Coriolis torques), each linear between samples:
    (I + I_t) q'' = tau_s - F(q') + (mglx + mglx_t) sin q - (mgly + mgly_t) cos q + tau_t.
    Without it the kernel runs exactly as before (no term is added)."""
    q_m = np.ascontiguousarray(q_m, dtype=np.float64)
    if q_m.ndim != 1 or q_m.size < 3 or not np.isfinite(q_m).all():
        raise InputError(None, "q_m", "a finite (T,) motor angle with T >= 3", q_m.shape)
    fr, sp = encode_friction(friction), encode_spring(spring)
    if fr is None or sp is None:
        raise InputError(None, "friction/spring", "elements link_forward runs (mocapfj.dynamics.link_forward)",
                         f"{type(friction).__name__}, {type(spring).__name__}")
    (cI, cgx, cgy, cex), I_min = context_arrays(context, q_m.shape, I)
    ctx = context is not None
    if not (I_min > 0 and math.isfinite(I) and math.isfinite(mglx) and math.isfinite(mgly) and math.isfinite(q0)):
        raise InputError(None, "I, mglx, mgly, q0", "finite numbers, I > 0", (I_min, mglx, mgly, q0))
    kind, P, gap = sp
    qd_m = np.gradient(q_m) * fs_hz if qd_m is None else np.ascontiguousarray(qd_m, dtype=np.float64)
    dt = 1.0 / fs_hz
    if kind == SPRING_POLY:
        k = float(P[0] + max(0.0, 3.0 * P[1] * d_span ** 2))
    elif kind == SPRING_PIECEWISE:
        k = float(P[:3].max())
    else:
        k = float(P[0] * (P[1] + (1.0 - P[1]) * P[4]))
    if transmission_error is not None:
        te = transmission_error
        N, amps, phases, orders = (float(te.gear_ratio), np.asarray(te.amplitudes, dtype=np.float64),
                                   np.asarray(te.phases, dtype=np.float64), np.asarray(te.orders, dtype=np.float64))
    else:
        N, amps, phases, orders = 1.0, np.zeros(0), np.zeros(0), np.zeros(0)
    n_sub = substeps(I_min, k, dt, max_phase)
    if amps.size:
        # the transmission error's fastest order advances at most 0.5 rad per substep
        rate = float(np.max(np.abs(orders)) * N * np.max(np.abs(qd_m)))
        n_sub = max(n_sub, int(math.ceil(rate * dt / 0.5)))
    q, w, tau = _kernel()(q_m, qd_m, dt, n_sub, float(I), float(mglx), float(mgly), fr, int(kind), P, float(gap), N,
                          amps, phases, orders, float(q0), float(qd_m[0] if w0 is None else w0), ctx, cI, cgx, cgy,
                          cex, *encode_ripple(friction))
    if not (np.isfinite(q).all() and np.isfinite(tau).all()):
        raise RuntimeError("the link simulation left the finite numbers (a spring or friction law without a "
                           "stable motion under this motor trajectory)")
    return q, w, tau
