"""Discovery on the concealed-effect suite through the whole chain: the proof table and the speed.

For every effect of datasets/suite (and the no-effect control, and the two-effect scenario of
datasets/discovery): simulate the identification and validation trials (60 s each; markers ->
`mocapfj joints` -> angles -> deflection), run `mocapfj discover` on the identification trial
against the nominal model (the scenario without its effect: the simulation a lab compares its
robot with) with the validation trial, and run the scenario's true model through the same chain
on the validation trial. Prints the table of docs/discovery.md:

effect planted | named first (joint) | location | fit ident before -> after | fit valid before ->
after | true model on valid | share of the gap recovered | p-value

Goals (issue 6): the planted effect named first on the right joint; on the validation trial at
least half of the gap between nominal and true model recovered; a planted time delay within
0.5 ms; the control reports none; both effects of the two-effect scenario found; a 60 s
single-joint recording analysed (joints + discovery, with validation) in under 60 s.
Bundles are cached in --cache (default benchmarks/.cache/discover).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")


ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mocapfj.discover import JointModel, simulate_joint  # noqa: E402
from mocapfj.discover.model import read_model_file  # noqa: E402

SUITE = ROOT / "datasets" / "suite"
EFFECTS = ["hysteresis", "stiffening", "backlash", "transmission_error", "position_dependent_friction", "stribeck",
           "friction_asymmetry", "time_delay", "coupling", "gravity_mismatch", "drive_gain"]


def scenario_path(label: str, trial: str) -> Path:
    p = SUITE / f"{label}_{trial}.toml"
    return p if p.exists() else ROOT / "datasets" / "discovery" / f"{label}_{trial}.toml"


def bundle(label: str, trial: str, cache: Path) -> Path:
    """The simulated recording bundle of a scenario (cached)."""
    from mocapfj.synth.record import record_scenario, write_scenario_bundle
    from mocapfj.synth.scenario import load_scenario

    d = cache / f"{label}_{trial}"
    if not (d / "recording.toml").exists():
        sr = record_scenario(load_scenario(scenario_path(label, trial)), with_concealment=False)
        write_scenario_bundle(sr, d)
    return d


def true_models(path: Path) -> dict[str, JointModel]:
    """The scenario's true system as discovery's joint models (its effects included)."""
    from mocapfj.synth.scenario import joint_models, load_scenario

    scn = load_scenario(path)
    nominal = read_model_file(path)
    sj = joint_models(scn, with_effects=True)
    out = {}
    for name, m in nominal.items():
        s, dt = sj[name], sj[name].drivetrain
        out[name] = m.with_(friction=s.friction.with_smoothing(0.0) if hasattr(s.friction, "with_smoothing") else s.friction,
                            spring=s.spring, transmission_error=dt.transmission_error, position_torque=dt.balancer,
                            torque_gain=dt.torque_gain)
    for e in scn.effects:
        if e.name == "time_delay":
            out[e.joint] = out[e.joint].with_(delay_s=float(e.params["delay_s"]))
        if e.name == "coupling":
            out[e.joint] = out[e.joint].with_(coupling={e.params["source"]: float(e.params["inertia_kgm2"])})
    return out


def true_fit(label: str, cache: Path) -> dict:
    """The true model's output-error fit on the validation trial, through the same chain."""
    from mocapfj.ident.conditioning import derivatives, lowpass
    import mocapfj

    sig = mocapfj.signals(bundle(label, "valid", cache))
    qdd = {n: lowpass(derivatives(lowpass(s.q_m, 250.0, 20.0), 250.0)[1], 250.0, 20.0) for n, s in sig.items()}
    out = {}
    for name, m in true_models(scenario_path(label, "valid")).items():
        s = sig[name]
        out[name] = simulate_joint(m, s.t, s.q, s.q_m, s.u, {k: v for k, v in qdd.items() if k != name}).fit
    return out


def run(label: str, cache: Path) -> dict:
    from mocapfj.pipeline import run_discover

    ident, valid = bundle(label, "ident", cache), bundle(label, "valid", cache)
    t0 = time.perf_counter()
    s = run_discover(ident, cache / f"{label}_out", model=scenario_path(label, "ident"), validation=valid)
    s["seconds"] = time.perf_counter() - t0
    s["true_fit_valid"] = true_fit(label, cache)
    return s


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=ROOT / "benchmarks" / ".cache" / "discover")
    ap.add_argument("--only", nargs="*", default=None, help="labels to run (default: all)")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    labels = args.only or (EFFECTS + ["control", "two_effects"])
    rows, ok = [], True
    print("| effect planted | named (joint) | location | fit ident before -> after | fit valid before -> after | "
          "true model, valid | gap recovered | p-value | s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label in labels:
        s = run(label, args.cache)
        j = "j2"
        named = [f"{e['name']} ({e['joint']})" for e in s["effects"]]
        first = s["effects"][0] if s["effects"] else None
        v = s["validation"]
        fb, fa, tf = v["fit_before"][j], v["fit_after"][j], s["true_fit_valid"][j]
        gap = tf - fb
        share = (fa - fb) / gap if gap > 0 else float("nan")
        if label == "control":
            good = not s["effects"]
        elif label == "two_effects":
            good = {e["name"] for e in s["effects"]} >= {"hysteresis", "friction_asymmetry"}
        else:
            good = first is not None and first["name"] == label and first["joint"] == j and share >= 0.5
            if label == "time_delay" and first is not None:
                good &= abs(first["parameters"].get("delay_s", 0) - 1e-3) < 5e-4
        good &= s["seconds"] < 60.0
        ok &= good
        loc = "" if first is None else first["location"].get("where", "")
        if label == "time_delay" and first is not None:
            loc += f", delay {1e3 * first['parameters']['delay_s']:.3f} ms (planted 1.000)"
        pval = "" if first is None else f"{first['p_value']:.1e}"
        print(f"| {label} | {', '.join(named) or 'none'} | {loc} | {s['fit_before'][j]:.2f} -> {s['fit_after'][j]:.2f} | "
              f"{fb:.2f} -> {fa:.2f} | {tf:.2f} | {100 * share:.0f} % | {pval} | {s['seconds']:.1f} |"
              f"{'' if good else ' MISSED'}", flush=True)
        rows.append({"label": label, **{k: s[k] for k in ("effects", "fit_before", "fit_after", "validation",
                                                            "true_fit_valid", "seconds")}})
    (args.cache / "table.json").write_text(json.dumps(rows, indent=1, default=float))
    print(f"\n{'all goals met' if ok else 'GOAL MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
