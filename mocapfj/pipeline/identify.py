"""Files over identification (``mocapfj identify``): :func:`mocapfj.identify` on the recordings,
each joints stage written under OUT, then identify.json and the Table-I-style tables."""

from __future__ import annotations

from pathlib import Path

from ..io import load_recording, write_json
from .core import write_joints

__all__ = ["run_identify", "write_tables"]

TABLE_COLUMNS = ("I", "c", "v", "mglx", "mgly", "b", "J", "k")
TABLE_UNITS = ("kg m2", "N m", "N m s", "N m", "N m", "N m s", "kg m2", "N m/rad")


def write_tables(summary: dict, out: Path) -> None:
    """OUT/table.md and OUT/table.csv: per joint, the mean and (with repeats) the CV % or (one
    trial) the relative SD % of each parameter, and the torque RMS error, in the columns of
    Lightcap and Banks (2007), Table I. A parameter the data do not determine is marked."""
    from ..io.atomic import write_text_atomic

    lines = ["| joint | statistic | " + " | ".join(f"{c} ({u})" for c, u in zip(TABLE_COLUMNS, TABLE_UNITS))
             + " | error (N m) |", "|" + "---|" * (len(TABLE_COLUMNS) + 3)]
    csv_lines = ["joint,statistic," + ",".join(TABLE_COLUMNS) + ",error"]
    for j in summary["joints"]:
        p = j.get("params", {})
        if not p:
            continue
        marks = ["" if c not in p or p[c].get("determined", True) else " (not determined)" for c in TABLE_COLUMNS]
        rows = [("mean", [p[c]["value"] if c in p else None for c in TABLE_COLUMNS], j["torque_rms"])]
        rows.append(("CV (%)", [j["cv_pct"].get(c) for c in TABLE_COLUMNS], None) if "cv_pct" in j
                    else ("rel. std (%)", [p[c]["rel_std_pct"] if c in p else None for c in TABLE_COLUMNS], None))
        for stat, vals, err in rows:
            cells = ["-" if v is None else f"{v:.4g}{m if stat == 'mean' else ''}" for v, m in zip(vals, marks)]
            lines.append(f"| {j['name']} | {stat} | " + " | ".join(cells) + f" | {'' if err is None else f'{err:.3g}'} |")
            csv_lines.append(",".join([j["name"], stat] + ["nan" if v is None else repr(float(v)) for v in vals]
                                      + ["" if err is None else repr(float(err))]))
    write_text_atomic(out / "table.md", "\n".join(lines) + "\n")
    write_text_atomic(out / "table.csv", "\n".join(csv_lines) + "\n")


def run_identify(recordings, out: str | Path, method: str = "output_error", cutoff_hz: float | None = None,
                 decimate: int = 2, validation=None, fit_clock_offset: bool = False) -> dict:
    """``mocapfj identify``: identify every joint of one or more recordings; repeats give CV %.

    Writes OUT/<k>_<recording>/joints/ (the joints stage of each recording with markers),
    OUT/identify.json (the Identification's ``to_dict()``) and the tables OUT/table.md and
    OUT/table.csv (:func:`write_tables`). A rigid robot's log (no markers) is identified through
    its URDF, and checked on `validation` when given.
    """
    from ..api import identify
    from ..joints.stage import calibrate_joints

    out = Path(out)
    recs = [load_recording(r) for r in recordings]
    cals = []
    for k, (path, rec) in enumerate(zip(recordings, recs)):
        if rec.markers is None:
            cals.append(None)
            continue
        cal = calibrate_joints(rec)
        write_joints(cal, out / f"{k:02d}_{Path(path).name}" / "joints")
        cals.append(cal)
    ident = identify(recs, method=method, cutoff_hz=cutoff_hz, decimate=decimate,
                     validation=None if validation is None else load_recording(validation),
                     calibrations=None if any(c is None for c in cals) else cals, fit_clock_offset=fit_clock_offset)
    summary = ident.to_dict()
    summary["recordings"] = [str(r) for r in recordings]
    write_json(out / "identify.json", summary)
    write_tables(summary, out)
    return summary
