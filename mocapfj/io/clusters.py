"""Clusters files: the rigid marker clusters (and AprilTags) that label unlabelled markers.

``mocapfj.clusters/1`` (docs/formats.md)::

    format = "mocapfj.clusters/1"
    [[clusters]]
    name = "link2"
    labels = ["L2_1", "L2_2", "L2_3", "L2_4"]
    template_m = [[0.10, 0.0, 0.02], ...]     # marker positions in the cluster's frame, metres
    [[tags]]                                  # optional: an AprilTag carried by a link
    name = "tag3"
    id = 3
    size_m = 0.05                             # the black square's side, metres
    family = "tag36h11"                       # optional, the default

A joint calibration file (``mocapfj.joint/1``) serves as one too: its link markers make the
cluster ``<joint>.link`` and its parent markers, when their template is stored, ``<joint>.parent``.
A tag's markers are its corners ``<name>_0`` .. ``<name>_3`` in OpenCV's order (top-left, top-right,
bottom-right, bottom-left as printed), in the tag frame of docs/conventions.md: origin at the
tag's centre, x to the right, y down, z into the tag.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import MarkerCluster
from .tomlio import check_format, describe, read_toml, require, write_toml

__all__ = ["read_clusters", "write_clusters", "tag_template", "TAG_FAMILIES"]

TAG_FAMILIES = ("tag36h11", "tag25h9", "tag16h5")


def tag_template(size_m: float) -> np.ndarray:
    """Corners (4, 3) of a square tag of side `size_m` in its own frame, OpenCV's corner order."""
    h = 0.5 * float(size_m)
    return np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])


def _template(path, tab, where, n):
    v = require(path, tab, "template_m", list, where)
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(path, f"{where}.template_m", f"{n} rows of 3 numbers (m)", describe(v)) from None
    if a.shape != (n, 3):
        raise InputError(path, f"{where}.template_m", f"{n} rows of 3 numbers (m), one per label", f"shape {a.shape}")
    return a


def _cluster(path, name, labels, template, **kw) -> MarkerCluster:
    try:
        return MarkerCluster(name, labels, template, **kw)
    except InputError as e:
        raise InputError(path, e.field, e.expected, e.got) from None


def read_clusters(path: str | os.PathLike[str]) -> tuple[MarkerCluster, ...]:
    """Read a clusters file (``mocapfj.clusters/1``) or a joint calibration (``mocapfj.joint/1``).

    Returns the clusters, then the tags, in file order; labels are unique across all of them.
    """
    path = Path(path)
    doc = read_toml(path)
    fmt = doc.get("format")
    out: list[MarkerCluster] = []
    if isinstance(fmt, str) and fmt.startswith("mocapfj.joint/"):
        check_format(path, doc, "joint", 1)
        joint = require(path, doc, "joint", str)
        link = require(path, doc, "link", dict)
        labels = require(path, link, "labels", list, "link")
        out.append(_cluster(path, f"{joint}.link", labels, _template(path, link, "link", len(labels))))
        parent = doc.get("parent")
        if isinstance(parent, dict) and isinstance(parent.get("labels"), list) and "template_m" in parent:
            out.append(_cluster(path, f"{joint}.parent", parent["labels"],
                                _template(path, parent, "parent", len(parent["labels"]))))
    else:
        check_format(path, doc, "clusters", 1)
        clusters = require(path, doc, "clusters", list, default=[])
        tags = require(path, doc, "tags", list, default=[])
        if not clusters and not tags:
            raise InputError(path, "clusters", "at least one [[clusters]] or [[tags]] table", "none")
        for k, tab in enumerate(clusters):
            where = f"clusters[{k}]"
            if not isinstance(tab, dict):
                raise InputError(path, where, "a table", describe(tab))
            name = require(path, tab, "name", str, where)
            labels = require(path, tab, "labels", list, where)
            if not all(isinstance(s, str) and s for s in labels):
                raise InputError(path, f"{where}.labels", "non-empty marker names", describe(labels))
            out.append(_cluster(path, name, labels, _template(path, tab, where, len(labels))))
        for k, tab in enumerate(tags):
            where = f"tags[{k}]"
            if not isinstance(tab, dict):
                raise InputError(path, where, "a table", describe(tab))
            name = require(path, tab, "name", str, where)
            tid = require(path, tab, "id", int, where)
            size = float(require(path, tab, "size_m", (int, float), where))
            family = require(path, tab, "family", str, where, default="tag36h11")
            if family not in TAG_FAMILIES:
                raise InputError(path, f"{where}.family", f"one of {', '.join(TAG_FAMILIES)}", repr(family))
            if not (0.0 < size < 10.0) or tid < 0:
                raise InputError(path, f"{where}.size_m" if not (0.0 < size < 10.0) else f"{where}.id",
                                 "a tag side in metres (0-10 m) and an id >= 0", f"size_m {size}, id {tid}")
            out.append(_cluster(path, name, [f"{name}_{i}" for i in range(4)], tag_template(size), tag_id=tid,
                                tag_family=family))
    seen: dict[str, str] = {}
    for c in out:
        for s in c.labels:
            if s in seen:
                raise InputError(path, f"label {s!r}", "each label in one cluster", f"in {seen[s]!r} and {c.name!r}")
            seen[s] = c.name
    tag_keys = [(c.tag_family, c.tag_id) for c in out if c.tag_id is not None]
    if len(set(tag_keys)) != len(tag_keys):
        raise InputError(path, "tags", "each tag id once per family", f"ids {[k[1] for k in tag_keys]}")
    return tuple(out)


def write_clusters(path: str | os.PathLike[str], clusters: Sequence[MarkerCluster]) -> None:
    """Write clusters (and tags) as a ``mocapfj.clusters/1`` file, atomically."""
    doc: dict = {"format": "mocapfj.clusters/1"}
    plain = [c for c in clusters if c.tag_id is None]
    tags = [c for c in clusters if c.tag_id is not None]
    if plain:
        doc["clusters"] = [{"name": c.name, "labels": list(c.labels), "template_m": c.template_m.tolist()} for c in plain]
    if tags:
        doc["tags"] = [{"name": c.name, "id": int(c.tag_id), "size_m": float(np.linalg.norm(c.template_m[1] - c.template_m[0])),
                        "family": c.tag_family or "tag36h11"} for c in tags]
    write_toml(path, doc)
