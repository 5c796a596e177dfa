"""The link kernel of output-error identification (mocapfj.dynamics.link_response): second order
in the step with and without Coulomb friction, sensitivities equal to finite differences (the
sign law's reversals included), and the same link motion as the project's LSODA simulator."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mocapfj.dynamics.link_response import N_SENS, link_response
from mocapfj.errors import InputError

FS = 250.0
T = np.arange(0.0, 20.0, 1.0 / FS)
Q_M = 0.8 * np.sin(2 * np.pi * 0.3 * T) + 0.2 * np.sin(2 * np.pi * 1.1 * T + 1.0)
QD_M = 0.8 * 2 * np.pi * 0.3 * np.cos(2 * np.pi * 0.3 * T) + 0.2 * 2 * np.pi * 1.1 * np.cos(2 * np.pi * 1.1 * T + 1.0)
PA10 = dict(I=6.15, mglx=111.64, mgly=-7.8, c=9.28, v=18.38, k=1.19e4)


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


@pytest.mark.parametrize("c, eps", [(0.0, 0.0), (9.28, 0.0), (9.28, 0.02)])
def test_second_order_in_the_substep(c, eps):
    """Halving the substep divides the error (against 512 substeps) by about 4: the friction's
    reversals (event-located) and its tanh form (implicit midpoint) keep the scheme second order."""
    p = dict(PA10, c=c)
    ref, _ = link_response(Q_M, FS, eps=eps, qd_m=QD_M, n_sub=512, **p)
    err = [_rms(link_response(Q_M, FS, eps=eps, qd_m=QD_M, n_sub=n, **p)[0] - ref) for n in (2, 4, 8)]
    assert 3.3 < err[0] / err[1] < 4.8 and 3.3 < err[1] / err[2] < 4.8, err
    # the default substeps keep the error near 1e-6 rad, below 0.1 % of this joint's deflection
    default, _ = link_response(Q_M, FS, eps=eps, qd_m=QD_M, **p)
    assert _rms(default - ref) < 2e-6


@pytest.mark.parametrize("eps, k3", [(0.0, 0.0), (0.01, 0.0), (0.0, 2e8), (0.01, 2e8)])
def test_sensitivities_equal_finite_differences(eps, k3):
    """d q / d (I, mglx, mgly, c, v, k, eps, k3) propagated in the kernel against central
    differences of the kernel itself (a light cobot joint: stick and slip at every reversal)."""
    p = dict(I=0.39, mglx=7.0, mgly=0.42, c=0.58, v=0.36, k=4625.0)
    _, _, Sq, _ = link_response(Q_M, FS, eps=eps, k3=k3, sensitivities=True, **p)
    assert Sq.shape == (Q_M.size, N_SENS)
    names = ("I", "mglx", "mgly", "c", "v", "k", "eps", "k3")
    for j, n in enumerate(names):
        if n == "eps" and eps == 0:              # the sign law has no eps
            assert np.all(Sq[:, j] == 0)
            continue
        base = dict(p, eps=eps, k3=k3)
        h = 1e-6 * max(abs(base[n]), 1e-3) if n != "k3" else 1e-6 * 2e8
        hi, lo = dict(base), dict(base)
        hi[n] += h
        lo[n] -= h
        fd = (link_response(Q_M, FS, **hi)[0] - link_response(Q_M, FS, **lo)[0]) / (2 * h)
        rel = np.linalg.norm(Sq[:, j] - fd) / np.linalg.norm(fd)
        assert rel < 1e-3, (n, rel)


def test_same_link_motion_as_the_lsoda_simulator():
    """The hinge generator integrates the whole joint under its PD loop with LSODA (friction as
    tanh(q'/1e-5)); driven by that run's motor angle, the kernel gives the same link angle to
    a few 1e-7 rad (0.01 % of the deflection)."""
    from mocapfj.synth.hinge import first_row_case, simulate_hinge

    case = replace(first_row_case(2), duration_s=8.0)
    _, truth = simulate_hinge(case)
    s = truth["signals"]["controller"]
    q, _ = link_response(s["q_m"], case.controller_hz, qd_m=s["qd_m"], q0=s["q"][0], w0=s["qd"][0],
                         **{n: getattr(case, n) for n in ("I", "mglx", "mgly", "c", "v", "k")})
    assert _rms(q - s["q"]) < 5e-7 < 1e-3 * np.std(s["delta"])


# a robot's joint (mocapfj.discover.context): an inertia, gravity terms and a coupling torque that
# vary with the other joints' motion
CONTEXT = (1.5 + 0.5 * np.cos(0.9 * T), 20.0 + 5.0 * np.sin(0.7 * T), 3.0 * np.cos(0.5 * T), 2.0 * np.sin(2.0 * T))


@pytest.mark.parametrize("eps", [0.0, 0.02])
def test_a_robots_joint_moves_as_link_forward_moves_it(eps):
    """With a context the kernel integrates (I + I_t) q'' = tau_s - F + (mglx + mglx_t) sin q
    - (mgly + mgly_t) cos q + tau_t, the equation link_forward (discovery's kernel, a peer written
    apart) integrates with the same context: the same link angle to 1e-9 rad; and a zero context
    is no context."""
    from mocapfj.dynamics import CoulombViscous, LinearSpring
    from mocapfj.dynamics.link_forward import link_forward

    p = dict(I=0.3, mglx=5.0, mgly=-1.0, c=2.0, v=3.0, k=2.0e4)
    q, _ = link_response(Q_M, FS, qd_m=QD_M, eps=eps, context=CONTEXT, **p)
    q_f, _, _ = link_forward(Q_M, FS, I=p["I"], mglx=p["mglx"], mgly=p["mgly"], qd_m=QD_M, q0=q[0],
                             friction=CoulombViscous(c=p["c"], v=p["v"], smoothing=eps), spring=LinearSpring(k=p["k"]),
                             context=CONTEXT)
    assert np.abs(q - q_f).max() < 1e-9 < 1e-6 * np.abs(Q_M - q).max()
    zero = tuple(np.zeros_like(T) for _ in range(4))
    assert np.array_equal(link_response(Q_M, FS, qd_m=QD_M, eps=eps, context=zero, **p)[0],
                          link_response(Q_M, FS, qd_m=QD_M, eps=eps, **p)[0])


def test_a_robots_joint_has_the_sensitivities_of_its_own_terms():
    """With a context, d q / d (I, mglx, mgly, c, v, k) of the joint's own terms (added to the
    robot's) against central differences of the kernel; its own inertia may be negative while the
    total stays positive."""
    p = dict(I=-0.4, mglx=5.0, mgly=-1.0, c=2.0, v=3.0, k=2.0e4)
    _, _, Sq, _ = link_response(Q_M, FS, qd_m=QD_M, context=CONTEXT, sensitivities=True, **p)
    for j, n in enumerate(("I", "mglx", "mgly", "c", "v", "k")):
        h = 1e-6 * max(abs(p[n]), 1.0)
        hi, lo = dict(p), dict(p)
        hi[n] += h
        lo[n] -= h
        fd = (link_response(Q_M, FS, qd_m=QD_M, context=CONTEXT, **hi)[0]
              - link_response(Q_M, FS, qd_m=QD_M, context=CONTEXT, **lo)[0]) / (2 * h)
        assert np.linalg.norm(Sq[:, j] - fd) / np.linalg.norm(fd) < 1e-3, n
    with pytest.raises(InputError, match="I > 0"):            # the total must stay positive
        link_response(Q_M, FS, context=CONTEXT, **dict(p, I=-1.1))


def test_bad_arguments():
    with pytest.raises(InputError, match="I > 0"):
        link_response(Q_M, FS, **dict(PA10, I=-1.0))
    with pytest.raises(InputError, match="q_m"):
        link_response(np.array([0.0, np.nan, 1.0, 2.0]), FS, **PA10)
