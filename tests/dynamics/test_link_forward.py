"""The compiled forward link kernel (mocapfj.dynamics.link_forward) against the general simulator
(LSODA at tight tolerances on the same equations), element by element, and against the plain
kernel of output-error identification where both apply."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj.dynamics import (AsymmetricCoulombViscous, Backlash, BoucWen, CoulombViscous, Drivetrain, LinearSpring,
                              PiecewiseSpring, PositionDependent, PrescribedMotor, SingleJoint, Stribeck,
                              TransmissionError, simulate)
from mocapfj.dynamics.link_forward import link_forward
from mocapfj.dynamics.link_response import link_response
from mocapfj.errors import InputError

FS = 1000.0
T = np.arange(0.0, 3.0, 1 / FS)
QM = 0.3 + 0.5 * np.sin(2 * np.pi * 0.3 * T) + 0.2 * np.sin(2 * np.pi * 0.9 * T + 1.0)
QD = 2 * np.pi * (0.15 * np.cos(2 * np.pi * 0.3 * T) + 0.18 * np.cos(2 * np.pi * 0.9 * T + 1.0))
# PA-10 joint 2 (Lightcap and Banks (2007), Table I)
I, MGLX, MGLY, K = 6.15, 111.64, -7.80, 1.19e4
EPS = 0.02

ELEMENTS = {
    "asymmetric": (AsymmetricCoulombViscous(c_pos=12, c_neg=6, v_pos=20, v_neg=14, smoothing=EPS), LinearSpring(K), None),
    "stribeck": (Stribeck(fc=9, fs=15, vs=0.05, fv=18, exponent=1, smoothing=EPS), LinearSpring(K), None),
    "bouc_wen": (CoulombViscous(9.28, 18.4, smoothing=EPS), BoucWen(k=K, alpha=0.7, beta=2500, gamma=2500), None),
    "backlash": (CoulombViscous(9.28, 18.4, smoothing=EPS), Backlash(4e-4, LinearSpring(K)), None),
    "piecewise": (CoulombViscous(9.28, 18.4, smoothing=EPS),
                  PiecewiseSpring(k1=8e3, k2=1.2e4, k3=1.6e4, tau1=20, tau2=60), None),
    "transmission_error": (CoulombViscous(9.28, 18.4, smoothing=EPS), LinearSpring(K),
                           TransmissionError(50, (6e-5, 3e-5), (0.3, 1.0), (1.0, 2.0))),
    # a Coulomb ripple with the link angle (discovery's position-dependent friction), over a
    # Stribeck law: before, only the general integrator ran it (36 minutes for one discovery)
    "position_dependent": (PositionDependent(Stribeck(fc=9, fs=12, vs=0.05, fv=18, exponent=2, smoothing=EPS),
                                             orders=(3.0, 7.0), amplitudes=(1.5, 0.8), phases=(0.2, 1.1)),
                           LinearSpring(K), None),
    "stribeck_free_play_bouc_wen": (Stribeck(fc=9, fs=15, vs=0.05, fv=18, exponent=2, smoothing=EPS),
                                    Backlash(3e-4, BoucWen(k=K, alpha=0.6, beta=1000, gamma=3000)), None),
}


@pytest.mark.parametrize("name", sorted(ELEMENTS))
def test_matches_the_general_simulator(name):
    """Within 1e-5 rad of LSODA (rtol 1e-8) on a PA-10 joint (deflection 5-10 mrad): a fiftieth of
    a deflection noise of 6.4e-5 rad; the spring torque within 0.1 % of its SD."""
    _check_against_lsoda(*ELEMENTS[name], max_step=1e-3)


def _check_against_lsoda(fr, sp, te, max_step):
    """The kernel's q and tau_s against LSODA (rtol 1e-8, `max_step` s) on the PA-10 joint."""
    m = SingleJoint(I=I, J=12.0, spring=sp, mglx=MGLX, mgly=MGLY, friction=fr, drivetrain=Drivetrain(transmission_error=te))
    q0 = m.static_link_angle(np.array([QM[0]]))
    ref = simulate(m, T, PrescribedMotor.from_samples(T, QM), q0=q0, qd0=[QD[0]], rtol=1e-8, atol=1e-11, max_step=max_step)
    q, _, tau = link_forward(QM, FS, I=I, mglx=MGLX, mgly=MGLY, friction=fr, spring=sp, transmission_error=te,
                             qd_m=QD, q0=float(q0[0]), d_span=0.02)
    assert np.abs(q - ref.q[:, 0]).max() < 1e-5
    assert np.abs(tau - ref.tau_s[:, 0]).max() < 1e-3 * ref.tau_s[:, 0].std()


def test_plain_joint_is_the_identification_kernel():
    """Coulomb-viscous (sign law) with a linear spring: the same scheme as link_response, to
    rounding."""
    q1, _ = link_response(QM, FS, I=I, mglx=MGLX, mgly=MGLY, c=9.28, v=18.4, k=K, qd_m=QD)
    q2, _, _ = link_forward(QM, FS, I=I, mglx=MGLX, mgly=MGLY, friction=CoulombViscous(9.28, 18.4),
                            spring=LinearSpring(K), qd_m=QD, q0=float(q1[0]))
    assert np.abs(q1 - q2).max() < 1e-12


def test_bouc_wen_state_is_bounded_and_matches_its_ode():
    """Through the kernel's exact state map: a deflection sweep gives the loop the state ODE gives."""
    bw = BoucWen(k=K, alpha=0.5, beta=4000, gamma=1000)
    fr = CoulombViscous(0.0, 50.0, smoothing=EPS)
    m = SingleJoint(I=I, J=12.0, spring=bw, mglx=0.0, mgly=0.0, friction=fr)
    q0 = m.static_link_angle(np.array([QM[0]]))
    q, _, tau = link_forward(QM, FS, I=I, mglx=0.0, mgly=0.0, friction=fr, spring=bw, qd_m=QD, q0=float(q0[0]),
                             d_span=0.02)
    ode = bw.run(QM - q, T)        # the state along the kernel's own deflection, by the ODE
    assert np.abs(tau - ode).max() < 2e-3 * np.abs(ode).max()


def test_refuses_what_it_does_not_run():
    with pytest.raises(InputError, match="friction/spring"):
        link_forward(QM, FS, I=I, mglx=0, mgly=0, friction=CoulombViscous(1, 1),
                     spring=BoucWen(k=K, alpha=0.5, beta=1, gamma=1, n=2.0), q0=0.0)


def test_a_fast_wave_generator_gets_the_substeps_it_needs():
    """N = 160: the second order of the transmission error runs at up to 800 rad/s, 0.8 rad per
    millisecond sample; the kernel substeps it and stays within 1e-5 rad of LSODA."""
    te = TransmissionError(160, (6e-5, 3e-5), (0.3, 1.0), (1.0, 2.0))
    _check_against_lsoda(CoulombViscous(9.28, 18.4, smoothing=EPS), LinearSpring(K), te, max_step=2e-4)


def test_a_sticking_stribeck_law_agrees_with_itself_at_fifty_times_the_substeps():
    """The sign law with a breakaway of twice the Coulomb level at 0.04 rad/s (exponent 2), on the
    PA-10 joint at 200 Hz through slow reversals where it sticks: the Stribeck excess taken at the
    substep's mid speed, the kernel at its default substeps is within 3e-5 rad (RMS 1e-5) of
    itself at 50 times as many (2.3e-5, 5.3e-6; at the starting speed, first order: 6.8e-4 and
    1.7e-4). A stuck phase begins where the slide before it ended, so an error there lasts until
    the link breaks free again."""
    fs = 200.0
    t = np.arange(0.0, 12.0, 1 / fs)
    qm = 0.4 * np.sin(2 * np.pi * 0.1 * t) + 0.1 * np.sin(2 * np.pi * 0.3 * t + 0.5)
    qd = 2 * np.pi * (0.04 * np.cos(2 * np.pi * 0.1 * t) + 0.03 * np.cos(2 * np.pi * 0.3 * t + 0.5))
    fr = Stribeck(fc=9.0, fs=18.0, vs=0.04, fv=23.0, exponent=2.0, smoothing=1e-5)
    m = SingleJoint(I=I, J=12.0, spring=LinearSpring(K), mglx=MGLX, mgly=MGLY, friction=fr)
    q0 = float(m.static_link_angle(np.array([qm[0]]))[0])
    run = [link_forward(qm, fs, I=I, mglx=MGLX, mgly=MGLY, friction=fr, spring=LinearSpring(K), qd_m=qd, q0=q0,
                        d_span=0.02, max_phase=mp)[0] for mp in (0.05, 0.001)]
    err = run[0] - run[1]
    stuck = np.mean(np.abs(np.gradient(run[1], 1 / fs)) < 1e-4)
    assert stuck > 0.05, stuck                            # it does stick
    assert np.abs(err).max() < 3e-5 and np.sqrt(np.mean(err ** 2)) < 1e-5, (np.abs(err).max(), np.sqrt(np.mean(err ** 2)))
