"""Discovery of an effect on the second joint of a two-joint URDF recording (issue "discovery that
holds", deliverable 4).

Each case is a pa10_joints23-like recording (datasets/pa10_joints23.toml: PA-10 joints 2 and 3
moving together, one Pinocchio model of the rendered arm's URDF, Lightcap and Banks (2007) Table I
motor, friction and spring parameters, PD motor loops) simulated by mocapfj.synth.record (the
n-link simulation: LSODA on the coupled 2 x 2 system, no code shared with discovery's per-joint
kernel), rendered as markers and a controller log and measured through mocapfj's joints stage.
Drawn per case (case i of a base seed depends only on (base seed, i)):

| quantity | rule |
|---|---|
| f0 | U(0.1, 0.2) Hz, five harmonics a_l = w_l / l, w_l U(0.3, 1), phases U(0, 2 pi) |
| peak | j2 U(0.2, 0.4) rad about q0 U(0, 0.5) rad; j3 U(0.25, 0.5) rad about q0 U(-0.8, 0) rad |
| duration | a whole number of periods within 20-40 s (at least two) |
| noise | markers U(0.1, 0.3) mm; motor torque logU(0.1, 1) N m (white, controller rate) |

The validation recording has the same joints, noise levels, f0 and effect, a new excitation and
new noise. Each case is recorded six ways, the effect on joint 3 (``j3``) at s x its deflection
noise, s ~ U(0.3, 0.8) (the deflection noise: the white noise of j3's mocap link angle on the
control trial, :func:`mocapfj.ident.conditioning.white_noise_sd`; the deflection's statistics
from the control's truth):

- ``control``: none;
- ``hysteresis``: Bouc-Wen, alpha = 0.7, beta = gamma, loop half-width (1 - alpha) z_max = s x noise;
- ``stiffening``: cubic k delta + k3 delta^3 whose departure from its best straight line over the
  deflection (mean mu, SD sigma), k3 sigma^2 sqrt(18 mu^2 + 6 sigma^2) / k, is s x noise
  (capped at +100 % stiffness at |mu| + 2 sigma), as bench_discover_grid.py;
- ``time_delay``: the mocap clock d late, d = s x noise / RMS q3' (d > 0: a scenario's clock delay
  is non-negative; the hinge grid, bench_discover_grid.py, plants both signs). A clock is the
  recording's: both joints see it, the true model has delay_s = d on both;
- ``friction_asymmetry``: Coulomb c +- dc and viscous v +- dv by direction, (dc + dv RMS|q3'|) / k =
  s x noise, a share U(0.5, 1) in dc, either sign;
- ``backlash``: free play of total width 2 s x noise.

Discovery runs as ``mocapfj discover IDENT --model NOMINAL --validation VALID`` would (the API
call behind it), NOMINAL the case's scenario without the effect (read as a model file: its URDF
joints, mocapfj.discover.context). Per kind it prints: the planted effect named first on j3 (on any
joint for a delay), any effect named on a control (false positive), the validation gain on the
effect's joint against the gap between the nominal and the true model there (in the nominal's
band), and for controls the true model's gap to the noise floor on both joints, trial and
validation (goal: within 1 point).

    python benchmarks/bench_discover_nlink.py --n 3 --base-seed 31000

``--bias``: the nominal model is off, as one identified on the spot or taken from a data sheet
is: per case (the same for each kind), each joint's J, b, Coulomb c, viscous v and k multiplied by
1 +- U(0.10, 0.20), 1 +- U(0.10, 0.30), 1 +- U(0.10, 0.20), 1 +- U(0.10, 0.30) and 1 +- U(0.05,
0.10) (random signs; the URDF exact). The gap is then the true model's fit against that nominal's,
so a control has one too, which only the re-identification of the nominal parameters can recover;
per row also each re-identified j3 parameter's error against the truth in its SDs.

    python benchmarks/bench_discover_nlink.py --n 3 --base-seed 32000 --bias
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse
import copy
import json
import math
import sys
import time
import traceback
import tomllib
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

KINDS = ("control", "hysteresis", "stiffening", "time_delay", "friction_asymmetry", "backlash")
ALPHA_HYST = 0.7
JOINT = "j3"


def _excitation(rng, f0: float, peak: float, q0: float) -> dict:
    w = rng.uniform(0.3, 1.0, 5) / np.arange(1, 6)
    phases = rng.uniform(0.0, 2 * np.pi, 5)
    t = np.linspace(0.0, 1.0 / f0, 2000, endpoint=False)
    shape = (w[:, None] * np.sin(2 * np.pi * f0 * np.arange(1, 6)[:, None] * t + phases[:, None])).sum(0)
    amps = w * peak / np.abs(shape).max()
    return {"f0_hz": f0, "q0_rad": q0, "amplitudes_rad": [float(a) for a in amps],
            "phases_rad": [float(p) for p in phases], "ramp_s": 2.0}


def case_doc(base_seed: int, i: int, trial: str) -> dict:
    """The scenario document (no effect) of case i, trial "ident" or "valid"."""
    base = tomllib.loads((ROOT / "datasets" / "pa10_joints23.toml").read_text())
    rng = np.random.default_rng(np.random.SeedSequence([base_seed, i]))
    f0 = float(rng.uniform(0.1, 0.2))
    lo, hi = max(2, math.ceil(20.0 * f0)), max(2, math.floor(40.0 * f0))
    duration = round(int(rng.integers(lo, hi + 1)) / f0, 1)
    marker, torque = float(rng.uniform(1e-4, 3e-4)), float(np.exp(rng.uniform(np.log(0.1), np.log(1.0))))
    peaks = (float(rng.uniform(0.2, 0.4)), float(rng.uniform(0.25, 0.5)))
    q0s = (float(rng.uniform(0.0, 0.5)), float(rng.uniform(-0.8, 0.0)))
    sub = np.random.default_rng(np.random.SeedSequence([base_seed, i, 0 if trial == "ident" else 1]))
    doc = copy.deepcopy(base)
    doc.update(name=f"nlink_{base_seed}_{i}_{trial}", seed=int(sub.integers(2**31)), duration_s=duration)
    doc["measurement"].update(marker_noise_m=marker, torque_noise_Nm=torque)
    for j, jt in enumerate(doc["joints"]):
        jt["reference"] = _excitation(sub, f0, peaks[j], q0s[j])
    return doc


def _planted(doc: dict, kind: str, s: float, sign: float, stats: dict, rng) -> tuple[dict, dict]:
    """(scenario document with the effect on j3, its parameters for the true model)."""
    if kind == "control":
        return doc, {}
    j3 = next(j for j in doc["joints"] if j["name"] == JOINT)
    k, c, v = j3["spring"]["k"], j3["friction"]["c"], j3["friction"]["v"]
    sd_n = stats["noise_rad"]
    eff: dict = {"name": kind, "joint": JOINT}
    if kind == "hysteresis":
        z_max = s * sd_n / (1.0 - ALPHA_HYST)
        eff["spring"] = {"model": "bouc_wen", "k": k, "alpha": ALPHA_HYST, "beta": 0.5 / z_max, "gamma": 0.5 / z_max}
    elif kind == "stiffening":
        sd_d, mu = stats["deflection_sd_rad"], stats["deflection_mean_rad"]
        k3 = s * sd_n * k / (sd_d ** 2 * math.sqrt(18.0 * mu ** 2 + 6.0 * sd_d ** 2))
        k3 = min(k3, k / (3.0 * (abs(mu) + 2.0 * sd_d) ** 2))
        eff["spring"] = {"model": "cubic", "k1": k, "k3": k3}
    elif kind == "time_delay":
        eff["delay_s"] = s * sd_n / stats["velocity_rms_rad_s"]
    elif kind == "friction_asymmetry":
        w = rng.uniform(0.5, 1.0)
        dc = min(w * s * sd_n * k, c / 2)
        dv = min((1 - w) * s * sd_n * k / stats["velocity_rms_rad_s"], v / 2)
        eff["friction"] = {"model": "asymmetric_coulomb_viscous", "c_pos": c + sign * dc, "c_neg": c - sign * dc,
                           "v_pos": v + sign * dv, "v_neg": v - sign * dv}
    elif kind == "backlash":
        eff["gap_rad"] = 2 * s * sd_n
    out = copy.deepcopy(doc)
    out["name"] = f"{doc['name']}_{kind}"
    out["effects"] = [eff]
    return out, eff


BIAS = {"J": (0.10, 0.20), "b": (0.10, 0.30), "c": (0.10, 0.20), "v": (0.10, 0.30), "k": (0.05, 0.10)}
"""Relative errors of a biased nominal model (--bias): |error| ~ U(lo, hi), random sign."""


def _biased_nominal(src: Path, dst: Path, base_seed: int, i: int) -> dict:
    """Write the scenario `src` as a nominal model file `dst` with every joint's J, b, c, v, k off by
    the factors of BIAS (drawn from (base_seed, i) alone); returns {joint: {name: factor}}."""
    import tomli_w

    doc = tomllib.loads(src.read_text())
    rng = np.random.default_rng(np.random.SeedSequence([base_seed, i, 9]))
    factors = {}
    for jt in doc["joints"]:
        f = {n: 1.0 + float(rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi)) for n, (lo, hi) in BIAS.items()}
        jt["J"], jt["b"] = jt["J"] * f["J"], jt["b"] * f["b"]
        jt["friction"]["c"], jt["friction"]["v"] = jt["friction"]["c"] * f["c"], jt["friction"]["v"] * f["v"]
        jt["spring"]["k"] = jt["spring"]["k"] * f["k"]
        factors[jt["name"]] = f
    doc["effects"] = []
    dst.write_text(tomli_w.dumps(doc))
    return factors


def _record(doc: dict, d: Path) -> Path:
    """The bundle of a scenario document at d (kept when its scenario is unchanged)."""
    import tomli_w

    from mocapfj.synth.record import record_scenario, write_scenario_bundle
    from mocapfj.synth.scenario import load_scenario

    d.mkdir(parents=True, exist_ok=True)
    text = tomli_w.dumps({"format": "mocapfj.scenario/1", **{k: v for k, v in doc.items() if k != "format"}})
    scn_path = d / "scenario.toml"
    bundle = d / "bundle"
    if not (bundle / "recording.toml").exists() or not scn_path.exists() or scn_path.read_text() != text:
        scn_path.write_text(text)
        write_scenario_bundle(record_scenario(load_scenario(scn_path), with_concealment=False), bundle)
    return bundle


def _stats(bundle: Path) -> dict:
    """j3's deflection noise (white noise of its mocap angle), true deflection mean / SD, RMS link velocity."""
    import mocapfj
    from mocapfj.ident.conditioning import white_noise_sd

    s = mocapfj.signals(bundle)[JOINT]
    tr = np.genfromtxt(bundle / "truth.csv", delimiter=",", names=True)
    d = tr[f"delta_{JOINT}"]
    qd = np.gradient(tr[f"q_{JOINT}"], tr["time"])
    return {"noise_rad": white_noise_sd(s.q, s.fs_hz), "deflection_mean_rad": float(d.mean()),
            "deflection_sd_rad": float(d.std()), "velocity_rms_rad_s": float(np.sqrt(np.mean(qd ** 2)))}


def _true_models(nominal: dict, eff: dict) -> dict:
    from mocapfj.dynamics.spec import FRICTION_MODELS, SPRING_MODELS, element_from_table
    from mocapfj.dynamics import Backlash

    if not eff:
        return dict(nominal)
    out = dict(nominal)
    m = nominal[JOINT]
    if "spring" in eff:
        out[JOINT] = m.with_(spring=element_from_table(eff["spring"], SPRING_MODELS, None, "spring"))
    elif "friction" in eff:
        out[JOINT] = m.with_(friction=element_from_table(eff["friction"], FRICTION_MODELS, None, "friction"))
    elif "gap_rad" in eff:
        out[JOINT] = m.with_(spring=Backlash(eff["gap_rad"], m.spring))
    elif "delay_s" in eff:
        out = {n: x.with_(delay_s=eff["delay_s"]) for n, x in nominal.items()}
    return out


def _gap(nominal: dict, true: dict, valid: Path, joint: str) -> float:
    """Fit of the true model minus the nominal's on the validation recording, joint `joint`, in the
    nominal's band."""
    import mocapfj
    from mocapfj.discover.context import ROBOT_KEY, robot_context, robot_of
    from mocapfj.discover.model import simulate_joint

    sig = mocapfj.signals(valid)
    ctx = robot_context(robot_of(nominal), sig, nominal)
    s = sig[joint]
    a = simulate_joint(nominal[joint], s.t, s.q, s.q_m, s.u, {ROBOT_KEY: ctx})
    b = simulate_joint(true[joint], s.t, s.q, s.q_m, s.u, {ROBOT_KEY: ctx}, band_hz=a.band_hz)
    return float(b.fit - a.fit)


def run_case(base_seed: int, i: int, kind: str, out: Path, bias: bool = False) -> dict:
    from mocapfj.api import discover
    from mocapfj.discover import read_model_file

    t0 = time.time()
    row = {"case": i, "kind": kind}
    try:
        cdir = out / f"case_{base_seed}_{i}"
        ident_doc, valid_doc = case_doc(base_seed, i, "ident"), case_doc(base_seed, i, "valid")
        ctrl = _record(ident_doc, cdir / "control_ident")
        stats = _stats(ctrl)
        rng = np.random.default_rng(np.random.SeedSequence([base_seed, i, 7, KINDS.index(kind)]))
        s, sign = float(rng.uniform(0.3, 0.8)), float(rng.choice([-1.0, 1.0]))
        shape = np.random.SeedSequence([base_seed, i, 8, KINDS.index(kind)])       # the same effect on both
        idoc, eff = _planted(ident_doc, kind, s, sign, stats, np.random.default_rng(shape))
        vdoc, _ = _planted(valid_doc, kind, s, sign, stats, np.random.default_rng(shape))
        ident = ctrl if kind == "control" else _record(idoc, cdir / f"{kind}_ident")
        valid = _record(vdoc, cdir / f"{kind}_valid")
        nominal_file = cdir / "control_ident" / "scenario.toml"
        true = _true_models(read_model_file(nominal_file), eff)
        if bias:
            row["bias"] = _biased_nominal(nominal_file, cdir / "nominal_biased.toml", base_seed, i)
            nominal_file = cdir / "nominal_biased.toml"
        nominal = read_model_file(nominal_file)
        row.update(s=s, duration_s=ident_doc["duration_s"], noise_mrad=1e3 * stats["noise_rad"],
                   planted={k: v for k, v in eff.items() if k not in ("name", "joint")})
        d = discover(ident, model=nominal_file, validation=valid)
        found = [(e["name"], e["joint"]) for e in d.effects]
        row.update(found=found, verdict=d.verdict)
        r3 = d.reidentified.get(JOINT, {})
        row["adopted"] = r3.get("adopted", r3.get("error"))
        if bias and "parameters" in r3:
            t3 = true[JOINT]
            truth = {"J": t3.J, "b": t3.b, "c": t3.friction.c if hasattr(t3.friction, "c") else None,
                     "v": t3.friction.v if hasattr(t3.friction, "v") else None, "k": t3.stiffness()}
            row["reid_sds"] = {n: (p["value"] - truth[n]) / p["std"] for n, p in r3["parameters"].items()
                               if truth.get(n) is not None and p["std"] and p["std"] > 0}
        if kind == "control" and not bias:
            row["gaps"] = {j: {"trial": d.fits[j]["before"]["gap_to_floor"],
                               "validation": d.validation["fits"][j]["before"]["gap_to_floor"]} for j in d.fits}
            row["named_first"] = not found
        elif kind == "control":
            row["named_first"] = not found
            row["gap"] = _gap(nominal, true, valid, JOINT)
            row["gain"] = float(d.validation["fit_after"][JOINT] - d.validation["fit_before"][JOINT])
        else:
            first = found[0] if found else None
            row["named_first"] = bool(first and first[0] == kind and (first[1] == JOINT or kind == "time_delay"))
            row["gap"] = _gap(nominal, true, valid, JOINT)
            v = d.validation
            row["gain"] = float(v["fit_after"][JOINT] - v["fit_before"][JOINT])
            if kind == "time_delay":
                est = [e["parameters"].get("delay_s") for e in d.effects if e["name"] == "time_delay"]
                row["delay_error_ms"] = 1e3 * (est[0] - eff["delay_s"]) if est else None
    except Exception as e:  # noqa: BLE001 - a case that fails is a row of the table
        row["error"] = f"{type(e).__name__}: {e}"
        row["traceback"] = traceback.format_exc()[-2000:]
    row["time_s"] = time.time() - t0
    return row


def _table(rows: list[dict]) -> str:
    lines = ["| planted on j3 | cases | named first | validation gain >= gap / 2 (named) | median gain / gap | errors |",
             "|---|---|---|---|---|---|"]
    for kind in KINDS:
        rs = [r for r in rows if r["kind"] == kind]
        if not rs:
            continue
        ok = [r for r in rs if "error" not in r]
        named = [r for r in ok if r["named_first"]]
        if kind == "control":
            gapped = [r for r in ok if r.get("gap", 0) > 0]
            half = [r for r in gapped if r["gain"] >= 0.5 * r["gap"]]
            ratio = [r["gain"] / r["gap"] for r in gapped]
            lines.append(f"| none (control) | {len(rs)} | none reported in {len(named)}/{len(ok)} | "
                         + (f"{len(half)}/{len(gapped)} (of all) | {np.median(ratio):.2f} | " if gapped else "| | ")
                         + f"{len(rs) - len(ok)} |")
            continue
        half = [r for r in named if r["gap"] > 0 and r["gain"] >= 0.5 * r["gap"]]
        ratio = [r["gain"] / r["gap"] for r in ok if r.get("gap", 0) > 0]
        lines.append(f"| {kind} | {len(rs)} | {len(named)}/{len(ok)} | {len(half)}/{len(named)} | "
                     f"{np.median(ratio) if ratio else float('nan'):.2f} | {len(rs) - len(ok)} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=3, help="cases per kind")
    ap.add_argument("--start", type=int, default=0, help="the first case (cases start..n-1 run)")
    ap.add_argument("--base-seed", type=int, default=31000)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--out", default="/tmp/bench_discover_nlink")
    ap.add_argument("--json", default=None, help="write the rows here")
    ap.add_argument("--bias", action="store_true", help="a nominal model that is off (module docstring)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    kinds = [k for k in a.kinds.split(",") if k]
    # the controls first: a case's planted recordings are sized on its control's trial
    jobs = [(a.base_seed, i, k, out, a.bias) for k in kinds for i in range(a.start, a.n)]
    rows = []
    with ProcessPoolExecutor(a.workers) as ex:
        for row in ex.map(run_case, *zip(*jobs)):
            rows.append(row)
            show = {k: v for k, v in row.items() if k not in ("traceback", "verdict")}
            print(json.dumps(show, default=str), flush=True)
            if "error" in row:
                print(row["traceback"], flush=True)
    print()
    print(f"base seed {a.base_seed}, cases {a.start}..{a.n - 1} of each kind")
    print(_table(rows))
    ctrl = [r for r in rows if r["kind"] == "control" and "gaps" in r]
    if ctrl:
        worst = max(max(g["trial"], g["validation"]) for r in ctrl for g in r["gaps"].values())
        print(f"controls, the true model's gap to the noise floor (points, j2 and j3, trial and validation): "
              f"worst {worst:.2f}; " + "; ".join(f"case {r['case']}: " + ", ".join(
                  f"{j} {g['trial']:.2f}/{g['validation']:.2f}" for j, g in r["gaps"].items()) for r in ctrl))
    sds = {}
    for r in rows:
        if r["kind"] != "control":          # a planted spring or friction effect: the linear base is not the truth
            continue
        for n, z in r.get("reid_sds", {}).items():
            sds.setdefault(n, []).append(z)
    if sds:
        print("re-identified j3 on the controls against the truth, |error| / SD: " + ", ".join(
            f"{n} median {np.median(np.abs(z)):.2f} max {np.max(np.abs(z)):.2f} ({len(z)})" for n, z in sds.items()))
        print("adopted on j3: " + ", ".join(f"{r['kind']} {r['case']}: {r.get('adopted')}" for r in rows))
    delays = [r["delay_error_ms"] for r in rows if r.get("delay_error_ms") is not None]
    if delays:
        print(f"time delay error: max |error| {max(abs(x) for x in delays):.2f} ms over {len(delays)} named")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
