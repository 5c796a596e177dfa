"""Marker trajectories made consistent with their rigid cluster before an axis is fitted.

A link's markers keep their distances: every frame's distance matrix is compared with the
cluster's shape at the start of the trial (the median over its first tenth). Two labels whose trajectories are exchanged over some frames (a labelling
swap in the mocap software) show as a pattern that the exchange restores, and are relabelled in
those frames; a sample whose distances to the others are off in a frame where the rest agree (a
spike, a ghost marker) is removed (NaN, filled or left out downstream). Both are counted and
reported. A cluster that stays inconsistent (a marker off in more than MAX_REMOVED_SHARE of its
frames) is refused: no axis fit can be trusted on it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

__all__ = ["ClusterRepair", "repair_cluster", "MIN_TOLERANCE_M", "MAX_REMOVED_SHARE"]

MIN_TOLERANCE_M = 0.015
"""A distance off its median by more than this (or 8 robust SDs of the distances' scatter, if more)
is inconsistent with the rigid cluster."""
MAX_REMOVED_SHARE = 0.2
"""A marker inconsistent in more than this share of its frames is refused, not repaired."""
MAX_STEP_DEG = 30.0
"""A cluster's pose turning by more than this between two frames with markers is a labelling jump
(a robot link turns a few degrees per frame at most), not motion."""


@dataclass(frozen=True)
class ClusterRepair:
    """What :func:`repair_cluster` changed: ``swaps`` [(label_a, label_b, frames, first time s)],
    ``removed`` {label: samples set to NaN}, the tolerance used (m)."""

    swaps: tuple = ()
    removed: dict = field(default_factory=dict)
    tolerance_m: float = 0.0

    @property
    def changed(self) -> bool:
        return bool(self.swaps or any(self.removed.values()))

    def to_dict(self) -> dict:
        return {"swaps": [{"labels": [a, b], "frames": n, "from_s": t} for a, b, n, t in self.swaps],
                "removed": dict(self.removed), "tolerance_m": self.tolerance_m}

    def describe(self) -> str:
        parts = [f"{a} and {b} exchanged in {n} frames from t = {t:.3f} s" for a, b, n, t in self.swaps]
        parts += [f"{n} samples of {s} off the cluster removed" for s, n in self.removed.items() if n]
        return "; ".join(parts)


def _errors(xyz: np.ndarray, D0: np.ndarray) -> np.ndarray:
    D = np.linalg.norm(xyz[:, :, None] - xyz[:, None], axis=-1)
    return D - D0


def _poses(xyz: np.ndarray, X0: np.ndarray) -> np.ndarray:
    """Per frame, the rotation (T, 3, 3) taking the template X0 (M, 3) onto the frame's markers
    (Kabsch, over the markers seen; identity where fewer than 3 are)."""
    w = np.isfinite(xyz[:, :, 0]).astype(float)                   # (T, M)
    x = np.nan_to_num(xyz)
    n = np.maximum(w.sum(axis=1, keepdims=True), 1.0)
    cx = (w[:, :, None] * x).sum(axis=1) / n                       # (T, 3)
    c0 = (w[:, :, None] * X0[None]).sum(axis=1) / n
    H = np.einsum("tm,tmi,tmj->tij", w, X0[None] - c0[:, None], x - cx[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("tij,tjk->tik", U, Vt)))
    Dm = np.tile(np.eye(3), (xyz.shape[0], 1, 1))
    Dm[:, 2, 2] = d
    R = np.einsum("tji,tjk,tlk->til", Vt, Dm, U)                   # V D U^T
    R[w.sum(axis=1) < 3] = np.eye(3)
    return R


def _turn_deg(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Angles (deg) of the rotations A B^T, elementwise over leading axes."""
    tr = np.einsum("...ij,...ij->...", A, B)
    return np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))


def _relabel_jumps(xyz: np.ndarray, labels, t: np.ndarray) -> list:
    """Exchanges a distance check cannot see (a cluster nearly symmetric under the swap): the
    pose jumps where the labels change. At each jump, the pair exchange that makes the pose
    continuous is applied from there on (a later jump back undoes it). Modifies xyz; returns the
    swaps [(a, b, frames, first time)]."""
    T, M = xyz.shape[:2]
    full = np.isfinite(xyz[:, :, 0]).all(axis=1)
    if full.sum() < 3:
        return []
    ref = xyz[np.argmax(full)]
    X0 = ref - ref.mean(axis=0)
    swaps = []
    pairs = [(i, j) for i in range(M) for j in range(i + 1, M)]
    for _ in range(8):                                           # a few jumps at most; each pass fixes one
        seen = np.isfinite(xyz[:, :, 0]).sum(axis=1) >= 3
        idx = np.flatnonzero(seen)
        R = _poses(xyz[idx], X0)
        step = _turn_deg(R[1:], R[:-1])
        jumps = np.flatnonzero(step > MAX_STEP_DEG)
        if jumps.size == 0:
            break
        k = int(jumps[0])
        t0, prev = idx[k + 1], R[k]
        best = None
        for i, j in pairs:
            perm = np.arange(M)
            perm[[i, j]] = [j, i]
            Rp = _poses(xyz[t0:t0 + 1][:, perm], X0)[0]
            turn = float(_turn_deg(Rp, prev))
            if turn <= MAX_STEP_DEG and (best is None or turn < best[0]):
                best = (turn, i, j, perm)
        if best is None:
            break                                                 # not a pair exchange: left to the checks
        _, i, j, perm = best
        xyz[t0:] = xyz[t0:][:, perm]
        swaps.append((labels[i], labels[j], int(T - t0), float(t[t0])))
    # an exchange undone later shows as two entries of the same pair: frames between them
    out = []
    for a, b, n, t_from in swaps:
        if out and {out[-1][0], out[-1][1]} == {a, b}:
            a0, b0, n0, t0_ = out.pop()
            out.append((a0, b0, n0 - n, t0_))
        else:
            out.append((a, b, n, t_from))
    return out


def repair_cluster(xyz: np.ndarray, labels, t: np.ndarray, *, source=None, where: str = "") -> tuple[np.ndarray, ClusterRepair]:
    """xyz (T, M, 3) m of one rigid cluster (NaN where lost), its labels and times: the repaired
    copy and what was done (module docstring). InputError naming the marker and the time when a
    marker stays off its cluster in more than MAX_REMOVED_SHARE of its frames."""
    xyz = np.array(xyz, dtype=np.float64)
    T, M = xyz.shape[:2]
    if M < 3 or T < 3:
        return xyz, ClusterRepair()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)          # all-NaN slices of lost markers
        # the cluster's shape from the start of the trial (the median of the first tenth of the
        # frames with every marker seen): a swap over half the trial would bias a whole-trial median
        D = np.linalg.norm(xyz[:, :, None] - xyz[:, None], axis=-1)
        full = np.flatnonzero(np.isfinite(D).all(axis=(1, 2)))
        head = full[:max(50, full.size // 10)] if full.size else np.arange(T)
        D0 = np.nanmedian(D[head], axis=0)
        E = _errors(xyz, D0)
        off = ~np.eye(M, dtype=bool)
        scatter = 1.4826 * float(np.nanmedian(np.abs(E[:, off]))) if np.isfinite(E[:, off]).any() else 0.0
    tol = max(MIN_TOLERANCE_M, 8.0 * scatter)

    def bad_count(e):
        return (np.abs(np.nan_to_num(e, nan=0.0)) > tol).sum(axis=(1, 2)) // 2

    # exchanges: a pair whose swap makes an inconsistent frame consistent
    swaps = []
    for i in range(M):
        for j in range(i + 1, M):
            perm = np.arange(M)
            perm[[i, j]] = [j, i]
            n_now = bad_count(E)
            cand = n_now > 0
            if not cand.any():
                break
            E_sw = _errors(xyz[:, perm], D0)
            both = np.isfinite(xyz[:, [i, j], 0]).all(axis=1)
            fix = cand & (bad_count(E_sw) == 0) & both
            if fix.any():
                # inside the exchange's span, the frames where one of the two is lost go with it
                a, b_ = np.flatnonzero(fix)[[0, -1]]
                span = np.zeros(T, bool)
                span[a:b_ + 1] = True
                fix |= span & ~both & (bad_count(E_sw) <= bad_count(E))
                xyz[fix] = xyz[fix][:, perm]
                E[fix] = E_sw[fix]
                swaps.append((labels[i], labels[j], int(fix.sum()), float(t[np.argmax(fix)])))
    # spikes: in a frame with inconsistent distances, the marker(s) with the most of them
    bad = np.abs(np.nan_to_num(E, nan=0.0)) > tol                  # (T, M, M)
    per = bad.sum(axis=2)                                          # (T, M)
    worst = per.max(axis=1, keepdims=True)
    out = (per == worst) & (worst >= 2)
    removed = {}
    if out.any():
        seen = np.isfinite(xyz[:, :, 0]).sum(axis=0)
        for m in np.flatnonzero(out.any(axis=0)):
            n = int(out[:, m].sum())
            if n > MAX_REMOVED_SHARE * max(int(seen[m]), 1):
                first = float(t[np.argmax(out[:, m])])
                raise InputError(source, f"marker {labels[m]!r}{where}",
                                 "a marker that keeps its distances to the rest of its rigid cluster",
                                 f"off by more than {1e3 * tol:.0f} mm in {n} of its {int(seen[m])} frames, first at "
                                 f"t = {first:.3f} s", hint="check its labelling in the mocap software (a swap "
                                 "with a marker of another cluster, or a ghost)")
            removed[labels[m]] = n
        xyz[out] = np.nan
    # exchanges the distances cannot see (a cluster nearly symmetric under them): pose jumps
    swaps += _relabel_jumps(xyz, labels, t)
    return xyz, ClusterRepair(swaps=tuple(swaps), removed=removed, tolerance_m=tol)
