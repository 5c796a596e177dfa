"""Files over frequency-domain identification (``mocapfj frf``): columns of a CSV (or of a recording
bundle's controller log) -> :func:`mocapfj.ident.frf.estimate_frf` -> :func:`mocapfj.ident.frf_fit.fit_two_inertia`,
written as OUT/frf.json and OUT/frf.csv. No maths here beyond reading the sampling grid and the period."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import write_json
from ..io.csvio import check_increasing, read_csv_columns, write_csv_columns

__all__ = ["run_frf", "read_frf_columns", "find_period", "FRF_CLI_MODELS", "read_identified_joint", "compare_with_identify"]

FRF_CLI_MODELS = ("two_inertia", "rational", "none")


def read_frf_columns(path, names: dict, time: str | None) -> tuple[Path, dict, np.ndarray]:
    """The CSV behind `path` (a CSV, a bundle directory or its recording.toml), the requested columns
    {option: column name} as arrays and the time column; errors name the file and the column."""
    path = Path(path)
    if path.is_dir() or path.suffix.lower() == ".toml":
        from ..io.tomlio import read_toml, require

        toml_path = path / "recording.toml" if path.is_dir() else path
        if not toml_path.is_file():
            raise InputError(toml_path, "file", "a CSV file or a recording bundle holding recording.toml", "no such file")
        doc = read_toml(toml_path)
        ctl = require(toml_path, doc, "controller", dict)
        csv = toml_path.parent / require(toml_path, ctl, "file", str, "controller")
        time = time or require(toml_path, ctl, "time_column", str, "controller", default="time")
    else:
        csv = path
    time = time or "time"
    cols = read_csv_columns(csv)
    out = {}
    for option, name in {**names, "--time": time}.items():
        if name is None:
            continue
        if name not in cols:
            raise InputError(csv, option, f"a column of the CSV ({', '.join(list(cols)[:8])}"
                             f"{', ...' if len(cols) > 8 else ''})", repr(name))
        x = cols[name]
        if x.size and not np.all(np.isfinite(x)):
            i = int(np.argmax(~np.isfinite(x)))
            raise InputError(csv, f"column {name!r}", "a finite number in every row", f"{x[i]} at row {i + 2}")
        out[option] = x
    t = out.pop("--time")
    check_increasing(csv, f"column {time!r}", t)
    if t.size < 16:
        raise InputError(csv, f"column {time!r}", "at least 16 samples", t.size)
    dt = np.diff(t)
    step = float(np.median(dt))
    if np.abs(dt - step).max() > 1e-3 * step:
        i = int(np.argmax(np.abs(dt - step)))
        raise InputError(csv, f"column {time!r}", f"a uniform sampling step ({step:.6g} s)",
                         f"a step of {dt[i]:.6g} s at row {i + 3}", hint="resample to a uniform grid first")
    return csv, out, t


def find_period(x, *, exact: bool) -> int | None:
    """Smallest lag L >= 8 samples at which x repeats: the normalised mismatch
    mean (x[n + L] - x[n])^2 / (2 var x) over the record after its first fifth (the transient) is
    below 1e-8 (`exact`, a reference), else below 2 m* + 0.02 with m* the smallest mismatch over
    the lags (a noisy input); None when nothing repeats (m* > 0.3)."""
    x = np.asarray(x, dtype=np.float64)
    x = x[x.size // 5:] - x[x.size // 5:].mean()
    n = x.size
    if n < 32 or not np.any(x):
        return None
    F = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(F * F.conj(), 2 * n)
    c2 = np.concatenate([[0.0], np.cumsum(x * x)])
    L = np.arange(8, n - n // 4 + 1)                   # an overlap of a quarter of the record at least
    m = (c2[n - L] + (c2[n] - c2[L]) - 2 * ac[L]) / np.maximum(n - L, 1) / (2 * x.var())
    hit = np.flatnonzero(m < 1e-8) if exact else np.empty(0, int)
    if not hit.size:                                   # noisy, or a reference whose ramp outlasts the first fifth
        if m.min() > 0.3:
            return None
        hit = np.flatnonzero(m < 2 * m.min() + 0.02)
        if hit.size:                                   # the best lag of the first run of near-minimal lags
            run = hit[: int(np.argmax(np.diff(np.r_[hit, hit[-1] + 2]) > 1)) + 1]
            return int(L[run[np.argmin(m[run])]])
    return int(L[hit[0]]) if hit.size else None


NEW_REALISATION = 0.5
"""A period whose mean squared change from the one before exceeds this share of 2 var(x) starts a new
realisation (an independent multisine changes by about 1; one period of a realisation to the next, by
its noise and transient only)."""


def find_realisations(x, n: int) -> int | None:
    """How many equal consecutive realisations of period n samples the record x holds: the periods
    where x changes from the period before by more than NEW_REALISATION start one (but a period right
    after a start: the transient's). 1 when none does; None when they do at unequal spacing (not
    equal realisations)."""
    x = np.asarray(x, dtype=np.float64)
    P = x.size // n
    if P < 2 or not x.var() > 0:
        return 1
    blocks = x[: P * n].reshape(P, n)
    change = np.mean(np.diff(blocks, axis=0) ** 2, axis=1) / (2 * x.var())
    starts = np.flatnonzero(change > NEW_REALISATION) + 1
    # a realisation's transient (a ramp into the multisine) changes its second period from its first
    # as well: a start right after a start (or after the record's) belongs to the realisation before
    starts = starts[~np.isin(starts - 1, np.r_[0, starts])]
    if starts.size == 0:
        return 1
    edges = np.r_[0, starts, P]
    lengths = np.diff(edges)
    if np.all(lengths == lengths[0]) and P * n >= x.size - n:
        return int(lengths.size)
    return None


def find_period_and_realisations(x, *, exact: bool) -> tuple[int | None, int]:
    """(period in samples, realisations) of a record of equal consecutive realisations of a periodic
    excitation: the period where the whole record repeats (:func:`find_period`), split at the periods
    where a new realisation starts; when the realisations' changes hide the period from the whole
    record, the period of its first 1/m (m = 2..8) that splits the record into exactly m."""
    n = find_period(x, exact=exact)
    if n is not None:
        m = find_realisations(x, n)
        if m is not None:
            return n, m
    x = np.asarray(x, dtype=np.float64)
    for m in range(2, 9):
        part = x[: x.size // m]
        n_m = find_period(part, exact=exact)
        if n_m is not None and part.size % n_m == 0 and find_realisations(x, n_m) == m:
            return n_m, m
    return n, 1


def run_frf(path, out, *, input: str, output: str, reference: str | None = None, time: str | None = None,
            period_s: float | None = None, model: str = "two_inertia", transient="auto", realisations="auto",
            estimator: str = "auto", single_record: bool = False, order=None, steady_period: bool = False,
            compare=None, joint: str | None = None, gravity_stiffness: float | None = None) -> dict:
    """``mocapfj frf``: the FRF of column `output` over column `input` (Makarov et al. 2012, eq. 23-27),
    and the two-inertia model fitted to it with its modes.

    The record holds `realisations` equal consecutive parts ("auto": :func:`find_period_and_realisations`,
    or :func:`find_realisations` with `period_s`), each starting with `transient` periods
    that are dropped ("auto": :func:`mocapfj.ident.frf.transient_count`). The period comes from `period_s` or, without it, from where the reference
    (else the input) repeats. `single_record`: the record is one period or not periodic at all, the FRF
    comes from :func:`mocapfj.ident.frf_single.estimate_frf_lpm` (the noise from the record's own
    spectrum) and the model is ``"rational"`` (degrees `order` = (n_b, n_a), default (4, 4):
    :func:`mocapfj.ident.frf_single.fit_rational`) or ``"none"``; `steady_period`: that record is one whole
    period in steady state (G = Y / U, the LPM for the noise only; modes narrower than a DFT line).
    Writes OUT/frf.json (the summary) and OUT/frf.csv (per line: f_hz,
    the FRF, magnitude, phase, coherence, noise SD, and the model's FRF). `compare`: the time-domain
    identification of the same joint (an identify.json, its directory or a run directory), joint
    `joint` (default its only one): the two-inertia parameters held against it
    (:func:`mocapfj.ident.crosscheck.cross_check`), in the summary's ``comparison``.

    gravity_stiffness : the link's gravity stiffness g = G'(q0), N m/rad, at the record's operating
    point (:mod:`mocapfj.ident.frf_fit`), held in the two-inertia fit; None: fitted with the rest.
    With `compare`, the g identify's gravity parameters imply (g = -mglx cos q0 - mgly sin q0, q0
    the mean of the `output` column: a link-side angle in identify's convention, as the controller
    log's motor column is) is compared with the FRF's like the other parameters. The summary's
    ``gravity`` says which, and what g is worth in k.
    """
    from ..ident.frf import estimate_frf
    from ..ident.frf_fit import fit_two_inertia

    if model not in FRF_CLI_MODELS:
        raise InputError(None, "model", f"one of {', '.join(FRF_CLI_MODELS)}", model)
    transient = _whole_or_auto(transient, "transient", 0)
    realisations = _whole_or_auto(realisations, "realisations", 1)
    if steady_period and not single_record:
        raise InputError(None, "steady-period", "only with --single-record", True)
    if order is not None and model != "rational":
        raise InputError(None, "order", "only with the rational model (--single-record)", list(order))
    reference_ident = None
    if compare is not None:
        if model != "two_inertia" or single_record:
            raise InputError(None, "compare", "the two-inertia model (its parameters are compared)",
                             "--single-record" if single_record else f"--model {model}")
        reference_ident = read_identified_joint(compare, joint)
    if single_record or model == "rational":
        return _run_single(path, out, input=input, output=output, reference=reference, time=time, model=model,
                           order=order, single_record=single_record, periodic=steady_period)
    names = {"--input": input, "--output": output, "--reference": reference}
    csv, cols, t = read_frf_columns(path, names, time)
    fs = (t.size - 1) / float(t[-1] - t[0])
    src = cols.get("--reference", cols["--input"])
    if period_s is None:
        exact = "--reference" in cols
        if realisations == "auto":
            n, realisations = find_period_and_realisations(src, exact=exact)
        else:
            n = find_period(src[: src.size // realisations], exact=exact)      # one realisation's
        if n is None:
            raise InputError(csv, "--reference" if "--reference" in cols else "--input",
                             "a periodic signal (the period found from where it repeats)", "no period found",
                             hint="pass --period")
    else:
        if not (np.isfinite(period_s) and period_s > 0):
            raise InputError(None, "period", "a positive period in s", period_s)
        n = int(round(period_s * fs))
        if n < 8 or abs(n - period_s * fs) > 1e-3 * n:
            raise InputError(None, "period", f"a whole number (>= 8) of sampling steps of {1 / fs:.6g} s",
                             f"{period_s} s = {period_s * fs:.6g} steps")
        if realisations == "auto":
            realisations = find_realisations(src, n) or 1
    T = t.size // realisations

    def parts(x):
        return x[: T * realisations].reshape(realisations, T)

    col_of = {"u": input, "y": output, "r": reference}
    try:
        frf = estimate_frf(parts(cols["--input"]), parts(cols["--output"]), fs, n,
                           r=parts(cols["--reference"]) if "--reference" in cols else None, estimator=estimator,
                           transient_periods=transient)
    except InputError as e:
        if e.file == "<argument>" and e.field in col_of:
            raise InputError(csv, f"column {col_of[e.field]!r}", e.expected, e.got, e.hint) from None
        raise
    gravity = _gravity_stiffness(gravity_stiffness, reference_ident, cols["--output"])
    fit = fit_two_inertia(frf, gravity_stiffness=gravity.get("g_Nm_per_rad")) if model == "two_inertia" else None
    if fit is not None:
        gravity.update(g_Nm_per_rad=fit.gravity_stiffness, g_std_Nm_per_rad=fit.gravity_stiffness_std,
                       share_of_k_pct=100.0 * fit.gravity_stiffness / fit.value("k"))
    summary = {"file": str(csv), "input": input, "output": output, "reference": reference, "fs_hz": fs,
               "gravity": gravity,
               "period_s": n / fs, "period_samples": n,
               "transient_periods": T // n - frf.n_periods if T // n >= frf.n_periods else None, "frf": frf.to_dict(),
               "model": None if fit is None else fit.to_dict(),
               "modes": [] if fit is None else [m.to_dict() for m in fit.modes],
               "notes": frf_notes(frf, fit, gravity_fitted=gravity_stiffness is None),
               "files": {"summary": "frf.json", "frf": "frf.csv"}}
    if reference_ident is not None and fit is not None:
        summary["comparison"] = compare_with_identify(summary, *reference_ident)
    _write(out, summary, frf, fit)
    return summary


def _whole_or_auto(value, name: str, least: int):
    """An option that is "auto" or a whole number >= least (given as a number or its text)."""
    if value == "auto":
        return value
    try:
        n = int(value)
    except (TypeError, ValueError):
        n = None
    if n is None or n != float(value) or n < least:
        raise InputError(None, name, f"a whole number >= {least} or auto", value)
    return n


def frf_notes(frf, fit, *, gravity_fitted: bool) -> list[str]:
    """What the numbers of an FRF and its fit leave unsaid (run_frf's ``notes``): a closed loop run
    without its reference, SDs that cannot hold a nonlinear distortion, a gravity stiffness that a
    distortion may have made."""
    notes = []
    fb = frf.feedback
    if fb and fb["suspected"]:
        notes.append(f"the input's noise follows the output's as a feedback loop's does ({fb['coherent_lines']} of "
                     f"{fb['lines']} lines coherent, their ratio {100 * fb['median_mismatch']:.0f} % from the FRF): "
                     "a closed loop, whose FRF without its reference is biased towards the controller's inverse; "
                     "pass --reference")
    distorted = frf.var_nl is not None and bool(np.any(frf.var_nl > 0))
    if frf.var_nl is None and fit is not None and fit.chi2_red > 3.0:
        notes.append(f"chi2/dof {fit.chi2_red:.3g} and no estimate of a nonlinear distortion (no detection lines, "
                     "one realisation): the SDs are the noise's scaled by the chi-square, and leave out a "
                     "distortion that varies over frequency (an odd multisine with detection lines, or "
                     "several realisations, measures it)")
    if (gravity_fitted and distorted and fit is not None
            and abs(fit.gravity_stiffness) > 3 * fit.gravity_stiffness_std):
        notes.append(f"the fitted gravity stiffness ({fit.gravity_stiffness:.4g} +- {fit.gravity_stiffness_std:.2g} "
                     "N m/rad) rests on the lowest lines, where the record shows a nonlinear distortion: a "
                     "friction's best linear approximation there is read as stiffness too; hold it with "
                     "--gravity-stiffness (0 without gravity, or the rigid model's) if it is known")
    return notes


def _gravity_stiffness(given, reference_ident, y) -> dict:
    """{"g_Nm_per_rad" (given only), "source"[, "identify"]}: the gravity stiffness the two-inertia fit
    holds, or that it fits it, and what identify's gravity parameters imply (run_frf)."""
    if given is not None:
        g = float(given)
        if not np.isfinite(g):
            raise InputError(None, "gravity-stiffness", "a finite gravity stiffness in N m/rad", given)
        return {"g_Nm_per_rad": g, "source": "given (--gravity-stiffness)"}
    out = {"source": "fitted with the rest (the FRF's lowest lines carry it)"}
    implied = _implied_gravity(reference_ident, y)
    if implied is not None:
        out["identify"] = implied
    return out


def _implied_gravity(reference_ident, y) -> dict | None:
    """The gravity stiffness identify's mglx, mgly imply at the record's mean angle, with its SD,
    or None when identify did not determine them."""
    if reference_ident is not None:
        _, params, src = reference_ident
        gp = {n: params.get(n) for n in ("mglx", "mgly")}
        if all(isinstance(p, dict) and p.get("determined", True) and np.isfinite(p.get("value", np.nan))
               for p in gp.values()):
            q0 = float(np.mean(y))
            mglx, mgly = float(gp["mglx"]["value"]), float(gp["mgly"]["value"])
            g = -mglx * np.cos(q0) - mgly * np.sin(q0)
            # its SD from theirs, taken as independent (identify.json gives no covariance)
            sd = float(np.hypot(np.cos(q0) * float(gp["mglx"].get("std", 0.0) or 0.0),
                                np.sin(q0) * float(gp["mgly"].get("std", 0.0) or 0.0)))
            return {"value": float(g), "std": sd if np.isfinite(sd) else 0.0,
                    "source": f"identify's mglx {mglx:.4g}, mgly {mgly:.4g} N m at the record's mean angle "
                    f"{q0:.4g} rad ({src})", "q0_rad": q0}
    return None


def read_identified_joint(path, joint: str | None = None) -> tuple[str, dict, str]:
    """(joint name, its ``params``, the file) from an identify.json, the directory holding it, or a
    run directory (``identify/identify.json``)."""
    from ..io import read_json

    p = Path(path)
    if p.is_dir():
        p = p / "identify.json" if (p / "identify.json").is_file() else p / "identify" / "identify.json"
    if not p.is_file():
        raise InputError(path, "compare", "an identify.json, its directory or a run directory", "no identify.json")
    try:
        doc = read_json(p)
    except ValueError as e:
        raise InputError(p, "JSON", "the identify.json mocapfj writes", str(e).split("\n")[0]) from None
    joints = [j for j in doc.get("joints", []) if isinstance(j, dict) and isinstance(j.get("params"), dict)]
    if not joints:
        raise InputError(p, "joints", "an identified flexible joint with params", "none")
    names = [j.get("name") for j in joints]
    if joint is None:
        if len(joints) > 1:
            raise InputError(p, "joints", "one joint, or --joint naming one", names)
        return names[0], joints[0]["params"], str(p)
    if joint not in names:
        raise InputError(p, "joints", f"one of {names}", repr(joint))
    return joint, joints[names.index(joint)]["params"], str(p)


def compare_with_identify(summary: dict, joint: str, params: dict, source: str) -> dict:
    """The FRF's two-inertia parameters against the time-domain identification of the joint, and
    the modes that identification predicts (spring damping 0: it has none) against the FRF's."""
    from ..ident.crosscheck import cross_check
    from ..ident.frf_fit import two_inertia_modes

    implied = (summary.get("gravity") or {}).get("identify")
    if implied is not None:
        params = {**params, "g": {"value": implied["value"], "std": implied["std"]}}
    c = cross_check(summary["model"]["params"], params, method_a="frf", method_b="identify", joint=joint,
                    names=("k", "J", "I", "b", "v", "g"))
    out = {"source": source, **c.to_dict(), "lines": c.lines()}
    coulomb = params.get("c") if isinstance(params.get("c"), dict) else None
    if "v" in c.disagree and coulomb and coulomb.get("determined", True) and coulomb.get("value", 0) > 0:
        note = (f"identify's link Coulomb friction (c {coulomb['value']:.4g} N m) is, to the linear model the FRF fits, "
                "extra viscous damping: the FRF's v holds both")
        out["notes"] = [note]
        out["lines"] = out["lines"] + [f"v: {note}"]
    try:
        pv = {n: float(params[n]["value"]) for n in ("J", "I", "k", "b", "v")}
        g = float(implied["value"]) if implied is not None else 0.0         # identify's own gravity
        pred = two_inertia_modes(J=pv["J"], I=pv["I"], k=pv["k"], d=0.0, b=pv["b"], v=pv["v"], g=g)
        by_kind = {kind: f for kind, f, _ in pred}
        out["modes"] = [{"kind": m["kind"], "f_hz_frf": m["f_hz"], "f_hz_std_frf": m.get("f_hz_std"),
                         "f_hz_identify": by_kind[m["kind"]], "diff_pct": 100.0 * (m["f_hz"] / by_kind[m["kind"]] - 1.0)}
                        for m in summary["modes"] if m["kind"] in by_kind]
    except (KeyError, TypeError, ValueError):
        out["modes"] = []
    return out


def _run_single(path, out, *, input, output, reference, time, model, order, single_record, periodic=False) -> dict:
    """``mocapfj frf --single-record``: the LPM FRF of one record and the rational model (see run_frf)."""
    from ..ident.frf_single import estimate_frf_lpm, fit_rational

    if not single_record:
        raise InputError(None, "model", "rational only with --single-record (a periodic record: two_inertia or none)",
                         model)
    if model == "two_inertia":
        raise InputError(None, "model", "rational or none with --single-record (the two-inertia fit takes the "
                         "noise of repeated periods)", model, hint="pass --model rational --order NB NA")
    if reference is not None:
        raise InputError(None, "reference", "no reference with --single-record (open loop only)", reference)
    order = (4, 4) if order is None else tuple(order)
    if len(order) != 2 or any(int(o) != o for o in order) or order[0] < 0 or order[1] < 1:
        raise InputError(None, "order", "two whole numbers NB >= 0, NA >= 1", order)
    csv, cols, t = read_frf_columns(path, {"--input": input, "--output": output}, time)
    fs = (t.size - 1) / float(t[-1] - t[0])
    try:
        r = estimate_frf_lpm(cols["--input"], cols["--output"], fs, periodic=periodic)
    except InputError as e:
        col = {"u": input, "y": output}.get(e.field)
        if e.file == "<argument>" and col is not None:
            raise InputError(csv, f"column {col!r}", e.expected, e.got, e.hint) from None
        raise
    frf = r.frf
    fit = fit_rational(r, int(order[0]), int(order[1])) if model == "rational" else None
    summary = {"file": str(csv), "input": input, "output": output, "reference": None, "fs_hz": fs,
               "period_s": None, "period_samples": None, "single_record": True, "transient_periods": None,
               "frf": r.to_dict(), "model": None if fit is None else fit.to_dict(),
               "modes": [] if fit is None else [m.to_dict() for m in fit.modes],
               "files": {"summary": "frf.json", "frf": "frf.csv"}}
    _write(out, summary, frf, fit)
    return summary


def _write(out, summary: dict, frf, fit) -> None:
    """frf.json (the summary) and frf.csv (the FRF per line, and the fitted model's) into `out`."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "frf.json", summary)
    table = {"f_hz": frf.f_hz, "G_real": frf.G.real, "G_imag": frf.G.imag, "magnitude": frf.magnitude,
             "phase_rad": frf.phase_rad, "coherence": frf.coherence, "noise": frf.std}
    if fit is not None:
        table.update({"model_real": fit.G_fit.real, "model_imag": fit.G_fit.imag})
    write_csv_columns(out / "frf.csv", table)
