"""Augmented re-identification: the joint identified again from the recording, its nominal
parameters free, by the output-error estimator of identification (:mod:`mocapfj.ident.output_error`)
with the effects that estimator fits itself: a stiffening (cubic) spring, a hysteretic (Bouc-Wen)
spring and an offset between the mocap and controller clocks (docs/discovery.md).

Why. The equation-error search of :mod:`.engine` fits each effect against the nominal model's
residual, the nominal parameters held. A nominal model that is off (an inertia 16 % low, a
stiffness 8 % high) leaves a residual of its own, which an effect can follow (a fake) or cover (a
hidden effect); and an effect of a fraction of the mocap noise per sample is lost in an
equation-error residual that differentiates that noise, while the output error's simulation
averages it out (benchmarks/bench_discover_grid.py: cubic stiffenings of 0.3-0.8 x the deflection
noise on light joints). Here the effect and the nominal parameters are fitted together, and
the effect is judged against the same re-identification without it (`base`).

A joint of a URDF robot is re-identified in its context (:mod:`.context`: the robot's inertia,
gravity and the other links' torque along the recording enter the output-error simulation), its
own I, mglx, mgly fitted as terms added to the robot's; discovery repeats it in the context the
first pass's models give (:func:`robot_reidentified`).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..dynamics import JointModel
from ..types import JointSignals

__all__ = ["Reidentified", "reidentify", "segment", "segment_mask", "REID_EFFECTS", "ROBOT_PASSES", "robot_reidentified",
           "train_part", "train_context"]

REID_EFFECTS = ("stiffening", "hysteresis", "time_delay")
"""The effects the re-identification fits with the nominal parameters."""
_NOMINAL = ("I", "J", "mglx", "mgly", "b", "k", "c", "v")


@dataclass(frozen=True, eq=False)
class Reidentified:
    """A joint re-identified (module docstring): `model` with the effects found (`effects`: list of
    {name, parameters, explanation}), `base` the same identification with a linear spring on the
    declared clocks, `parameters` {name: {nominal, value, std, change_pct, sds}} of `base` against
    the nominal model (sds: the change in the identification's SDs), `identification` the
    :class:`mocapfj.ident.IdentifiedJoint` of `model`."""

    model: JointModel
    base: JointModel
    effects: list
    parameters: dict
    identification: object = field(repr=False, default=None)


def segment_mask(s: JointSignals, start: float, end: float) -> np.ndarray:
    """The (T,) mask of a joint's mocap samples between fractions `start` and `end` of its span."""
    t0, t1 = float(s.t[0]), float(s.t[-1])
    return (s.t >= t0 + start * (t1 - t0)) & (s.t <= t0 + end * (t1 - t0))


def segment(s: JointSignals, start: float, end: float) -> JointSignals:
    """The part of a joint's signals between fractions `start` and `end` of its span (mocap and
    controller samples alike)."""
    t0, t1 = float(s.t[0]), float(s.t[-1])
    a, b = t0 + start * (t1 - t0), t0 + end * (t1 - t0)
    m = segment_mask(s, start, end)
    kw = {}
    if s.t_c is not None:
        mc = (s.t_c >= a - 1e-9) & (s.t_c <= b + 1e-9)
        kw = {"t_c": s.t_c[mc], "q_m_c": s.q_m_c[mc], "u_c": s.u_c[mc], "fs_c_hz": s.fs_c_hz}
    filled = None if s.filled is None else s.filled[m]
    return JointSignals(t=s.t[m], q=s.q[m], q_m=s.q_m[m], u=s.u[m], fs_hz=s.fs_hz,
                        n_filled=int(filled.sum()) if filled is not None else 0, name=s.name, filled=filled,
                        smoothing_hz=s.smoothing_hz, **kw)


def _keep_terms(model: JointModel, nominal: JointModel) -> JointModel:
    """The re-identified model with the nominal's name and its terms single-joint output error
    does not fit (coupling, transmission error, position torque, torque gain)."""
    return model.with_(name=nominal.name, coupling=dict(nominal.coupling), transmission_error=nominal.transmission_error,
                       position_torque=nominal.position_torque, torque_gain=nominal.torque_gain, robot=nominal.robot)


def _effects_of(ident, s: JointSignals) -> list[dict]:
    """The effects the identification kept, each with its parameters (and SDs where it has them)
    and what an engineer is told."""
    out = []
    sp = ident.spring
    if sp.model == "cubic":
        k1, k3 = float(sp.params["k1"]), float(sp.params["k3"])
        # the deflection the spring carries the motor torque with (the mocap deflection is mostly
        # noise on a light joint)
        d95 = float(np.percentile(np.abs(s.u), 95)) / k1
        change = 300.0 * k3 * d95 ** 2 / k1
        out.append({"name": "stiffening", "parameters": {"k1": k1, "k3": k3, "k3_std": float(sp.params.get("k3_std", np.nan)),
                                                         "stiffness_change_pct_at_d95": change, "d95_rad": d95},
                    "explanation": (f"The joint's stiffness {'rises' if k3 > 0 else 'falls'} with the load: the spring is "
                                    f"k1 delta + k3 delta^3 with k1 {k1:.4g} N m/rad and k3 {k3:.3g} N m/rad^3 "
                                    f"(+- {sp.params.get('k3_std', np.nan):.2g}), {change:+.1f} % stiffness at the "
                                    f"{1e3 * d95:.3g} mrad the joint reaches 5 % of the time. Harmonic drives stiffen "
                                    "as more flexspline teeth come into contact; found with the nominal parameters "
                                    "identified with it by output error.")})
    elif sp.model == "bouc_wen":
        p = {k: float(v) for k, v in sp.params.items()}
        half = 1.0 / (p["beta"] + p["gamma"])
        out.append({"name": "hysteresis", "parameters": {**p, "loop_half_width_rad": half},
                    "explanation": (f"The spring torque depends on the direction the deflection last moved: "
                                    f"{100 * (1 - p['alpha']):.1f} % of the stiffness {p['k']:.4g} N m/rad acts through "
                                    f"a hysteretic state whose loop saturates over about {1e3 * half:.3g} mrad. "
                                    "Hysteresis in the harmonic drive's flexspline contact; found with the nominal "
                                    "parameters identified with it by output error.")})
    clock = ident.extra.get("clock_offset") or {}
    if clock.get("applied"):
        d, sd = float(clock["offset_s"]), float(clock["sd_s"])
        out.append({"name": "time_delay", "parameters": {"delay_s": d, "delay_sd_s": sd},
                    "explanation": (f"The mocap samples are {1e3 * abs(d):.3g} +- {1e3 * sd:.2g} ms "
                                    f"{'late' if d > 0 else 'early'} on the controller's clock: the link's motion "
                                    "shows a phase the dynamics cannot make. A delay in the logging or an "
                                    "undeclared clock offset; found with the nominal parameters identified with it.")})
    return out


def reidentify(s: JointSignals, nominal: JointModel, context=None, _plain=None) -> Reidentified:
    """Re-identify a joint with its nominal parameters free (module docstring). Raises InputError
    when the signals cannot be identified (too short, non-physical). `context`: a robot's joint's
    :class:`.context.LinkContext` at the samples of `s` (its link simulated in the recorded
    motion of the others; its I, mglx, mgly then its own terms added to the robot's). `_plain`: a
    callable giving the identification with a linear spring only (computed elsewhere;
    :func:`_reidentify_split`)."""
    from ..ident.joint import identify_signals

    if (nominal.robot is not None) != (context is not None):
        raise InputError(None, f"model.joints[{nominal.name}]", "a robot's joint with its context, or a single joint "
                         "without one", "a robot's joint without its context" if context is None else
                         "a context for a single joint")
    kw = {} if context is None else {"link_context": context.arrays()}
    full = identify_signals(s, gear_ratio=nominal.gear_ratio, spring_models=("linear", "cubic", "bouc_wen"),
                            fit_clock_offset=True, **kw)
    effects = _effects_of(full, s)
    delay = next((e["parameters"]["delay_s"] for e in effects if e["name"] == "time_delay"), 0.0)
    model = _keep_terms(full.model, nominal).with_(delay_s=float(delay))
    plain = full if not effects else (_plain() if _plain is not None else
                                      identify_signals(s, gear_ratio=nominal.gear_ratio, spring_models=("linear",), **kw))
    base = _keep_terms(plain.model, nominal)
    params = {}
    for n in _NOMINAL:
        p = plain.params.get(n)
        if p is None:
            continue
        nom = float(nominal.stiffness()) if n == "k" else float(getattr(nominal, n, np.nan))
        if n in ("c", "v"):
            nom = float(getattr(nominal.friction, n, np.nan))
        sd = float(p.std)
        params[n] = {"nominal": nom, "value": float(p.value), "std": sd,
                     "change_pct": float(100.0 * (p.value - nom) / nom) if nom else None,
                     "sds": float((p.value - nom) / sd) if sd > 0 and np.isfinite(sd) else None}
    return Reidentified(model=model, base=base, effects=effects, parameters=params, identification=full)


_CAUGHT = (InputError, RuntimeError, FloatingPointError, np.linalg.LinAlgError)


STALL_S = 60.0
"""A worker that uses no CPU for this long while the discovery waits for it is taken as stalled."""
POLL_S = 1.0


def _cpu_seconds(pid: int) -> float | None:
    """The CPU time (user + system, in clock ticks) process pid has used, from /proc (Linux, where
    the worker runs); None when it cannot be read."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        return float(int(fields[11]) + int(fields[12]))
    except (OSError, IndexError, ValueError):
        return None


class ReidentificationError(RuntimeError):
    """A re-identification in the worker failed the way :func:`reidentify` can (bad or
    non-physical signals): its one-line message, raised again in the discovery's process."""


def _reidentify_split(s: JointSignals, nominal: JointModel, context=None, close_in_spare=()) -> Reidentified:
    """:func:`reidentify` on two cores: the identification with a linear spring only (needed
    when the full one finds an effect) is made in a second forked process as soon as the linear
    fit both share is done (its memo, mocapfj.ident.output_error.LINEAR_FITS, inherited), while
    this one goes on with the spring models and the clock. The same result; the spare process's
    failure or death means the plain identification is made here. `close_in_spare`: connections
    the spare process must not hold open (the worker's to the discovery)."""
    from ..ident.joint import identify_signals
    from ..ident.output_error import LINEAR_FITS

    kw = {} if context is None else {"link_context": context.arrays()}

    def plain_here():
        return identify_signals(s, gear_ratio=nominal.gear_ratio, spring_models=("linear",), **kw)

    spare = {}

    def start(key):
        if spare:
            return
        recv, send = multiprocessing.Pipe(duplex=False)
        try:
            with _signals_held():
                pid = os.fork()
        except OSError:
            recv.close()
            send.close()
            spare["pid"] = None
            return
        if pid == 0:                                    # the spare process
            try:
                signal.pthread_sigmask(signal.SIG_UNBLOCK, _HELD)
                recv.close()                            # a reader gone means a broken pipe, not a hang
                for c in close_in_spare:
                    c.close()
                LINEAR_FITS.listeners.clear()
                send.send(("ok", plain_here()))
            except BaseException:                       # noqa: BLE001 - repeated by the worker, which reports it
                pass
            finally:
                os._exit(0)
        send.close()
        spare.update(pid=pid, conn=recv)

    def plain():
        if spare.get("pid"):
            try:
                kind, value = spare["conn"].recv()
                if kind == "ok":
                    return value
            except (EOFError, OSError):
                pass
        return plain_here()

    LINEAR_FITS.listeners.append(start)
    try:
        return reidentify(s, nominal, context, _plain=plain)
    finally:
        LINEAR_FITS.listeners.remove(start)
        if spare.get("pid"):
            spare["conn"].close()
            try:
                os.kill(spare["pid"], 9)
            except ProcessLookupError:
                pass
            os.waitpid(spare["pid"], 0)


_HELD = (signal.SIGINT, signal.SIGTERM)


class _signals_held:
    """Ctrl-C and SIGTERM held back while this process forks, delivered after: one that lands in
    the fork's own handlers (logging's lock release after it) is reported there as "Exception
    ignored" and lost, and the run went on to its end with that traceback on stderr (the Ctrl-C
    test, under the full suite's load). The forked child unblocks them itself."""

    def __enter__(self):
        self.old = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)

    def __exit__(self, *exc):
        signal.pthread_sigmask(signal.SIG_SETMASK, self.old)
        return False


def _ahead_worker(jobs: dict, conn) -> None:
    out = {}
    try:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _HELD)
        for jn, (s, nominal, context) in jobs.items():
            try:
                out[jn] = ("ok", _reidentify_split(s, nominal, context, (conn,)))
            except _CAUGHT as e:
                out[jn] = ("caught", str(e))
            except Exception:                           # a fault: the discovery's process repeats it
                out[jn] = ("other", None)
        conn.send(out)
    except (KeyboardInterrupt, BrokenPipeError, EOFError):
        pass
    finally:
        conn.close()
        os._exit(0)                                     # no atexit handlers, no buffered output of the parent's


class Ahead:
    """The re-identifications of a discovery's joints (:func:`reidentify` of each (signals, nominal,
    context) of `jobs`), started at once in a forked worker process: they depend only on the trial and the
    nominal model, not on what the search finds, so the search (one process, one core) and the
    re-identification (the longest stage: some twenty output-error fits) run on two cores side by
    side. :meth:`get` returns the same result :func:`reidentify` would return in this process, or
    raises what it would raise (a fault in the worker, or a worker that died, is repeated here).
    Where fork is unavailable (not Linux), in a daemonic process (a Dask worker: it may not start
    processes) or with `parallel` False, everything runs in :meth:`get`."""

    def __init__(self, jobs: dict, parallel: bool = True):
        self._jobs = dict(jobs)
        self._results = None
        self._proc = self._conn = None
        if (parallel and self._jobs and sys.platform.startswith("linux")
                and "fork" in multiprocessing.get_all_start_methods() and (os.cpu_count() or 1) > 1
                and not multiprocessing.current_process().daemon):      # a Dask worker may not have children
            ctx = multiprocessing.get_context("fork")
            recv, send = ctx.Pipe(duplex=False)
            try:
                proc = ctx.Process(target=_ahead_worker, args=(self._jobs, send), daemon=True)
                with _signals_held():
                    proc.start()
            except (OSError, AssertionError):            # no process to spare: in this one
                recv.close()
            else:
                self._proc, self._conn = proc, recv
            send.close()

    def _collect(self) -> dict:
        if self._results is None:
            self._results = {}
            if self._conn is not None:
                try:
                    if self._wait():
                        self._results = self._conn.recv()
                except (EOFError, OSError):
                    self._results = {}                   # the worker died: each joint again here
                finally:
                    self._conn.close()
                    if self._proc.is_alive():
                        self._proc.kill()
                    self._proc.join()
        return self._results

    def _wait(self) -> bool:
        """Wait for the worker's answer: True when it is there, False when the worker stalled (no
        CPU time used for STALL_S while alive: a lock held at the fork by another thread of this
        process can deadlock a forked child) or died without one; the caller then works here."""
        cpu, since = _cpu_seconds(self._proc.pid), time.monotonic()
        while not self._conn.poll(POLL_S):
            if not self._proc.is_alive():
                return self._conn.poll(0)
            now = _cpu_seconds(self._proc.pid)
            if now is None or now != cpu:
                cpu, since = now, time.monotonic()
            elif time.monotonic() - since > STALL_S:
                return False
        return True

    def get(self, jn: str) -> Reidentified:
        kind, value = self._collect().get(jn, ("other", None))
        if kind == "ok":
            return value
        if kind == "caught":
            raise ReidentificationError(value)
        return reidentify(*self._jobs[jn])

    def close(self) -> None:
        """Stop the worker if it still runs (the discovery ended early, or failed)."""
        if self._proc is not None and self._results is None:
            self._proc.kill()
            self._proc.join()
            self._conn.close()
            self._results = {}


def train_part(s: JointSignals, on_valid: bool, holdout: float) -> JointSignals:
    """What a joint is re-identified on: the whole trial when a validation recording holds the
    evidence out, else the trial's first 1 - holdout."""
    return s if on_valid else segment(s, 0.0, 1.0 - holdout)


ROBOT_PASSES = 2
"""Re-identifications of a robot's joints: the first in the context the nominal models give, the
next in the one the previous re-identified models give (:func:`robot_reidentified`)."""


def robot_reidentified(robot, signals: dict, nominal: dict, validation, holdout: float, ahead, ctx,
                       parallel: bool) -> dict:
    """{joint: Reidentified, or the error it raised} of a URDF robot's joints, ROBOT_PASSES passes.

    A joint's context (:mod:`.context`) holds the other links' motion rebuilt from their motors
    with the nominal J, b and k, so a nominal model that is off biases every joint's
    re-identification through the others' context (pa10_joints23 case, nominal J -11 %, k +7 %:
    the elbow's k +4.5 % at 12 SDs, J -6.4 %). Each pass after the first rebuilds the context with
    the previous pass's models (then +1.0 % and +2.4 %, the same as in the true models' context);
    its joints run two at a time (one in a worker, :class:`Ahead`)."""
    from .context import robot_context

    on = {jn: validation is not None and jn in validation for jn in robot.joints}
    trains = {jn: train_part(signals[jn], on[jn], holdout) for jn in robot.joints}
    caught = _CAUGHT + (ReidentificationError,)
    made = {}
    for jn in robot.joints:
        try:
            made[jn] = (ahead.get(jn) if ahead is not None else
                        reidentify(trains[jn], nominal[jn], train_context(ctx, jn, signals[jn], on[jn], holdout)))
        except caught as e:
            made[jn] = e
    for _ in range(ROBOT_PASSES - 1):
        if any(isinstance(r, Exception) for r in made.values()):
            break                                       # a joint not identified: no better context
        try:
            # the clock is the recording's: the best-determined delay the pass found aligns every link
            delays = sorted((e["parameters"]["delay_sd_s"], e["parameters"]["delay_s"])
                            for jn in robot.joints for e in made[jn].effects if e["name"] == "time_delay")
            delay = delays[0][1] if delays else 0.0
            rc = robot_context(robot, signals, {jn: made[jn].base.with_(delay_s=delay) for jn in robot.joints})
        except InputError:
            break
        jobs = {jn: (trains[jn], nominal[jn], train_context(rc, jn, signals[jn], on[jn], holdout))
                for jn in robot.joints}
        first, *rest = robot.joints
        worker = Ahead({first: jobs[first]}, parallel=parallel)
        nxt = {}
        try:
            for jn in rest:
                try:
                    nxt[jn] = reidentify(*jobs[jn])
                except caught as e:
                    nxt[jn] = e
            try:
                nxt[first] = worker.get(first)
            except caught as e:
                nxt[first] = e
        finally:
            worker.close()
        for jn, r in nxt.items():
            if not isinstance(r, Exception):
                count_context_shift(r, made[jn])
        made = nxt
    return made


def count_context_shift(r, prev) -> None:
    """Count in each parameter's SD (not remove) how far the last context change moved it: the
    context is itself an estimate (the others' link motion rebuilt from their motors, the link
    angle from mocap), and the pass-to-pass shift bounds what its remaining error can move (on a
    pa10_joints23 control the elbow's J moved +8.8 %, from -6.4 to +2.4 % of the truth, at an SD
    of 1.3 %). Updates r.parameters in place."""
    for n, p in r.parameters.items():
        q = prev.parameters.get(n)
        if q is None or not (np.isfinite(p["std"]) and np.isfinite(q["value"])):
            continue
        p["context_shift"] = float(p["value"] - q["value"])
        p["std"] = float(np.hypot(p["std"], p["context_shift"]))
        p["sds"] = float((p["value"] - p["nominal"]) / p["std"]) if p["std"] > 0 else None


def train_context(rc, jn: str, s: JointSignals, on_valid: bool, holdout: float):
    """A robot's joint's :class:`.context.LinkContext` over what it is re-identified on (:func:`train_part`),
    from the trial's :class:`.context.RobotContext` `rc`; None for a single joint."""
    if rc is None or jn not in rc.links:
        return None
    return rc.of(jn) if on_valid else rc.of(jn)[segment_mask(s, 0.0, 1.0 - holdout)]
