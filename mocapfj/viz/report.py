"""The report of a run: one self-contained HTML file and its Markdown twin, from the run's results.

:func:`build_report` reads ``RUN_DIR`` as ``mocapfj run`` writes it (docs/formats.md, "Run
directory"), or one command's ``--out`` (an ``identify`` or ``discover`` directory alone), and
writes ``report.html`` (figures embedded as base64 PNG), ``report.md`` and ``report_files/`` (its
figures). Sections, each present when its results are: the stages (and which did not run), the
recording, calibration and coverage, joint geometry with uncertainty, identification
(determined / not determined with the reason), the spring fit, the FRF, discovery. Inputs are
only read; the three outputs are written atomically (the figure folder is staged and renamed).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ..io.outdir import replace_dir
from .document import Note, Paragraph, Section, Table, render_html, render_markdown
from .report_format import fmt, read_result_json

__all__ = ["ReportResult", "build_report", "STAGE_FILES"]

# The stages a run may hold, in run order, and the result file that says a stage ran.
STAGE_FILES = {"calibrate_rig": "calibrate_rig.json", "triangulate": "triangulate.json", "joints": "joints.json",
               "identify": "identify.json", "discover": "discovery.json", "frf": "frf.json"}
_WHAT = {"calibrate_rig": "rig calibration", "triangulate": "3D markers from 2D detections",
         "joints": "joint axes, angles and deflection", "identify": "flexible-joint identification",
         "discover": "missing-physics discovery", "frf": "frequency response",
         "recording": "the rerun recording (recording.rrd)", "report": "this report"}
FIGURES_DIR = "report_files"


@dataclass(frozen=True)
class ReportResult:
    """What :func:`build_report` wrote.

    html, markdown: the report's paths; figures: the figure files (in ``report_files/``, in
    report order); sections: the keys of the sections present; stages_missing: the stages whose
    results are absent (with the reason run.json gives, when it gives one).
    """

    run_dir: Path
    html: Path
    markdown: Path
    figures: tuple[str, ...]
    sections: tuple[str, ...]
    stages_missing: tuple[tuple[str, str], ...]

    def to_dict(self) -> dict:
        return {"run_dir": str(self.run_dir), "html": str(self.html), "markdown": str(self.markdown),
                "figures_dir": str(self.run_dir / FIGURES_DIR), "figures": list(self.figures),
                "sections": list(self.sections),
                "stages_missing": [{"name": n, "reason": r} for n, r in self.stages_missing]}


@dataclass(frozen=True)
class RunFiles:
    """Where a run's results are: `stages` maps a stage to the directory holding its result file;
    `manifest` is run.json (None for one command's --out); `joints_dir` the joints stage's files
    (its own directory, else the copy discover or identify keeps)."""

    root: Path
    manifest: dict | None
    stages: dict[str, Path]
    joints_dir: Path | None


def locate(run_dir: Path) -> RunFiles:
    """Find the results of each stage under `run_dir` (docs/formats.md, "Run directory")."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise InputError(run_dir, "RUN_DIR", "a run directory (mocapfj run --out, or one command's --out)",
                         "no such directory" if not run_dir.exists() else "a file")
    manifest = None
    if (run_dir / "run.json").is_file():
        manifest = read_result_json(run_dir / "run.json")
        if manifest.get("format") != "mocapfj.run/1":
            raise InputError(run_dir / "run.json", "format", '"mocapfj.run/1"', manifest.get("format"))
        if not isinstance(manifest.get("stages", []), list):
            raise InputError(run_dir / "run.json", "stages", "a list of stages", type(manifest["stages"]).__name__)
    stages = {}
    for name, file in STAGE_FILES.items():
        for d in (run_dir / name, run_dir):
            if (d / file).is_file():
                stages[name] = d
                break
    joints_dir = stages.get("joints")
    if joints_dir is None:
        cands = []
        if "discover" in stages:
            cands.append(stages["discover"] / "joints")
        if "identify" in stages:
            cands += sorted(p.parent for p in stages["identify"].glob("*/joints/joints.json"))
        joints_dir = next((c for c in cands if (c / "joints.json").is_file()), None)
    if not stages and manifest is None:
        raise InputError(run_dir, "results", "a run directory (run.json) or one command's --out holding one of "
                         + ", ".join(STAGE_FILES.values()), "none of them")
    return RunFiles(run_dir, manifest, stages, joints_dir)


def _manifest_stages(files: RunFiles) -> dict[str, dict]:
    out = {}
    for i, s in enumerate((files.manifest or {}).get("stages", [])):
        if not isinstance(s, dict) or not isinstance(s.get("name"), str):
            raise InputError(files.root / "run.json", f"stages[{i}]", "an object with a name", s)
        out[s["name"]] = s
    return out


def _stages_section(files: RunFiles) -> tuple[Section, list[tuple[str, str]]]:
    listed = _manifest_stages(files)
    names = list(listed) + [n for n in STAGE_FILES if n not in listed]
    rows, flags, missing = [], [], []
    for n in names:
        m = listed.get(n, {})
        present = n in files.stages or (n == "joints" and files.joints_dir is not None)
        status = m.get("status") or ("done" if present else "not run")
        if n in STAGE_FILES and not present:
            reason = m.get("reason") or m.get("error") or ("no results in this directory" if not m else status)
            missing.append((n, f"{status}: {reason}" if m and reason != status else reason))
            flags.append("bad" if status == "failed" else "")
        else:
            reason = m.get("reason") or m.get("error") or ""
            flags.append("")
        where = (files.stages.get(n) or (files.joints_dir if n == "joints" else None))
        where_s = (os.path.relpath(where, files.root) if where is not None else "")
        rows.append((n, _WHAT.get(n, ""), status if present or m else "not run",
                     fmt(m.get("seconds")) if m.get("seconds") is not None else "", where_s or "—", reason))
    header = ("stage", "what", "status", "time (s)", "results in", "note")
    if not any(r[3] for r in rows):                       # no times recorded: no empty column
        header, rows = header[:3] + header[4:], [r[:3] + r[4:] for r in rows]
    blocks = [Table(header, tuple(rows), tuple(flags))]
    if missing:
        blocks.append(Note("Stages that did not run (their sections are left out): "
                           + "; ".join(f"{n} ({r})" for n, r in missing) + ".", "warn"))
    return Section("stages", "Stages", tuple(blocks)), missing


def _recording_section(files: RunFiles) -> Section | None:
    man = files.manifest
    if not man or not man.get("recording"):
        return None
    from ..pipeline.core import inspect_path
    from .report_sections import recording_blocks

    blocks = []
    for role in ("recording", "validation"):
        path = man.get(role)
        if not path:
            continue
        if not Path(path).exists():
            name = "The recording" if role == "recording" else "The validation recording"
            blocks.append(Note(f"{name} named in run.json ({path}) is not there: its summary is left out.",
                               "warn"))
            continue
        blocks += recording_blocks(inspect_path(path), role, path)
    return Section("recording", "Recording", tuple(blocks))


def _write_figures(run_dir: Path, figures) -> None:
    """report_files/ replaced whole: the figures written into a staging folder beside it, renamed."""
    stage = Path(tempfile.mkdtemp(prefix=f".{FIGURES_DIR}.", suffix=".tmp", dir=run_dir))
    try:
        for f in figures:
            (stage / f.name).write_bytes(f.png)
        os.chmod(stage, 0o755)
        replace_dir(stage, run_dir / FIGURES_DIR, run_dir / f".{FIGURES_DIR}.old.{os.getpid()}")
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise


def build_report(run_dir) -> ReportResult:
    """Write RUN_DIR/report.html, report.md and report_files/ from the run's results.

    run_dir: a ``mocapfj run`` output directory, or one command's ``--out`` (``identify``,
    ``discover``, ``joints``, ``frf``, ...). Raises :class:`~mocapfj.errors.InputError` (naming
    the file) for a missing directory, a directory without results, or a malformed result file.
    """
    from ..io.atomic import write_text_atomic
    from . import report_sections as rs
    from .document import Figure

    files = locate(Path(run_dir))
    root = files.root.resolve()
    stages_sec, missing = _stages_section(files)
    sections = [stages_sec]
    rec = _recording_section(files)
    if rec is not None:
        sections.append(rec)
    sections += rs.calibration_sections(files)
    sections += rs.joint_sections(files)
    sections += rs.identification_sections(files)
    sections += rs.frf_sections(files)
    sections += rs.discovery_sections(files)

    figures = [b for s in sections for b in s.blocks if isinstance(b, Figure)]
    names = [f.name for f in figures]
    if len(set(names)) != len(names):
        raise AssertionError(f"figure names repeat: {names}")      # a bug in the sections, not bad input
    man = files.manifest or {}
    rec_name = next((b.rows[0][1] for s in sections if s.key == "recording" for b in s.blocks
                     if isinstance(b, Table) and b.rows and b.rows[0][0] == "name" and b.rows[0][1]), None)
    title = "mocapfj report: " + (rec_name or (Path(man["recording"]).name if man.get("recording") else root.name))
    meta = (f"Run directory {root}" + (f"; created {man['created_utc']}" if man.get("created_utc") else "")
            + (f"; mocapfj {man['mocapfj_version']}" if man.get("mocapfj_version") else "")
            + ". SI units unless a unit is given; ± is one standard deviation.")
    if not any(s.key not in ("stages", "recording") for s in sections):
        sections.append(Section("empty", "Results", (Paragraph("No stage results in this directory yet."),)))
    _write_figures(root, figures)
    md = root / "report.md"
    html = root / "report.html"
    write_text_atomic(md, render_markdown(title, meta, sections, FIGURES_DIR))
    write_text_atomic(html, render_html(title, meta, sections))
    keys = tuple(dict.fromkeys(s.key.split("/")[0] for s in sections))
    return ReportResult(root, html, md, tuple(names), keys, tuple(missing))
