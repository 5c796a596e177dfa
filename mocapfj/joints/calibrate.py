"""Joint calibration from a recording's markers: the link cluster in its parent's frame, the hinge
fit chosen per joint, and the per-frame angles that go with it.

- :func:`markers_in_parent_frame`: link markers in the parent cluster's frame (one fitted pose for
  a parent that does not move, per-frame Kabsch for one that does).
- :func:`calibrate_joint`: one named method (maximum likelihood, Halvorsen 2003, Gamage and
  Lasenby 2002, or SARA, Ehrig et al. 2007) and the angles with it.
- :func:`auto_calibrate_joint`: maximum likelihood, or SARA where the markers do not move as a
  hinge (skin, a forearm that also pronates).
- :func:`fit_sara_geometry`, :func:`sara_angles`: a hinge from the cluster's rigid rotations.

Frames and units: docs/conventions.md. Markers (T, P, 3) metres, NaN where missing.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..rotations import twist_angle
from ..types import JointAngles, JointGeometry
from .angles import joint_angles, predict_markers
from .axis import fit_gamage_lasenby, fit_halvorsen, fit_hinge_ml
from .segments import cluster_template, fit_sara, kabsch, to_parent_frame

__all__ = ["STATIC_PARENT_SD_M", "HINGE_MISFIT_RATIO", "CALIBRATION_METHODS", "ParentFrame", "markers_in_parent_frame",
           "fit_sara_geometry", "sara_angles", "calibrate_joint", "auto_calibrate_joint", "solve_angles",
           "flip_axis"]

STATIC_PARENT_SD_M = 1e-3
"""A parent cluster whose markers move less than this (SD over the trial, metres) is static (a
braked link): one pose fitted over all frames is used, so the parent adds no per-frame noise."""

HINGE_MISFIT_RATIO = 5.0
"""`auto` fits by SARA when the ML hinge's marker residual exceeds this many times the link
cluster's own rigid-fit residual: the markers then do not move as a hinge (skin, a forearm that
also pronates), and the cluster's rotations locate the axis better than its marker positions."""

CALIBRATION_METHODS = ("auto", "ml", "halvorsen", "gamage_lasenby", "sara")


@dataclass(frozen=True, eq=False)
class ParentFrame:
    """The frame a joint's geometry is expressed in.

    template : (P, 3) float or None
        The parent cluster's marker template (its own frame, metres); None for the world.
    static : bool
        The parent does not move (or is the world).
    R_world_parent : (3, 3) float or None
        For a static parent, the rotation from the parent frame into the world (identity for the
        world); None for a moving parent.
    t_world_parent : (3,) float or None
        The translation of the same map, metres.
    """

    template: np.ndarray | None
    static: bool
    R_world_parent: np.ndarray | None
    t_world_parent: np.ndarray | None


def markers_in_parent_frame(v_link: np.ndarray, v_parent: np.ndarray | None) -> tuple[np.ndarray, ParentFrame]:
    """Link markers (T, P, 3) expressed in the parent cluster's frame, and that frame.

    A parent cluster (T, Q, 3) is located per frame by a rigid fit (Kabsch) to its template; when
    it does not move (`STATIC_PARENT_SD_M`), one pose fitted over all frames is used so that it
    adds no per-frame noise. `v_parent` None: the world is the parent.
    """
    if v_parent is None:
        return v_link, ParentFrame(None, True, np.eye(3), np.zeros(3))
    template = cluster_template(v_parent)
    static = bool(np.nanmax(np.nanstd(v_parent, axis=0)) < STATIC_PARENT_SD_M)
    if static:
        R, t, _ = kabsch(template, np.nanmean(v_parent, axis=0)[None])
        frame = ParentFrame(template, True, R[0], t[0])
        R, t = np.broadcast_to(R, (v_link.shape[0], 3, 3)), np.broadcast_to(t, (v_link.shape[0], 3))
    else:
        R, t, _ = kabsch(template, v_parent)
        frame = ParentFrame(template, False, None, None)
    return to_parent_frame(v_link, R, t), frame


def fit_sara_geometry(v: np.ndarray, labels) -> JointGeometry:
    """A hinge from the motion of the link cluster as a rigid body in the parent frame (SARA).

    For joints between two moving segments, where the markers also move in ways a hinge does not
    (skin, pronation of a forearm): the axis comes from the cluster's rotations (Ehrig et al.
    2007), which such motion disturbs far less than marker positions. The template is the cluster
    at its first complete frame. `cov_axis` and `cov_point` are NaN: judge the axis by refitting
    on parts of the trial.
    """
    tmpl = cluster_template(v)
    R, t, _ = kabsch(tmpl, v)
    n_frames = R.shape[0]
    axis_i, _, c_i, _ = fit_sara(np.broadcast_to(np.eye(3), (n_frames, 3, 3)), np.zeros((n_frames, 3)), R, t)
    axis = axis_i / np.linalg.norm(axis_i)
    complete = np.flatnonzero(~np.isnan(v[..., 0]).any(axis=1))
    if complete.size == 0:
        raise InputError(None, "v", "a frame in which every link marker is seen", "none")
    ref = v[complete[0]]
    centroid = np.nanmean(v.reshape(-1, 3), axis=0)
    point = c_i + ((centroid - c_i) @ axis) * axis
    template = ref - point
    radii = np.linalg.norm(template - np.outer(template @ axis, axis), axis=1)
    nan33 = np.full((3, 3), np.nan)
    geometry = JointGeometry(axis=axis, point=point, template=template, labels=tuple(labels), radii=radii,
                             radius_rms=np.zeros(len(labels)), marker_rms=float("nan"), cov_axis=nan33,
                             cov_point=nan33, sigma_m=float("nan"), method="sara",
                             n_frames=int(np.isfinite(R[:, 0, 0]).sum()))
    # residuals of the hinge through the cluster's own motion
    rel = v - point
    dist = np.linalg.norm(rel - (rel @ axis)[..., None] * axis, axis=-1)
    radius_rms = np.sqrt(np.nanmean((dist - radii) ** 2, axis=0))
    R_ref = R[np.flatnonzero(np.isfinite(R[:, 0, 0]))[0]]
    q = twist_angle(np.einsum("tij,kj->tik", R, R_ref), axis)
    resid = v - predict_markers(geometry, np.where(np.isfinite(q), q, 0.0))
    d2 = np.where(np.isfinite(q)[:, None], (resid ** 2).sum(-1), np.nan)
    marker_rms = float(np.sqrt(np.nanmean(d2)))
    return replace(geometry, radius_rms=radius_rms, marker_rms=marker_rms, sigma_m=marker_rms / np.sqrt(3))


def sara_angles(v: np.ndarray, geometry: JointGeometry, t) -> JointAngles:
    """Angles of a SARA joint: the twist about its axis of the link cluster's rigid rotation.

    The cluster (its template in the parent frame) is fitted to each frame (Kabsch); frames with
    fewer than 3 markers are NaN. sigma_q is sigma_m / sqrt(sum of r_p^2 over the markers seen).
    """
    R, _, _ = kabsch(geometry.point + geometry.template, v)
    q = twist_angle(R, geometry.axis)
    seen = ~np.isnan(v[..., 0])
    valid = np.isfinite(q)
    r2 = (np.where(seen, geometry.radii**2, 0.0)).sum(axis=1)
    sigma_q = np.where(valid, geometry.sigma_m / np.sqrt(np.maximum(r2, 1e-300)), np.nan)
    resid = np.linalg.norm(v - predict_markers(geometry, np.where(valid, q, 0.0)), axis=-1)
    sq = np.where(seen & valid[:, None], resid, 0.0) ** 2
    marker_rms = np.where(valid, np.sqrt(sq.sum(axis=1) / np.maximum(seen.sum(axis=1), 1)), np.nan)
    n = np.where(valid, seen.sum(axis=1), 0)
    return JointAngles(t=np.asarray(t, float), q=q, sigma_q=sigma_q, marker_rms=marker_rms, n_markers=n,
                       n_rejected=np.zeros_like(n))


def solve_angles(v: np.ndarray, geometry: JointGeometry, t) -> JointAngles:
    """Per-frame angles of a joint with a given geometry, by the solver that goes with its fit:
    the closed-form hinge angle (:func:`.angles.joint_angles`), or the cluster's twist for SARA."""
    if geometry.method == "sara":
        return sara_angles(v, geometry, t)
    return joint_angles(v, geometry, t)


def calibrate_joint(v: np.ndarray, labels, t: np.ndarray, method: str = "ml") -> tuple[JointGeometry, JointAngles]:
    """Fit a joint's geometry from its markers in the parent frame and solve its angles.

    v (T, P, 3) metres, labels P str, t (T,) s. `method`: "ml" (maximum likelihood seeded by the
    bias-compensated fit), "halvorsen", "gamage_lasenby", "sara" (:func:`fit_sara_geometry`) or
    "auto" (:func:`auto_calibrate_joint`).
    """
    if method == "auto":
        return auto_calibrate_joint(v, labels, t)
    if method == "gamage_lasenby":
        geometry = fit_gamage_lasenby(v, labels=labels)
    elif method == "halvorsen":
        geometry = fit_halvorsen(v, labels=labels)
    elif method == "ml":
        # the seed's axis and point only: its bootstrap covariance (2.6 s on a 60 s recording) is
        # not used, the ML fit reports its own
        geometry, _ = fit_hinge_ml(v, labels=labels, init=fit_halvorsen(v, labels=labels, n_boot=0))
    elif method == "sara":
        geometry = fit_sara_geometry(v, labels)
    else:
        raise InputError(None, "method", f"one of {list(CALIBRATION_METHODS)}", repr(method))
    return geometry, solve_angles(v, geometry, t)


def auto_calibrate_joint(v: np.ndarray, labels, t) -> tuple[JointGeometry, JointAngles]:
    """Maximum likelihood, or SARA where the markers do not move as a hinge (`HINGE_MISFIT_RATIO`)."""
    geometry, angles = calibrate_joint(v, labels, t, "ml")
    _, _, rigid = kabsch(cluster_template(v), v)
    rigid_rms = float(np.nanmedian(rigid))
    if geometry.marker_rms > HINGE_MISFIT_RATIO * max(rigid_rms, 1e-6):
        return calibrate_joint(v, labels, t, "sara")
    return geometry, angles


def flip_axis(geometry: JointGeometry) -> JointGeometry:
    """The same hinge with its axis reversed (angles change sign)."""
    return replace(geometry, axis=-geometry.axis)
