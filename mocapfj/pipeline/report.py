"""``mocapfj report RUN_DIR``: the report of a run (re)built from its results' files.

The files are those of docs/formats.md, "Run directory"; :func:`mocapfj.viz.report.build_report`
reads them and writes RUN_DIR/report.html, report.md and report_files/. Nothing else in RUN_DIR
is touched.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["run_report"]


def run_report(run_dir: str | Path) -> dict:
    """Build the report of `run_dir`; return its summary (paths, figures, sections, stages missing).

    Raises :class:`~mocapfj.errors.InputError` naming the file for a missing directory, one without
    results, or a malformed result file.
    """
    from ..viz.report import build_report

    return build_report(Path(run_dir)).to_dict()
