"""``mocapfj batch`` on Dask (mocapfj.pipeline.batch): ten repeated trials of PA-10 joint 2
(Lightcap and Banks (2007) run each joint 10 times), simulated with ten seeds, plus a trial too
short to calibrate the joint.

- a local two-worker cluster gives exactly the files and numbers of ten sequential runs, and the
  table's mean, SD and CV % are those of the trials' values;
- the bad trial is reported with its stage and a one-line error, and the others finish;
- a worker killed with SIGKILL in the middle of a batch (a real process death, not an exception):
  the task it was running is rescheduled on another worker and the batch completes with the same
  numbers.

The identification method is motor_first (0.4 s a recording; output_error, the default, takes
3-4 s): the batch machinery does not depend on it.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from mocapfj.pipeline.batch import _task, run_batch  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "datasets" / "pa10_joint2.toml"
METHOD = "motor_first"
STAGES = ("joints", "identify")             # of mocapfj run: the ones that give the parameters
N = 10


@pytest.fixture(scope="module")
def trials(tmp_path_factory):
    """Ten 7.5 s trials (seeds 100-109: the rig, the markers' placement, every noise) and one of
    2 s (the joint moves 4 deg: too little to fit its axis). The arm's motion is integrated once
    per duration: simulate_scenario draws no random numbers, so every seed gives the same motion
    (what a lab's repeated trials of one excitation are) and only the measurement differs."""
    from dataclasses import replace

    from mocapfj.synth import record
    from mocapfj.synth.record import record_scenario, write_scenario_bundle
    from mocapfj.synth.scenario import load_scenario

    root = tmp_path_factory.mktemp("trials")
    motion, integrate = {}, record.simulate_scenario

    def once(scn, with_effects=True):
        key = (scn.duration_s, with_effects)
        if key not in motion:
            motion[key] = integrate(scn, with_effects)
        return motion[key]

    outs = [root / f"trial_{i:02d}" for i in range(N)] + [root / "short"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(record, "simulate_scenario", once)
        for out, seed, duration in zip(outs, [100 + i for i in range(N)] + [200], [7.5] * N + [2.0]):
            scn = replace(load_scenario(SCENARIO).with_duration(duration), seed=seed)
            write_scenario_bundle(record_scenario(scn), out)
    return outs


@pytest.fixture(scope="module")
def cluster():
    """A local cluster of two single-threaded worker processes, reached by its address (as an
    existing cluster is); the kill test kills one of its workers (its nanny starts a new one).
    The cluster run_batch starts itself (no address) is what the CLI test runs."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=":0", silence_logs=logging.ERROR) as cl:
        yield cl


@pytest.fixture(scope="module")
def batch(trials, cluster, tmp_path_factory):
    out = tmp_path_factory.mktemp("batch") / "out"
    lines = []
    r = run_batch(trials, out, method=METHOD, stages=STAGES, scheduler=cluster.scheduler_address,
                  progress=lines.append)
    return r, out, lines


def _files(d: Path) -> dict:
    """Every file's bytes; run.json by what is not a time (its creation, each stage's seconds)."""
    out = {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}
    run = json.loads(out.pop("run.json"))
    out["run.json"] = (run["recording"], [{k: v for k, v in st.items() if k != "seconds"} for st in run["stages"]])
    return out


def test_two_workers_give_exactly_the_numbers_of_ten_sequential_runs(batch, cluster, trials, tmp_path):
    r, out, lines = batch
    assert r.cluster == f"scheduler {cluster.scheduler_address} (2 workers at start)"
    assert len({t.worker for t in r.trials if t.worker}) == 2                  # both workers took tasks
    seq = {}
    for p in trials[:N]:
        s = _task(str(p), tmp_path / p.name, METHOD, STAGES)
        assert s["status"] == "done", s["error"]
        seq[p.name] = s
        assert _files(out / p.name) == _files(tmp_path / p.name)               # joints/ and identify/, byte for byte
    for t in r.trials[:N]:
        ident = json.loads((out / t.name / "identify" / "identify.json").read_text())
        assert ident == json.loads(json.dumps(seq[t.name]["identify"]))
    # the table: mean, SD (n - 1) and CV % of the ten sequential values, per parameter
    rows = {row["parameter"]: row for row in r.table}
    assert {row["group"] for row in r.table} == {"pa10_joint2"} and {row["joint"] for row in r.table} == {"j2"}
    for name in ("I", "mglx", "mgly", "c", "v", "J", "b", "k"):
        vals = np.array([seq[f"trial_{i:02d}"]["identify"]["joints"][0]["params"][name]["value"] for i in range(N)])
        row = rows[name]
        assert row["n"] == N and row["trials"] == [f"trial_{i:02d}" for i in range(N)]
        assert row["values"] == vals.tolist()
        assert row["mean"] == pytest.approx(vals.mean(), rel=1e-12)
        assert row["sd"] == pytest.approx(vals.std(ddof=1), rel=1e-9)
        assert row["cv_pct"] == pytest.approx(100 * vals.std(ddof=1) / abs(vals.mean()), rel=1e-9)
    # the scenario's truth (Lightcap and Banks (2007), Table I, joint 2) within 4 standard errors
    # of the ten trials' mean, for the well-determined parameters
    for name, truth in (("mglx", 111.64), ("J", 12.57), ("k", 1.19e4)):
        row = rows[name]
        assert abs(row["mean"] - truth) < 4 * row["sd"] / np.sqrt(N), (name, row["mean"], row["sd"])
        assert row["cv_pct"] < 5
    # files: the table, every trial's values, the summary
    assert (out / "batch.csv").read_text().count("\npa10_joint2,j2,") == 9              # 8 parameters + torque RMS
    assert (out / "trials.csv").read_text().count(",pa10_joint2,j2,k,") == N
    md = (out / "batch.md").read_text()
    assert "## pa10_joint2, joint j2 (10 trials" in md and "| k |" in md
    assert json.loads((out / "batch.json").read_text())["n_done"] == N
    assert len([ln for ln in lines if ln.startswith("[")]) == N + 1           # a progress line per finished task


def test_a_bad_recording_is_reported_and_the_others_finish(batch):
    r, out, lines = batch
    (bad,) = r.failed
    assert bad.name == "short" and bad.stage == "joints" and bad.status == "failed"
    assert "range of motion of at least 5 deg" in bad.error and "\n" not in bad.error
    assert [t.status for t in r.trials[:N]] == ["done"] * N
    assert not (out / "short" / "identify").exists()
    assert "| short | joints |" in (out / "batch.md").read_text()
    assert any(ln.startswith("[") and "short: FAILED at joints" in ln for ln in lines)
    doc = json.loads((out / "batch.json").read_text())
    assert doc["n_failed"] == 1 and doc["failed"][0]["name"] == "short"


def test_a_worker_killed_mid_batch_is_replaced_and_the_batch_completes(cluster, trials, batch, tmp_path):
    """SIGKILL of a worker process while it runs a task: Dask reschedules the task on the other
    worker (the nanny starts a new process) and every recording finishes, with the numbers of the
    undisturbed batch."""
    r0, out0, _ = batch
    names = [p.name for p in trials[:5]]
    killed = {}
    with distributed.Client(cluster) as c:
        pids = c.run(os.getpid)                                              # {worker address: pid}

        def progress(line):
            if killed or "done in" not in line:
                return
            # a worker mid-task that holds no finished, unfetched result: what this test is about is a
            # death mid-run (a result lost before the client fetched it is Dask's own recomputation)
            held = c.has_what()
            busy = {w: keys for w, keys in c.processing().items()
                    if keys and not any(str(h).startswith("mocapfj-batch") for h in held.get(w, ()))}
            if not busy:                                                      # try again at the next one
                return
            just_done = line.rsplit(":", 1)[1]
            victim = min(busy, key=lambda w: str(pids[w]) == just_done)       # rather the one mid-task
            killed.update(pid=pids[victim], keys=list(busy[victim]))
            os.kill(pids[victim], signal.SIGKILL)

        r = run_batch(trials[:5], tmp_path / "o", method=METHOD, stages=STAGES, scheduler=cluster.scheduler_address,
                      progress=progress)
        c.wait_for_workers(2, timeout=60)
        after = c.run(os.getpid)
    assert killed, "no task finished while another was running"
    assert killed["pid"] not in after.values()                               # a new process took its place
    with pytest.raises(ProcessLookupError):
        os.kill(killed["pid"], 0)
    assert [t.status for t in r.trials] == ["done"] * 5, [(t.name, t.stage, t.error) for t in r.trials]
    interrupted = [n for n in names if any(n in k for k in killed["keys"])]
    rerun = [t for t in r.trials if t.name in interrupted and t.worker.split(":")[1] != str(killed["pid"])]
    assert rerun, (interrupted, [t.worker for t in r.trials])                # at least the task it was running
    for t in r.trials:
        assert _files(tmp_path / "o" / t.name) == _files(out0 / t.name)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "mocapfj.cli", "batch", *map(str, args)], capture_output=True,
                          text=True, timeout=120)


def test_cli_a_failed_recording_exits_1_and_bad_input_2(trials, tmp_path):
    """As a shell runs it (the workers spawned from the command): the short trial through a
    one-worker cluster is reported on stderr and in the JSON, the files are written, exit 1."""
    r = _cli(trials[-1], "--out", tmp_path / "o", "--workers", "1", "--json")     # every stage, on a new cluster
    assert r.returncode == 1, r.stderr[-2000:]
    s = json.loads(r.stdout)
    assert s["n_failed"] == 1 and s["failed"][0]["stage"] == "joints" and s["cluster"].startswith("local cluster of 1")
    assert "[1/1] short: FAILED at joints: " in r.stderr and "Traceback" not in r.stderr
    assert (tmp_path / "o" / "batch.json").is_file() and (tmp_path / "o" / "batch.md").is_file()
    r = _cli(trials[0], tmp_path / "missing", "--out", tmp_path / "x")
    assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1, r.stderr
    assert "missing: RECORDING: expected a bundle directory" in r.stderr and not (tmp_path / "x").exists()
    r = _cli(trials[0], trials[0] / "recording.toml", "--out", tmp_path / "x")
    assert r.returncode == 2 and "the same bundle as" in r.stderr and not (tmp_path / "x").exists()
