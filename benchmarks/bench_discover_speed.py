"""How long `mocapfj discover` takes on a 60 s single-joint recording, through the command line.

The recording is the reference row of the hinge simulator (PA-10 joint 2, Lightcap and Banks
(2007), Table I; 0.1 Hz x 5 harmonics at +-50 deg; 1 kHz controller, 250 Hz mocap, 0.2 mm markers,
0.5 N m torque noise) made 60 s long, once with each effect of the grid
(benchmarks/bench_discover_grid.py) sized to half the deflection noise, with a validation
recording of the same joint (new phases and noise). The nominal model is the truth without the
effect. Each run is a fresh process, `mocapfj discover IDENT --model NOMINAL --validation VALID
--out DIR` (imports, markers -> joint angles for both recordings, the search, the
re-identification, the proof), timed by wall clock after one warm-up run (numba's compiled
kernels are cached on disk on the first one).

Goal (issue "discovery that holds"): under 15 s on 2 cores. No peer does this job (PySINDy fits
a model to clean derivatives; it neither calibrates joints nor simulates a flexible joint), so
the table has no ratio column.

    python benchmarks/bench_discover_speed.py
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

KINDS = ("control", "hysteresis", "stiffening", "time_delay", "stribeck", "friction_asymmetry", "backlash",
         "transmission_error")


def _bundles(kind: str, root: Path) -> tuple[Path, Path, Path]:
    from bench_discover_grid import _models, _planted, _shift_controller, _with_mean
    from mocapfj.discover import write_model_file
    from mocapfj.io import read_json
    from mocapfj.synth.hinge import case_digest, first_row_case, write_hinge_bundle

    base = replace(first_row_case(11), duration_s=60.0, name="speed")
    ctrl = root / "control_ident"
    if not (ctrl / "truth.json").exists() or read_json(ctrl / "truth.json")["case_sha256"] != case_digest(base):
        write_hinge_bundle(base, ctrl)
    t0 = read_json(ctrl / "truth.json")
    case, delay = _planted(base, kind, _with_mean(t0["stats"], ctrl), t0["noise"], 0.5, 1.0)
    out = []
    for name, c in (("ident", case), ("valid", replace(case, seed=case.seed + 1,
                                                        phases_rad=tuple(p + 1.0 for p in case.phases_rad)))):
        d = root / f"{kind}_{name}"
        if kind == "control" and name == "ident":
            d = ctrl
        elif not (d / "truth.json").exists() or read_json(d / "truth.json")["case_sha256"] != case_digest(c):
            write_hinge_bundle(c, d)
            if delay:
                _shift_controller(d, delay)
        out.append(d)
    nominal, _ = _models(read_json(out[0] / "truth.json"), case, delay)
    mfile = root / f"{kind}_nominal.toml"
    write_model_file(mfile, [nominal])
    return out[0], out[1], mfile


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, default=ROOT / "benchmarks" / ".cache" / "discover_speed")
    ap.add_argument("--kinds", default=",".join(KINDS))
    args = ap.parse_args(argv)
    args.cache.mkdir(parents=True, exist_ok=True)
    exe = [str(Path(sys.executable).parent / "mocapfj")]           # the console script, as a user runs it
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    rows = []
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    for i, kind in enumerate(kinds):
        ident, valid, mfile = _bundles(kind, args.cache)
        cmd = exe + ["discover", str(ident), "--model", str(mfile), "--validation", str(valid),
                     "--out", str(args.cache / f"{kind}_out"), "--json"]
        if i == 0:
            subprocess.run(cmd, capture_output=True, env=env, cwd=ROOT)          # warm-up: numba's cache
        tic = time.perf_counter()
        p = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT)
        sec = time.perf_counter() - tic
        named = "ERROR " + p.stderr.strip()[-120:] if p.returncode else ",".join(
            e["name"] for e in json.loads(p.stdout)["effects"]) or "none"
        rows.append((kind, sec, named))
    print(f"mocapfj discover, 60 s PA-10 recording + 60 s validation, one process per run, {os.cpu_count()} cores")
    print(f"{'planted':20s} {'seconds':>8s}  named")
    for kind, sec, named in rows:
        print(f"{kind:20s} {sec:8.1f}  {named}")
    secs = [r[1] for r in rows]
    print(f"\nmedian {sorted(secs)[len(secs) // 2]:.1f} s, max {max(secs):.1f} s; goal under 15 s: "
          f"{'met' if max(secs) < 15 else 'not met'} ({sum(s < 15 for s in secs)}/{len(secs)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
