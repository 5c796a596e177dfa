"""The frequency-domain fit checked against the time-domain identification of the same joint.

One recording, two methods: PA-10 joint 2 (datasets/pa10_joint2.toml, Lightcap and Banks 2007
Table I, its PD loop) plays an odd random-phase multisine 0.5-20 Hz as its motor reference,
(RMS 0.03 rad, so the same recording also calibrates the axis), recorded as the simulator records any scenario (markers through 8 cameras, the controller log
with resolver quantisation and torque noise). `mocapfj identify` (output error: the mocap link
angle and the motor torque) and `mocapfj frf --compare` (motor-side signals only, the indirect
estimator with the reference) are run on it; the table gives each method's k and the modes
against the truth, and the cross-check's verdict. Variants: the scenario's Coulomb friction on
(9.28 N m) and off, two seeds each (seeds 61, 62: not used in development).

    python benchmarks/bench_frf_crosscheck.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mocapfj.api import identify  # noqa: E402
from mocapfj.ident.frf_fit import two_inertia_modes  # noqa: E402
from mocapfj.ident.multisine import design_multisine  # noqa: E402
from mocapfj.io import read_csv_columns, write_csv_columns, write_json  # noqa: E402
from mocapfj.pipeline.frf import run_frf  # noqa: E402
from mocapfj.synth.record import record_scenario, write_scenario_bundle  # noqa: E402
from mocapfj.synth.scenario import load_scenario, reference_trajectory  # noqa: E402

FS, N, PERIODS = 1000.0, 4096, 6


def case(coulomb: bool, seed: int, workdir: Path) -> dict:
    scn = load_scenario(ROOT / "datasets" / "pa10_joint2.toml")
    ms = design_multisine(FS, N, 0.5, 20.0, rms=0.03, seed=seed)   # +-6 deg: enough to fit the axis
    ref_table = ms.to_reference(q0_rad=0.3, ramp_s=2.0)
    (j,) = scn.joints
    joint = replace(j, reference=ref_table)
    if not coulomb:
        joint = replace(joint, friction={**dict(j.friction), "c": 0.0})
    scn = replace(scn, seed=seed, joints=(joint,), duration_s=PERIODS * N / FS)
    sr = record_scenario(scn, with_concealment=False)
    bundle = write_scenario_bundle(sr, workdir / f"rec_{int(coulomb)}_{seed}").parent
    ident = identify(bundle)
    write_json(workdir / "identify.json", ident.to_dict())
    params = ident.to_dict()["joints"][0]["params"]
    ctl = read_csv_columns(bundle / "controller.csv")
    q_ref = reference_trajectory(ref_table)(ctl["time"])[0]
    write_csv_columns(workdir / "log.csv", {"time": ctl["time"], "tau": ctl["tau_j2"], "qm": ctl["qm_j2"],
                                            "qref": q_ref})
    # as a user runs it: `mocapfj frf ... --compare identify.json` (the gravity stiffness fitted and
    # held against the one identify's mglx, mgly imply), and without the gravity term
    # (--gravity-stiffness 0)
    s = run_frf(workdir / "log.csv", workdir / "frf", input="tau", output="qm", reference="qref", period_s=N / FS,
                compare=workdir / "identify.json")
    s0 = run_frf(workdir / "log.csv", workdir / "frf0", input="tau", output="qm", reference="qref", period_s=N / FS,
                 gravity_stiffness=0.0)
    nom = sr.truth["joints"][0]["nominal"]
    k_true = nom["spring"]["k"]
    q0 = float(np.mean(ctl["qm_j2"]))
    g_true = -nom["mglx"] * np.cos(q0) - nom["mgly"] * np.sin(q0)
    truth_modes = {kind: f for kind, f, _ in two_inertia_modes(J=nom["J"], I=nom["I"], k=k_true, b=nom["b"],
                                                                v=nom["friction"]["v"], g=g_true)}
    return {"coulomb": coulomb, "seed": seed, "k_true": k_true, "g_true": g_true, "gravity": s["gravity"],
            "k_frf": s["model"]["params"]["k"], "k_frf_nog": s0["model"]["params"]["k"], "k_id": params["k"],
            "modes": {m["kind"]: (m["f_hz"], m["f_hz_std"], truth_modes[m["kind"]]) for m in s["modes"]},
            "check": s["comparison"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one seed per variant")
    args = ap.parse_args()
    seeds = (61,) if args.quick else (61, 62)
    print("| Coulomb | seed | g FRF +- SD; identify's; true (N m/rad) | k FRF err % (SD %) | k FRF without g err % (SD %) | "
          "k identify err % (SD %) | anti-res err % | res err % | verdict | sim+ident+frf s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for coulomb in (False, True):
        for seed in seeds:
            t0 = time.time()
            with tempfile.TemporaryDirectory() as d:
                r = case(coulomb, seed, Path(d))
            kt = r["k_true"]
            kf, ki = r["k_frf"], r["k_id"]
            m = r["modes"]
            fa = m.get("antiresonance")
            fr = m.get("resonance")
            k0 = r["k_frf_nog"]
            gr = r["gravity"]
            print(f"| {'9.28 N m' if coulomb else 'none'} | {seed} | {gr['g_Nm_per_rad']:.1f} +- "
                  f"{gr['g_std_Nm_per_rad']:.1f}; {gr.get('identify', {}).get('value', float('nan')):.1f}; "
                  f"{r['g_true']:.1f} | {100 * (kf['value'] / kt - 1):+.2f} "
                  f"({100 * kf['std'] / kf['value']:.2f}) | {100 * (k0['value'] / kt - 1):+.2f} "
                  f"({100 * k0['std'] / k0['value']:.2f}) | {100 * (ki['value'] / kt - 1):+.2f} "
                  f"({100 * ki['std'] / ki['value']:.2f}) | "
                  f"{'' if fa is None else f'{100 * (fa[0] / fa[2] - 1):+.2f}'} | "
                  f"{'' if fr is None else f'{100 * (fr[0] / fr[2] - 1):+.2f}'} | {r['check']['verdict']} | "
                  f"{time.time() - t0:.0f} |", flush=True)
            for line in r["check"]["lines"]:
                print(f"|  |  |  |  | {line} |  |  |  |  |  |")


if __name__ == "__main__":
    main()
