"""Identification model of n rigid links through Pinocchio: the observation matrix of the link
equation and its base parameters (Lightcap and Banks (2007), eq. 1 and 5-6; Khalil & Dombre ch. 12; Gautier 1990
for base parameters by QR).

Link side, docs/conventions.md:

    M(q) q'' + C(q, q') q' + G(q) + F(q') + Ia q'' = tau        (tau = tau_s, or the motor torque of a rigid joint)
    tau = W(q, q', q'') phi

phi, per moving joint j in model order (names ``<param>_<joint name>``):
    10 inertial parameters of the body joint j carries, about the JOINT frame origin, Pinocchio's
    order [m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] (kg, kg m, kg m^2; api-notes §2); a URDF's
    fixed children are merged into that body by Pinocchio;
then per joint the friction columns (Lightcap and Banks (2007), eq. 4 / Bompos et al. (2007), eq. 18 without Stribeck):
    fc_j sign(q'_j), fv_j q'_j, and with ``friction="coulomb_viscous_offset"`` off_j;
then, with ``armature=True``, Ia_j q''_j (rotor inertia reflected to the link; Pinocchio's
``computeJointTorqueRegressor`` leaves ``model.armature`` out although rnea includes it).
"""

from __future__ import annotations

from collections.abc import Sequence
from os import PathLike

import numpy as np
import pinocchio as pin
from scipy.linalg import qr

from ..errors import InputError
from .ls import ZERO_COLUMN_RTOL

__all__ = ["INERTIAL_NAMES", "FRICTION_MODELS", "load_pin_model", "nlink_regressor", "standard_parameters",
           "base_parameters", "base_from_standard"]

INERTIAL_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
FRICTION_MODELS = {"none": (), "coulomb_viscous": ("fc", "fv"), "coulomb_viscous_offset": ("fc", "fv", "off")}


def load_pin_model(model: "pin.Model | str | PathLike[str]") -> "pin.Model":
    """A pin.Model as is, or one built from a URDF XML string (starts with '<') or file path.

    Only 1-DoF joints (revolute, continuous, prismatic: nq = nv = njoints - 1) are accepted.
    """
    if not isinstance(model, pin.Model):
        from ..io.urdf import build_pin_model

        model = build_pin_model(model)
    if not (model.nq == model.nv == model.njoints - 1):
        raise InputError(None, "model", "only 1-DoF joints (nq = nv = number of joints)",
                         f"nq {model.nq}, nv {model.nv}, {model.njoints - 1} joints")
    return model


def _names(model: "pin.Model", friction: str, armature: bool) -> tuple[str, ...]:
    joints = list(model.names)[1:]
    names = [f"{p}_{j}" for j in joints for p in INERTIAL_NAMES]
    names += [f"{p}_{j}" for j in joints for p in FRICTION_MODELS[friction]]
    if armature:
        names += [f"Ia_{j}" for j in joints]
    return tuple(names)


def nlink_regressor(model: "pin.Model | str | PathLike[str]", q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                    friction: str = "coulomb_viscous", *, armature: bool = True) -> tuple[np.ndarray, tuple[str, ...]]:
    """Observation matrix of the link equation, tau.ravel() = W phi (module docstring).

    Parameters
    ----------
    model : pin.Model, URDF XML string or URDF path; n moving 1-DoF joints.
    q, qd, qdd : (T, n) float (or (n,) for one sample), rad, rad/s, rad/s^2 (m for prismatic).
    friction : "none", "coulomb_viscous" or "coulomb_viscous_offset".
    armature : add the n columns Ia_j q''_j.

    Returns
    -------
    W : (T n, p) float, rows sample-major (row t n + j is joint j at sample t), so it pairs with
        tau.reshape(-1) of a (T, n) torque; p = 10 n + n len(friction terms) + n armature.
    names : p str, e.g. "Izz_j2", "fc_j3", "Ia_j3".
    """
    model = load_pin_model(model)
    if friction not in FRICTION_MODELS:
        raise InputError(None, "friction", f"one of {sorted(FRICTION_MODELS)}", friction)
    n = model.nv
    arrs = []
    for label, a in (("q", q), ("qd", qd), ("qdd", qdd)):
        a = np.atleast_2d(np.asarray(a, dtype=np.float64))
        if a.ndim != 2 or a.shape[1] != n or not np.isfinite(a).all():
            raise InputError(None, label, f"(T, {n}) finite joint values", np.shape(a))
        arrs.append(a)
    q, qd, qdd = arrs
    if not (q.shape == qd.shape == qdd.shape):
        raise InputError(None, "q, qd, qdd", "three arrays of the same shape (T, n)", f"{q.shape}, {qd.shape}, {qdd.shape}")
    T = q.shape[0]
    data = model.createData()
    Y = np.stack([pin.computeJointTorqueRegressor(model, data, q[k], qd[k], qdd[k]) for k in range(T)])  # (T, n, 10n)
    eye = np.eye(n)
    blocks = [Y]
    cols = {"fc": np.sign(qd), "fv": qd, "off": np.ones_like(qd)}
    if FRICTION_MODELS[friction]:
        # (T, n joints-rows, n joints, n_terms) -> parameter order joint-major, term-minor
        terms = np.stack([cols[p] for p in FRICTION_MODELS[friction]], axis=-1)   # (T, n, n_terms)
        F = eye[None, :, :, None] * terms[:, :, None, :]                          # (T, n, n, n_terms)
        blocks.append(F.reshape(T, n, -1))
    if armature:
        blocks.append(eye[None] * qdd[:, :, None])
    W = np.concatenate(blocks, axis=2).reshape(T * n, -1)
    return W, _names(model, friction, armature)


def standard_parameters(model: "pin.Model | str | PathLike[str]", friction: str = "coulomb_viscous", *,
                        coulomb=0.0, viscous=0.0, offset=0.0, armature: bool = True) -> tuple[np.ndarray, tuple[str, ...]]:
    """phi (p,) of a model in nlink_regressor's order: its body inertias (toDynamicParameters),
    the given friction (scalars or (n,) N m, N m s/rad, N m) and model.armature (kg m^2)."""
    model = load_pin_model(model)
    if friction not in FRICTION_MODELS:
        raise InputError(None, "friction", f"one of {sorted(FRICTION_MODELS)}", friction)
    n = model.nv
    parts = [np.concatenate([model.inertias[j].toDynamicParameters() for j in range(1, model.njoints)])]
    given = {"fc": coulomb, "fv": viscous, "off": offset}
    terms = FRICTION_MODELS[friction]
    if terms:
        vals = []
        for p in terms:
            v = np.asarray(given[p], dtype=np.float64)
            if v.shape not in ((), (n,)) or not np.isfinite(v).all():
                raise InputError(None, {"fc": "coulomb", "fv": "viscous", "off": "offset"}[p], f"a number or ({n},) numbers", v.shape)
            vals.append(np.broadcast_to(v, (n,)))
        parts.append(np.stack(vals, axis=1).ravel())  # joint-major, term-minor
    if armature:
        parts.append(np.asarray(model.armature, dtype=np.float64).copy())
    return np.concatenate(parts), _names(model, friction, armature)


def _fmt(c: float) -> str:
    return "" if np.isclose(abs(c), 1.0, rtol=1e-9) else f"{abs(c):.6g} "


def base_parameters(W: np.ndarray, names: Sequence[str], rtol: float = 1e-10,
                    ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Base parameters by QR with column pivoting (Gautier 1990; api-notes §2).

    W (r, p) = [W_b W_d] P^T with W_d = W_b Kd, so W phi = W_b beta with
    beta = phi_b + Kd phi_d. Columns are scaled to unit norm; the pivoted QR gives the rank b;
    the b base columns are then chosen in column order (a column is dependent when it lies in
    the span of the columns before it), so for nlink_regressor's order the distal bodies'
    parameters regroup into the proximal ones' and armature into Izz, as in Khalil's symbolic
    rules (if that greedy pass disagrees with the rank, the QR's pivots are used). Zero columns
    (unexcited or structurally absent parameters) are dependent with Kd = 0, and so are columns
    that are zero to rounding: below `ls.ZERO_COLUMN_RTOL` of the largest column's norm (a joint
    origin rotated by rpy = +-pi/2 leaves 6e-17 where the exact regressor has 0; scaled to unit
    norm, such a column of rounding errors would look independent of everything).

    Parameters
    ----------
    W : (r, p) float, a stacked regressor of an exciting trajectory (r >> p).
    names : p str.
    rtol : rank threshold on |R_ii| relative to |R_00| (times max(r, p)).

    Returns
    -------
    base_idx : (b,) int, sorted indices of the standard parameters kept as base columns.
    Kd : (b, p - b) float, the regrouping coefficients; entries below 1e-9 x the largest are 0.
    base_names : b str, each base parameter written as the combination it is, e.g.
        "Izz_j2 + 0.2025 m_j3 + Ia_j2" (0.45 m link: Izz_j2 + a^2 m_j3).
    """
    W = np.asarray(W, dtype=np.float64)
    names = tuple(names)
    if W.ndim != 2 or W.shape[1] != len(names) or not np.isfinite(W).all():
        raise InputError(None, "W, names", "a finite (r, p) matrix and p names", f"{W.shape}, {len(names)} names")
    scale = np.linalg.norm(W, axis=0)
    nonzero = np.flatnonzero(scale > ZERO_COLUMN_RTOL * scale.max()) if scale.max() > 0 else np.empty(0, int)
    if nonzero.size == 0:
        raise InputError(None, "W", "at least one non-zero column", "all columns zero")
    Ws = W[:, nonzero] / scale[nonzero]
    _, R, P = qr(Ws, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    tol = rtol * max(Ws.shape) * d[0]
    rank = int((d > tol).sum())
    base_idx = _in_order_basis(Ws, tol)
    base_idx = nonzero[base_idx] if base_idx.size == rank else np.sort(nonzero[P[:rank]])
    dep_idx = np.setdiff1d(np.arange(W.shape[1]), base_idx)
    Kd = np.linalg.lstsq(W[:, base_idx], W[:, dep_idx], rcond=None)[0] if dep_idx.size else np.zeros((rank, 0))
    Kd[np.abs(Kd) < 1e-9 * max(1.0, np.abs(Kd).max(initial=0.0))] = 0.0
    base_names = []
    for i, b in enumerate(base_idx):
        s = names[b]
        for k in np.flatnonzero(Kd[i]):
            c = Kd[i, k]
            s += f" {'+' if c > 0 else '-'} {_fmt(c)}{names[dep_idx[k]]}"
        base_names.append(s)
    return base_idx, Kd, tuple(base_names)


def _in_order_basis(Ws: np.ndarray, tol: float) -> np.ndarray:
    """Columns of Ws (unit norm) taken in order, each kept when it is not in the span of those
    kept before (Gram-Schmidt residual > tol): later parameters regroup into earlier ones, so
    distal links' parameters regroup into proximal ones (Khalil & Dombre §12.5.3)."""
    Q = np.zeros((Ws.shape[0], 0))
    keep = []
    for j in range(Ws.shape[1]):
        v = Ws[:, j] - Q @ (Q.T @ Ws[:, j])
        v -= Q @ (Q.T @ v)  # twice is enough (Giraud et al. 2005)
        nv = np.linalg.norm(v)
        if nv > tol:
            keep.append(j)
            Q = np.column_stack([Q, v / nv])
    return np.array(keep, dtype=int)


def base_from_standard(phi: np.ndarray, base_idx: np.ndarray, Kd: np.ndarray) -> np.ndarray:
    """beta (b,) = phi[base_idx] + Kd phi[dependent] for standard parameters phi (p,)."""
    phi = np.asarray(phi, dtype=np.float64)
    dep = np.setdiff1d(np.arange(phi.shape[0]), base_idx)
    if Kd.shape != (len(base_idx), dep.size):
        raise InputError(None, "Kd", f"({len(base_idx)}, {dep.size}) for {phi.shape[0]} parameters", Kd.shape)
    return phi[base_idx] + Kd @ phi[dep]
