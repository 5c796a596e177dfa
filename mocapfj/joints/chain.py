"""Per-frame angles of all revolute joints of a kinematic chain from markers on its links.

Lightcap and Banks (2007), eq. (13) fits one angle per frame by matching predicted to measured marker positions;
here the prediction is the forward kinematics of a whole chain (or tree) read from a Pinocchio
model, and all joint angles of a frame are fitted at once:

    min_q  sum_p |v_p - y_p(q)|^2,     y_p(q) = T_world_link(p)(q) a_p

with a_p the marker template in its link frame. Gauss-Newton runs batched over frames: the
forward kinematics is re-implemented in numpy from the fixed joint placements of the model
(checked against ``pin.forwardKinematics`` in the tests), and the Jacobian of a marker is
dy_p/dq_j = n_j x (y_p - o_j) for the joints j upstream of its link (n_j, o_j: world axis and
origin of joint j). Frames, units and shapes follow docs/conventions.md.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.special import erfc
from scipy.stats import chi2

from ..errors import InputError
from .gauss_newton import BatchCholesky, chain_fk, gauss_newton, normal_equations, subtree_sums

__all__ = ["ChainModel", "ChainAngles", "solve_chain"]

_REVOLUTE = {"JointModelRX": (1.0, 0, 0), "JointModelRY": (0, 1.0, 0), "JointModelRZ": (0, 0, 1.0)}


def _read_only(obj) -> None:
    for value in vars(obj).values():
        if isinstance(value, np.ndarray):
            value.setflags(write=False)


def _basis(axis: np.ndarray) -> np.ndarray:
    """A rotation P (3, 3) whose third column is the unit `axis`: Rot(axis, q) = P Rz(q) P^T."""
    z = axis / np.linalg.norm(axis)
    x = np.cross(z, [1.0, 0, 0] if abs(z[0]) < 0.9 else [0, 1.0, 0])
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


@dataclass(frozen=True, eq=False)
class ChainModel:
    """Revolute joints of a Pinocchio model and the marker templates on its links.

    Build it with `from_urdf` or `from_model`. Internally every joint is re-expressed in a frame
    whose z axis is its rotation axis (Rot(n, q) = P Rz(q) P^T), so the forward kinematics is
    products of fixed placements and Rz(q_j).

    Attributes
    ----------
    joint_names : tuple of n str
        Revolute joints in Pinocchio order; column j of every (T, n) angle array.
    labels : tuple of M str
        Marker labels in the column order `solve_chain` expects of ``v_world``.
    marker_link : tuple of M str
        Link frame of each marker.
    parent : (n,) int
        Parent joint index, -1 for the root.
    R_parent_joint, t_parent_joint : (n, 3, 3), (n, 3)
        Fixed placement of each (axis-aligned) joint frame in its parent's, metres.
    P_joint : (n, 3, 3)
        Rotation from the axis-aligned frame to the model's joint frame (column 3 = axis).
    marker_joint : (M,) int
        Joint that carries each marker's link (-1: fixed to the root, moved by no joint).
    p_joint : (M, 3)
        Marker positions in the axis-aligned frame of `marker_joint`, metres.
    moves : (M, n) bool
        moves[m, j]: joint j is upstream of marker m.
    moves_joint : (n, n) bool
        moves_joint[k, j]: joint j is joint k or upstream of it.
    T_world_root : (4, 4)
        Pose of the model's root (URDF ``world``) in the mocap world frame.
    """

    joint_names: tuple[str, ...]
    labels: tuple[str, ...]
    marker_link: tuple[str, ...]
    parent: np.ndarray
    R_parent_joint: np.ndarray
    t_parent_joint: np.ndarray
    P_joint: np.ndarray
    marker_joint: np.ndarray
    p_joint: np.ndarray
    moves: np.ndarray
    moves_joint: np.ndarray
    T_world_root: np.ndarray

    def __post_init__(self) -> None:
        _read_only(self)

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @classmethod
    def from_urdf(cls, urdf: str | Path, templates, *, T_world_root=None) -> ChainModel:
        """From URDF text (a string starting with ``<``) or a URDF file path; see `from_model`."""
        from ..io.urdf import build_pin_model

        return cls.from_model(build_pin_model(urdf), templates, T_world_root=T_world_root)

    @classmethod
    def from_model(cls, model, templates: Mapping[str, tuple[Sequence[str], np.ndarray]], *,
                   T_world_root=None) -> ChainModel:
        """Read the fixed joint placements of a Pinocchio model once and attach marker templates.

        Parameters
        ----------
        model : pinocchio.Model
            Only 1-DoF revolute joints (RX, RY, RZ, RevoluteUnaligned); braked joints must be fixed.
        templates : mapping of link frame name -> (labels (P,), positions (P, 3))
            Marker positions in the frame of that link (a Pinocchio frame, e.g. ``"link3"``), metres.
        T_world_root : (4, 4), optional
            Pose of the model root in the mocap world; default identity.
        """
        n = model.njoints - 1
        if n < 1:
            raise InputError(None, "model", "a model with at least one revolute joint", "no joints")
        parent, R_pl, t_pl, P = np.empty(n, np.int64), np.empty((n, 3, 3)), np.empty((n, 3)), np.empty((n, 3, 3))
        for j in range(1, n + 1):
            jm = model.joints[j]
            kind = jm.shortname()
            if kind in _REVOLUTE:
                axis = np.array(_REVOLUTE[kind])
            elif kind == "JointModelRevoluteUnaligned":
                axis = np.asarray(jm.extract().axis, dtype=np.float64)
            else:
                raise InputError(None, f"joint {model.names[j]!r}", "a 1-DoF revolute joint (revolute in the URDF)",
                                 kind, hint="continuous and prismatic joints are not supported; brake "
                                 "(make fixed) the joints that do not move")
            parent[j - 1] = model.parents[j] - 1
            P[j - 1] = _basis(axis)
            Pp = P[parent[j - 1]] if parent[j - 1] >= 0 else np.eye(3)
            pl = model.jointPlacements[j]
            R_pl[j - 1] = Pp.T @ pl.rotation @ P[j - 1]
            t_pl[j - 1] = Pp.T @ pl.translation
        if not isinstance(templates, Mapping) or not templates:
            raise InputError(None, "templates", "a mapping link frame name -> (labels, (P, 3) positions)",
                             "an empty mapping" if isinstance(templates, Mapping) else type(templates).__name__)
        labels, links, mj, pj = [], [], [], []
        for link, (lab, pos) in templates.items():
            if not model.existFrame(link):
                bodies = [f.name for f in model.frames if str(f.type).endswith("BODY")]
                raise InputError(None, "templates", f"link frame names of the model, one of {bodies}", repr(link))
            pos = np.asarray(pos, dtype=np.float64)
            lab = [str(s) for s in lab]
            if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] != len(lab) or not np.isfinite(pos).all():
                raise InputError(None, f"templates[{link!r}]", f"finite positions of shape ({len(lab)}, 3) in m",
                                 f"shape {pos.shape}")
            fr = model.frames[model.getFrameId(link)]
            k = int(fr.parentJoint) - 1
            Pk = P[k] if k >= 0 else np.eye(3)
            p_in_joint = pos @ fr.placement.rotation.T + fr.placement.translation
            labels += lab
            links += [link] * len(lab)
            mj += [k] * len(lab)
            pj.append(p_in_joint @ Pk)
        if len(set(labels)) != len(labels):
            raise InputError(None, "templates", "unique marker labels",
                             f"duplicates {sorted({s for s in labels if labels.count(s) > 1})}")
        mj = np.asarray(mj, np.int64)
        up = np.eye(n, dtype=bool)                      # up[k, j]: joint j is joint k or upstream of it
        for k in range(n):
            if parent[k] >= 0:
                up[k] |= up[parent[k]]
        moves = np.where((mj >= 0)[:, None], up[mj], False)
        T0 = np.eye(4) if T_world_root is None else np.asarray(T_world_root, dtype=np.float64)
        if T0.shape != (4, 4):
            raise InputError(None, "T_world_root", "a (4, 4) homogeneous transform", f"shape {T0.shape}")
        names = tuple(str(model.names[j]) for j in range(1, n + 1))
        for j in np.flatnonzero(~moves.any(axis=0)):
            raise InputError(None, "templates", f"markers on a link moved by joint {names[j]!r}",
                             "none", hint="put a marker cluster on a link after that joint")
        chain = cls(names, tuple(labels), tuple(links), parent, R_pl, t_pl, P, mj, np.concatenate(pj), moves, up, T0)
        chain._check_determined()
        return chain

    def _check_determined(self) -> None:
        """Raise InputError if all markers together cannot determine every joint (zero and random poses)."""
        q = np.hstack([np.zeros((self.n_joints, 1)), np.random.default_rng(0).uniform(-np.pi, np.pi, (self.n_joints, 3))])
        A, _, _ = normal_equations(self, q, np.zeros((len(self.labels), 3, 4)), np.ones((len(self.labels), 4)))
        if not BatchCholesky(A).determined.any():
            d = np.sqrt(np.maximum(np.diag(A[:, :, 0]), 1e-300))
            _, V = np.linalg.eigh(A[:, :, 0] / np.outer(d, d))
            j = int(np.argmax(np.abs(V[:, 0])))
            raise InputError(None, "templates", f"markers that determine every joint angle (the least determined is "
                             f"joint {self.joint_names[j]!r})", f"{len(self.labels)} markers", hint="markers on a joint's axis or too few "
                             "markers after it; add markers off the axis")

    def joint_poses(self, q) -> tuple[np.ndarray, np.ndarray]:
        """World poses of the model's joint frames (Pinocchio ``data.oMi[1:]``).

        Parameters
        ----------
        q : (T, n) float, rad

        Returns
        -------
        R_world_joint : (T, n, 3, 3);  t_world_joint : (T, n, 3) m
        """
        R, t, _ = chain_fk(self, np.atleast_2d(np.asarray(q, dtype=np.float64)).T, with_markers=False)
        return np.moveaxis(R[:-1], 3, 0) @ np.swapaxes(self.P_joint, 1, 2), np.moveaxis(t[:-1], 2, 0)

    def marker_positions(self, q) -> np.ndarray:
        """Predicted marker positions y_p(q), (T, M, 3) m, world frame, for angles q (T, n) rad."""
        return np.moveaxis(chain_fk(self, np.atleast_2d(np.asarray(q, dtype=np.float64)).T)[2], 2, 0)


# Internals work frame-last: q (n, F), v and y (M, 3, F), w (M, F), so that every operation is an
# elementwise operation on contiguous length-F vectors or one BLAS call.

@dataclass(frozen=True, eq=False)
class ChainAngles:
    """Per-frame joint angles of a chain (`solve_chain`).

    Attributes
    ----------
    t : (T,) float or None
        Sample times, seconds, when given.
    q : (T, n) float
        Joint angles, rad, columns `joint_names`; NaN rows where the frame could not determine
        every joint.
    sigma_q : (T, n) float
        SD of each angle from the Gauss-Newton covariance sigma^2 (J^T J)^-1 at the solution
        (the Cramér-Rao bound for isotropic Gaussian marker noise), rad.
    marker_rms : (T,) float
        RMS of the 3D residuals |v_p - y_p| of the markers used, metres (at the last Gauss-Newton
        evaluation, within `tol` of q).
    n_markers, n_rejected : (T,) int
        Markers used, and markers rejected as outliers, per frame.
    used : (T, M) bool
        Which markers (``model.labels`` order) each frame used.
    n_iter : (T,) int
        Gauss-Newton iterations of each frame (all rounds).
    converged : (T,) bool
        The last step was below `tol` (False on NaN rows).
    sigma_m : float
        Marker noise SD used for sigma_q (given, or estimated from the inlier residuals), metres.
    joint_names : tuple of n str
    """

    t: np.ndarray | None
    q: np.ndarray
    sigma_q: np.ndarray
    marker_rms: np.ndarray
    n_markers: np.ndarray
    n_rejected: np.ndarray
    used: np.ndarray
    n_iter: np.ndarray
    converged: np.ndarray
    sigma_m: float
    joint_names: tuple[str, ...]

    def __post_init__(self) -> None:
        _read_only(self)

    @property
    def n_invalid(self) -> int:
        """Frames with a NaN row."""
        return int(np.isnan(self.q[:, 0]).sum())


def _check(v_world, model, q0, sigma, t):
    v = np.asarray(v_world, dtype=np.float64)
    M = len(model.labels)
    if v.ndim != 3 or v.shape[1:] != (M, 3) or v.shape[0] < 1:
        raise InputError(None, "v_world", f"marker positions of shape (T, {M}, 3) in model.labels order", f"shape {v.shape}")
    if not np.isfinite(v).all(axis=2).any():
        raise InputError(None, "v_world", "at least one frame with markers", "all NaN",
                         hint="check that the marker labels match the recording")
    T, n = v.shape[0], model.n_joints
    if q0 is not None:
        q0 = np.asarray(q0, dtype=np.float64)
        if q0.shape not in ((n,), (T, n)) or not np.isfinite(q0).all():
            raise InputError(None, "q0", f"finite seed angles of shape ({n},) or ({T}, {n}) in rad",
                             f"shape {q0.shape}" if q0.shape not in ((n,), (T, n)) else "non-finite values",
                             hint="interpolate the motor angles onto the mocap times")
    if sigma is not None and not (np.isfinite(sigma) and sigma > 0):
        raise InputError(None, "sigma", "a positive marker noise SD in metres, or None to estimate it", sigma)
    if t is not None and np.shape(t) != (T,):
        raise InputError(None, "t", f"shape ({T},)", f"shape {np.shape(t)}")
    return v, q0


def _require_some(ok: np.ndarray) -> None:
    if not ok.any():
        raise InputError(None, "v_world", "at least one frame whose markers determine every joint",
                         f"none of {ok.size} frames", hint="too many markers missing; check labels and occlusion")


def solve_chain(model: ChainModel, v_world, *, t=None, q0=None, sigma: float | None = None, max_iter: int = 10,
                tol: float = 1e-10, outlier_sigma: float | None = 4.0, min_markers_per_link: int = 1,
                block_frames: int = 32) -> ChainAngles:
    """Joint angles of every frame by batched Gauss-Newton on Lightcap and Banks (2007), eq. (13) over the chain.

    Parameters
    ----------
    model : ChainModel
    v_world : (T, M, 3) float
        Measured marker positions, metres, world frame, columns in ``model.labels`` order; NaN
        where missing.
    t : (T,) float, optional
        Sample times, copied to the result.
    q0 : (T, n) or (n,) float, optional
        Seeds, rad. (T, n), e.g. the motor angles: every frame starts from its own row and all
        frames are solved at once. (n,) or None (zeros): a seeding pass runs in blocks of
        `block_frames` frames, each block seeded by linear extrapolation of the block before it
        (the first block from q0 with up to 5 x max_iter iterations) -- Lightcap and Banks (2007) seeds each
        frame with the previous one; blocks keep that idea vectorised, at ~10x the cost of
        per-frame seeds. It assumes the first pose is within about 1 rad of q0 and that the
        extrapolation errs by less than about 0.5 rad within a block.
    sigma : float, optional
        Marker noise SD per coordinate, metres. None: robustly estimated (median residual) for
        the outlier test, then from the inliers' residual sum of squares over 3 M - n per frame.
    max_iter, tol : int, float
        Gauss-Newton iterations and step tolerance (rad) per solve.
    outlier_sigma : float or None
        A marker whose |residual|^2 / sigma^2 exceeds the chi-square(3) quantile of the two-sided
        Gaussian tail beyond this many SDs (4: 22.06) is rejected, worst marker first, and the frame
        re-solved until none is left. None disables it.
    min_markers_per_link : int
        A link whose cluster has fewer valid markers in a frame is not used in that frame.

    Returns
    -------
    ChainAngles
        Frames whose remaining markers do not determine every joint (normal matrix of rank < n)
        get NaN rows (`n_invalid`).
    """
    v, q0 = _check(v_world, model, q0, sigma, t)
    if max_iter < 1 or not tol >= 0 or min_markers_per_link < 1 or block_frames < 1:
        raise InputError(None, "max_iter/tol/min_markers_per_link/block_frames", "max_iter >= 1, tol >= 0, "
                         "min_markers_per_link >= 1, block_frames >= 1",
                         f"{max_iter}, {tol}, {min_markers_per_link}, {block_frames}")
    T, n = v.shape[0], model.n_joints
    groups = [np.array([lk == name for lk in model.marker_link]) for name in sorted(set(model.marker_link))]

    def usable(wt):  # drop clusters with fewer than min_markers_per_link markers; wt (M, F) 0/1
        if min_markers_per_link > 1:
            for g in groups:
                wt[g] *= wt[g].sum(axis=0) >= min_markers_per_link
        return wt

    def solvable(wt):  # every joint moves at least one used marker
        return (subtree_sums(model, wt[:, None, :])[:, 0] > 0).all(axis=0)

    valid = np.isfinite(v).all(axis=2).T                                                        # (M, T)
    v = np.moveaxis(np.where(np.isfinite(v), v, 0.0), 0, 2)                                     # (M, 3, T)
    w = usable(valid.astype(float))
    ok = solvable(w)
    _require_some(ok)
    q = np.zeros((n, T))
    n_it = np.zeros(T, np.int64)
    conv = np.zeros(T, bool)
    if q0 is None or q0.ndim == 1:               # seeding pass in blocks, extrapolated from the last one
        last, i_last, vel = (np.zeros(n) if q0 is None else q0), 0, np.zeros(n)
        for i0 in range(0, T, block_frames):
            idx = np.arange(i0, min(T, i0 + block_frames))[ok[i0:i0 + block_frames]]
            if idx.size:
                seed = last[:, None] + vel[:, None] * (idx - i_last)
                qb, _, _, Ab, _ = gauss_newton(model, seed, v[..., idx], w[:, idx],
                                                max_iter * (5 if i0 == 0 else 1), 1e-6)
                q[:, idx] = qb
                det = np.flatnonzero(BatchCholesky(Ab).determined)
                if det.size:
                    last, i_last = qb[:, det[-1]], idx[det[-1]]
                    vel = (last - qb[:, det[0]]) / max(i_last - idx[det[0]], 1)
    else:
        q[:] = q0.T
    A, e2 = np.zeros((n, n, T)), np.zeros((len(model.labels), T))
    q[:, ok], n_it[ok], conv[ok], A[..., ok], e2[:, ok] = gauss_newton(model, q[:, ok], v[..., ok], w[:, ok],
                                                                         max_iter, tol)
    n_rej = np.zeros(T, np.int64)
    if outlier_sigma is not None:
        s_rob = sigma
        if s_rob is None:
            use = (w > 0) & ok
            n_used = w.sum(axis=0)[ok]
            s_rob = np.sqrt(np.median(e2[use]) / chi2.ppf(0.5, 3) * 3 * n_used.sum() / max((3 * n_used - n).sum(), 1))
        thr = chi2.isf(erfc(outlier_sigma / np.sqrt(2.0)), 3) * max(s_rob, 1e-300) ** 2
        while True:                                                       # worst marker first, re-solve
            worst = np.argmax(e2, axis=0)
            bad = np.flatnonzero(e2[worst, np.arange(T)] > thr)
            if bad.size == 0:
                break
            w[worst[bad], bad] = 0.0
            w[:, bad] = usable(w[:, bad])
            n_rej[bad] += 1
            ok[bad] &= solvable(w[:, bad])
            bad = bad[ok[bad]]
            e2[:, ~ok] = 0.0
            if bad.size:
                q[:, bad], it, conv[bad], A[..., bad], e2[:, bad] = gauss_newton(
                    model, q[:, bad], v[..., bad], w[:, bad], max_iter, tol)
                n_it[bad] += it

    fac = BatchCholesky(A)
    ok &= fac.determined
    _require_some(ok)
    n_used = w.sum(axis=0)
    rss = e2.sum(axis=0)
    dof = 3 * n_used - n
    if sigma is None:
        good = ok & (dof > 0)
        if not good.any():
            raise InputError(None, "v_world", f"a frame with more than {n / 3:g} markers to estimate the noise",
                             f"at most {int(n_used.max())} markers", hint="pass sigma= (marker noise SD in metres)")
        sigma = float(np.sqrt(rss[good].sum() / dof[good].sum()))
    sigma_q = sigma * np.sqrt(fac.inv_diag().T)
    rms = np.sqrt(rss / np.maximum(n_used, 1))
    q = q.T.copy()
    q[~ok], sigma_q[~ok], rms[~ok], conv[~ok] = np.nan, np.nan, np.nan, False
    return ChainAngles(t=None if t is None else np.asarray(t, dtype=np.float64), q=q, sigma_q=sigma_q,
                       marker_rms=rms, n_markers=n_used.astype(np.int64), n_rejected=n_rej, used=(w > 0).T, n_iter=n_it,
                       converged=conv, sigma_m=float(sigma), joint_names=model.joint_names)
