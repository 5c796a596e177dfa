"""Files over the clamped end-effector stiffness of Jubien et al. (2014): ``mocapfj clamped`` reads
a CSV (and the force sensor's CSV), runs :mod:`mocapfj.ident.clamped` and writes its results under
``--out``. No maths here."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import read_csv_columns, write_json

__all__ = ["run_clamped"]


def _column(path, cols: dict, name: str) -> np.ndarray:
    if name not in cols:
        raise InputError(path, f"column {name!r}", f"one of the CSV's columns ({', '.join(list(cols)[:12])})", "absent")
    return cols[name]


def _names(arg: str, what: str) -> list[str]:
    names = [s.strip() for s in str(arg).split(",")]
    if not names or any(not s for s in names):
        raise InputError(None, what, "comma-separated column names", repr(arg))
    return names


def _as_options(e: InputError, csv, time: str) -> InputError:
    """identify_clamped's complaint about one of its arguments, named by the command's options."""
    if e.file != "<argument>":
        return e
    field = e.field.rsplit(": ", 1)[-1]
    where = e.field.rsplit(": ", 1)[0] + ": " if ": " in e.field else ""
    # the command's own options by their argparse names where the CLI says them (--urdf, --torques)
    option = {"model": "urdf", "tau_m, wrench": "torques", "cutoff_hz": "--cutoff",
              "decimate_cutoff_hz": "--decimate-cutoff", "excitation": "--positions"}.get(field)
    if option is None:
        return e
    hint = e.hint
    if field == "cutoff_hz":
        hint = f"the cut-off is in Hz and column {time!r} in s"
    elif field == "excitation":
        hint = "the motor angles must move with the torques (the motors pushing on the clamped arm)"
    return InputError(csv if field in ("cutoff_hz", "excitation") else None, f"{where}{option}", e.expected, e.got,
                      hint)


MISFIT_PCT = 10.0
"""|W chi - Y| / |Y| above which the joint's torques are not k q_m + offset: the model is said to be off."""


def clamped_notes(res) -> list[str]:
    """What the numbers leave unsaid: a stiffness that is not positive (a wrench read with the other
    sign: the tool's on the environment is asked for), and a fit the torques do not follow (a wrench
    in another frame, a tool offset the model lacks, an unclamped end effector)."""
    notes = []
    for r in res:
        for f in (r.motor, r.wrench):
            if f is None:
                continue
            what = f"{r.name} by {f.source.replace('_', ' ')}"
            if not f.k > 0:
                notes.append(f"{what}: k {f.k:.4g} N m/rad is not a stiffness"
                             + (" (the wrench's sign: --wrench is the one the tool applies to the environment)"
                                if f.source == "wrench" else " (the motor angle's or the torque's sign)"))
            if f.rel_error_pct > MISFIT_PCT:
                notes.append(f"{what}: the torques do not follow k q_m + offset (|W chi - Y| / |Y| "
                             f"{f.rel_error_pct:.3g} %)" + (": check --frame and the tool's offset in the model"
                                                             if f.source == "wrench" else ""))
    return notes


def run_clamped(csv, out: str | Path, positions: str, torques: str | None = None, wrench: str | None = None,
                wrench_file: str | Path | None = None, time: str = "time", urdf: str | Path | None = None,
                mdh: str | Path | None = None, frame: str = "tool", joints: str | None = None,
                cutoff: float = 10.0, decimate_cutoff: float = 5.0) -> dict:
    """``mocapfj clamped``: joint stiffness with the end-effector clamped (Jubien et al. 2014).

    `positions` and `torques`: comma-separated columns of the motor angles and torques (link side,
    rad and N m, one per joint in the robot's order); `wrench`: six columns fx, fy, fz, mx, my, mz
    (N, N m, in `frame`; "0" for a component not measured), read from `wrench_file` (with its own
    `time` column) when the sensor logs apart; the robot from `urdf` or `mdh` (a CSV with columns
    alpha, d, theta_offset, r, or "kr500" for Jubien et al.'s Table 1). `joints`: comma-separated
    1-based joint numbers (default all). Writes OUT/clamped.json and OUT/table.md.
    """
    from ..ident.clamped import KR500_MDH, identify_clamped

    out = Path(out)
    cols = read_csv_columns(csv)
    t = _column(csv, cols, time)
    pos_names = _names(positions, "positions")
    q_m = np.column_stack([_column(csv, cols, c) for c in pos_names])
    n = q_m.shape[1]
    tau = None
    if torques is not None:
        tq = _names(torques, "torques")
        if len(tq) != n:
            raise InputError(None, "torques", f"{n} columns (one per --positions column)", len(tq))
        tau = np.column_stack([_column(csv, cols, c) for c in tq])
    F = tw = model = None
    if wrench is not None:
        wn = _names(wrench, "wrench")
        if len(wn) != 6:
            raise InputError(None, "wrench", "six columns fx,fy,fz,mx,my,mz ('0' for one not measured)", len(wn))
        src, wcols = (csv, cols) if wrench_file is None else (wrench_file, read_csv_columns(wrench_file))
        rows = len(next(iter(wcols.values()))) if wcols else 0
        F = np.column_stack([np.zeros(rows) if c == "0" else _column(src, wcols, c) for c in wn])
        if wrench_file is not None:
            tw = _column(wrench_file, wcols, time)
        if urdf is not None and mdh is not None:
            raise InputError(None, "urdf", "--urdf or --mdh, not both", "both")
        if mdh is not None:
            if str(mdh).lower() == "kr500":
                model = KR500_MDH
            else:
                mc = read_csv_columns(mdh)
                model = np.column_stack([_column(mdh, mc, c) for c in ("alpha", "d", "theta_offset", "r")])
        else:
            model = urdf
    sel = None
    if joints is not None:
        try:
            sel = [int(s) - 1 for s in _names(joints, "joints")]
        except ValueError:
            raise InputError(None, "joints", "joint numbers, comma-separated", joints) from None
        if min(sel) < 0 or max(sel) >= len(pos_names):
            raise InputError(None, "joints", f"joint numbers in 1..{len(pos_names)} (one per --positions column)",
                             joints)
    try:
        res = identify_clamped(t, q_m, tau_m=tau, wrench=F, t_wrench=tw, model=model, frame=frame, joints=sel,
                               names=pos_names, cutoff_hz=cutoff, decimate_cutoff_hz=decimate_cutoff)
    except InputError as e:
        raise _as_options(e, csv, time) from None
    summary = {"file": str(csv), "joints": [r.to_dict() for r in res], "notes": clamped_notes(res)}
    lines = ["| joint | method | k (N m/rad) | rel. SD (%) | offset (N m) | rel. SD (%) | |W chi - Y| / |Y| (%) |",
             "|---|---|---|---|---|---|---|"]
    for r in res:
        for f in (r.motor, r.wrench):
            if f is not None:
                lines.append(f"| {r.name} | {f.source} | {f.k:.4g} | {f.k_rel_std_pct:.2g} | {f.offset:.4g} | "
                             f"{f.offset_rel_std_pct:.2g} | {f.rel_error_pct:.3g} |")
        if r.motor is not None and r.wrench is not None:
            lines.append(f"| {r.name} | difference | {r.rel_diff_pct:.3g} % | | | | |")
    from ..io.atomic import write_text_atomic

    write_text_atomic(out / "table.md", "\n".join(lines) + "\n")
    write_json(out / "clamped.json", summary)
    return summary
