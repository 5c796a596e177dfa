"""``mocapfj run``: every stage that applies to a recording, into one run directory
(docs/formats.md, "Run directory").

The stages, in order: ``triangulate`` (a bundle whose markers come from its cameras),
``joints``, ``identify``, ``discover``, ``recording`` (the rerun ``.rrd``) and ``report``. Each
writes the files its own command writes, into ``RUN_DIR/<stage>/``, staged beside it and renamed
into place when it completes, so a failing stage leaves the finished ones intact. ``run.json``
records each stage's status and a digest of its inputs (the bundle's files, the stage's options
and the digests of the stages it reads); a rerun skips a finished stage whose digest did not
change. No maths here: the stages are the Python API's.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..errors import InputError
from ..io import load_recording, read_json, write_json

__all__ = ["STAGES", "RunResult", "StageRecord", "run_pipeline", "bundle_digest"]

STAGES = ("triangulate", "joints", "identify", "discover", "recording", "report")
RUN_FORMAT = "mocapfj.run/1"


@dataclass(frozen=True)
class StageRecord:
    """One stage of a run: `status` "done", "skipped" (its inputs did not change since it was
    done), "failed" or "not_applicable" (with the `reason`)."""

    name: str
    status: str
    reason: str | None = None
    inputs_sha256: str | None = None
    dir: str | None = None
    files: tuple[str, ...] = ()
    seconds: float | None = None
    error: str | None = None
    summary: dict | None = field(default=None, compare=False)

    def to_dict(self) -> dict:
        d = {"name": self.name, "status": self.status, "inputs_sha256": self.inputs_sha256, "dir": self.dir,
             "files": list(self.files), "seconds": self.seconds, "error": self.error}
        if self.reason is not None:
            d["reason"] = self.reason
        return d


@dataclass(frozen=True)
class RunResult:
    """What ``mocapfj run`` did: the run directory, the recording(s) and each stage's record."""

    out: Path
    recording: str
    validation: str | None
    stages: tuple[StageRecord, ...]

    @property
    def failed(self) -> StageRecord | None:
        return next((s for s in self.stages if s.status == "failed"), None)

    def stage(self, name: str) -> StageRecord:
        return next(s for s in self.stages if s.name == name)

    def to_dict(self) -> dict:
        from .. import __version__

        return {"format": RUN_FORMAT, "recording": self.recording, "validation": self.validation,
                "out": str(self.out), "mocapfj_version": __version__,
                "stages": [s.to_dict() for s in self.stages],
                "failed": None if self.failed is None else self.failed.name}


def _sha(*parts) -> str:
    h = hashlib.sha256()
    for p in parts:
        h.update(json.dumps(p, sort_keys=True, default=str).encode())
        h.update(b"\0")
    return h.hexdigest()


def _file_sha(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def bundle_digest(rec) -> str:
    """SHA-256 over the files a loaded bundle was read from: recording.toml and every file it
    names (markers, controller log, URDF, rig, detections, clusters)."""
    root = Path(rec.root)
    names = {"recording.toml", rec.marker_file, rec.controller_file}
    spec = rec.spec
    for table, key in (("model", "urdf"), ("rig", "file"), ("rig", "detections"), ("rig", "clusters")):
        tab = spec.get(table)
        if isinstance(tab, dict) and isinstance(tab.get(key), str):
            names.add(tab[key])
    files = sorted(n for n in names if n and (root / n).is_file())
    return _sha([(n, _file_sha(root / n)) for n in files])


class _Context:
    """The in-memory results stages share: the recordings and the joints stage's calibrations,
    computed when a stage first needs them (a skipped stage's results are recomputed only when a
    later stage must run)."""

    def __init__(self, out: Path, recording, validation):
        self.out = out
        self.rec = load_recording(recording)
        self.val = load_recording(validation) if validation is not None else None
        self._cal: dict = {}

    def markers_from(self, which: str):
        rec = self.rec if which == "rec" else self.val
        if rec.markers_from_cameras:
            from ..io import read_markers
            from ..io.recording import with_markers

            path = self.out / "triangulate" / ("markers.c3d" if which == "rec" else "validation_markers.c3d")
            rec = with_markers(rec, read_markers(path), path)
            if which == "rec":
                self.rec = rec
            else:
                self.val = rec
        return rec

    def calibration(self, which: str = "rec"):
        if which not in self._cal:
            from ..joints.stage import calibrate_joints

            self._cal[which] = calibrate_joints(self.markers_from(which))
        return self._cal[which]


def _rig_paths(rec) -> tuple[Path, Path, Path, float]:
    tab = rec.spec["rig"]
    root = Path(rec.root)
    return root / tab["file"], root / tab["detections"], root / tab["clusters"], float(tab["rate_hz"])


def _stage_triangulate(ctx: _Context, d: Path) -> tuple[dict, tuple[str, ...]]:
    from .triangulate import run_triangulate

    summary = {}
    for which, rec in (("rec", ctx.rec), ("val", ctx.val)):
        if rec is None or not rec.markers_from_cameras:
            continue
        rig, det, clusters, rate = _rig_paths(rec)
        sub = d if which == "rec" else d / "validation"
        s = run_triangulate([det], rig, sub, clusters=[clusters], rate_hz=rate, progress=False)
        if which == "val":
            os.replace(sub / "markers.c3d", d / "validation_markers.c3d")
        summary[which] = s
    files = ("markers.c3d", "triangulate.json") + (("validation_markers.c3d",) if "val" in summary else ())
    return summary["rec"], files


def _stage_joints(ctx: _Context, d: Path):
    from .core import write_joints

    s = write_joints(ctx.calibration("rec"), d)
    files = ["joints.json"] + [f for j in s["joints"] for f in j.get("files", {}).values()]
    return s, tuple(files)


def _stage_identify(ctx: _Context, d: Path):
    from ..api import identify
    from .identify import write_tables

    rec = ctx.markers_from("rec")
    cal = [ctx.calibration("rec")] if rec.markers is not None else None
    method = getattr(ctx, "method", None)
    ident = identify([rec], calibrations=cal, **({} if method is None else {"method": method}))
    summary = ident.to_dict()
    summary["recordings"] = [str(rec.root)]
    write_json(d / "identify.json", summary)
    write_tables(summary, d)
    return summary, ("identify.json", "table.md", "table.csv")


def _stage_discover(ctx: _Context, d: Path):
    from ..api import discover
    from .core import write_joints
    from .discover import write_discovery

    rec = ctx.markers_from("rec")
    val = ctx.markers_from("val") if ctx.val is not None else None
    write_joints(ctx.calibration("rec"), d / "joints")
    if val is not None:
        write_joints(ctx.calibration("val"), d / "validation_joints")
    disc = discover(rec, validation=val, calibration=ctx.calibration("rec"),
                    validation_calibration=ctx.calibration("val") if val is not None else None)
    disc = replace(disc, recording=str(rec.root), model_source="identified")
    summary = write_discovery(disc, d)
    return summary, tuple(f for f in ("discovery.json", "model.toml", "residuals.csv") if (d / f).is_file())


def _stage_recording(ctx: _Context, d: Path):
    from ..viz.rrd import write_run_recording

    path = write_run_recording(ctx.out)
    return {"file": path.name}, (path.name,)


def _stage_report(ctx: _Context, d: Path):
    from ..viz.report import build_report

    r = build_report(ctx.out)
    s = r.to_dict()
    return s, ("report.html", "report.md")


_RUNNERS: dict[str, Callable] = {"triangulate": _stage_triangulate, "joints": _stage_joints,
                                 "identify": _stage_identify, "discover": _stage_discover,
                                 "recording": _stage_recording, "report": _stage_report}
_READS = {"triangulate": (), "joints": ("triangulate",), "identify": ("triangulate", "joints"),
          "discover": ("triangulate", "joints"), "recording": ("triangulate", "joints", "identify", "discover"),
          "report": ("triangulate", "joints", "identify", "discover")}
_OWN_DIR = {"triangulate", "joints", "identify", "discover"}   # the others write into RUN_DIR itself


def _applies(name: str, rec, val) -> str | None:
    """None when stage `name` applies to the recording, else the reason it does not."""
    has_markers = rec.markers is not None or rec.markers_from_cameras
    if name == "triangulate":
        if not (rec.markers_from_cameras or (val is not None and val.markers_from_cameras)):
            return "the bundle holds 3D markers" if rec.markers is not None else "the bundle has no cameras' detections"
    elif name == "joints":
        if not has_markers:
            return "no markers (a rigid robot's controller log)"
    elif name == "identify":
        if rec.controller is None:
            return "no controller log (markers only: axes and angles, no dynamics)"
    elif name == "discover":
        if rec.controller is None or not has_markers:
            return ("no controller log" if rec.controller is None else
                    "no markers: discovery compares the measured link side with the model")
    return None


def _previous(out: Path) -> dict:
    p = out / "run.json"
    if not p.is_file():
        return {}
    try:
        doc = read_json(p)
        return {s["name"]: s for s in doc.get("stages", []) if isinstance(s, dict) and "name" in s}
    except (ValueError, OSError, TypeError, AttributeError):
        return {}                                            # an unreadable manifest: everything reruns


def _write_manifest(out: Path, recording, validation, records: Sequence[StageRecord]) -> None:
    from .. import __version__

    write_json(out / "run.json", {
        "format": RUN_FORMAT, "recording": str(Path(recording).resolve()),
        "validation": None if validation is None else str(Path(validation).resolve()),
        "created_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "mocapfj_version": __version__, "stages": [r.to_dict() for r in records]})


def run_pipeline(recording, out: str | Path, validation=None, stages: Sequence[str] | None = None,
                 progress: Callable[[str], None] | None = None, force: bool = False,
                 method: str | None = None) -> RunResult:
    """Every stage that applies to `recording` (a bundle directory or recording.toml), into `out`.

    `validation`: a second recording of the same joint, on which discovery proves its fit gain.
    `stages`: the stages to run (default all of :data:`STAGES`); the others are recorded "not
    requested". `progress(line)` is called as each stage starts and ends. `force`: run every stage
    even when its inputs did not change. A stage that fails is recorded with its error and the
    run stops there: the finished stages' directories stay, and ``run.json`` says which failed.
    `method`: the identify stage's method (:func:`mocapfj.identify`; default its own).
    """
    from ..io.outdir import MARKER, replace_dir

    out = Path(out)
    wanted = tuple(STAGES if stages is None else stages)
    unknown = [s for s in wanted if s not in STAGES]
    if unknown:
        raise InputError(None, "stages", f"stages among {list(STAGES)}", unknown)
    ctx = _Context(out, recording, validation)
    ctx.method = method
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).touch()
    say = progress or (lambda line: None)
    previous = _previous(out)
    from .. import __version__

    base = _sha(__version__, bundle_digest(ctx.rec), None if ctx.val is None else bundle_digest(ctx.val))
    digests: dict[str, str] = {}
    records: list[StageRecord] = []
    failed = False
    for k, name in enumerate(STAGES):
        reason = _applies(name, ctx.rec, ctx.val)
        if reason is None and name not in wanted:
            reason = "not requested (--stages)"
        if reason is not None or failed:
            records.append(StageRecord(name, "not_applicable" if reason else "not_run",
                                       reason=reason or "an earlier stage failed"))
            continue
        digest = _sha(name, base, [digests.get(r) for r in _READS[name]])
        if name == "identify" and method is not None:
            digest = _sha(digest, method)
        digests[name] = digest
        d = out / name if name in _OWN_DIR else out
        prev = previous.get(name, {})
        if (not force and prev.get("status") in ("done", "skipped") and prev.get("inputs_sha256") == digest
                and all((d / f).exists() for f in prev.get("files", ()))):
            records.append(StageRecord(name, "skipped", inputs_sha256=digest, dir=prev.get("dir"),
                                       files=tuple(prev.get("files", ())), seconds=0.0))
            say(f"[{k + 1}/{len(STAGES)}] {name}: inputs unchanged, kept")
            continue
        _write_manifest(out, recording, validation, records + [StageRecord(n, "pending") for n in STAGES[k:]])
        say(f"[{k + 1}/{len(STAGES)}] {name} ...")
        t0 = time.perf_counter()
        staging = out / f".{name}.tmp"
        if staging.exists():
            shutil.rmtree(staging)
        try:
            if name in _OWN_DIR:
                staging.mkdir()
                summary, files = _RUNNERS[name](ctx, staging)
                replace_dir(staging, d, out / f".{name}.old.{os.getpid()}")
            else:
                summary, files = _RUNNERS[name](ctx, d)
        except (InputError, OSError, ValueError, RuntimeError, ArithmeticError, LookupError, TypeError) as e:
            shutil.rmtree(staging, ignore_errors=True)
            text = str(e) if isinstance(e, InputError) else f"{type(e).__name__}: {' '.join(str(e).split())[:300]}"
            records.append(StageRecord(name, "failed", inputs_sha256=None, dir=name if name in _OWN_DIR else ".",
                                       seconds=round(time.perf_counter() - t0, 3), error=text))
            say(f"[{k + 1}/{len(STAGES)}] {name} FAILED: {text}")
            failed = True
            continue
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        sec = round(time.perf_counter() - t0, 3)
        records.append(StageRecord(name, "done", inputs_sha256=digest, dir=name if name in _OWN_DIR else ".",
                                   files=tuple(files), seconds=sec, summary=summary))
        say(f"[{k + 1}/{len(STAGES)}] {name}: done in {sec:.1f} s")
    _write_manifest(out, recording, validation, records)
    return RunResult(out=out.resolve(), recording=str(Path(recording).resolve()),
                     validation=None if validation is None else str(Path(validation).resolve()),
                     stages=tuple(records))


def _stderr_progress(line: str) -> None:                  # pragma: no cover - the CLI's printer
    print(line, file=sys.stderr, flush=True)
