"""``mocapfj batch``: many recordings at once, one Dask task per recording, and one table of the
identified parameters across repeated trials of each joint.

Lightcap and Banks (2007) identify each joint from 10 repeated trials and report the mean and
the coefficient of variation (CV %) of every parameter; :func:`run_batch` does that for any set
of recordings: each task runs ``mocapfj run`` on one recording in a worker (:func:`_task`, the
stages that apply or those asked for), the client writes its run directory as ``OUT/<name>/`` as
tasks finish and gathers the parameters
into ``OUT/batch.json``, ``batch.csv``, ``trials.csv`` and ``batch.md``.

The cluster: a local one of N single-threaded worker processes by default, or an existing
scheduler (``tcp://host:port``, docs/batch.md). A recording whose stage fails is reported (its
name, the stage and a one-line error) and the others finish; a worker that dies (killed, out of
memory) has its tasks rescheduled on the others by Dask. Workers read the recordings by path
(the same paths must be readable on every worker) and send their files back to the client, so
the output directory needs to exist only where ``mocapfj batch`` runs.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import socket
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

__all__ = ["BATCH_FORMAT", "STAGES", "BatchResult", "Trial", "run_batch", "summarize_trials", "write_batch",
           "trial_group"]

BATCH_FORMAT = "mocapfj.batch/1"
STAGES = ("triangulate", "joints", "identify", "discover", "recording", "report")   # mocapfj run's, the default
METHODS = ("output_error", "motor_first", "two_step")     # mocapfj.ident.IDENTIFY_METHODS, without importing ident
PARAMS = ("I", "mglx", "mgly", "c", "v", "J", "b", "k")   # Lightcap and Banks (2007), Table I order


# -- one recording, in a worker ------------------------------------------------------------------

def _one_line(e: BaseException) -> str:
    text = str(e) if isinstance(e, InputError) else f"{type(e).__name__}: {str(e)}"
    return " ".join(text.split())[:400] or type(e).__name__


def _recording_name(recording: str) -> str | None:
    """recording.toml's ``name`` (read without loading the bundle), else None."""
    import tomllib

    p = Path(recording)
    toml = p if p.name == "recording.toml" else p / "recording.toml"
    try:
        name = tomllib.loads(toml.read_text(encoding="utf-8")).get("name")
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return name if isinstance(name, str) and name else None


def _task(recording: str, out_dir: str, method: str = "output_error", stages: Sequence[str] | None = STAGES) -> dict:
    """``mocapfj run`` on one recording into `out_dir` (:func:`mocapfj.pipeline.run.run_pipeline`:
    the `stages` that apply, default :data:`STAGES`; `method` for identify). Returns {"status":
    "done" or "failed", "stage" and "error" (the failed stage), "name" (the recording's own name),
    "identify" (the Identification's to_dict(), or None), "stages" (each stage's name, status and
    reason)}. Never raises for a bad recording."""
    from ..io import read_json
    from .run import run_pipeline

    name = _recording_name(recording)
    try:
        res = run_pipeline(recording, out_dir, stages=stages, method=method)
    except Exception as e:                                   # the bundle did not load, or a stage crashed
        stage = "load"
        try:
            manifest = read_json(Path(out_dir) / "run.json")
            stage = next(s["name"] for s in manifest["stages"] if s["status"] == "pending")
        except (OSError, ValueError, KeyError, TypeError, StopIteration):
            pass
        return {"status": "failed", "stage": stage, "error": _one_line(e), "name": name, "identify": None,
                "stages": []}
    done = [{"name": r.name, "status": r.status, "reason": r.reason} for r in res.stages]
    ident = next((r.summary for r in res.stages if r.name == "identify" and r.status == "done"), None)
    if res.failed is not None:
        return {"status": "failed", "stage": res.failed.name, "error": " ".join((res.failed.error or "").split()),
                "name": name, "identify": ident, "stages": done}
    return {"status": "done", "stage": None, "error": None, "name": name, "identify": ident, "stages": done}


def _remote(recording: str, method: str = "output_error", stages: Sequence[str] | None = STAGES) -> dict:
    """What a Dask task runs: :func:`_task` into a private temporary directory, its files sent
    back as bytes (the client writes them), and where and how long it ran."""
    t0 = time.perf_counter()
    tmp = tempfile.mkdtemp(prefix="mocapfj-batch-")
    try:
        r = _task(recording, tmp, method, stages)
        files = {}
        for p in sorted(Path(tmp).rglob("*")):
            if p.is_file():
                files[p.relative_to(tmp).as_posix()] = p.read_bytes()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    r["files"] = files
    r["seconds"] = time.perf_counter() - t0
    r["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return r


# -- results -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Trial:
    """One recording of the batch: `name` (its directory under OUT), the recording's path, the
    trial group it is a repeat of, the identified joints, the failed stage and its error, and each
    run stage's status (run.json's: done, failed, not_applicable with the reason, ...)."""

    name: str
    recording: str
    group: str | None
    status: str
    stage: str | None
    error: str | None
    seconds: float | None
    worker: str | None
    joints: tuple[dict, ...] = ()
    stages: tuple[dict, ...] = ()

    def to_dict(self) -> dict:
        return {"name": self.name, "recording": self.recording, "group": self.group, "status": self.status,
                "stage": self.stage, "error": self.error, "seconds": self.seconds, "worker": self.worker,
                "joints": list(self.joints), "stages": list(self.stages)}


@dataclass(frozen=True)
class BatchResult:
    """A batch: its trials in the order given and the table across repeated trials (one row per
    trial group, joint and parameter: n, mean, SD, CV %, the reported SD's RMS, the values)."""

    cluster: str
    stages: tuple[str, ...]
    method: str
    trials: tuple[Trial, ...]
    table: tuple[dict, ...]
    seconds: float

    @property
    def failed(self) -> tuple[Trial, ...]:
        return tuple(t for t in self.trials if t.status != "done")

    def to_dict(self) -> dict:
        return {"format": BATCH_FORMAT, "cluster": self.cluster, "stages": list(self.stages), "method": self.method,
                "n_recordings": len(self.trials), "n_done": len(self.trials) - len(self.failed),
                "n_failed": len(self.failed), "seconds": self.seconds,
                "failed": [{"name": t.name, "stage": t.stage, "error": t.error} for t in self.failed],
                "table": list(self.table), "trials": [t.to_dict() for t in self.trials]}


_TRIAL_SUFFIX = re.compile(r"[_\-. ]*(trial|run|rep|repeat|take)[_\-. ]*\d+$", re.I)


def trial_group(recording_name: str) -> str:
    """The trial group of a recording: its name (recording.toml ``name``) without a trailing trial
    number ("pa10_j2_trial03" -> "pa10_j2"); recordings of one group are repeats of its joints."""
    g = _TRIAL_SUFFIX.sub("", recording_name)
    return g or recording_name


def _joint_rows(ident: dict | None) -> tuple[dict, ...]:
    """Per joint: its parameters {name: {value, std, determined}} and torque RMS (identify.json)."""
    out = []
    for j in (ident or {}).get("joints", []):
        p = j.get("params") or {}
        if not p:
            continue
        out.append({"name": j["name"], "torque_rms": j.get("torque_rms"),
                    "params": {n: {"value": v.get("value"), "std": v.get("std"),
                                   "determined": v.get("determined", True)} for n, v in p.items()}})
    return tuple(out)


def summarize_trials(trials: Sequence[Trial]) -> tuple[dict, ...]:
    """Mean, SD (n - 1) and CV % = 100 SD / |mean| of every parameter over the finished trials of
    each group and joint, with the RMS of the SDs each trial reported (a trial's own uncertainty:
    when it is much smaller than the SD across trials, the trials differ by more than noise)."""
    groups: dict[tuple[str, str], list[tuple[str, dict]]] = {}
    for t in trials:
        for j in t.joints:
            groups.setdefault((t.group, j["name"]), []).append((t.name, j))
    rows = []
    for (group, joint), members in groups.items():
        names = [n for n, _ in members]
        params = [n for n in PARAMS if any(n in j["params"] for _, j in members)]
        params += sorted({n for _, j in members for n in j["params"]} - set(params))
        for p in params + ["torque_rms"]:
            vals, stds, det = [], [], True
            for _, j in members:
                if p == "torque_rms":
                    v, s = j.get("torque_rms"), None
                else:
                    e = j["params"].get(p) or {}
                    v, s = e.get("value"), e.get("std")
                    det = det and bool(e.get("determined", True))
                vals.append(float("nan") if v is None else float(v))
                if s is not None:
                    stds.append(float(s))
            finite = [v for v in vals if math.isfinite(v)]
            n = len(finite)
            mean = sum(finite) / n if n else float("nan")
            sd = math.sqrt(sum((v - mean) ** 2 for v in finite) / (n - 1)) if n > 1 else float("nan")
            cv = 100.0 * sd / abs(mean) if n > 1 and mean != 0 else float("nan")
            rms_std = math.sqrt(sum(s * s for s in stds) / len(stds)) if stds else float("nan")
            rows.append({"group": group, "joint": joint, "parameter": p, "n": n, "mean": mean, "sd": sd,
                         "cv_pct": cv, "reported_sd_rms": rms_std, "determined": det,
                         "trials": names, "values": vals})
    return tuple(rows)


def _fmt(v) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.4g}"


def write_batch(result: BatchResult, out: str | Path) -> None:
    """OUT/batch.json (the result's to_dict()), batch.csv (the table), trials.csv (every trial's
    value and reported SD of every parameter) and batch.md (both, and the failed recordings)."""
    from ..io import write_json
    from ..io.atomic import write_text_atomic

    out = Path(out)
    write_json(out / "batch.json", result.to_dict())
    lines = ["group,joint,parameter,n,mean,sd,cv_pct,reported_sd_rms,determined"]
    for r in result.table:
        lines.append(",".join([r["group"], r["joint"], r["parameter"], str(r["n"])]
                              + [repr(float(r[k])) for k in ("mean", "sd", "cv_pct", "reported_sd_rms")]
                              + [str(r["determined"]).lower()]))
    write_text_atomic(out / "batch.csv", "\n".join(lines) + "\n")
    lines = ["name,group,joint,parameter,value,std"]
    for t in result.trials:
        for j in t.joints:
            for p, e in j["params"].items():
                lines.append(",".join([t.name, t.group or "", j["name"], p, repr(float(e["value"])),
                                       "" if e["std"] is None else repr(float(e["std"]))]))
    write_text_atomic(out / "trials.csv", "\n".join(lines) + "\n")

    md = [f"# Batch of {len(result.trials)} recordings", "",
          f"{len(result.trials) - len(result.failed)} finished, {len(result.failed)} failed; stages "
          f"{', '.join(result.stages)} ({result.method}); {result.cluster}; {result.seconds:.1f} s.", ""]
    keyed: dict[tuple[str, str], list[dict]] = {}
    for r in result.table:
        keyed.setdefault((r["group"], r["joint"]), []).append(r)
    for (group, joint), rows in keyed.items():
        md += [f"## {group}, joint {joint} ({rows[0]['n']} trials: {', '.join(rows[0]['trials'])})", "",
               "| parameter | mean | SD | CV (%) | reported SD (RMS) |", "|---|---|---|---|---|"]
        for r in rows:
            mark = "" if r["determined"] else " (not determined)"
            md.append(f"| {r['parameter']}{mark} | {_fmt(r['mean'])} | {_fmt(r['sd'])} | {_fmt(r['cv_pct'])} | "
                      f"{_fmt(r['reported_sd_rms'])} |")
        md.append("")
        md += ["| trial | " + " | ".join(r["parameter"] for r in rows) + " |", "|---" * (len(rows) + 1) + "|"]
        for k, name in enumerate(rows[0]["trials"]):
            md.append(f"| {name} | " + " | ".join(_fmt(r["values"][k]) for r in rows) + " |")
        md.append("")
    if result.failed:
        md += ["## Failed", "", "| recording | stage | error |", "|---|---|---|"]
        md += [f"| {t.name} | {t.stage} | {(t.error or '').replace('|', '/')} |" for t in result.failed]
        md.append("")
    write_text_atomic(out / "batch.md", "\n".join(md))


# -- the batch -----------------------------------------------------------------------------------

def _names(recordings: Sequence) -> list[str]:
    """OUT/<name> for each recording: its bundle directory's name, made unique."""
    seen: dict[str, int] = {}
    names = []
    for r in recordings:
        p = Path(r)
        base = p.parent.name if p.name == "recording.toml" else (p.stem if p.suffix in (".c3d", ".trc") else p.name)
        base = base or "recording"
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}_{seen[base]}")
    return names


def _check(recordings: Sequence, workers: int | None) -> list[str]:
    if not recordings:
        raise InputError(None, "recordings", "at least one recording bundle", "none")
    if workers is not None and (not isinstance(workers, int) or isinstance(workers, bool) or workers < 1):
        raise InputError(None, "workers", "a whole number of workers of at least 1", workers)
    paths, seen = [], {}
    for r in recordings:
        p = Path(r)
        if not p.exists():
            raise InputError(p, "RECORDING", "a bundle directory or its recording.toml", "no such path")
        key = (p.parent if p.name == "recording.toml" else p).resolve()
        if key in seen:
            raise InputError(p, "RECORDING", "each recording once (a repeat is a separate trial bundle)",
                             f"the same bundle as {seen[key]}")
        seen[key] = r
        paths.append(str(p.resolve()))
    return paths


def _client(scheduler: str | None, workers: int | None):
    """A Dask client and a description: on an existing scheduler, or on a new local cluster of
    `workers` processes with one thread each (closed with the client)."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        if "://" not in scheduler and not re.match(r"^[\w.\-]+:\d+$", scheduler):
            raise InputError(None, "scheduler", "a Dask scheduler address, e.g. tcp://host:8786", scheduler)
        try:
            client = Client(scheduler, timeout="15s")
        except (OSError, TimeoutError, ValueError) as e:
            raise InputError(None, "scheduler", "a reachable Dask scheduler (dask scheduler; dask worker ADDRESS)",
                             f"{scheduler}: {_one_line(e)}") from None
        n = len(client.scheduler_info().get("workers", {}))
        return client, None, f"scheduler {scheduler} ({n} workers at start)"
    n = workers or min(os.cpu_count() or 1, 4)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=":0", silence_logs=logging.ERROR)
    return Client(cluster), cluster, f"local cluster of {n} worker process{'es' if n != 1 else ''}, 1 thread each"


def _result(fut, resubmit, tries: int = 3):
    """A finished task's result. When the worker holding it dies before the client fetches it,
    Dask's own rescheduling can leave this future lost or cancelled ("Couldn't gather keys"): the
    task is then submitted again (a task is a pure function of its recording), up to `tries`
    times. A task that raised, or that killed its workers (KilledWorker), fails at once."""
    from distributed import KilledWorker

    for attempt in range(tries + 1):
        try:
            return fut.result()
        except KilledWorker:
            raise
        except Exception:
            if fut.status == "error" or attempt == tries:
                raise
            fut = resubmit(attempt + 1)


def run_batch(recordings: Sequence, out: str | Path, *, method: str = "output_error",
              stages: Sequence[str] | None = None, scheduler: str | None = None, workers: int | None = None,
              progress: Callable[[str], None] | None = None) -> BatchResult:
    """``mocapfj run`` on every recording (`stages`, default all that apply: :data:`STAGES`) as one
    Dask task, its run directory as ``out/<name>/``, the parameters across repeated trials in
    ``out/batch.*`` (:func:`write_batch`).

    `method`: the identification method (output_error, motor_first, two_step: :func:`mocapfj.identify`).
    `scheduler`: an existing Dask scheduler's address; else a local cluster of `workers` processes
    (default: the cores, at most 4). `progress(line)` is called as each task finishes. A failed
    recording is a Trial with status "failed"; raises only for bad arguments (InputError)."""
    from distributed import as_completed

    from ..io.atomic import write_bytes_atomic

    paths = _check(recordings, workers)
    if method not in METHODS:
        raise InputError(None, "method", f"one of {', '.join(METHODS)}", method)
    stages = STAGES if stages is None else tuple(stages)
    unknown = [x for x in stages if x not in STAGES]
    if unknown or not stages:
        raise InputError(None, "stages", f"stages among {', '.join(STAGES)}", ", ".join(unknown) or "none")
    names = _names(recordings)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda line: None)
    t0 = time.perf_counter()
    client, cluster, where = _client(scheduler, workers)
    results: dict[int, dict] = {}
    try:
        def submit(k, retry=0):
            key = f"mocapfj-batch-{k:04d}-{names[k]}" + (f"-retry{retry}" if retry else "")
            return client.submit(_remote, paths[k], method, stages, key=key, pure=False)

        futures = {submit(k): k for k in range(len(paths))}
        say(f"{len(paths)} recording(s) on a {where}")
        for done, fut in enumerate(as_completed(list(futures)), 1):
            k = futures[fut]
            try:
                r = _result(fut, lambda retry, k=k: submit(k, retry))
            except Exception as e:                           # Dask gave up (e.g. KilledWorker after repeated deaths)
                r = {"status": "failed", "stage": "dask", "error": _one_line(e), "name": None, "identify": None,
                     "files": {}, "seconds": None, "worker": None}
            fut.release()                                    # fetched: the worker may drop the files' bytes
            for rel, data in r.pop("files").items():
                write_bytes_atomic(out / names[k] / rel, data)
            results[k] = r
            if r["status"] == "done":
                say(f"[{done}/{len(paths)}] {names[k]}: done in {r['seconds']:.1f} s on {r['worker']}")
            else:
                say(f"[{done}/{len(paths)}] {names[k]}: FAILED at {r['stage']}: {r['error']}")
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    trials = tuple(Trial(name=names[k], recording=paths[k],
                         group=None if results[k]["name"] is None else trial_group(results[k]["name"]),
                         status=results[k]["status"], stage=results[k]["stage"], error=results[k]["error"],
                         seconds=None if results[k]["seconds"] is None else round(results[k]["seconds"], 3),
                         worker=results[k]["worker"], joints=_joint_rows(results[k]["identify"]),
                         stages=tuple(results[k].get("stages") or ()))
                   for k in range(len(paths)))
    result = BatchResult(cluster=where, stages=stages, method=method, trials=trials, table=summarize_trials(trials),
                         seconds=round(time.perf_counter() - t0, 3))
    write_batch(result, out)
    return result
