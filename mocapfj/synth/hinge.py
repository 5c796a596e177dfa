"""A flexible joint alone, seen by one marker cluster: synthetic recordings for robustness grids.

No arm, no cameras, no mesh: one link turns about an arbitrary axis of the world on a flexible
joint (Lightcap and Banks (2007), eq. 4, the signs of docs/conventions.md),

    I q'' - mglx sin(q) + mgly cos(q) + c sgn(q') + v q' = tau_s          (link)
    J q_m'' + b q_m' + tau_s = u                                           (motor)
    tau_s = k (q_m - q)                                                    (spring, eq. 7)

driven by a PD loop on the motor angle that follows a finite Fourier reference (Lightcap and Banks
(2007), eq. 9; :func:`mocapfj.synth.scenario.reference_trajectory`), so the motor does not follow
the reference exactly. What a lab would record:

- the controller log at ``controller_hz``: q_m resolver-quantised (2 pi / (2^bits N)) plus white
  noise, and u with white, coloured (AR(1), correlation time tau_c) or quantised-current noise;
- the markers at ``mocap_hz``: marker p at ``point + R(axis, q(t) + mocap_zero) @ template[p]``
  plus white noise per coordinate, lost (NaN) in bursts. The cluster's orientation at q = 0 is
  arbitrary (``mocap_zero_rad``), so the mocap link angle and the motor angle differ by an
  unknown constant.

:class:`HingeCase` holds everything that defines one recording; :func:`simulate_hinge` makes the
:class:`~mocapfj.types.Recording` and its truth; :func:`write_hinge_bundle` writes the bundle,
``truth.json`` and ``truth_mocap.csv`` (the true signals at the mocap instants).
Randomness comes only from numpy Generators spawned (``SeedSequence``) from ``HingeCase.seed``, so
one case always gives a byte-identical bundle.

Grid sampling (:func:`sample_cases`)
------------------------------------
Case ``i`` of ``sample_cases(n, base_seed)`` depends only on ``(base_seed, i)``: growing ``n``
keeps the earlier cases. Each quantity is drawn independently (U = uniform, logU = log-uniform):

| quantity | rule |
|---|---|
| family | in blocks of 13 cases, shuffled per block: 4 ``pa10`` (a), 4 ``cobot`` (b), 4 ``heavy`` (c), 1 ``vertical`` (d) (1/13 = 7.7 %) |
| (a) ``pa10`` | PA-10 joint 2 (Lightcap and Banks (2007), Table I): I 6.15 kg m2, J 12.57 kg m2, mglx 111.64 N m, mgly -7.80 N m, b 23.28 N m s, c 9.28 N m, v 18.38 N m s, k 1.19e4 N m/rad, N 50; each x U(0.8, 1.2) |
| (b) ``cobot`` | ~2 kg, 0.3 m link: I 0.35, J 0.2, mglx 5.5, mgly 0.4, b 0.8, c 0.6, v 0.5, k 4.5e3, N 120; each x U(0.7, 1.3) |
| (c) ``heavy`` | I 180, J 60, mglx 4000, mgly -300, b 300, c 150, v 400, k 1.08e6, N 200; each x U(0.7, 1.3) |
| (d) ``vertical`` | (a) or (b) at random, each x U(0.75, 1.25), mglx = mgly = 0 |
| friction law | ``sign`` (p = 1/2; integrated as tanh(q'/1e-5 rad/s)) or ``tanh`` with eps logU(0.002, 0.05) rad/s |
| f0 | U(0.05, 0.3) Hz; harmonics: integer U{3..10} |
| peak amplitude | U(10, 60) deg about q0; q0 U(-45, 45) deg |
| harmonics | a_l = w_l / l^p, w_l U(0.3, 1), phases U(0, 2 pi), scaled to the peak; p = 1, raised by 0.25 (to 3) while the reference's peak acceleration exceeds the family's cap (pa10 20, cobot 40, heavy 10 rad/s2) |
| duration | a whole number of periods n_p / f0, n_p integer U within [max(2, 20 f0), 120 f0], rounded to 0.1 s (20-120 s, >= 2 periods); ramp U(1, 3) s |
| PD gains | loop bandwidth f_c logU(3, 30) Hz, damping zeta U(0.6, 1.0), on the total inertia I + J: kp = (I + J) (2 pi f_c)^2, kd = 2 zeta (I + J) (2 pi f_c) |
| torque noise | SD = logU(lo, hi) N m, [lo, hi] = [0.05, 6] N m (the range a lab's drives log) intersected with [0.1, 3] % of the RMS of u estimated from the reference with the rigid model ((I + J) r'' + (b + v) r' + c sgn(r') + gravity) (a drive's noise scales with its size); kind ``white`` / ``coloured`` (AR(1), tau_c logU(2, 50) ms) / ``quantised`` (quantum Delta with Delta^2/12 = U(0.3, 0.9) of the variance, the rest white, added before quantising), p = 1/3 each |
| motor angle | resolver bits in {14, 16, 18}; extra white noise 0 (p = 1/2) or logU(1e-5, 1e-4) rad |
| markers | 3-5 (integer U); noise U(0.1, 0.5) mm per coordinate; dropouts U(0, 3) % of samples in bursts of mean length U(1, 20) frames |
| cluster | radius scale r_c logU(50 sqrt 3, 800 / sqrt 3) mm, r_p = r_c 3^(U - 1/2) (50-800 mm, within a factor 3); heights along the axis U(-r_c/2, r_c/2); azimuths evenly spaced + U(-0.3, 0.3) of the spacing |
| axis, point | axis uniform on the sphere; point uniform in the ball of radius 2 m |
| mocap zero | U(-pi, pi) rad |
| rates | mocap_hz in {100, 120, 200, 250}, controller_hz in {500, 1000} |

The ranges are physical ones, fixed before and without reference to any identification method:
the grid is meant to test estimators, not to be tuned to them.

The PD rule treats the loop as the rigid inertia I + J (motor and link move together below the
joint's resonance sqrt(k (1/I + 1/J))); with f_c above the resonance the motor is held stiffly and
the link rings on the spring at sqrt(k/I). The PD acts on the motor angle only (collocated), and
its stiffness in series with the spring, kp k / (kp + k), exceeds the gravity gradient
sqrt(mglx^2 + mgly^2) by a wide margin in every sampled case. There is no feedforward, so gravity and inertia show up as tracking error.
Every run starts at rest at the PD/gravity equilibrium (no start transient).

So the torque noise's SD spans about 0.05-0.15 N m for the cobot, 0.1-3 N m for the PA-10 and 4-6 N m
for the heavy joint (whose u RMS is a few thousand N m). The cobot's
deflection (~1e-3 rad) is often below the per-sample mocap angle noise (sigma / sqrt(sum r_p^2));
``truth["stats"]["deflection_snr"]`` gives the ratio per case.

:func:`first_row_case` is the reference row (PA-10 joint 2 exactly, 40 s); :func:`small_grid`
five short cases, one per family, for fast tests.

Example
-------
>>> from mocapfj.synth.hinge import first_row_case, simulate_hinge
>>> from dataclasses import replace
>>> rec, truth = simulate_hinge(replace(first_row_case(1), duration_s=4.0))
>>> rec.markers.xyz.shape[1:], truth["params"]["k"]
((4, 3), 11900.0)
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..dynamics import (PID, AsymmetricCoulombViscous, Backlash, BoucWen, CoulombViscous, CubicSpring, Drivetrain,
                        LinearSpring, SingleJoint, Stribeck, TransmissionError, simulate)
from ..errors import InputError
from ..io import write_csv_columns, write_json, write_recording
from ..rotations import rotate
from ..types import WORLD, ControllerLog, JointSpec, MarkerTrajectories, Recording
from .scenario import reference_trajectory

__all__ = ["HingeCase", "FAMILIES", "PARAMETER_NAMES", "simulate_hinge", "write_hinge_bundle", "sample_cases",
           "first_row_case", "small_grid", "fourier_from_peak", "pd_gains", "case_digest", "GENERATOR_VERSION",
           "logged_torque", "dropout_mask", "with_spring", "SPRINGS", "FRICTION_KINDS", "deflection_noise_sd"]

PARAMETER_NAMES = ("I", "mglx", "mgly", "c", "v", "J", "b", "k")
FRICTION_LAWS = ("sign", "tanh")
NOISE_KINDS = ("white", "coloured", "quantised")
SPRINGS = {"linear": 0, "cubic": 1, "bouc_wen": 3}
"""Spring kinds and how many spring_params each takes."""
FRICTION_KINDS = {"coulomb_viscous": 0, "stribeck": 3, "asymmetric": 2}
"""Link friction kinds and how many friction_params each takes (see :class:`HingeCase`)."""
_EFFECT_DEFAULTS = {"friction_kind": "coulomb_viscous", "friction_params": (), "backlash_rad": 0.0,
                    "te_amplitudes_rad": (), "te_phases_rad": (), "te_orders": ()}

FAMILIES = {
    # PA-10 joint 2, Lightcap and Banks (2007), Table I
    "pa10": dict(params=dict(I=6.15, J=12.57, mglx=111.64, mgly=-7.80, b=23.28, c=9.28, v=18.38, k=1.19e4),
                 gear_ratio=50.0, spread=0.20, accel_max=20.0),
    # a light cobot joint: ~2 kg link, 0.3 m to its centre of mass
    "cobot": dict(params=dict(I=0.35, J=0.2, mglx=5.5, mgly=0.4, b=0.8, c=0.6, v=0.5, k=4.5e3),
                  gear_ratio=120.0, spread=0.30, accel_max=40.0),
    # a heavy industrial joint
    "heavy": dict(params=dict(I=180.0, J=60.0, mglx=4000.0, mgly=-300.0, b=300.0, c=150.0, v=400.0, k=1.08e6),
                  gear_ratio=200.0, spread=0.30, accel_max=10.0),
}
"""Nominal parameters (SI, link side), gear ratio, per-case relative spread and the reference's
peak-acceleration cap (rad/s^2) of each family; ``vertical`` borrows pa10 or cobot without gravity."""

FAMILY_NAMES = ("pa10", "cobot", "heavy", "vertical")
_BLOCK = ("vertical",) + ("pa10",) * 4 + ("cobot",) * 4 + ("heavy",) * 4
SIGN_SIM_SMOOTHING = 1e-5
"""rad/s: the ``sign`` law is integrated as tanh(q' / 1e-5 rad/s), indistinguishable from sign(q')
at the recorded rates (a stiff but smooth right-hand side for LSODA; eps = 0 makes LSODA fail)."""


def _tuple(x, n=None, name="") -> tuple[float, ...]:
    t = tuple(float(v) for v in np.asarray(x, dtype=np.float64).ravel())
    if n is not None and len(t) != n:
        raise InputError(None, name, f"{n} numbers", len(t))
    if not all(math.isfinite(v) for v in t):
        raise InputError(None, name, "finite numbers", t)
    return t


@dataclass(frozen=True)
class HingeCase:
    """Everything that defines one synthetic hinge recording (SI units, link side of the gear).

    Joint (Lightcap and Banks (2007), eq. 4)
        I, J : kg m^2 link and motor inertia; mglx, mgly : N m gravity moments; b : N m s/rad motor
        viscous friction; c : N m Coulomb level; v : N m s/rad link viscous friction; k : N m/rad
        spring; gear_ratio : N (only the resolver quantum depends on it);
        friction_law : "sign" or "tanh" (c tanh(q'/eps)); eps_rad_s : eps of the tanh law (0 for
        sign); sim_smoothing_rad_s : the eps the ``sign`` law is integrated with.
    Excitation (motor reference, Lightcap and Banks (2007), eq. 9)
        f0_hz, amplitudes_rad (H,), phases_rad (H,) : q_ref = q0 + s(t) sum_l a_l [sin(l w t +
        phi_l) - sin(phi_l)]; q0_rad : offset; duration_s; ramp_s : the smooth start s(t).
        `peak_rad` documents the peak |q_ref - q0| the amplitudes were scaled to (see
        :func:`fourier_from_peak`); empty amplitudes with a peak derive them from the seed.
    Control
        kp N m/rad, kd N m s/rad : PD on the motor angle (no integral, no feedforward).
    Measurement
        mocap_hz, controller_hz : Hz; marker_noise_m : white per coordinate, m;
        dropout_fraction : share of marker samples lost; dropout_burst_frames : mean burst length;
        torque_noise_Nm : SD of the logged torque's error, N m; torque_noise_kind : "white",
        "coloured" (AR(1) with correlation time torque_corr_time_s) or "quantised" (quantum
        torque_quantum_Nm, the rest of the variance white noise added before quantising);
        motor_noise_rad : white noise on the logged q_m on top of the resolver quantisation, rad;
        resolver_bits : q_m quantum 2 pi / (2^bits N).
    Geometry
        marker_radii_m (P,), marker_heights_m (P,), marker_azimuths_rad (P,) : the cluster in
        cylinder coordinates about the axis (P = 3..5); axis (3,) unit direction in the world;
        point_m (3,) : a point of the axis, m; mocap_zero_rad : rotation of the cluster at q = 0.
    Integration
        sim_max_step_s : LSODA's largest step (None: min(5 ms, 0.1 / fastest mode)); sim_rtol.
    Effects beyond the linear joint (all off by default)
        spring, spring_params : ``cubic`` (k3,) or ``bouc_wen`` (alpha, beta, gamma), see
        :meth:`spring_element`; friction_kind, friction_params : ``coulomb_viscous`` (), ``stribeck``
        (excess N m, vs rad/s, exponent): F = (c + excess exp(-|q'/vs|^exponent)) sgn(q') + v q',
        or ``asymmetric`` (dc N m, dv N m s/rad): Coulomb c + dc and viscous v + dv for q' > 0,
        c - dc and v - dv for q' < 0; backlash_rad : total free play in front of the spring, rad;
        te_amplitudes_rad, te_phases_rad, te_orders : kinematic transmission error
        e = sum a sin(n N q_m + phi), the spring seeing q_m + e - q and the motor (1 + e') tau_s.
    """

    name: str
    seed: int
    family: str
    # joint
    I: float
    J: float
    mglx: float
    mgly: float
    b: float
    c: float
    v: float
    k: float
    gear_ratio: float
    friction_law: str = "sign"
    eps_rad_s: float = 0.0
    sim_smoothing_rad_s: float = SIGN_SIM_SMOOTHING
    # excitation
    f0_hz: float = 0.1
    amplitudes_rad: tuple[float, ...] = ()
    phases_rad: tuple[float, ...] = ()
    peak_rad: float = 0.0
    n_harmonics: int = 5
    q0_rad: float = 0.0
    duration_s: float = 40.0
    ramp_s: float = 2.0
    # control
    kp: float = 0.0
    kd: float = 0.0
    # measurement
    mocap_hz: float = 250.0
    controller_hz: float = 1000.0
    marker_noise_m: float = 2e-4
    dropout_fraction: float = 0.0
    dropout_burst_frames: float = 5.0
    torque_noise_Nm: float = 0.0
    torque_noise_kind: str = "white"
    torque_corr_time_s: float = 0.0
    torque_quantum_Nm: float = 0.0
    motor_noise_rad: float = 0.0
    resolver_bits: int = 16
    # geometry
    marker_radii_m: tuple[float, ...] = (0.1, 0.15, 0.2)
    marker_heights_m: tuple[float, ...] = (0.0, 0.0, 0.0)
    marker_azimuths_rad: tuple[float, ...] = (0.0, 2.1, 4.2)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    point_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mocap_zero_rad: float = 0.0
    # integration
    sim_max_step_s: float | None = None
    sim_rtol: float = 1e-8
    # spring (the joint's small-deflection stiffness is k in every case)
    spring: str = "linear"
    spring_params: tuple[float, ...] = ()
    # further effects (left out of to_dict at their defaults, so older cases keep their digests)
    friction_kind: str = "coulomb_viscous"
    friction_params: tuple[float, ...] = ()
    backlash_rad: float = 0.0
    te_amplitudes_rad: tuple[float, ...] = ()
    te_phases_rad: tuple[float, ...] = ()
    te_orders: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        for n in ("I", "J", "k", "gear_ratio", "f0_hz", "duration_s", "mocap_hz", "controller_hz", "kp",
                  "sim_rtol", "sim_smoothing_rad_s"):
            if not (math.isfinite(getattr(self, n)) and getattr(self, n) > 0):
                raise InputError(None, f"HingeCase.{n}", "a positive number", getattr(self, n))
        for n in ("b", "c", "v", "kd", "ramp_s", "marker_noise_m", "dropout_fraction", "torque_noise_Nm",
                  "torque_corr_time_s", "torque_quantum_Nm", "motor_noise_rad", "eps_rad_s", "peak_rad"):
            if not (math.isfinite(getattr(self, n)) and getattr(self, n) >= 0):
                raise InputError(None, f"HingeCase.{n}", "a non-negative number", getattr(self, n))
        if self.spring not in SPRINGS or len(tuple(self.spring_params)) != SPRINGS[self.spring]:
            raise InputError(None, "HingeCase.spring", f"one of {sorted(SPRINGS)} with {SPRINGS} parameters",
                             (self.spring, self.spring_params))
        object.__setattr__(self, "spring_params", _tuple(self.spring_params, name="spring_params"))
        if self.friction_kind not in FRICTION_KINDS or len(tuple(self.friction_params)) != FRICTION_KINDS[self.friction_kind]:
            raise InputError(None, "HingeCase.friction_kind", f"one of {sorted(FRICTION_KINDS)} with "
                             f"{FRICTION_KINDS} parameters", (self.friction_kind, self.friction_params))
        object.__setattr__(self, "friction_params", _tuple(self.friction_params, name="friction_params"))
        if self.friction_kind == "stribeck" and not (self.friction_params[1] > 0 and self.friction_params[2] > 0):
            raise InputError(None, "HingeCase.friction_params", "a positive Stribeck velocity and exponent",
                             self.friction_params)
        if self.friction_kind == "asymmetric" and not (abs(self.friction_params[0]) <= self.c
                                                       and abs(self.friction_params[1]) <= self.v):
            raise InputError(None, "HingeCase.friction_params", "|dc| <= c and |dv| <= v", self.friction_params)
        if not (math.isfinite(self.backlash_rad) and self.backlash_rad >= 0):
            raise InputError(None, "HingeCase.backlash_rad", "a non-negative number", self.backlash_rad)
        te = [_tuple(getattr(self, n), name=n) for n in ("te_amplitudes_rad", "te_phases_rad", "te_orders")]
        if len({len(x) for x in te}) != 1:
            raise InputError(None, "HingeCase.te_*", "amplitudes, phases and orders of equal length",
                             [len(x) for x in te])
        for n, x in zip(("te_amplitudes_rad", "te_phases_rad", "te_orders"), te):
            object.__setattr__(self, n, x)
        if self.friction_law not in FRICTION_LAWS:
            raise InputError(None, "HingeCase.friction_law", f"one of {FRICTION_LAWS}", repr(self.friction_law))
        if self.friction_law == "tanh" and not self.eps_rad_s > 0:
            raise InputError(None, "HingeCase.eps_rad_s", "eps > 0 for the tanh law", self.eps_rad_s)
        if self.torque_noise_kind not in NOISE_KINDS:
            raise InputError(None, "HingeCase.torque_noise_kind", f"one of {NOISE_KINDS}", repr(self.torque_noise_kind))
        if self.torque_noise_kind == "coloured" and self.torque_noise_Nm > 0 and not self.torque_corr_time_s > 0:
            raise InputError(None, "HingeCase.torque_corr_time_s", "a positive correlation time", 0.0)
        if self.torque_noise_kind == "quantised" and self.torque_quantum_Nm ** 2 / 12 > self.torque_noise_Nm ** 2 * (1 + 1e-9):
            raise InputError(None, "HingeCase.torque_quantum_Nm", "a quantum with Delta^2/12 <= torque_noise_Nm^2",
                             self.torque_quantum_Nm)
        if not 0 <= self.dropout_fraction < 0.5 or not self.dropout_burst_frames >= 1:
            raise InputError(None, "HingeCase.dropout", "a fraction in [0, 0.5) and bursts >= 1 frame",
                             (self.dropout_fraction, self.dropout_burst_frames))
        object.__setattr__(self, "resolver_bits", int(self.resolver_bits))
        object.__setattr__(self, "n_harmonics", int(self.n_harmonics))
        amps, phases = _tuple(self.amplitudes_rad, name="amplitudes_rad"), _tuple(self.phases_rad, name="phases_rad")
        if not amps:
            if not self.peak_rad > 0 or self.n_harmonics < 1:
                raise InputError(None, "HingeCase.amplitudes_rad", "harmonic amplitudes, or a peak and n_harmonics",
                                 "none")
            fam = FAMILIES.get(self.family, FAMILIES["pa10"])
            rng = np.random.default_rng(np.random.SeedSequence([self.seed, 7]))
            a, p = fourier_from_peak(self.peak_rad, self.n_harmonics, self.f0_hz, rng, accel_max=fam["accel_max"])
            amps, phases = _tuple(a), _tuple(p)
        if len(phases) != len(amps):
            raise InputError(None, "HingeCase.phases_rad", f"{len(amps)} phases", len(phases))
        object.__setattr__(self, "amplitudes_rad", amps)
        object.__setattr__(self, "phases_rad", phases)
        object.__setattr__(self, "n_harmonics", len(amps))
        P = len(_tuple(self.marker_radii_m))
        if not 3 <= P <= 5:
            raise InputError(None, "HingeCase.marker_radii_m", "3 to 5 markers", P)
        for n in ("marker_radii_m", "marker_heights_m", "marker_azimuths_rad"):
            object.__setattr__(self, n, _tuple(getattr(self, n), P, f"HingeCase.{n}"))
        if min(self.marker_radii_m) <= 0:
            raise InputError(None, "HingeCase.marker_radii_m", "positive radii", self.marker_radii_m)
        ax = np.asarray(_tuple(self.axis, 3, "HingeCase.axis"))
        if not np.linalg.norm(ax) > 0:
            raise InputError(None, "HingeCase.axis", "a non-zero direction", self.axis)
        object.__setattr__(self, "axis", _tuple(ax / np.linalg.norm(ax)))
        object.__setattr__(self, "point_m", _tuple(self.point_m, 3, "HingeCase.point_m"))

    # ---------------------------------------------------------------- derived
    @property
    def params(self) -> dict[str, float]:
        """The parameters to recover, {I, mglx, mgly, c, v, J, b, k} (SI)."""
        return {n: float(getattr(self, n)) for n in PARAMETER_NAMES}

    @property
    def gravity_magnitude(self) -> float:
        """sqrt(mglx^2 + mgly^2), N m."""
        return float(math.hypot(self.mglx, self.mgly))

    @property
    def n_markers(self) -> int:
        return len(self.marker_radii_m)

    @property
    def labels(self) -> tuple[str, ...]:
        return tuple(f"H{p + 1}" for p in range(self.n_markers))

    def reference(self) -> dict:
        """The reference table of :func:`mocapfj.synth.scenario.reference_trajectory`."""
        return {"f0_hz": self.f0_hz, "q0_rad": self.q0_rad, "amplitudes_rad": self.amplitudes_rad,
                "phases_rad": self.phases_rad, "ramp_s": self.ramp_s}

    def spring_element(self):
        """The spring: linear k; ``cubic`` k delta + k3 delta^3 (spring_params = (k3,), N m/rad^3);
        ``bouc_wen`` with scale k and spring_params = (alpha, beta, gamma) (A = n = 1)."""
        if self.spring == "cubic":
            return CubicSpring(k1=self.k, k3=self.spring_params[0])
        if self.spring == "bouc_wen":
            a, b, g = self.spring_params
            return BoucWen(k=self.k, alpha=a, beta=b, gamma=g)
        return LinearSpring(self.k)

    def friction_element(self):
        """The link friction, smoothed as integrated (see `friction_kind`)."""
        eps = self.eps_rad_s if self.friction_law == "tanh" else self.sim_smoothing_rad_s
        if self.friction_kind == "stribeck":
            excess, vs, e = self.friction_params
            return Stribeck(fc=self.c, fs=self.c + excess, vs=vs, fv=self.v, exponent=e, smoothing=eps)
        if self.friction_kind == "asymmetric":
            dc, dv = self.friction_params
            return AsymmetricCoulombViscous(c_pos=self.c + dc, c_neg=self.c - dc, v_pos=self.v + dv,
                                            v_neg=self.v - dv, smoothing=eps)
        return CoulombViscous(self.c, self.v, smoothing=eps)

    def transmission_error(self) -> TransmissionError | None:
        if not self.te_amplitudes_rad:
            return None
        return TransmissionError(self.gear_ratio, self.te_amplitudes_rad, self.te_phases_rad, self.te_orders)

    def model(self) -> SingleJoint:
        """The true joint as a :class:`SingleJoint`, friction smoothed as integrated."""
        spring = self.spring_element()
        if self.backlash_rad > 0:
            spring = Backlash(self.backlash_rad, spring)
        return SingleJoint(I=self.I, J=self.J, spring=spring, mglx=self.mglx, mgly=self.mgly,
                           b=self.b, friction=self.friction_element(),
                           drivetrain=Drivetrain(transmission_error=self.transmission_error()), name="j1")

    def natural_frequency_hz(self) -> float:
        """sqrt(k (1/I + 1/J)) / 2 pi, Hz: the motor and the link swinging against each other."""
        return math.sqrt(self.k * (1 / self.I + 1 / self.J)) / (2 * math.pi)

    def max_step_s(self) -> float:
        """LSODA's largest step: `sim_max_step_s`, or min(5 ms, a tenth of the fastest period among
        the joint's resonance, the locked-motor link mode sqrt(k/I) and the PD loop)."""
        if self.sim_max_step_s is not None:
            return float(self.sim_max_step_s)
        f_loop = math.sqrt(self.kp / (self.I + self.J)) / (2 * math.pi)
        f_fast = max(self.natural_frequency_hz(), math.sqrt(self.k / self.I) / (2 * math.pi), f_loop)
        return float(min(5e-3, 0.1 / f_fast))

    def template_m(self) -> np.ndarray:
        """(P, 3) m: the markers relative to `point_m` at mocap angle 0 (link angle -mocap_zero)."""
        n = np.asarray(self.axis)
        e1, e2 = _basis(n)
        r, h, a = (np.asarray(getattr(self, f)) for f in ("marker_radii_m", "marker_heights_m", "marker_azimuths_rad"))
        return r[:, None] * (np.cos(a)[:, None] * e1 + np.sin(a)[:, None] * e2) + h[:, None] * n

    def to_dict(self) -> dict:
        d = asdict(self)
        for n, v in _EFFECT_DEFAULTS.items():
            if d[n] == v:
                del d[n]
        return d


GENERATOR_VERSION = 2
"""Bumped whenever the same case would give a different bundle; part of :func:`case_digest`."""


def case_digest(case: HingeCase) -> str:
    """SHA-256 of the case's fields (JSON, sorted keys) and GENERATOR_VERSION: a bundle cache key."""
    doc = {"case": case.to_dict(), "generator_version": GENERATOR_VERSION}
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def _basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (3,) completing the unit axis n to a right-handed frame (e1, e2, n)."""
    h = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(n, h)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


# ---------------------------------------------------------------------------- excitation and gains
def fourier_from_peak(peak_rad: float, n_harmonics: int, f0_hz: float, rng: np.random.Generator, *,
                      accel_max: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Harmonic amplitudes (H,) rad and phases (H,) rad of a reference whose peak |q_ref - q0| over
    a period is `peak_rad`.

    a_l = w_l / l^p with w_l ~ U(0.3, 1) and phases ~ U(0, 2 pi), scaled to the peak; p starts at 1
    and rises by 0.25 (up to 3) while the peak acceleration exceeds `accel_max` rad/s^2 (the
    fundamental alone may still exceed it).
    """
    n = int(n_harmonics)
    w_rel = rng.uniform(0.3, 1.0, n)
    phases = rng.uniform(0.0, 2 * np.pi, n)
    l = np.arange(1, n + 1)
    w = 2 * np.pi * f0_hz * l
    tt = np.linspace(0.0, 1.0 / f0_hz, 128 * n + 1)
    S = np.sin(tt[:, None] * w + phases)
    for p in np.arange(1.0, 3.0001, 0.25):
        a = w_rel / l ** p
        a = a * peak_rad / np.max(np.abs((S - np.sin(phases)) @ a))
        acc = float(np.max(np.abs(S @ (a * w ** 2))))
        if accel_max is None or acc <= accel_max:
            break
    return a, phases


def pd_gains(I: float, J: float, bandwidth_hz: float, zeta: float) -> tuple[float, float]:
    """(kp N m/rad, kd N m s/rad) of a motor PD loop with natural frequency `bandwidth_hz` and
    damping `zeta` on the total inertia I + J: kp = (I + J) w^2, kd = 2 zeta (I + J) w."""
    w = 2 * np.pi * bandwidth_hz
    return float((I + J) * w * w), float(2 * zeta * (I + J) * w)


def _pd_equilibrium(case: HingeCase) -> tuple[float, float]:
    """(q_m0, q0) rad: the joint at rest under the PD loop at the reference's start, gravity held
    by the spring (friction at rest is 0 for the smoothed laws):
    kp (q_ref0 - q_m) = k (q_m - q) = G(q)."""
    r = case.q0_rad
    q = r
    for _ in range(100):
        g = -case.mglx * math.sin(q) + case.mgly * math.cos(q)
        qm = r - g / case.kp
        q_new = qm + _te(case, qm) - _spring_deflection(case, g)
        if abs(q_new - q) < 1e-15:
            q = q_new
            break
        q = q_new
    g = -case.mglx * math.sin(q) + case.mgly * math.cos(q)
    return r - g / case.kp, q


def _te(case: HingeCase, q_m: float) -> float:
    te = case.transmission_error()
    return 0.0 if te is None else float(te.error(q_m))


def _spring_deflection(case: HingeCase, tau: float) -> float:
    """The deflection at which the spring holds `tau` from rest (a Bouc-Wen spring's state 0),
    with the free play's half width on the side of `tau`."""
    return _engaged_deflection(case, tau) + math.copysign(case.backlash_rad / 2, tau)


def _engaged_deflection(case: HingeCase, tau: float) -> float:
    if case.spring == "bouc_wen":
        return tau / (case.spring_params[0] * case.k)
    d = tau / case.k
    if case.spring == "cubic":
        k3 = case.spring_params[0]
        for _ in range(50):                       # Newton on k d + k3 d^3 = tau
            d -= (case.k * d + k3 * d ** 3 - tau) / (case.k + 3 * k3 * d * d)
    return d


def _rigid_torque_rms(params: dict, ref: dict, duration_s: float) -> float:
    """RMS of u, N m, predicted from the reference with the rigid model
    (I + J) r'' + (b + v) r' + c sgn(r') - mglx sin r + mgly cos r, sampled at 200 Hz."""
    fn = reference_trajectory(ref)
    t = np.arange(0.0, duration_s, 5e-3)
    r, rd = fn(t)
    rdd = np.gradient(rd, t)
    p = params
    u = ((p["I"] + p["J"]) * rdd + (p["b"] + p["v"]) * rd + p["c"] * np.sign(rd) - p["mglx"] * np.sin(r)
         + p["mgly"] * np.cos(r))
    return float(np.sqrt(np.mean(u * u)))


# ---------------------------------------------------------------------------- simulation
def _last_value(fn):
    """fn with a one-entry cache for scalar t: the PD loop asks for the reference twice per
    right-hand-side call (torque and error); same values, half the cost."""
    last: list = [None, None]

    def g(t):
        if np.ndim(t) != 0:
            return fn(t)
        t = float(t)
        if last[0] != t:
            last[0], last[1] = t, fn(t)
        return last[1]

    return g


def _times(duration_s: float, rate_hz: float) -> np.ndarray:
    return np.arange(int(np.floor(duration_s * rate_hz + 1e-9)) + 1) / rate_hz


def logged_torque(case: HingeCase, u: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The logged torque (T,) N m: u (T,) with the case's noise (SD torque_noise_Nm for every kind)."""
    sd = case.torque_noise_Nm
    if sd == 0:
        return u.copy()
    e = rng.standard_normal(u.shape)
    if case.torque_noise_kind == "white":
        return u + sd * e
    if case.torque_noise_kind == "coloured":
        from scipy.signal import lfilter

        a = math.exp(-1.0 / (case.controller_hz * case.torque_corr_time_s))
        # AR(1) x_k = a x_(k-1) + sqrt(1 - a^2) sd e_k, started in its stationary distribution
        x = lfilter([math.sqrt(1 - a * a) * sd], [1.0, -a], e[1:], zi=[a * sd * e[0]])[0]
        return u + np.concatenate([[sd * e[0]], x])
    quantum = case.torque_quantum_Nm
    white = math.sqrt(max(sd * sd - quantum * quantum / 12, 0.0))
    y = u + white * e
    return quantum * np.round(y / quantum) if quantum > 0 else y


def dropout_mask(shape: tuple[int, int], fraction: float, burst: float, rng: np.random.Generator) -> np.ndarray:
    """(T, M) bool, True where a sample is lost: bursts start with probability fraction / burst per
    sample and last a geometric number of frames of mean `burst`."""
    T = shape[0]
    if fraction <= 0:
        return np.zeros(shape, bool)
    starts = rng.random(shape) < fraction / burst
    until = np.full(shape, -1, dtype=np.int64)
    ti, mi = np.nonzero(starts)
    until[ti, mi] = ti + rng.geometric(1.0 / burst, ti.size)
    return np.maximum.accumulate(until, axis=0) > np.arange(T)[:, None]


def simulate_hinge(case: HingeCase) -> tuple[Recording, dict]:
    """Simulate one case: the recording a lab would get and the truth behind it.

    The true joint (:meth:`HingeCase.model`) is integrated by :func:`mocapfj.dynamics.simulate`
    (LSODA, step <= :meth:`HingeCase.max_step_s`, rtol `sim_rtol`) under the PD loop, from rest at
    the PD/gravity equilibrium, with output at the union of the controller and mocap instants
    (both clocks start at 0; no clock offset).

    Returns
    -------
    recording : Recording
        One joint "j1" (controller columns qm_j1, tau_j1; link markers H1..HP; parent "world"),
        markers (T_m, P, 3) m with NaN where lost, controller log (T_c, 1).
    truth : dict
        JSON-ready facts (``params``, ``family``, ``case``, ``noise``, ``geometry``, ``stats``)
        plus ``signals`` (numpy arrays, not written to truth.json): ``mocap`` {t, q, qd, q_m, u,
        tau_s} at the mocap instants and ``controller`` {t, q, qd, qdd, q_m, qd_m, qdd_m, u, tau_s,
        delta} at the controller instants, all true values (rad, rad/s, rad/s^2, N m).
    """
    rng_markers, rng_drop, rng_torque, rng_motor = (np.random.default_rng(s)
                                                    for s in np.random.SeedSequence(case.seed).spawn(4))
    t_ctrl = _times(case.duration_s, case.controller_hz)
    t_moc = _times(case.duration_s, case.mocap_hz)
    t_all = np.union1d(t_ctrl, t_moc)
    i_ctrl, i_moc = np.searchsorted(t_all, t_ctrl), np.searchsorted(t_all, t_moc)
    ref = reference_trajectory(case.reference())
    qm0, q0 = _pd_equilibrium(case)
    drive = PID(_last_value(ref), kp=case.kp, kd=case.kd)
    res = simulate(case.model(), t_all, drive, q0=[q0], qd0=[0.0], q_m0=[qm0], qd_m0=[0.0],
                   max_step=case.max_step_s(), rtol=case.sim_rtol, atol=case.sim_rtol * 1e-2)
    sig = {f: getattr(res, f)[:, 0] for f in ("q", "qd", "qdd", "q_m", "qd_m", "qdd_m", "u", "tau_s", "delta")}

    # controller log
    quantum = 2 * np.pi / (2.0 ** case.resolver_bits * case.gear_ratio)
    q_m_true, u_true = sig["q_m"][i_ctrl], sig["u"][i_ctrl]
    q_m_log = quantum * np.round(q_m_true / quantum)
    if case.motor_noise_rad > 0:
        q_m_log = q_m_log + rng_motor.normal(0.0, case.motor_noise_rad, q_m_log.shape)
    tau_log = logged_torque(case, u_true, rng_torque)
    controller = ControllerLog(t=t_ctrl, q_m=q_m_log[:, None], tau=tau_log[:, None], joint_names=("j1",))

    # markers: point + R(axis, q + zero) @ template + noise, lost in bursts
    q_moc = sig["q"][i_moc]
    template = case.template_m()
    clean = np.asarray(case.point_m) + rotate(case.axis, (q_moc + case.mocap_zero_rad)[:, None], template[None])
    noise = rng_markers.normal(0.0, case.marker_noise_m, clean.shape) if case.marker_noise_m > 0 else 0.0
    xyz = clean + noise
    lost = dropout_mask(xyz.shape[:2], case.dropout_fraction, case.dropout_burst_frames, rng_drop)
    xyz[lost] = np.nan
    markers = MarkerTrajectories(t=t_moc, xyz=xyz, labels=case.labels, rate_hz=case.mocap_hz)

    joint = JointSpec(name="j1", motor_position="qm_j1", motor_torque="tau_j1", gear_ratio=case.gear_ratio,
                      link_markers=case.labels, parent_markers=WORLD)
    rec = Recording(name=case.name, markers=markers, controller=controller, joints=(joint,),
                    spec={"synthetic": {"generator": "mocapfj.synth.hinge", "case": case.name, "seed": case.seed}})

    angle_sigma, deflection_noise = _angle_sigma(case), deflection_noise_sd(case)
    u_rms = float(np.sqrt(np.mean(u_true ** 2)))
    truth = {
        "generator": "mocapfj.synth.hinge",
        "generator_version": GENERATOR_VERSION,
        "name": case.name,
        "family": case.family,
        "params": case.params,
        "gravity_magnitude_Nm": case.gravity_magnitude,
        "gear_ratio": case.gear_ratio,
        "friction": {"law": case.friction_law, "eps_rad_s": case.eps_rad_s,
                     "integrated_eps_rad_s": case.eps_rad_s if case.friction_law == "tanh" else case.sim_smoothing_rad_s},
        "joint": "j1",
        "link_markers": list(case.labels),
        "noise": {
            "marker_noise_m": case.marker_noise_m,
            "angle_sigma_rad": angle_sigma,
            "q_m_quantum_rad": quantum,
            "motor_noise_rad": case.motor_noise_rad,
            "deflection_noise_sd_rad": deflection_noise,
            "torque_noise_Nm": case.torque_noise_Nm,
            "torque_noise_kind": case.torque_noise_kind,
            "torque_noise_realised_Nm": float(np.std(tau_log - u_true)),
            "torque_noise_pct_of_rms": 100 * case.torque_noise_Nm / u_rms if u_rms > 0 else 0.0,
            "dropout_fraction_realised": float(lost.mean()),
        },
        "geometry": {"axis": list(case.axis), "point_m": list(case.point_m), "radii_m": list(case.marker_radii_m),
                     "mocap_zero_rad": case.mocap_zero_rad, "template_m": template,
                     "mocap_angle": "q_mocap = q + mocap_zero_rad (q at which the markers sit at template_m)"},
        "stats": {
            "torque_rms_Nm": u_rms,
            "spring_torque_rms_Nm": float(np.sqrt(np.mean(sig["tau_s"][i_ctrl] ** 2))),
            "deflection_std_rad": float(np.std(sig["delta"][i_ctrl])),
            "deflection_snr": float(np.std(sig["delta"][i_ctrl])) / deflection_noise,
            "link_angle_range_rad": [float(q_moc.min()), float(q_moc.max())],
            "link_velocity_rms_rad_s": float(np.sqrt(np.mean(sig["qd"][i_ctrl] ** 2))),
            "tracking_error_rms_rad": float(np.sqrt(np.mean((ref(t_ctrl)[0] - q_m_true) ** 2))),
            "natural_frequency_hz": case.natural_frequency_hz(),
            "pd_bandwidth_hz": math.sqrt(case.kp / (case.I + case.J)) / (2 * math.pi),
            "initial_state": {"q_rad": q0, "q_m_rad": qm0},
        },
        "case": case.to_dict(),
        "case_sha256": case_digest(case),
        "files": {"truth_mocap": "truth_mocap.csv"},
        "signals": {
            "mocap": {"t": t_moc, "q": q_moc, **{f: sig[f][i_moc] for f in ("qd", "q_m", "u", "tau_s")}},
            "controller": {"t": t_ctrl, **{f: v[i_ctrl] for f, v in sig.items()}},
        },
    }
    return rec, truth


def write_hinge_bundle(case: HingeCase, out_dir: str | os.PathLike[str]) -> Path:
    """Simulate `case` and write its bundle in `out_dir`: truth.json (without the signal arrays),
    truth_mocap.csv (t, q, qd, q_m, u, tau_s at the mocap instants, true values) and then the
    recording (:func:`mocapfj.io.write_recording`, recording.toml last). Returns recording.toml."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rec, truth = simulate_hinge(case)
    sig = truth.pop("signals")
    write_csv_columns(out / "truth_mocap.csv", {("t_mocap" if k == "t" else f"{k}_j1"): v for k, v in sig["mocap"].items()})
    write_json(out / "truth.json", truth)
    return write_recording(rec, out)


# ---------------------------------------------------------------------------- grid sampling
def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _family_params(rng: np.random.Generator, family: str) -> tuple[dict, float, float, str]:
    """(params, gear_ratio, accel_max, base family) of one case of `family`, varied per case."""
    if family == "vertical":
        base = ("pa10", "cobot")[int(rng.integers(2))]
        spread = 0.25
    elif family in FAMILIES:
        base, spread = family, FAMILIES[family]["spread"]
    else:
        raise InputError(None, "family", f"one of {FAMILY_NAMES}", repr(family))
    fam = FAMILIES[base]
    p = {n: float(v * rng.uniform(1 - spread, 1 + spread)) for n, v in fam["params"].items()}
    if family == "vertical":
        p["mglx"] = p["mgly"] = 0.0
    return p, float(fam["gear_ratio"]), float(fam["accel_max"]), base


def _sample_case(rng: np.random.Generator, seed: int, name: str, family: str, *,
                 f0_range=(0.05, 0.3), duration_range=(20.0, 120.0), friction_law: str | None = None,
                 noise_kind: str | None = None) -> HingeCase:
    """One case drawn with `rng` by the rules of the module docstring."""
    p, gear, accel_max, _ = _family_params(rng, family)
    law = friction_law or FRICTION_LAWS[int(rng.integers(2))]
    eps = _log_uniform(rng, 0.002, 0.05) if law == "tanh" else 0.0
    # excitation: a whole number of periods within the duration range
    while True:
        f0 = float(rng.uniform(*f0_range))
        lo, hi = math.ceil(max(2.0, duration_range[0] * f0)), math.floor(duration_range[1] * f0)
        if lo <= hi:
            break
    duration = round(int(rng.integers(lo, hi + 1)) / f0, 1)
    n_h = int(rng.integers(3, 11))
    peak = math.radians(rng.uniform(10.0, 60.0))
    q0 = math.radians(rng.uniform(-45.0, 45.0))
    amps, phases = fourier_from_peak(peak, n_h, f0, rng, accel_max=accel_max)
    ramp = float(rng.uniform(1.0, 3.0))
    ref = {"f0_hz": f0, "q0_rad": q0, "amplitudes_rad": amps, "phases_rad": phases, "ramp_s": ramp}
    kp, kd = pd_gains(p["I"], p["J"], _log_uniform(rng, 3.0, 30.0), float(rng.uniform(0.6, 1.0)))
    # measurement
    u_rms = _rigid_torque_rms(p, ref, duration)
    hi = min(6.0, 0.03 * u_rms)
    lo = min(max(0.05, 1e-3 * u_rms), hi)
    tau_sd = _log_uniform(rng, lo, hi) if hi > lo else hi
    kind = noise_kind or NOISE_KINDS[int(rng.integers(3))]
    corr = _log_uniform(rng, 2e-3, 50e-3) if kind == "coloured" else 0.0
    quantum = tau_sd * math.sqrt(12 * rng.uniform(0.3, 0.9)) if kind == "quantised" else 0.0
    motor_noise = 0.0 if rng.random() < 0.5 else _log_uniform(rng, 1e-5, 1e-4)
    # geometry
    P = int(rng.integers(3, 6))
    r_c = _log_uniform(rng, 0.05 * math.sqrt(3), 0.8 / math.sqrt(3))
    radii = r_c * 3.0 ** (rng.uniform(0, 1, P) - 0.5)
    heights = rng.uniform(-0.5, 0.5, P) * r_c
    azimuths = rng.uniform(0, 2 * np.pi) + 2 * np.pi / P * (np.arange(P) + rng.uniform(-0.3, 0.3, P))
    axis = rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    d = rng.standard_normal(3)
    point = d / np.linalg.norm(d) * 2.0 * rng.random() ** (1 / 3)
    return HingeCase(
        name=name, seed=seed, family=family, gear_ratio=gear, **p,
        friction_law=law, eps_rad_s=eps,
        f0_hz=f0, amplitudes_rad=tuple(amps), phases_rad=tuple(phases), peak_rad=peak, n_harmonics=n_h, q0_rad=q0,
        duration_s=duration, ramp_s=ramp, kp=kp, kd=kd,
        mocap_hz=float(rng.choice([100.0, 120.0, 200.0, 250.0])), controller_hz=float(rng.choice([500.0, 1000.0])),
        marker_noise_m=float(rng.uniform(1e-4, 5e-4)), dropout_fraction=float(rng.uniform(0.0, 0.03)),
        dropout_burst_frames=float(rng.uniform(1.0, 20.0)),
        torque_noise_Nm=tau_sd, torque_noise_kind=kind, torque_corr_time_s=corr, torque_quantum_Nm=quantum,
        motor_noise_rad=motor_noise, resolver_bits=int(rng.choice([14, 16, 18])),
        marker_radii_m=tuple(radii), marker_heights_m=tuple(heights), marker_azimuths_rad=tuple(azimuths),
        axis=tuple(axis), point_m=tuple(point), mocap_zero_rad=float(rng.uniform(-np.pi, np.pi)),
    )


def _case_streams(base_seed: int, i: int) -> tuple[np.random.Generator, int]:
    """(sampling Generator, simulation seed) of case i: both from SeedSequence([base_seed, i])."""
    s_sample, s_sim = np.random.SeedSequence([int(base_seed), int(i)]).spawn(2)
    return np.random.default_rng(s_sample), int(s_sim.generate_state(1, np.uint32)[0])


def _family_of(base_seed: int, i: int) -> str:
    """Case i's family: blocks of 13 (1 vertical, 4 of each other family), shuffled per block."""
    block = np.random.default_rng(np.random.SeedSequence([int(base_seed), i // len(_BLOCK), 13])).permutation(
        len(_BLOCK))
    return _BLOCK[int(block[i % len(_BLOCK)])]


def _angle_sigma(case: HingeCase) -> float:
    """SD of the mocap link angle per sample, rad (the markers' noise over the cluster's radii)."""
    return case.marker_noise_m / float(np.sqrt(np.sum(np.asarray(case.marker_radii_m) ** 2)))


def deflection_noise_sd(case: HingeCase) -> float:
    """The per-sample SD of the measured deflection q_m - q, rad: the mocap angle's, the resolver's
    quantisation (2 pi / (2^bits N)) and the motor angle's white noise together (truth.json's
    ``noise.deflection_noise_sd_rad``, without simulating)."""
    quantum = 2 * np.pi / (2.0 ** case.resolver_bits * case.gear_ratio)
    return float(np.sqrt(_angle_sigma(case) ** 2 + quantum ** 2 / 12 + case.motor_noise_rad ** 2))


def sample_cases(n: int, base_seed: int, *, family: str | None = None) -> list[HingeCase]:
    """`n` cases of the robustness grid (rules in the module docstring), named
    ``hinge_<base_seed>_<i>``; case i depends only on (base_seed, i, family).

    family : None (the mixture: pa10, cobot, heavy 4/13 each, vertical 1/13) or one of
        "pa10", "cobot", "heavy", "vertical" for all cases.
    """
    if family is not None and family not in FAMILY_NAMES:
        raise InputError(None, "family", f"None or one of {FAMILY_NAMES}", repr(family))
    out = []
    for i in range(int(n)):
        rng, seed = _case_streams(base_seed, i)
        fam = family or _family_of(base_seed, i)
        out.append(_sample_case(rng, seed, f"hinge_{base_seed}_{i:03d}", fam))
    return out


def with_spring(case: HingeCase, kind: str, seed: int = 0) -> HingeCase:
    """`case` with a nonlinear spring of the same small-deflection stiffness k, sized to the
    deflection the case's torque causes (delta_rms ~ torque RMS / k, from the rigid model):

    - ``cubic``: stiffening by U(30, 80) % at 2 delta_rms (k3 = r k / (3 (2 delta_rms)^2));
    - ``bouc_wen``: alpha U(0.5, 0.8), beta = gamma, the hysteretic state saturating at
      U(0.3, 1) delta_rms (beta + gamma = 1 / that);
    - ``linear``: unchanged.
    Drawn from `seed` alone; the name gets the kind appended."""
    if kind == "linear":
        return case
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 17]))
    p = case.params
    d_rms = _rigid_torque_rms(p, case.reference(), case.duration_s) / case.k
    if kind == "cubic":
        r = rng.uniform(0.3, 0.8)
        params = (r * case.k / (3 * (2 * d_rms) ** 2),)
    elif kind == "bouc_wen":
        a = rng.uniform(0.5, 0.8)
        sat = rng.uniform(0.3, 1.0) * d_rms
        params = (a, 0.5 / sat, 0.5 / sat)
    else:
        raise InputError(None, "kind", f"one of {sorted(SPRINGS)}", repr(kind))
    from dataclasses import replace

    return replace(case, name=f"{case.name}_{kind}", spring=kind, spring_params=params)


def first_row_case(seed: int = 0) -> HingeCase:
    """The reference row: PA-10 joint 2 exactly (Lightcap and Banks (2007), Table I), 40 s, a motor
    Fourier reference of 0.1 Hz x 5 harmonics peaking at +-50 deg, torque noise 0.5 N m white,
    markers 0.2 mm (4 markers, 120-300 mm), mocap 250 Hz, controller 1000 Hz, resolver 16 bits,
    sign friction, PD at 10 Hz (zeta 0.8), dropouts 0.2 % in bursts of 5 frames. The seed sets the
    harmonic phases, the cluster's pose (axis, point, mocap zero) and the noise."""
    rng, sim_seed = _case_streams(seed, 10**6)
    p = dict(FAMILIES["pa10"]["params"])
    amps, phases = fourier_from_peak(math.radians(50.0), 5, 0.1, rng, accel_max=FAMILIES["pa10"]["accel_max"])
    kp, kd = pd_gains(p["I"], p["J"], 10.0, 0.8)
    axis = rng.standard_normal(3)
    d = rng.standard_normal(3)
    return HingeCase(
        name=f"hinge_first_row_{seed}", seed=sim_seed, family="pa10", gear_ratio=50.0, **p, friction_law="sign",
        f0_hz=0.1, amplitudes_rad=tuple(amps), phases_rad=tuple(phases), peak_rad=math.radians(50.0), n_harmonics=5,
        q0_rad=0.0, duration_s=40.0, ramp_s=2.0, kp=kp, kd=kd, mocap_hz=250.0, controller_hz=1000.0,
        marker_noise_m=2e-4, dropout_fraction=0.002, dropout_burst_frames=5.0, torque_noise_Nm=0.5,
        torque_noise_kind="white", motor_noise_rad=0.0, resolver_bits=16,
        marker_radii_m=(0.12, 0.18, 0.24, 0.30), marker_heights_m=(0.02, -0.03, 0.04, -0.01),
        marker_azimuths_rad=tuple(rng.uniform(0, 2 * np.pi) + np.arange(4) * np.pi / 2),
        axis=tuple(axis / np.linalg.norm(axis)), point_m=tuple(d / np.linalg.norm(d) * 2.0 * rng.random() ** (1 / 3)),
        mocap_zero_rad=float(rng.uniform(-np.pi, np.pi)),
    )


_SMALL = (("pa10", "sign", "white"), ("cobot", "tanh", "coloured"), ("heavy", "sign", "quantised"),
          ("vertical", "tanh", "white"), ("pa10", "tanh", "quantised"))


def small_grid(base_seed: int = 0) -> list[HingeCase]:
    """Five short cases (20-30 s, f0 0.1-0.3 Hz) for fast tests: pa10 / sign / white,
    cobot / tanh / coloured, heavy / sign / quantised, vertical / tanh / white, pa10 / tanh /
    quantised; everything else drawn by the grid's rules."""
    out = []
    for i, (fam, law, kind) in enumerate(_SMALL):
        rng, seed = _case_streams(base_seed, 10**6 + 1 + i)
        out.append(_sample_case(rng, seed, f"hinge_small_{base_seed}_{i}", fam, f0_range=(0.1, 0.3),
                                duration_range=(20.0, 30.0), friction_law=law, noise_kind=kind))
    return out
