"""Cluster calibration files: a joint's fitted geometry as TOML (docs/formats.md).

Written under a run's output by ``mocapfj joints`` and reusable later: ``calibration/`` holds
those of the shipped datasets. Lengths in metres; the axis and point are in the parent cluster's
frame (the world when the parent does not move); the parent cluster's own template is stored
with it so that the frame can be found again in another trial.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import JointGeometry
from .tomlio import check_format, read_toml, require, write_toml

__all__ = ["write_joint_geometry", "read_joint_geometry"]

_FORMAT = "mocapfj.joint/1"


def write_joint_geometry(path: str | os.PathLike[str], name: str, geometry: JointGeometry,
                         parent_labels: tuple[str, ...] | str = "world", parent_template: np.ndarray | None = None,
                         extra: dict | None = None) -> None:
    """Write one joint's calibration, atomically."""
    doc = {
        "format": _FORMAT,
        "joint": name,
        "method": geometry.method,
        "n_frames": int(geometry.n_frames),
        "axis": geometry.axis.tolist(),
        "point_m": geometry.point.tolist(),
        "sigma_m": float(geometry.sigma_m),
        "marker_rms_m": float(geometry.marker_rms),
        "cov_axis": geometry.cov_axis.tolist(),
        "cov_point_m2": geometry.cov_point.tolist(),
        "link": {"labels": list(geometry.labels), "template_m": geometry.template.tolist(),
                 "radii_m": geometry.radii.tolist(), "radius_rms_m": geometry.radius_rms.tolist()},
    }
    if isinstance(parent_labels, str):
        doc["parent"] = {"labels": parent_labels}
    else:
        doc["parent"] = {"labels": list(parent_labels)}
        if parent_template is not None:
            doc["parent"]["template_m"] = np.asarray(parent_template, float).tolist()
    if extra:
        doc["extra"] = extra
    write_toml(path, doc)


def _arr(path, tab, key, where, shape):
    v = require(path, tab, key, list, where)
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(path, f"{where}.{key}" if where else key, f"numbers of shape {shape}", repr(v)[:60]) from None
    if shape is not None and a.shape != shape:
        raise InputError(path, f"{where}.{key}" if where else key, f"numbers of shape {shape}", f"shape {a.shape}")
    return a


def read_joint_geometry(path: str | os.PathLike[str]) -> tuple[str, JointGeometry, dict]:
    """Read a joint calibration: (joint name, geometry, parent table {labels, template_m})."""
    path = Path(path)
    doc = read_toml(path)
    check_format(path, doc, "joint", 1)
    link = require(path, doc, "link", dict)
    labels = tuple(require(path, link, "labels", list, "link"))
    P = len(labels)
    geometry = JointGeometry(
        axis=_arr(path, doc, "axis", "", (3,)), point=_arr(path, doc, "point_m", "", (3,)),
        template=_arr(path, link, "template_m", "link", (P, 3)), labels=labels,
        radii=_arr(path, link, "radii_m", "link", (P,)), radius_rms=_arr(path, link, "radius_rms_m", "link", (P,)),
        marker_rms=float(require(path, doc, "marker_rms_m", (int, float))),
        cov_axis=_arr(path, doc, "cov_axis", "", (3, 3)), cov_point=_arr(path, doc, "cov_point_m2", "", (3, 3)),
        sigma_m=float(require(path, doc, "sigma_m", (int, float))), method=require(path, doc, "method", str),
        n_frames=int(require(path, doc, "n_frames", int)))
    if abs(np.linalg.norm(geometry.axis) - 1.0) > 1e-6:
        raise InputError(path, "axis", "a unit vector", f"norm {np.linalg.norm(geometry.axis):.6g}")
    parent = require(path, doc, "parent", dict)
    return require(path, doc, "joint", str), geometry, parent
