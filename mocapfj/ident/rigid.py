"""A rigid robot identified from its controller log and URDF: IDIM-LS of the links' base
parameters and the joints' friction (Gautier 1997; Khalil and Dombre 2002, ch. 12).

For rigid joints the controller's joint angle is the link angle, and

    tau = M(q) q'' + C(q, q') q' + G(q) + Ia q'' + F(q')  =  W(q, q', q'') phi      (docs/conventions.md)

is linear in the standard parameters phi: the links' inertial parameters (Pinocchio's joint torque
regressor, :func:`.regressor.nlink_regressor`), the rotor inertias Ia (armature) and the friction
coefficients of one friction law shared by the joints, chosen by held-out torque error among
`RIGID_FRICTION_MODELS`:

- ``coulomb_viscous``: fc sign(q') + fv q'
- ``coulomb_viscous_offset``: the same plus a constant torque (a sensor offset, an unbalanced cable)
- ``tanh_coulomb_viscous``: fc tanh(q' / eps) + fv q' (a smooth Coulomb law; eps by a grid search)
- ``stribeck``: (fc + fs exp(-(q' / vs)^2)) sign(q') + fv q' (vs by a grid search)

Procedure (the EMPS benchmark's, Janot, Gautier and Brunot 2019): the log is put on a uniform time
base (samples off it are resampled and counted); q is low-passed (zero phase) at a cut-off five
times the trajectory's bandwidth and differentiated by central differences; every column of W and
the torque go through the same low-pass and are decimated together (parallel decimation); samples
near zero velocity are left out of the rows of that joint (the Coulomb sign is ambiguous there);
base parameters by QR with column pivoting (:func:`.regressor.base_parameters`); ordinary least
squares with a Newey-West covariance (:func:`.ls.ls_fit`; the filtered residual is correlated).
A friction law with a step is evaluated at the logged instants and resampled like the torque.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import InputError
from ..types import Recording
from .conditioning import decimate_parallel, derivatives, lowpass
from .ls import ls_fit
from .regressor import base_parameters, load_pin_model, nlink_regressor
from .result import RigidIdentification, RigidJointFit

__all__ = ["RIGID_FRICTION_MODELS", "uniform_log", "identify_rigid_log", "identify_rigid", "torque_rms_on"]

RIGID_FRICTION_MODELS = ("coulomb_viscous", "coulomb_viscous_offset", "tanh_coulomb_viscous", "stribeck")
_EPS_GRID = (1e-3, 3e-3, 1e-2, 3e-2, 0.1)        # rad/s, tanh velocity scale
_VS_GRID = (3e-3, 1e-2, 3e-2, 0.1, 0.3)          # rad/s, Stribeck velocity
HOLDOUT = 0.3
MIN_GAIN_PCT = 1.0
"""A friction law with more parameters is chosen only when it lowers the held-out torque RMS by at
least this much against the plain Coulomb + viscous law."""


def uniform_log(t, X, *, source=None) -> tuple[np.ndarray, np.ndarray, float, int]:
    """A log (t (T,) s strictly increasing, X (T, ...)) on a uniform time base at its median rate.

    Returns (t_uniform, X_uniform, fs_hz, n_resampled): when every step is within 1 % of the
    median step the log is kept as is (n_resampled = 0); otherwise it is linearly interpolated
    onto the uniform grid and n_resampled counts the samples whose time stamps were off it.
    """
    t = np.asarray(t, dtype=np.float64)
    X = np.asarray(X, dtype=np.float64)
    if t.ndim != 1 or t.size < 10 or X.shape[0] != t.size:
        raise InputError(source, "time", "at least 10 samples with one time stamp each", t.shape)
    dt = np.diff(t)
    if not (dt > 0).all():
        raise InputError(source, "time", "strictly increasing time stamps", f"{int((dt <= 0).sum())} steps <= 0")
    step = float(np.median(dt))
    off = np.abs(dt - step) > 0.01 * step
    if not off.any():
        return t, X, 1.0 / step, 0
    n = int(np.floor((t[-1] - t[0]) / step + 1e-9)) + 1
    tu = t[0] + np.arange(n) * step
    flat = X.reshape(t.size, -1)
    Xu = np.column_stack([np.interp(tu, t, flat[:, k]) for k in range(flat.shape[1])]).reshape((n,) + X.shape[1:])
    grid = np.rint((t - t[0]) / step)
    n_off = int((np.abs(t - (t[0] + grid * step)) > 0.01 * step).sum())
    return tu, Xu, 1.0 / step, max(n_off, 1)


def _bandwidth_hz(qd: np.ndarray, fs_hz: float, share: float = 0.99) -> float:
    """Frequency below which `share` of the velocities' power lies (all joints together)."""
    P = (np.abs(np.fft.rfft(qd - qd.mean(axis=0), axis=0)) ** 2).sum(axis=1)
    f = np.fft.rfftfreq(qd.shape[0], 1.0 / fs_hz)
    c = np.cumsum(P)
    return float(f[min(np.searchsorted(c, share * c[-1]), f.size - 1)])


def _friction_columns(qd: np.ndarray, model: str, h: float | None) -> tuple[np.ndarray, tuple[str, ...]]:
    """Per joint friction columns (T, n, n_terms) and term names for one friction law."""
    s = np.sign(qd)
    if model == "coulomb_viscous":
        return np.stack([s, qd], -1), ("fc", "fv")
    if model == "coulomb_viscous_offset":
        return np.stack([s, qd, np.ones_like(qd)], -1), ("fc", "fv", "off")
    if model == "tanh_coulomb_viscous":
        return np.stack([np.tanh(qd / h), qd], -1), ("fc", "fv")
    if model == "stribeck":
        return np.stack([s, s * np.exp(-((qd / h) ** 2)), qd], -1), ("fc", "fs", "fv")
    raise InputError(None, "friction", f"one of {list(RIGID_FRICTION_MODELS)}", repr(model))


def _decimated(X3: np.ndarray, fs_hz, fc, decimate) -> np.ndarray:
    """Parallel low-pass and decimation of columns X3 (T, n, p) (the same filter as the torque's)."""
    T, n, p = X3.shape
    Xd, _ = decimate_parallel(X3.reshape(T, n * p), np.zeros(T), decimate, fs_hz, min(fc, 0.8 * fs_hz / (2 * decimate)))
    return Xd.reshape(-1, n, p)


def _observation(W_in_d, qd, model: str, h, fs_hz, fc, decimate, joints, stamps=None):
    """(W (Td, n, p), names) for one friction law: the decimated inertial columns W_in_d (computed
    once; the parallel filter is linear) and this law's friction columns, decimated alike.

    `stamps` = (t_grid (T,), t_log (T0,)) when the log was resampled onto the grid: a friction law
    with a step (sign q') is then evaluated at the logged instants and resampled onto the grid by
    the same linear interpolation as the torque, so that the step is smeared alike on both sides
    (evaluated on the grid directly, each reversal would leave a one-sample misfit of 2 fc)."""
    T, n = qd.shape
    if stamps is None:
        cols, terms = _friction_columns(qd, model, h)
    else:
        tg, tl = stamps
        qd_log = np.column_stack([np.interp(tl, tg, qd[:, j]) for j in range(n)])
        cl, terms = _friction_columns(qd_log, model, h)
        cols = np.stack([np.column_stack([np.interp(tg, tl, cl[:, j, k]) for j in range(n)])
                         for k in range(cl.shape[2])], axis=-1)
    eye = np.eye(n)
    F = (eye[None, :, :, None] * cols[:, :, None, :]).reshape(T, n, -1)        # joint-major, term-minor
    return np.concatenate([W_in_d, _decimated(F, fs_hz, fc, decimate)], axis=2), \
        tuple(f"{p_}_{j}" for j in joints for p_ in terms)


def _torque(tau, fs_hz, fc, decimate, sign_eps, qd):
    """The decimated torque (Td, n) and the rows kept (Td, n): joint speeds above sign_eps."""
    yd = _decimated(tau[:, :, None], fs_hz, fc, decimate)[:, :, 0]
    return yd, np.abs(qd[::decimate]) > sign_eps


def _solve(W3, y, keep, rows):
    """Stacked rows (sample-major) of the samples `rows`, without the rows of slow joints, and each
    row's sample index."""
    W = W3[rows].reshape(-1, W3.shape[2])
    Y = y[rows].ravel()
    k = keep[rows].ravel()
    idx = np.repeat(np.asarray(rows), W3.shape[1])
    return W[k], Y[k], idx[k]


def identify_rigid_log(model, t, Q, TAU, *, joint_names: Sequence[str] | None = None, friction: str = "auto",
                       cutoff_hz: float | None = None, sign_eps: float = 0.02, source=None) -> RigidIdentification:
    """IDIM-LS of a rigid robot from its log (module docstring).

    Parameters
    ----------
    model : pin.Model, URDF path or XML string (n 1-DoF joints, in the columns' order).
    t : (T,) float
        Time stamps, s, strictly increasing (non-uniform steps are resampled and counted).
    Q, TAU : (T, n) float
        Joint angles (rad, m for prismatic) and joint torques (N m, N), link side.
    friction : "auto" (chosen by held-out error) or one of RIGID_FRICTION_MODELS.
    cutoff_hz : float, optional
        Low-pass of q before differentiation; default five times the trajectory's bandwidth (the
        frequency holding 99 % of the velocity's power), within [2 Hz, 0.1 x the rate].
    sign_eps : float
        Rows of a joint whose speed is below this (rad/s) are left out.
    """
    pm = load_pin_model(model)
    n = pm.nv
    names_j = tuple(pm.names[1:]) if joint_names is None else tuple(joint_names)
    Q = np.asarray(Q, dtype=np.float64)
    TAU = np.asarray(TAU, dtype=np.float64)
    if Q.shape != TAU.shape or Q.ndim != 2 or Q.shape[1] != n or len(names_j) != n:
        raise InputError(source, "joints", f"angles and torques of the model's {n} joints", f"{Q.shape}, {TAU.shape}")
    for label, a in (("joint angle", Q), ("joint torque", TAU)):
        if not np.isfinite(a).all():
            raise InputError(source, label, "finite samples", f"{int((~np.isfinite(a)).sum())} NaN or infinite")
    t_log = np.asarray(t, dtype=np.float64)
    t, X, fs, n_res = uniform_log(t_log, np.concatenate([Q, TAU], axis=1), source=source)
    Q, TAU = X[:, :n], X[:, n:]
    if t.size < 200:
        raise InputError(source, "time", "at least 200 samples for the filters and the fit", t.size)
    qd_raw = np.gradient(Q, 1.0 / fs, axis=0)
    if cutoff_hz is None:
        cutoff_hz = float(np.clip(5.0 * _bandwidth_hz(qd_raw, fs), 2.0, 0.1 * fs))
    q = lowpass(Q, fs, cutoff_hz)
    qd, qdd = derivatives(q, fs)
    decimate = max(1, int(fs // (5 * cutoff_hz)))
    trim = int(np.ceil(fs / cutoff_hz)) * 3
    sl = slice(trim, t.size - trim)
    q, qd, qdd, TAU = q[sl], qd[sl], qdd[sl], TAU[sl]
    T = q.shape[0]
    stamps = (t[sl], t_log) if n_res else None

    W_in, names_in = nlink_regressor(pm, q, qd, qdd, friction="none", armature=True)
    W_in_d = _decimated(W_in.reshape(T, n, -1), fs, cutoff_hz, decimate)
    y, keep = _torque(TAU, fs, cutoff_hz, decimate, sign_eps, qd)

    def fit(model_name, h, rows):
        W3, fnames = _observation(W_in_d, qd, model_name, h, fs, cutoff_hz, decimate, names_j, stamps)
        names = tuple(names_in) + fnames
        W, Y, idx = _solve(W3, y, keep, rows)
        base_idx, Kd, base_names = base_parameters(W, names)
        return W3, y, keep, names, base_idx, Kd, base_names, ls_fit(W[:, base_idx], Y, base_names, cov="hac",
                                                                    time_index=idx)

    Td = (T + decimate - 1) // decimate
    n_tr = int(round(Td * (1 - HOLDOUT)))
    train, test = np.arange(n_tr), np.arange(n_tr, Td)
    candidates = [(m, h) for m in RIGID_FRICTION_MODELS
                  for h in ({"tanh_coulomb_viscous": _EPS_GRID, "stribeck": _VS_GRID}.get(m, (None,)))]
    if friction != "auto":
        if friction not in RIGID_FRICTION_MODELS:
            raise InputError(None, "friction", f'"auto" or one of {list(RIGID_FRICTION_MODELS)}', repr(friction))
        candidates = [c for c in candidates if c[0] == friction]
    scores = {}
    for m, h in candidates:
        W3, y, keep, names, base_idx, Kd, base_names, res = fit(m, h, train)
        W, Y, _ = _solve(W3, y, keep, test)
        r = Y - W[:, base_idx] @ res.values
        scores[(m, h)] = float(np.sqrt(np.mean(r**2)))
    best_per_model = {}
    for (m, h), s in scores.items():
        if m not in best_per_model or s < scores[best_per_model[m]]:
            best_per_model[m] = (m, h)
    ref = scores.get(best_per_model.get("coulomb_viscous", ("", None)))
    chosen = min(best_per_model.values(), key=lambda c: scores[c])
    if ref is not None and scores[chosen] > (1 - MIN_GAIN_PCT / 100) * ref:
        chosen = best_per_model["coulomb_viscous"]
    m, h = chosen
    W3, y, keep, names, base_idx, Kd, base_names, res = fit(m, h, np.arange(Td))
    # per joint torque RMS of the final fit, and its friction coefficients
    theta = np.zeros(len(names))
    theta[base_idx] = res.values
    pred = W3 @ theta
    joints = []
    for j, jn in enumerate(names_j):
        r = (y[:, j] - pred[:, j])[keep[:, j]]
        fp = {}
        for bn in base_names:
            head = bn.split(" ")[0]
            term, _, joint = head.partition("_")
            if joint == jn and term in ("fc", "fv", "off", "fs"):
                fp[term] = float(res[bn])
        if h is not None:
            fp["eps" if m == "tanh_coulomb_viscous" else "vs"] = float(h)
        joints.append(RigidJointFit(name=jn, friction=m, friction_params=fp, torque_rms=float(np.sqrt(np.mean(r**2)))))
    label = {mm + ("" if hh is None else f" ({'eps' if mm.startswith('tanh') else 'vs'} {hh:g} rad/s)"): sc
             for (mm, hh), sc in scores.items()}
    return RigidIdentification(base=res, joints=tuple(joints), friction=m, friction_scores=label, fs_hz=fs,
                               n_samples=int(t.size), n_resampled=n_res, base_idx=base_idx, Kd=Kd,
                               standard_names=names, joint_names=names_j, friction_scale=h, cutoff_hz=cutoff_hz,
                               sign_eps=sign_eps)


def torque_rms_on(model, fit: RigidIdentification, t, Q, TAU, source=None) -> dict:
    """Each joint's torque RMS (N m) of an identified rigid model on another log of the same robot
    (t (T,) s, Q and TAU (T, n) in the model's joint order), with the same conditioning."""
    pm = load_pin_model(model)
    m, h, cutoff_hz, names_j, sign_eps = fit.friction, fit.friction_scale, fit.cutoff_hz, fit.joint_names, fit.sign_eps
    n = pm.nv
    t_log = np.asarray(t, dtype=np.float64)
    t, X, fs, n_res = uniform_log(t_log, np.concatenate([Q, TAU], axis=1), source=source)
    Q, TAU = X[:, :n], X[:, n:]
    q = lowpass(Q, fs, min(cutoff_hz, 0.45 * fs))
    qd, qdd = derivatives(q, fs)
    decimate = max(1, int(fs // (5 * cutoff_hz)))
    trim = int(np.ceil(fs / cutoff_hz)) * 3
    sl = slice(trim, t.size - trim)
    W_in, names_in = nlink_regressor(pm, q[sl], qd[sl], qdd[sl], friction="none", armature=True)
    W_in_d = _decimated(W_in.reshape(q[sl].shape[0], n, -1), fs, cutoff_hz, decimate)
    W3, fnames = _observation(W_in_d, qd[sl], m, h, fs, cutoff_hz, decimate, names_j, (t[sl], t_log) if n_res else None)
    y, keep = _torque(TAU[sl], fs, cutoff_hz, decimate, sign_eps, qd[sl])
    names = tuple(names_in) + fnames
    if tuple(names) != tuple(fit.standard_names):
        raise InputError(source, "joints", "the joints of the identified recording", list(names_j))
    theta = np.zeros(len(names))
    theta[fit.base_idx] = fit.base.values
    pred = W3 @ theta
    return {jn: float(np.sqrt(np.mean(((y[:, j] - pred[:, j])[keep[:, j]]) ** 2))) for j, jn in enumerate(names_j)}


def _log_of(rec: Recording):
    if rec.urdf is None:
        raise InputError(rec.root, "model.urdf", "a URDF for a recording without markers (a rigid robot)", "none",
                         hint="add [model] urdf = \"robot.urdf\" to recording.toml")
    if rec.controller is None:
        raise InputError(rec.root, "controller", "a controller log", "none")
    return rec.controller.t, rec.controller.q_m, rec.controller.tau, tuple(rec.controller.joint_names)


def identify_rigid(rec: Recording, validation: Recording | None = None, **kw) -> RigidIdentification:
    """:func:`identify_rigid_log` on a bundle with a controller log and a URDF (no markers): the
    joints' logged angles are the link angles. With `validation` (a second recording of the same
    robot), each joint's torque RMS on it is reported (``validation``)."""
    from dataclasses import replace

    t, Q, TAU, names = _log_of(rec)
    pm = load_pin_model(rec.urdf)
    model_names = tuple(pm.names[1:])
    if set(names) != set(model_names) or len(names) != len(model_names):
        raise InputError(rec.root, "joints", f"the URDF's moving joints {list(model_names)}", list(names))
    order = [names.index(nm) for nm in model_names]
    fit = identify_rigid_log(pm, t, Q[:, order], TAU[:, order], joint_names=model_names, source=rec.root, **kw)
    if validation is None:
        return fit
    tv, Qv, TAUv, names_v = _log_of(validation)
    if set(names_v) != set(model_names):
        raise InputError(validation.root, "joints", f"the joints of {rec.name} {list(model_names)}", list(names_v))
    order_v = [names_v.index(nm) for nm in model_names]
    val = torque_rms_on(pm, fit, tv, Qv[:, order_v], TAUv[:, order_v], source=validation.root)
    joints = tuple(replace(j, validation_torque_rms=val[j.name]) for j in fit.joints)
    return replace(fit, joints=joints, validation=val)
