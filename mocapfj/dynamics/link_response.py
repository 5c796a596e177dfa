"""The link of one flexible joint driven by a prescribed motor motion, integrated fast: the forward
model of output-error identification, run hundreds of times per fit.

The link equation (Lightcap and Banks 2007, eq. 4; signs docs/conventions.md) with the motor angle
given (its position loop is stiff; the motor equation then gives the torque):

    I q'' + v q' + f + G(q) = tau_s(q_m - q),      G(q) = -mglx sin q + mgly cos q

with the spring tau_s(delta) = k delta + k3 delta^3 (k3 = 0: linear; k3 > 0: stiffening)

with Coulomb friction f = c sign(q') as a set-valued law: when the link is at rest and the net
torque is below c it stays at rest (sticks). That stick phase matters: at every reversal of the
motor the spring must wind by 2 c / k before the link turns back (lost motion: about 100 ms on a
PA-10 joint 2), and a smooth or lagged friction law misses it and rings at the resonance instead.
With ``eps > 0`` the law is c tanh(q' / eps).

Scheme, second order in the step h including the friction (a first-order friction treatment
leaves errors of 1e-5 rad at 250 Hz on a PA-10 joint, a few percent of its deflection):

- Stormer-Verlet: position half step, the spring and gravity at the midpoint, velocity update,
  position half step; the viscous term trapezoidal.
- ``eps = 0``: friction is constant while the link slides one way, so the step is exact in it;
  when the velocity would change sign within the step, the step is split where it reaches zero
  (velocity taken linear in the step), and the rest of the step either sticks (the net torque is
  below c) or slides the other way. From rest the link breaks away when the net torque exceeds c.
- ``eps > 0``: the friction at the step's mean velocity (implicit midpoint, solved by Newton);
  a law stiffer than the substep resolves (h c / (eps I) > 1) is sign(q') within the velocity
  the step resolves, and is integrated as such.

The motor angle is interpolated between samples by cubic Hermite with its velocity (linear
interpolation would lower the angle the spring sees by h^2 q_m'' / 12 on average: an inertia
error of k h^2 / 12, 1.7 % for a light cobot joint at 250 Hz). `n_sub` substeps per sample are
chosen so that the resonance sqrt(k / I) advances at most 0.05 rad per substep (global error
about 1e-6 rad on the grids of benchmarks/bench_identify_grid.py). The kernel is compiled with
numba: a sequential recursion has no vector form, and numpy would run it as a Python loop, about
300 times slower.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError

__all__ = ["link_response", "substeps", "context_arrays", "N_SENS"]

_KERNEL = None
N_SENS = 8
"""Parameters the sensitivities are taken with respect to, in this order: I, mglx, mgly, c, v, k,
eps (0 under the sign law), k3."""


def _kernel():
    """The compiled kernel (numba is imported on first use: it takes 0.3 s to load)."""
    global _KERNEL
    if _KERNEL is None:
        from numba import njit

        @njit(cache=True, fastmath=False)
        def run(q_m, qd_m, dt, n_sub, I0, mglx0, mgly0, c, v, k, eps, k3, q0, w0, dq0, sens,
                ctx, cI, cgx, cgy, cex):  # pragma: no cover - compiled
            T = q_m.shape[0]
            q_out = np.empty(T)
            w_out = np.empty(T)
            ns = 8 if sens else 0
            Sq = np.zeros((T, ns))
            Sw = np.zeros((T, ns))
            dq = dq0.copy()
            dw = np.zeros(8)
            dqm = np.zeros(8)
            dF = np.zeros(8)
            dp = np.zeros(8)
            dmass = np.zeros(8)
            h = dt / n_sub
            I = I0
            mglx = mglx0
            mgly = mgly0
            tx = 0.0
            I_min = I0
            if ctx:
                I_min = I0 + cI.min()
            mass = I + 0.5 * h * v
            dmass[0] = 1.0
            dmass[4] = 0.5 * h
            if eps > 0.0 and h * c > eps * I_min:
                eps = 0.0                                    # stiffer than the step resolves: sign
            q = q0
            w = w0
            q_out[0] = q
            w_out[0] = w
            if sens:
                for j in range(8):
                    Sq[0, j] = dq[j]
            for i in range(1, T):
                a = q_m[i - 1]
                b = q_m[i]
                ma = qd_m[i - 1] * dt
                mb = qd_m[i] * dt
                for s in range(n_sub):
                    x = (s + 0.5) / n_sub                    # the motor angle by cubic Hermite
                    x2 = x * x
                    x3 = x2 * x
                    if ctx:                                  # a robot's terms, linear within the sample
                        I = I0 + cI[i - 1] + x * (cI[i] - cI[i - 1])
                        mglx = mglx0 + cgx[i - 1] + x * (cgx[i] - cgx[i - 1])
                        mgly = mgly0 + cgy[i - 1] + x * (cgy[i] - cgy[i - 1])
                        tx = cex[i - 1] + x * (cex[i] - cex[i - 1])
                        mass = I + 0.5 * h * v
                    qm = ((2 * x3 - 3 * x2 + 1) * a + (x3 - 2 * x2 + x) * ma + (-2 * x3 + 3 * x2) * b
                          + (x3 - x2) * mb)
                    qmid = q + 0.5 * h * w
                    sn = math.sin(qmid)
                    cs = math.cos(qmid)
                    dl = qm - qmid
                    F = (k + k3 * dl * dl) * dl + mglx * sn - mgly * cs + tx
                    p = I * w + h * F - 0.5 * h * v * w      # momentum without friction
                    if sens:
                        dFdq = -(k + 3.0 * k3 * dl * dl) + mglx * cs + mgly * sn
                        for j in range(8):
                            dqm[j] = dq[j] + 0.5 * h * dw[j]
                            dF[j] = dFdq * dqm[j]
                        dF[5] += dl
                        dF[7] += dl * dl * dl
                        dF[1] += sn
                        dF[2] -= cs
                        for j in range(8):
                            dp[j] = I * dw[j] + h * dF[j] - 0.5 * h * v * dw[j]
                        dp[0] += w
                        dp[4] -= 0.5 * h * w
                    if eps > 0.0:
                        # mass w1 + h c tanh(wf / eps) = p with wf = (w + w1) / 2: Newton
                        w1 = w                               # the velocity changes little per substep
                        th = 0.0
                        for _ in range(50):
                            th = math.tanh(0.5 * (w + w1) / eps)
                            g = mass * w1 + h * c * th - p
                            dg = mass + 0.5 * h * c * (1.0 - th * th) / eps
                            dw1 = g / dg
                            w1 -= dw1
                            if abs(dw1) <= 1e-12 * (abs(w1) + eps):
                                break
                        if sens:
                            th = math.tanh(0.5 * (w + w1) / eps)
                            sech2 = 1.0 - th * th
                            den = mass + 0.5 * h * c * sech2 / eps
                            for j in range(8):
                                dwj = (dp[j] - dmass[j] * w1 - 0.5 * h * c * sech2 * dw[j] / eps) / den
                                if j == 3:
                                    dwj -= h * th / den
                                elif j == 6:                 # d/d eps of c tanh((w + w1) / (2 eps))
                                    dwj += h * c * sech2 * 0.5 * (w + w1) / (eps * eps) / den
                                dq[j] = dqm[j] + 0.5 * h * dwj
                                dw[j] = dwj
                        q = qmid + 0.5 * h * w1
                        w = w1
                    elif w > 0.0 or w < 0.0:
                        sg = 1.0 if w > 0.0 else -1.0
                        w1 = (p - sg * h * c) / mass
                        if w1 * sg >= 0.0:                   # slides one way all along: exact
                            if sens:
                                for j in range(8):
                                    dwj = (dp[j] - dmass[j] * w1) / mass
                                    if j == 3:
                                        dwj -= sg * h / mass
                                    dq[j] = dqm[j] + 0.5 * h * dwj
                                    dw[j] = dwj
                            q = qmid + 0.5 * h * w1
                            w = w1
                        else:                                # reaches rest within the step
                            frac = w / (w - w1)
                            h2 = h * (1.0 - frac)
                            q_stop = q + 0.5 * h * frac * w
                            sn2 = math.sin(q_stop)
                            cs2 = math.cos(q_stop)
                            d2 = qm - q_stop
                            F2 = (k + k3 * d2 * d2) * d2 + mglx * sn2 - mgly * cs2 + tx
                            a_minus = (w1 - w) / h
                            if sens:                         # at the stop: velocity linear in the step
                                for j in range(8):
                                    dw1c = (dp[j] - dmass[j] * w1) / mass
                                    if j == 3:
                                        dw1c -= sg * h / mass
                                    dws = dw[j] + frac * (dw1c - dw[j])
                                    dq[j] = dq[j] + 0.5 * h * frac * (dw[j] + dws)
                                    dw[j] = dws
                            if abs(F2) <= c:                 # sticks: its velocity no longer varies
                                w = 0.0
                                q = q_stop
                                if sens:
                                    for j in range(8):
                                        dw[j] = 0.0
                            else:                            # turns: the friction flips at the stop
                                sg2 = 1.0 if F2 > 0.0 else -1.0
                                m2 = I + 0.5 * h2 * v
                                a_plus = (F2 - sg2 * c) / m2
                                w = h2 * a_plus
                                if sens:
                                    # the stop time moves with theta: the velocity's sensitivity
                                    # jumps by the ratio of the accelerations after and before
                                    dFdq2 = -(k + 3.0 * k3 * d2 * d2) + mglx * cs2 + mgly * sn2
                                    ratio = a_plus / a_minus
                                    for j in range(8):
                                        dwe = ratio * dw[j]
                                        dF2 = dFdq2 * dq[j]
                                        if j == 5:
                                            dF2 += d2
                                        elif j == 7:
                                            dF2 += d2 * d2 * d2
                                        elif j == 1:
                                            dF2 += sn2
                                        elif j == 2:
                                            dF2 -= cs2
                                        elif j == 3:
                                            dF2 -= sg2
                                        dm2 = 1.0 if j == 0 else (0.5 * h2 if j == 4 else 0.0)
                                        dwj = dwe + h2 * (dF2 - a_plus * dm2) / m2
                                        dq[j] = dq[j] + 0.5 * h2 * (dwe + dwj)
                                        dw[j] = dwj
                                q = q_stop + 0.5 * h2 * w
                    else:                                    # at rest: sticks or breaks away
                        if abs(F) <= c:
                            w = 0.0
                            if sens:
                                for j in range(8):
                                    dw[j] = 0.0
                        else:
                            sg = 1.0 if F > 0.0 else -1.0
                            w = h * (F - sg * c) / mass
                            if sens:
                                for j in range(8):
                                    dFj = dF[j] - (sg if j == 3 else 0.0)
                                    dwj = (h * dFj - w * dmass[j]) / mass
                                    dq[j] = dq[j] + 0.5 * h * dwj
                                    dw[j] = dwj
                            q = q + 0.5 * h * w
                q_out[i] = q
                w_out[i] = w
                if sens:
                    for j in range(8):
                        Sq[i, j] = dq[j]
                        Sw[i, j] = dw[j]
            return q_out, w_out, Sq, Sw

        _KERNEL = run
    return _KERNEL


def substeps(I: float, k: float, dt: float, max_phase: float = 0.05) -> int:
    """Substeps per sample so that the resonance sqrt(k / I) advances at most `max_phase` rad."""
    return max(1, int(math.ceil(math.sqrt(k / I) * dt / max_phase)))


def link_response(q_m, fs_hz: float, *, I: float, mglx: float, mgly: float, c: float, v: float, k: float,
                  eps: float = 0.0, k3: float = 0.0, qd_m=None, q0: float | None = None, w0: float | None = None,
                  n_sub: int | None = None, sensitivities: bool = False, max_phase: float = 0.05, context=None):
    """The link's angle q (T,) rad and velocity q' (T,) rad/s under the motor angle q_m (T,) rad
    sampled at fs_hz (module docstring); `qd_m` (T,) rad/s its velocity (default: central
    differences). `max_phase`: the resonance's advance per substep (accuracy, :func:`substeps`).
    Starts at the static equilibrium of the first sample (q0 = q_m[0] + G / k) moving
    with the motor (w0 = qd_m[0]) unless given. I, k > 0 and c, v, eps >= 0 (SI, link side); k3
    (N m/rad^3) the spring's cubic term.

    With ``sensitivities=True`` it returns (q, q', dq/dtheta (T, 8), dq'/dtheta (T, 8)) for theta
    = (I, mglx, mgly, c, v, k, eps, k3), propagated through every substep (the derivative of the update;
    where the sign law stops the link within a step, the stop time's own dependence on theta is
    taken as linear in the step; a reversal without sticking carries the velocity's sensitivity
    over by the ratio of the accelerations after and before, the saltation of a friction switch;
    the default initial state's dependence on gravity and k included).

    context : (I_t, mglx_t, mgly_t, tau_t), each (T,) at the samples of q_m, or None: the link of a
    robot's joint in the motion of the others (:mod:`mocapfj.discover.context`), as
    :func:`.link_forward.link_forward` takes it: the inertia is I + I_t, the gravity terms
    mglx + mglx_t and mgly + mgly_t, and tau_t acts on the link besides, each linear between samples.
    I, mglx and mgly (the parameters the sensitivities are taken for) are then the joint's own
    terms added to the robot's, and I + min(I_t) must be positive."""
    q_m = np.ascontiguousarray(q_m, dtype=np.float64)
    if q_m.ndim != 1 or q_m.size < 3 or not np.isfinite(q_m).all():
        raise InputError(None, "q_m", "a finite (T,) motor angle with T >= 3", q_m.shape)
    ctx, I_min = context_arrays(context, q_m.shape, I)
    vals = (I_min, k, c, v, eps, mglx, mgly)
    if not (all(math.isfinite(x) for x in vals) and I_min > 0 and k > 0 and c >= 0 and v >= 0 and eps >= 0):
        raise InputError(None, "I, k, c, v, eps", "finite, I > 0, k > 0, c >= 0, v >= 0, eps >= 0", vals[:5])
    qd_m = np.gradient(q_m) * fs_hz if qd_m is None else np.ascontiguousarray(qd_m, dtype=np.float64)
    dt = 1.0 / fs_hz
    dq0 = np.zeros(N_SENS)
    if q0 is None:
        gx, gy, tx = (mglx + ctx[1][0], mgly + ctx[2][0], ctx[3][0]) if context is not None else (mglx, mgly, 0.0)
        g = -gx * math.sin(q_m[0]) + gy * math.cos(q_m[0]) - tx
        q0 = q_m[0] - g / k
        dq0[1], dq0[2], dq0[5] = math.sin(q_m[0]) / k, -math.cos(q_m[0]) / k, g / k ** 2   # (k3 neglected)
    if w0 is None:
        w0 = qd_m[0]
    if n_sub is None:
        n = substeps(I_min, k, dt, max_phase)
    else:
        n = int(n_sub)
    q, w, Sq, Sw = _kernel()(q_m, qd_m, dt, n, float(I), float(mglx), float(mgly), float(c), float(v), float(k),
                             float(eps), float(k3), float(q0), float(w0), dq0, bool(sensitivities),
                             context is not None, *ctx)
    return (q, w, Sq, Sw) if sensitivities else (q, w)


_NO_CONTEXT = tuple(np.zeros(1) for _ in range(4))


def context_arrays(context, shape, I: float) -> tuple[tuple, float]:
    """(the four context arrays of a robot's link (:func:`link_response`), or one-sample zeros
    without a context; the least link inertia I + min(I_t)). InputError unless they are four
    finite arrays of `shape`."""
    if context is None:
        return _NO_CONTEXT, I
    arrs = tuple(np.ascontiguousarray(a, dtype=np.float64) for a in context)
    if len(arrs) != 4 or not all(a.shape == shape and np.isfinite(a).all() for a in arrs):
        raise InputError(None, "context", f"four finite {shape} arrays (inertia, mglx, mgly, torque)",
                         [a.shape for a in arrs])
    return arrs, float(I + arrs[0].min())
