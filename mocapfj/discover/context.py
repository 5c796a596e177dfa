"""A joint of a URDF robot seen by discovery as its own flexible joint, in the context the other
joints of the recording give it.

The link equation of joint j of an n-link robot on flexible joints (Lightcap and Banks (2007),
eq. 1, the signs of docs/conventions.md) is

    M_jj(q) q_j'' + sum_{i != j} M_ji(q) q_i'' + c_j(q, q') + G_j(q) + F_j(q_j') = tau_s,j

with M from ``pin.crba``, c = C(q, q') q' the Coriolis and centrifugal torque
(``pin.nonLinearEffects`` less ``pin.computeGeneralizedGravity``) and G the gravity torque.
Discovery simulates each joint alone under its recorded motor angle (:func:`.model.simulate_joint`),
so the robot enters as four signals per joint, computed once per recording (:func:`robot_context`):

- the inertia I_t = M_jj(q): it does not depend on q_j (turning joint j turns its subtree rigidly
  about its own axis), only on the joints after it, so the recorded angles give it exactly;
- the gravity terms mglx_t, mgly_t: turning joint j turns the subtree's centre of mass about the
  axis, so G_j = -mglx_t sin q_j + mgly_t cos q_j exactly, with mglx_t, mgly_t functions of the
  other joints (read from G_j at q_j and at q_j + pi/2). The simulation evaluates them at its own
  link angle, as a single joint's gravity: the gravity's stiffness (dG_j/dq_j, 1-2 % of the
  spring's on a PA-10) stays in the simulated deflection;
- the torque tau_t = -(sum_{i != j} M_ji(q) q_i'' + c_j(q, q')): what the other links' motion
  puts on this one.

Measured or simulated: the configuration q is the recorded link angle (mocap, low-passed at 20
Hz), its zero set by the spring (the mean of q_m - tau_s / k, tau_s below): the joints stage
aligns the link angle's zero to the motor's, off by the mean deflection (10 mrad on the elbow),
and the motor angle itself is off by the deflection at every instant (mrad, a newton-metre on
the elbow's gravity), where the mocap noise, ~1e-4 rad after the low-pass, costs 0.01 N m. The velocities and
accelerations are not the mocap angle's: its second derivative carries its noise times
(2 pi f)^2 into the band the comparison reads. They are the motor's (the Wiener-filtered drive's
cubic spline, as the joint's own simulation takes them, :func:`.model.predict`) less the
deflection's, rebuilt from the motor side as the spring torque over the stiffness,
(g u - J q_m'' - b q_m') / k low-passed at 20 Hz (the link residual's rebuilt link angle,
:mod:`.residuals`, does the same above 2 Hz): each joint's deflection rings at its resonance and
that ringing reaches the other joints through M_ji. On a 20 s control recording of
pa10_joints23 the true model with its context scored 0.9 and 0.8 points below the noise floor
(joints 2, 3) with the motor's accelerations and the joints stage's zero, 0.2 and -0.1 with the
deflection's accelerations removed, 0.0 and -0.1 with the zero set by the spring too, as with
the true link motion (benchmarks/bench_discover_nlink.py checks it on its controls).

The model file says which joints belong to the robot (docs/discovery.md, "An effect on the
second joint of a two-joint arm"): ``urdf`` names the URDF, each joint's ``urdf_joint`` its name there (default its own);
the joint's own I, mglx, mgly are then added to the robot's (default 0: a rotor inertia on the
link side, a gravity-model correction discovery may find).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["Robot", "LinkContext", "RobotContext", "ROBOT_KEY", "robot_context", "link_motion", "robot_of",
           "urdf_joint_names"]

ROBOT_KEY = "<robot>"
"""The key of the :class:`RobotContext` in the {joint: acceleration} maps discovery passes with
each joint's signals (the other joints' terms); not a joint name (joint names are identifiers)."""


@dataclass(frozen=True)
class Robot:
    """The URDF robot a joint model belongs to.

    urdf : a URDF file path or its XML text; joints : the model's joint names of the robot's
    moving joints, in the URDF's (Pinocchio's) joint order; urdf_joints : their names in the URDF.
    """

    urdf: str
    joints: tuple[str, ...]
    urdf_joints: tuple[str, ...]

    def pin_model(self):
        """The Pinocchio model (one per URDF, kept)."""
        return _pin_model(self.urdf)


@functools.lru_cache(maxsize=4)
def _pin_model(urdf: str):
    from ..io.urdf import build_pin_model

    return build_pin_model(urdf)


def urdf_joint_names(urdf: str) -> tuple[str, ...]:
    """The moving joints' names of a URDF (path or XML), Pinocchio's order; InputError for a URDF
    that is not a chain of 1-DoF joints."""
    model = _pin_model(urdf)
    if model.nq != model.nv or any(j.nq != 1 for j in model.joints[1:]):
        raise InputError(None if urdf.lstrip().startswith("<") else urdf, "urdf",
                         "a chain of 1-DoF joints (no floating base)", f"nq={model.nq}, nv={model.nv}")
    return tuple(str(s) for s in model.names[1:])


@dataclass(frozen=True, eq=False)
class LinkContext:
    """What the robot puts on one joint's link over a recording (module docstring): I (T,) kg m^2,
    mglx, mgly (T,) N m, tau (T,) N m. Indexing with a (T,) mask or slice cuts all four."""

    I: np.ndarray
    mglx: np.ndarray
    mgly: np.ndarray
    tau: np.ndarray

    def __getitem__(self, m) -> "LinkContext":
        return LinkContext(self.I[m], self.mglx[m], self.mgly[m], self.tau[m])

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.I, self.mglx, self.mgly, self.tau

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """G_j (T,) N m at the link angle q (T,) rad."""
        return -self.mglx * np.sin(q) + self.mgly * np.cos(q)


@dataclass(frozen=True, eq=False)
class RobotContext:
    """Each robot joint's :class:`LinkContext` over one recording ({joint: LinkContext}); indexing
    with a (T,) mask or slice cuts them all (as the accelerations it travels with are cut)."""

    links: dict

    def __getitem__(self, m) -> "RobotContext":
        return RobotContext({k: v[m] for k, v in self.links.items()})

    def of(self, joint: str) -> LinkContext:
        return self.links[joint]


def robot_of(models: dict) -> Robot | None:
    """The robot the models belong to (None: single joints); InputError when they name two."""
    robots = {m.robot for m in models.values() if getattr(m, "robot", None) is not None}
    if len(robots) > 1:
        raise InputError(None, "model.urdf", "one robot per recording", f"{len(robots)} URDFs")
    return next(iter(robots)) if robots else None


def link_motion(robot: Robot, signals: dict, models: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, q', q'') (T, n) of the robot's links in its joint order over a recording, rad, rad/s,
    rad/s^2 (module docstring: the recorded link angle with its zero set by the spring; the motor's
    rates less the spring's deflection's).

    signals : {joint: JointSignals} on one clock, holding every moving joint of the robot;
    models : {joint: JointModel}, whose J, b, torque_gain and stiffness rebuild each link's
    motion from its motor's, and whose delay_s puts its mocap angle on the controller's clock
    (the nominal models: the context is the recording's, fixed while
    discovery changes the models)."""
    from ..ident.conditioning import derivatives, lowpass
    from .memo import spline_rates, wiener_drive_of
    from .residuals import LINK_HZ

    missing = [j for j in robot.joints if j not in signals]
    if missing:
        raise InputError(None, "model.urdf", f"every moving joint of the URDF in the recording {list(robot.joints)}",
                         f"none for {missing}", hint="brake the others in the URDF (fixed joints)")
    sig = [signals[j] for j in robot.joints]
    t = np.asarray(sig[0].t, dtype=np.float64)
    if any(s.t.shape != t.shape or not np.allclose(s.t, t, rtol=0, atol=1e-9) for s in sig):
        raise InputError(None, "recording", "the robot's joints on one clock", [s.t.shape for s in sig])
    fs = 1.0 / float(np.median(np.diff(t)))
    q, v, a = (np.empty((t.size, len(sig))) for _ in range(3))
    inner = slice(int(fs), t.size - int(fs))                  # 1 s trims: the filters' ends
    for j, s in enumerate(sig):
        m = models[robot.joints[j]]
        drive = wiener_drive_of(np.asarray(s.q_m, dtype=np.float64), fs)
        qd_m, qdd_m = spline_rates(t, drive)
        tau_s = m.torque_gain * np.asarray(s.u, dtype=np.float64) - m.J * qdd_m - m.b * qd_m
        d_spring = lowpass(tau_s / m.stiffness(), fs, LINK_HZ)
        dd, ddd = derivatives(d_spring, fs)
        v[:, j], a[:, j] = qd_m - dd, qdd_m - ddd
        # the recorded link angle, its zero (the joints stage's is the motor's, off by the mean
        # deflection) set by the spring: the mean of q_m - tau_s / k
        q_rec = np.asarray(s.q, dtype=np.float64)
        if getattr(m, "delay_s", 0.0):
            # the mocap angle stamped t is the link's at t + delay_s (.model.predict): the link's at t
            # is the one stamped t - delay_s
            q_rec = np.interp(t - m.delay_s, t, q_rec)
        q_l = lowpass(q_rec, fs, LINK_HZ)
        q[:, j] = q_l - float(np.mean((q_l - (drive - d_spring))[inner]))
    if not (np.isfinite(q).all() and np.isfinite(v).all() and np.isfinite(a).all()):
        raise InputError(None, "recording", "finite link and motor angles for the robot's context", "NaN")
    return q, v, a


def robot_context(robot: Robot, signals: dict, models: dict) -> RobotContext:
    """Each robot joint's context over a recording (module docstring), from the links' motion
    (:func:`link_motion`, same arguments). Pinocchio runs once per sample and joint set (n + 3
    calls of a few microseconds: 0.3 s for 60 s of two joints at 250 Hz), once per recording."""
    import pinocchio as pin

    q, v, a = link_motion(robot, signals, models)
    model = robot.pin_model()
    data = model.createData()
    T, n = q.shape
    M = np.empty((T, n, n))
    nle = np.empty((T, n))
    G = np.empty((T, n))
    G90 = np.empty((T, n))
    turn = 0.5 * np.pi * np.eye(n)
    for k in range(T):             # Pinocchio evaluates one configuration per call (api-notes)
        qk = q[k]
        M[k] = pin.crba(model, data, qk)
        nle[k] = pin.nonLinearEffects(model, data, qk, v[k])
        G[k] = pin.computeGeneralizedGravity(model, data, qk)
        for j in range(n):
            G90[k, j] = pin.computeGeneralizedGravity(model, data, qk + turn[j])[j]
    diag = np.einsum("tjj->tj", M)
    tau = -(np.einsum("tji,ti->tj", M, a) - diag * a + nle - G)
    s, c = np.sin(q), np.cos(q)
    # G_j(theta) = -mglx sin theta + mgly cos theta at theta = q_j and q_j + pi/2
    mglx = -(G * s + G90 * c)
    mgly = G * c - G90 * s
    return RobotContext({name: LinkContext(*(np.ascontiguousarray(x[:, j]) for x in (diag, mglx, mgly, tau)))
                         for j, name in enumerate(robot.joints)})


def robot_from_table(doc: dict, path: Path, names: list[str], tables: list[dict]) -> Robot:
    """The robot of a model file with a top-level ``urdf`` (a path relative to the file): each
    joint's ``urdf_joint`` (default its name) must be the URDF's moving joints, one each."""
    rel = doc["urdf"]
    if not isinstance(rel, str) or not rel:
        raise InputError(path, "urdf", "a URDF file path (relative to the model file)", repr(rel))
    urdf = str((path.parent / rel).resolve()) if not rel.lstrip().startswith("<") else rel
    try:
        moving = urdf_joint_names(urdf)
    except InputError as e:
        raise InputError(path, "urdf", e.expected, e.got) from None
    mine = [str(t.get("urdf_joint", n)) for n, t in zip(names, tables)]
    if sorted(mine) != sorted(moving):
        raise InputError(path, "joints.urdf_joint", f"the URDF's moving joints {list(moving)}, one table each",
                         mine)
    order = [mine.index(u) for u in moving]
    return Robot(urdf=urdf, joints=tuple(names[i] for i in order), urdf_joints=moving)
