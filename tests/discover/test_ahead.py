"""The re-identification run ahead in a worker process (mocapfj.discover.reident.Ahead): the same
result as in the discovery's own process, and the same errors, whether the worker finishes, fails
or dies."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from mocapfj.discover.reident import Ahead, ReidentificationError, reidentify, segment
from mocapfj.errors import InputError


@pytest.fixture(scope="module")
def half_trial(pa10_hinge):
    """The PA-10 hinge's first 12 s (the shortest the re-identification takes: its trims and 5 s)."""
    _, sig, nominal = pa10_hinge
    s = sig["j1"]
    return segment(s, 0.0, 12.0 / float(s.t[-1] - s.t[0])), nominal


def _params(R):
    return {n: (p["value"], p["std"]) for n, p in R.parameters.items()}


def test_the_worker_returns_what_this_process_computes(half_trial):
    s, nominal = half_trial
    with threadpool_limits(1, user_api="blas"):
        here = reidentify(s, nominal)
        ahead = Ahead({"j1": (s, nominal, None)})
        assert ahead._proc is not None                  # Linux, 2 cores: it did run in a worker
        there = ahead.get("j1")
    assert _params(there) == _params(here)
    assert there.model == here.model and there.base == here.base
    assert [e["name"] for e in there.effects] == [e["name"] for e in here.effects]
    # the truth within 4 SDs of the worker's re-identification (it is an identification, not a copy)
    k = there.parameters["k"]
    assert abs(k["value"] - nominal.spring.k) < 4 * k["std"]


def test_a_worker_that_dies_is_replaced_by_this_process(half_trial):
    s, nominal = half_trial
    ahead = Ahead({"j1": (s, nominal, None)})
    ahead._proc.kill()
    R = ahead.get("j1")                                  # computed here instead, not lost
    assert abs(R.parameters["k"]["value"] / nominal.spring.k - 1) < 0.05
    ahead.close()


def test_the_workers_error_is_the_same_one_line(half_trial):
    s, nominal = half_trial
    short = segment(s, 0.0, 0.2)                         # 2.4 s: too short for output error
    with pytest.raises(InputError) as here:
        reidentify(short, nominal)
    ahead = Ahead({"j1": (short, nominal, None)})
    with pytest.raises(ReidentificationError) as there:
        ahead.get("j1")
    assert str(there.value) == str(here.value) and "\n" not in str(there.value)


def test_closed_before_use_stops_the_worker(half_trial):
    s, nominal = half_trial
    ahead = Ahead({"j1": (s, nominal, None)})
    ahead.close()
    assert not ahead._proc.is_alive()


def test_the_plain_identification_from_the_spare_process_is_the_same(half_trial, monkeypatch):
    """When the full re-identification names an effect, the one with a linear spring only comes
    from a second forked process (started once the shared linear fit is done): the same numbers
    as made here. An effect is forced so that the plain identification is needed."""
    from mocapfj.discover import reident

    s, nominal = half_trial
    real = reident._effects_of
    monkeypatch.setattr(reident, "_effects_of", lambda ident, sig: real(ident, sig) or [
        {"name": "stiffening", "parameters": {}, "explanation": "forced by the test"}])
    from mocapfj.ident.output_error import LINEAR_FITS

    forks = []
    fork = reident.os.fork
    monkeypatch.setattr(reident.os, "fork", lambda: forks.append(1) or fork())
    with threadpool_limits(1, user_api="blas"):
        here = reidentify(s, nominal)
        LINEAR_FITS._d.clear()                      # the linear fit made again, so the spare starts
        import mocapfj.ident.joint as joint

        calls, identify = [], joint.identify_signals
        monkeypatch.setattr(joint, "identify_signals", lambda *a, **k: calls.append(k["spring_models"]) or identify(*a, **k))
        there = reident._reidentify_split(s, nominal)
    assert len(forks) == 1
    assert calls == [("linear", "cubic", "bouc_wen")]     # the linear-only one was made in the spare process
    assert _params(there) == _params(here) and there.base == here.base and there.model == here.model
    assert not LINEAR_FITS.listeners                # the worker's listener is removed


def _in_daemon(jobs, conn):
    try:
        ahead = Ahead(jobs)
        conn.send(("worker" if ahead._proc is not None else "here", None))
        ahead.get("j1")
    except (ReidentificationError, InputError) as e:       # here: InputError itself, as without a worker
        conn.send(("error", str(e)))
    except BaseException as e:                           # noqa: BLE001 - sent to the test
        conn.send(("crash", repr(e)))
    conn.close()


def test_in_a_daemonic_process_it_runs_there(half_trial):
    """A Dask worker is a daemonic process, which may not start processes: the re-identification
    then runs in it, with the same one-line error."""
    import multiprocessing

    s, nominal = half_trial
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    p = ctx.Process(target=_in_daemon, args=({"j1": (segment(s, 0.0, 0.2), nominal)}, send), daemon=True)
    p.start()
    send.close()
    where, _ = recv.recv()
    kind, msg = recv.recv()
    p.join(30)
    assert (where, kind) == ("here", "error"), msg
    assert "samples" in msg


def _stalled_worker(jobs, conn):
    import time

    time.sleep(600)                                      # alive, using no CPU: a deadlocked child


def test_a_stalled_worker_is_given_up_and_the_work_done_here(half_trial, monkeypatch):
    """A forked child can deadlock on a lock another thread held at the fork: a worker alive but
    using no CPU for STALL_S is killed and the re-identification made in this process (here the
    2.4 s trial's own one-line InputError, raised directly), not waited for forever."""
    import time

    from mocapfj.discover import reident

    s, nominal = half_trial
    monkeypatch.setattr(reident, "_ahead_worker", _stalled_worker)
    monkeypatch.setattr(reident, "STALL_S", 2.0)
    monkeypatch.setattr(reident, "POLL_S", 0.2)
    ahead = Ahead({"j1": (segment(s, 0.0, 0.2), nominal, None)})
    t0 = time.monotonic()
    with pytest.raises(InputError, match="samples"):
        ahead.get("j1")
    assert time.monotonic() - t0 < 30 and not ahead._proc.is_alive()
