"""Discovery on variants the suite never had: other effect parameters, another excitation
(f0 0.15 Hz, other amplitudes and phases), 1.5 x the marker noise and 1.7 x the torque noise,
other seeds. Build for the physics, not for the suite: each planted effect must be named alone,
with its parameters; the control must report none. 60 s trials through the whole chain, against
the nominal model; bundles cached in --cache (default benchmarks/.cache/discover_variants).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import tomli_w  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "datasets"))

import make_suite  # noqa: E402

from mocapfj.pipeline import run_discover  # noqa: E402
from mocapfj.synth.record import record_scenario, write_scenario_bundle  # noqa: E402
from mocapfj.synth.scenario import load_scenario  # noqa: E402

# name -> (effect, planted parameters, the parameter checked and its tolerance)
VARIANTS = {
    "time_delay_2.5ms": ("time_delay", {"delay_s": 2.5e-3}, ("delay_s", 2.5e-3, 0.5e-3)),
    "stribeck_wide": ("stribeck", {"friction": {"model": "stribeck", "fc": 9.28, "fs": 12.5, "vs": 0.05, "fv": 18.38}},
                      ("vs", 0.05, 0.01)),
    "hysteresis_strong": ("hysteresis", {"spring": {"model": "bouc_wen", "k": 1.19e4, "alpha": 0.85, "beta": 500.0,
                                                    "gamma": 200.0}}, ("alpha", 0.85, 0.03)),
    "transmission_error_2x": ("transmission_error", {"amplitudes_rad": [1.5e-4, 2.0e-4], "phases_rad": [2.0, -0.5],
                                                     "orders": [1.0, 2.0]}, ("amplitudes_rad", [1.5e-4, 2.0e-4], 3e-5)),
    "control": (None, None, None),
}


def scenario(name: str, out: Path) -> Path:
    eff, params, _ = VARIANTS[name]
    doc = make_suite.scenario(eff, "ident")
    doc["name"], doc["seed"] = name, 700 + sorted(VARIANTS).index(name)
    doc["joints"][0]["reference"] = {"f0_hz": 0.15, "q0_rad": 0.1, "amplitudes_rad": [0.2, 0.15, 0.1, 0.04, 0.02],
                                     "phases_rad": [0.3, 1.9, 0.2, 2.2, 1.0], "ramp_s": 2.0}
    doc["measurement"]["marker_noise_m"] = 3.0e-4
    doc["measurement"]["torque_noise_Nm"] = 0.5
    if eff:
        doc["effects"] = [{"name": eff, "joint": "j2", **params}]
    p = out / f"{name}.toml"
    p.write_text(tomli_w.dumps(doc))
    return p


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=ROOT / "benchmarks" / ".cache" / "discover_variants")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    ok = True
    print("| variant | named | recovered | planted | fit before -> after | s |")
    print("|---|---|---|---|---|---|")
    for name, (eff, _, check) in VARIANTS.items():
        p = scenario(name, args.cache)
        b = args.cache / f"{name}_bundle"
        if not (b / "recording.toml").exists():
            write_scenario_bundle(record_scenario(load_scenario(p), with_concealment=False), b)
        t0 = time.perf_counter()
        s = run_discover(b, args.cache / f"{name}_out", model=p)
        sec = time.perf_counter() - t0
        named = [e["name"] for e in s["effects"]]
        if eff is None:
            good, got, want = not named, "", ""
        else:
            key, want, tol = check
            got = s["effects"][0]["parameters"].get(key) if named else None
            close = got is not None and all(abs(g - w) < tol for g, w in zip(*(
                (got, want) if isinstance(want, list) else ([got], [want]))))
            good = named == [eff] and close
        ok &= good
        fmt = (lambda v: "" if v in ("", None) else (", ".join(f"{x:.4g}" for x in v) if isinstance(v, list) else f"{v:.4g}"))
        print(f"| {name} | {', '.join(named) or 'none'} | {check[0] + ' ' if check else ''}{fmt(got)} | {fmt(want)} | "
              f"{s['fit_before']['j2']:.2f} -> {s['fit_after']['j2']:.2f} | {sec:.1f} |{'' if good else ' MISSED'}",
              flush=True)
    print(f"\n{'all goals met' if ok else 'GOAL MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
