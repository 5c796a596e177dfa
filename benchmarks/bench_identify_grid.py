"""Identification estimators on a grid of synthetic single-joint recordings: bias, scatter, honesty.

The grid (:func:`mocapfj.synth.hinge.sample_cases`: four joint families, friction laws, torque
noise kinds, marker clusters, rates; the rules are in that module's docstring) is generated
independently of any estimator and cached in ``--cache/<base seed>/<case>/`` (one recording
bundle with truth.json per case; only missing or stale bundles are regenerated, on ``--jobs``
processes). Every estimator of ``--methods`` runs on every bundle through :func:`estimate`, the
one function to rewrite when the identification API changes.

Per estimator it prints: cases and failures (exceptions, with their messages); per parameter
(I, mglx, mgly, c, v, J, b, k) the median signed relative error %, its robust SD (1.4826 MAD),
the share of cases within tolerance (2 %, 5 % for c; mglx and mgly relative to the gravity
magnitude sqrt(mglx^2 + mgly^2); on a joint without gravity mglx and mgly pass only when flagged
not determined) and the share flagged not determined; |error| / reported SD over all determined
estimates (median, share <= 3, share <= 1); the share of cases where every parameter passes
(within tolerance or flagged not determined; a failure passes nothing) and where any parameter
is flagged; the all-pass share per family; the 10 worst cases; timing per case.

    python benchmarks/bench_identify_grid.py --n 72 --base-seed 5000 --methods motor_first
    python benchmarks/bench_identify_grid.py --n 8 --write-docs docs/grid_benchmark.md
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")        # one BLAS thread per process: the cores go to the workers

import argparse
import math
import shutil
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))


# ------------------------------------------------------------------------------------------ ADAPTER
def estimate(bundle_dir: Path, out_dir: Path, method: str) -> dict[str, dict]:
    """ADAPTER between this benchmark and the identification API: one recording bundle in, its
    joint's parameters out, {name: {"value": float, "std": float, "determined": bool,
    "reason": str | None}} in SI units, plus "_spring": the spring model chosen. Rewrite this
    function (only) when the API changes."""
    import mocapfj

    joint = mocapfj.identify(str(bundle_dir), method=method).to_dict()["joints"][0]
    out = {n: {"value": float(p["value"]), "std": float(p["std"]) if p.get("std") is not None else float("nan"),
               "determined": bool(p.get("determined", True)), "reason": p.get("reason")}
           for n, p in joint["params"].items()}
    out["_spring"] = joint["spring"]["model"]
    return out
# --------------------------------------------------------------------------------------------------


NAMES = ("I", "mglx", "mgly", "c", "v", "J", "b", "k")
TOL_PCT = {n: (5.0 if n == "c" else 2.0) for n in NAMES}
GRAVITY = ("mglx", "mgly")
START, END = "<!-- bench_identify_grid:start -->", "<!-- bench_identify_grid:end -->"


# ---------------------------------------------------------------------------- the grid
def _bundle_ok(case, d: Path) -> bool:
    from mocapfj.io import read_json
    from mocapfj.synth.hinge import case_digest

    if not ((d / "recording.toml").is_file() and (d / "truth.json").is_file()):
        return False
    try:
        return read_json(d / "truth.json").get("case_sha256") == case_digest(case)
    except Exception:
        return False


def _generate(case, d: Path) -> float | None:
    """Write the bundle of `case` in `d` unless a current one is there; seconds taken or None."""
    from mocapfj.synth.hinge import write_hinge_bundle

    if _bundle_ok(case, d):
        return None
    if d.exists():
        shutil.rmtree(d)
    tic = time.perf_counter()
    write_hinge_bundle(case, d)
    return time.perf_counter() - tic


def _bound(case, d: Path) -> dict[str, float]:
    """The case's Cramér-Rao bound (hinge_bound.py), cached in d/bound.json for its digest."""
    from hinge_bound import hinge_bound

    from mocapfj.io import read_json, write_json
    from mocapfj.synth.hinge import case_digest

    f = d / "bound.json"
    digest = case_digest(case)
    if f.is_file():
        got = read_json(f)
        if got.get("case_sha256") == digest:            # NaN (no gravity) is stored as null
            return {n: (float("nan") if v is None else float(v)) for n, v in got["bound_pct"].items()}
    b = hinge_bound(case)
    write_json(f, {"case_sha256": digest, "bound_pct": b})
    return b


def bound_lines(rows: list[dict]) -> list[str]:
    """Markdown lines: what the Cramér-Rao bound allows on this grid (rows: {"truth", "bound"})."""
    from hinge_bound import pass_probability

    n = len(rows)
    lines = ["### What any estimator can reach: the Cramér-Rao bound", "",
             "Per case, the bound on each parameter's SD (benchmarks/hinge_bound.py: the case's true signals and "
             "noise model, with more information than an estimator has, so a lower bound). A parameter whose "
             "bound is above 5 % must be flagged not determined; an efficient unbiased estimator lands within "
             "tolerance with the probability its Gaussian at the bound gives.", "",
             "| parameter | bound above 5 % (must be flagged, % of cases) | median bound (%) | "
             "expected within tolerance when not flagged (%) |", "|---|---|---|---|"]
    for p in NAMES:
        b = np.array([r["bound"][p] for r in rows if math.isfinite(r["bound"][p])])
        ok = b[b <= 5.0]
        within = np.mean([math.erf(TOL_PCT[p] / (x * math.sqrt(2))) if x > 0 else 1.0 for x in ok]) if ok.size else float("nan")
        lines.append(f"| {p} | {_pct(int((b > 5).sum()), b.size)} | {_fmt(float(np.median(b)) if b.size else float('nan'), '.2f')} | "
                     f"{_fmt(100 * within, '.0f')} |")
    must = [any(math.isfinite(v) and v > 5.0 for v in r["bound"].values()) for r in rows]
    probs = [pass_probability(r["bound"], TOL_PCT) for r in rows]
    lines += ["", f"Some parameter must be flagged in {_pct(sum(must), n)} % of the cases; the expected share of "
                  f"cases where an efficient estimator passes every parameter (flagging exactly those above 5 %) is "
                  f"{100 * np.mean(probs):.0f} %.", "", "| family | cases | must flag (%) | expected all pass (%) |",
              "|---|---|---|---|"]
    for fam in ("pa10", "cobot", "heavy", "vertical"):
        idx = [i for i, r in enumerate(rows) if r["truth"]["family"] == fam]
        if idx:
            lines.append(f"| {fam} | {len(idx)} | {_pct(sum(must[i] for i in idx), len(idx))} | "
                         f"{100 * np.mean([probs[i] for i in idx]):.0f} |")
    return lines + [""]


def _estimate_one(bundle: Path, out: Path, method: str) -> dict:
    """Run the adapter on one bundle; never raises."""
    tic = time.perf_counter()
    try:
        if out.exists():
            shutil.rmtree(out)
        est = estimate(bundle, out, method)
        return {"estimates": est, "error": None, "seconds": time.perf_counter() - tic}
    except Exception as e:                  # a failure of the estimator is a result
        msg = f"{type(e).__name__}: {e}".strip().splitlines()[0][:300]
        return {"estimates": None, "error": msg, "trace": traceback.format_exc(limit=3),
                "seconds": time.perf_counter() - tic}


# ---------------------------------------------------------------------------- scoring
def score_case(truth: dict, est: dict | None) -> dict:
    """Errors of one case's estimates against its truth.

    Returns {name: {"err_pct", "pass", "flagged", "z"}}, plus "all_pass" and "any_flagged".
    err_pct: 100 (est - true) / |true|, for mglx and mgly / sqrt(mglx^2 + mgly^2); on a joint
    without gravity mglx and mgly are scored in % of the torque RMS (shown, not in the medians).
    z: |est - true| / reported SD (determined estimates with SD > 0), else NaN.
    """
    p = truth["params"]
    g = math.hypot(p["mglx"], p["mgly"])
    out = {}
    for n in NAMES:
        e = (est or {}).get(n)
        if e is None or e.get("value") is None or not math.isfinite(e["value"]):
            flagged = bool(e is not None and not e.get("determined", True))
            out[n] = {"err_pct": float("nan"), "pass": flagged, "flagged": flagged, "z": float("nan"),
                      "no_gravity": n in GRAVITY and g == 0}
            continue
        flagged = not e.get("determined", True)
        no_gravity = n in GRAVITY and g == 0
        if no_gravity:
            err = 100 * e["value"] / truth["stats"]["torque_rms_Nm"]
            ok = flagged
        else:
            scale = g if n in GRAVITY else abs(p[n])
            err = 100 * (e["value"] - p[n]) / scale
            ok = flagged or abs(err) <= TOL_PCT[n]
        sd = e.get("std")
        z = abs(e["value"] - p[n]) / sd if (not flagged and sd is not None and math.isfinite(sd) and sd > 0) \
            else float("nan")
        out[n] = {"err_pct": float(err), "pass": bool(ok), "flagged": flagged, "z": float(z), "no_gravity": no_gravity}
    out["all_pass"] = est is not None and all(out[n]["pass"] for n in NAMES)
    out["any_flagged"] = est is not None and any(out[n]["flagged"] for n in NAMES)
    return out


def _robust_sd(x: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(x - np.median(x)))) if x.size else float("nan")


def _pct(k: float, n: int) -> str:
    return f"{100 * k / n:.0f}" if n else "-"


def _fmt(x: float, spec: str = "+.2f") -> str:
    return "-" if x is None or not math.isfinite(x) else format(x, spec)


def summarize(method: str, rows: list[dict]) -> list[str]:
    """Markdown lines for one estimator; rows: {"name", "truth", "result", "score"}."""
    n = len(rows)
    fails = [r for r in rows if r["result"]["error"] is not None]
    lines = [f"### {method}", ""]
    all_pass = sum(r["score"]["all_pass"] for r in rows)
    any_flag = sum(r["score"]["any_flagged"] for r in rows)
    lines.append(f"{n} cases, {len(fails)} failures; every parameter passes in {_pct(all_pass, n)} % of the cases "
                 f"({all_pass}/{n}); some parameter flagged not determined in {_pct(any_flag, n)} %.")
    lines += ["", "| parameter | median error (%) | robust SD (%) | within tolerance (%) | tolerance (%) | "
                  "not determined (%) |", "|---|---|---|---|---|---|"]
    for p in NAMES:
        errs = np.array([r["score"][p]["err_pct"] for r in rows
                         if r["result"]["error"] is None and not r["score"][p]["no_gravity"]
                         and not r["score"][p]["flagged"] and math.isfinite(r["score"][p]["err_pct"])])
        within = sum(1 for r in rows if r["result"]["error"] is None and not r["score"][p]["no_gravity"]
                     and not r["score"][p]["flagged"] and abs(r["score"][p]["err_pct"]) <= TOL_PCT[p])
        graded = sum(1 for r in rows if not r["score"][p]["no_gravity"])
        flagged = sum(1 for r in rows if r["score"][p]["flagged"])
        tol = f"{TOL_PCT[p]:g}" + (" of \\|g\\|" if p in GRAVITY else "")
        lines.append(f"| {p} | {_fmt(float(np.median(errs)) if errs.size else float('nan'))} | "
                     f"{_fmt(_robust_sd(errs), '.2f')} | {_pct(within, graded)} | {tol} | {_pct(flagged, n)} |")
    z = np.array([r["score"][p]["z"] for r in rows for p in NAMES if math.isfinite(r["score"][p]["z"])])
    lines += ["", f"|error| / reported SD over {z.size} determined estimates: median {_fmt(float(np.median(z)) if z.size else float('nan'), '.3g')}, "
                  f"<= 3 in {_pct(int((z <= 3).sum()), z.size)} %, <= 1 in {_pct(int((z <= 1).sum()), z.size)} %."]
    no_g = [r for r in rows if r["score"]["mglx"]["no_gravity"]]
    if no_g:
        flagged_g = sum(1 for r in no_g if r["score"]["mglx"]["flagged"] and r["score"]["mgly"]["flagged"])
        lines.append(f"Joints without gravity: {len(no_g)}; mglx and mgly both flagged not determined in "
                     f"{flagged_g}.")
    # per family
    lines += ["", "| family | cases | failures | all pass (%) |", "|---|---|---|---|"]
    for fam in ("pa10", "cobot", "heavy", "vertical"):
        fr = [r for r in rows if r["truth"]["family"] == fam]
        if fr:
            lines.append(f"| {fam} | {len(fr)} | {sum(r['result']['error'] is not None for r in fr)} | "
                         f"{_pct(sum(r['score']['all_pass'] for r in fr), len(fr))} |")
    # worst cases
    def badness(r):
        if r["result"]["error"] is not None:
            return math.inf
        s = r["score"]
        b = 0.0
        for p in NAMES:
            e = s[p]["err_pct"]
            if s[p]["no_gravity"]:
                b = max(b, 0.0 if s[p]["flagged"] else 1.0 + abs(e) / TOL_PCT[p])
            elif not s[p]["flagged"]:
                b = max(b, abs(e) / TOL_PCT[p] if math.isfinite(e) else math.inf)
        return b

    worst = sorted(rows, key=badness, reverse=True)[:10]
    lines += ["", "Worst cases (error %; mglx, mgly of a joint without gravity in % of the torque RMS; "
                  "'nd' = flagged not determined):", "",
              "| case | family | true parameters | setting | " + " | ".join(NAMES) + " |",
              "|---|---|---|---|" + "---|" * len(NAMES)]
    for r in worst:
        c = r["truth"]["case"]
        nz = r["truth"]["noise"]
        setting = (f"{c['duration_s']:.0f} s, f0 {c['f0_hz']:.2f} Hz x{c['n_harmonics']}, "
                   f"±{math.degrees(c['peak_rad']):.0f}°, {c['friction_law']}"
                   + (f" {c['eps_rad_s']:.3g}" if c['friction_law'] == 'tanh' else '')
                   + f", tau {c['torque_noise_kind']} {nz['torque_noise_pct_of_rms']:.1f} %, "
                   f"markers {c['marker_noise_m'] * 1e3:.2f} mm x{len(c['marker_radii_m'])} "
                   f"r {min(c['marker_radii_m']) * 1e3:.0f}-{max(c['marker_radii_m']) * 1e3:.0f} mm, "
                   f"{c['mocap_hz']:.0f}/{c['controller_hz']:.0f} Hz, drop {100 * c['dropout_fraction']:.1f} %")
        if r["result"]["error"] is not None:
            cells = [f"failed: {r['result']['error'][:120]}"] + [""] * (len(NAMES) - 1)
        else:
            cells = ["nd" if r["score"][p]["flagged"] else _fmt(r["score"][p]["err_pct"], "+.1f") for p in NAMES]
        params = ", ".join(f"{p} {r['truth']['params'][p]:.3g}" for p in NAMES)
        lines.append(f"| {r['name']} | {r['truth']['family']} | {params} | {setting} | " + " | ".join(cells) + " |")
    if fails:
        lines += ["", "Failures:", ""] + [f"- {r['name']}: {r['result']['error']}" for r in fails]
    springs = [r["result"]["estimates"].get("_spring") for r in rows if r["result"]["estimates"]]
    if springs:
        counts = {m: springs.count(m) for m in dict.fromkeys(springs)}
        lines += ["", "Spring model chosen: " + ", ".join(f"{m} {k}" for m, k in counts.items()) + "."]
    secs = np.array([r["result"]["seconds"] for r in rows])
    lines += ["", f"Estimation time per case: median {np.median(secs):.1f} s, max {secs.max():.1f} s.", ""]
    return lines


def _write_docs(path: Path, text: str) -> None:
    from mocapfj.io.atomic import write_text_atomic

    block = f"{START}\n{text.rstrip()}\n{END}\n"
    if path.is_file():
        old = path.read_text(encoding="utf-8")
        if START in old and END in old:
            block = old[:old.index(START)] + block + old[old.index(END) + len(END):].lstrip("\n")
        else:
            block = old.rstrip() + "\n\n" + block
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, block)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=72, help="number of grid cases (default 72)")
    ap.add_argument("--base-seed", type=int, default=5000)
    ap.add_argument("--family", choices=("pa10", "cobot", "heavy", "vertical"), default=None,
                    help="restrict the grid to one family (default: the mixture)")
    ap.add_argument("--methods", default="output_error", help="comma-separated estimators (default output_error)")
    ap.add_argument("--spring", choices=("linear", "cubic", "bouc_wen"), default="linear",
                    help="give every case this spring (mocapfj.synth.hinge.with_spring); the table then "
                         "also counts the spring model each estimator chose")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--cache", type=Path, default=ROOT / "benchmarks" / ".cache" / "grid")
    ap.add_argument("--write-docs", type=Path, default=None, metavar="PATH",
                    help="write the Markdown report into PATH (between bench_identify_grid markers)")
    ap.add_argument("--no-bound", dest="bound", action="store_false",
                    help="skip the Cramér-Rao bound per case (hinge_bound.py; cached in the case's bound.json)")
    args = ap.parse_args(argv)

    from mocapfj.io import read_json, write_json
    from mocapfj.synth.hinge import sample_cases, with_spring

    cases = sample_cases(args.n, args.base_seed, family=args.family)
    cases = [with_spring(c, args.spring, seed=i) for i, c in enumerate(cases)]
    root = args.cache / ("_".join([str(args.base_seed)] + ([args.family] if args.family else [])
                                  + ([args.spring] if args.spring != "linear" else [])))
    dirs = [root / c.name for c in cases]
    tic = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as ex:
        gen = list(ex.map(_generate, cases, dirs))
    t_gen = time.perf_counter() - tic
    made = [g for g in gen if g is not None]
    print(f"grid: {len(cases)} cases in {root} ({len(made)} generated in {t_gen:.1f} s wall on {args.jobs} processes, "
          f"{len(cases) - len(made)} cached)")
    if made:
        durs = np.array([c.duration_s for c, g in zip(cases, gen) if g is not None])
        made = np.array(made)
        print(f"generation per case: median {np.median(made):.1f} s, max {made.max():.1f} s; "
              f"{np.sum(made) / np.sum(durs):.3f} s per simulated second")
    truths = [read_json(d / "truth.json") for d in dirs]
    bounds = None
    if args.bound:
        tic = time.perf_counter()
        with ProcessPoolExecutor(args.jobs) as ex:
            bounds = list(ex.map(_bound, cases, dirs))
        print(f"Cramér-Rao bounds in {time.perf_counter() - tic:.1f} s wall")

    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    fam_count = {f: sum(t["family"] == f for t in truths) for f in ("pa10", "cobot", "heavy", "vertical")}
    md = ["## Identification on the hinge grid", "",
          f"`python benchmarks/bench_identify_grid.py --n {args.n} --base-seed {args.base_seed}"
          + (f" --family {args.family}" if args.family else "") + f" --methods {','.join(methods)}`: "
          f"{len(cases)} synthetic single-joint recordings (mocapfj.synth.hinge; families "
          + ", ".join(f"{f} {k}" for f, k in fam_count.items() if k) + ").", ""]
    all_results = {}
    for method in methods:
        outs = [root / "_runs" / method / c.name for c in cases]
        tic = time.perf_counter()
        with ProcessPoolExecutor(args.jobs) as ex:
            results = list(ex.map(_estimate_one, dirs, outs, [method] * len(cases)))
        wall = time.perf_counter() - tic
        rows = [{"name": c.name, "truth": t, "result": r, "score": score_case(t, r["estimates"])}
                for c, t, r in zip(cases, truths, results)]
        print(f"\n{method}: {len(cases)} cases estimated in {wall:.1f} s wall on {args.jobs} processes")
        print("| case | family | duration (s) | generate (s) | estimate (s) | all pass | status |")
        print("|---|---|---|---|---|---|---|")
        for c, g, r in zip(cases, gen, rows):
            print(f"| {c.name} | {c.family} | {c.duration_s:.1f} | {'cached' if g is None else f'{g:.1f}'} | "
                  f"{r['result']['seconds']:.1f} | {'yes' if r['score']['all_pass'] else 'no'} | "
                  f"{'ok' if r['result']['error'] is None else r['result']['error'][:80]} |")
        md += summarize(method, rows)
        if bounds is not None:
            over = sum(1 for r, b in zip(rows, bounds) for p in NAMES
                       if r["score"][p]["flagged"] and math.isfinite(b[p]) and b[p] <= 5.0)
            under = sum(1 for r, b in zip(rows, bounds) for p in NAMES
                        if not r["score"][p]["flagged"] and r["result"]["error"] is None and math.isfinite(b[p]) and b[p] > 5.0)
            md += [f"Against the bound: {over} flags on parameters whose bound is at most 5 % (the data could "
                   f"determine them), {under} parameters reported determined whose bound is above 5 %.", ""]
        all_results[method] = [{"name": r["name"], "family": r["truth"]["family"], "truth": r["truth"]["params"],
                                "estimates": r["result"]["estimates"], "error": r["result"]["error"],
                                "seconds": r["result"]["seconds"],
                                "score": {k: v for k, v in r["score"].items()}} for r in rows]
        write_json(root / "_runs" / method / "results.json", all_results[method])
    if bounds is not None:
        md += bound_lines([{"truth": t, "bound": b} for t, b in zip(truths, bounds)])
    text = "\n".join(md)
    print("\n" + text)
    if args.write_docs is not None:
        _write_docs(args.write_docs, text)
        print(f"written to {args.write_docs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
