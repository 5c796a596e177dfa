"""Files over the fast methods of Oueslati et al. (2012): ``mocapfj algebraic`` and ``mocapfj
precompensate`` read a CSV, run :mod:`mocapfj.ident.algebraic` or
:mod:`mocapfj.ident.precompensation`, and write their results under ``--out``. No maths here."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import read_csv_columns, write_csv_columns, write_json

__all__ = ["run_algebraic", "run_precompensate"]


def _column(path, cols: dict, name: str) -> np.ndarray:
    if name not in cols:
        raise InputError(path, f"column {name!r}", f"one of the CSV's columns ({', '.join(list(cols)[:12])})", "absent")
    return cols[name]


def _finite(path, name: str, x: np.ndarray) -> None:
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise InputError(path, f"column {name!r}", "a number in every row of the segment",
                         f"NaN or empty at row {int(bad[0]) + 2}")


def _segment(path, t, start, duration):
    lo = t[0] if start is None else float(start)
    hi = t[-1] if duration is None else lo + float(duration)
    sel = np.flatnonzero((t >= lo - 1e-9) & (t <= hi + 1e-9))
    if sel.size == 0:
        raise InputError(path, "time", f"samples in [{lo:g}, {hi:g}] s", f"a record over {t[0]:g}..{t[-1]:g} s")
    return sel


def run_algebraic(csv, out: str | Path, output: str, input: str | None = None, time: str = "time",
                  start: float | None = None, duration: float | None = None, window: float | None = None,
                  offset: bool = True, inertia: float | None = None, damping: str = "auto") -> dict:
    """``mocapfj algebraic``: omega0 and zeta of a joint's oscillation in the segment
    [start, start + duration] of a CSV, by the algebraic estimator and (for a free vibration) the
    logarithmic decrement; with `window` also over sliding windows of that segment.

    Either estimate may fail where the other holds (the algebraic one is for a fraction of a period to
    a few periods, the decrement needs 1.5 periods or more): the one that fails is reported with its
    reason; only when every estimate fails is it an error. Writes OUT/algebraic.json (the summary) and,
    with `window`, OUT/sliding.csv (t_end, omega0, omega0_std, zeta, zeta_std per window).
    """
    if inertia is not None and not (math.isfinite(inertia) and inertia > 0):
        raise InputError(None, "inertia", "a positive link inertia in kg m^2", inertia)
    from ..ident.algebraic import algebraic_estimate, algebraic_sliding
    from ..ident.decrement import log_decrement

    out = Path(out)
    cols = read_csv_columns(csv)
    t_all = _column(csv, cols, time)
    y_all = _column(csv, cols, output)
    u_all = None if input is None else _column(csv, cols, input)
    sel = _segment(csv, t_all, start, duration)
    t, y = t_all[sel], y_all[sel]
    u = None if u_all is None else u_all[sel]
    for name, x in ((time, t), (output, y)) + (() if u is None else ((input, u),)):
        _finite(csv, name, x)
    joint: dict = {"name": output, "input": input, "segment_s": [float(t[0]), float(t[-1])]}
    estimates = {}
    failed = None
    try:
        a = algebraic_estimate(t, y, u, offset=offset, damping=damping)
        estimates["algebraic"] = a
        joint["algebraic"] = a.to_dict()
        if a.link_reversals:
            joint["note"] = (f"the link reverses {a.link_reversals} time(s) in the segment: with Coulomb friction zeta is "
                             "the transient's equivalent viscous damping (a velocity change without reversal avoids it)")
    except InputError as e:
        failed = InputError(csv, f"column {output!r} ({e.field})", e.expected, e.got, e.hint)
        joint["algebraic"] = {"error": str(failed).split(": ", 2)[-1]}
    if u is None:
        try:
            ld = log_decrement(t, y)
            estimates["log_decrement"] = ld
            joint["log_decrement"] = ld.to_dict()
        except InputError as e:
            joint["log_decrement"] = {"error": str(e).split(": ", 2)[-1]}
    if not estimates:
        raise failed
    if len(estimates) == 2:
        a, ld = estimates["algebraic"], estimates["log_decrement"]
        dz = (a.zeta - ld.zeta) / math.hypot(a.zeta_std, ld.zeta_std)
        dw = (a.omega0 - ld.omega0) / math.hypot(a.omega0_std, ld.omega0_std)
        joint["agreement_sd"] = {"omega0": dw, "zeta": dz}
        joint["agree"] = bool(abs(dw) < 3 and abs(dz) < 3)
    elif failed is not None:
        joint["note"] = ("the algebraic estimate failed on this segment (it is for a fraction of a period to a few "
                         "periods: --duration shorter), the logarithmic decrement holds")
    if inertia is not None:
        for key, e in estimates.items():
            k, k_std = e.stiffness(inertia)
            joint[key]["stiffness"] = k
            joint[key]["stiffness_std"] = k_std
            joint[key]["damping_coefficient"] = 2 * e.zeta * math.sqrt(k * inertia)
    if window is not None:
        # without an input the two damping forms are one
        chosen = estimates["algebraic"].damping if "algebraic" in estimates else "link"
        s = algebraic_sliding(t, y, u, window_s=window, offset=offset, damping=chosen)
        joint["sliding"] = s.to_dict()
        write_csv_columns(out / "sliding.csv", {"t_end": s.t_end, "omega0": s.omega0, "omega0_std": s.omega0_std,
                                                "zeta": s.zeta, "zeta_std": s.zeta_std})
    summary = {"file": str(csv), "inertia": inertia, "joints": [joint]}
    write_json(out / "algebraic.json", summary)
    return summary


def run_precompensate(csv, out: str | Path, reference: str, time: str = "time", omega0: float | None = None,
                      zeta: float | None = None, model: str | Path | None = None, iterations: int = 1,
                      damping: str | None = None, method: str = "eq17") -> dict:
    """``mocapfj precompensate``: the motor command of Oueslati et al. (2012), eq. 17, for the
    reference column of a CSV, from omega0 and zeta (given, or the algebraic estimate in an
    algebraic.json, with the damping form it chose). Writes OUT/command.csv (time, reference, command, and the link's error the
    model predicts before and after) and OUT/precompensate.json."""
    from ..ident.precompensation import precompensate
    from ..io import read_json

    out = Path(out)
    if model is not None:
        m = read_json(model)
        try:
            est = m["joints"][0]["algebraic"]
            omega0 = float(est["omega0"]) if omega0 is None else omega0
            zeta = float(est["zeta"]) if zeta is None else zeta
            damping = str(est.get("damping", "link")) if damping is None else damping
        except (KeyError, IndexError, TypeError, ValueError):
            raise InputError(model, "joints[0].algebraic", "an algebraic.json written by mocapfj algebraic",
                             "no omega0 / zeta there") from None
    if omega0 is None or zeta is None:
        raise InputError(None, "omega0", "--omega0 and --zeta, or --model algebraic.json", "neither")
    cols = read_csv_columns(csv)
    t = _column(csv, cols, time)
    r = _column(csv, cols, reference)
    _finite(csv, time, t)
    _finite(csv, reference, r)
    p = precompensate(t, r, omega0, zeta, iterations=iterations, damping=damping or "link", method=method)
    write_csv_columns(out / "command.csv", {time: t, reference: r, "command": p.command,
                                            "predicted_error_before": p.predicted_error_before,
                                            "predicted_error_after": p.predicted_error_after})
    summary = {"file": str(csv), "reference": reference, **p.to_dict()}
    write_json(out / "precompensate.json", summary)
    return summary
