"""Single-record FRF (local polynomial method) and the rational fit: do the SDs of the modes cover
their errors on records the method was not developed on?

Grid: three sets of two resonances and two anti-resonances (ARM, ARM2 of tests/ident/test_frf_single.py
and LIGHT, damping ratios 0.008-0.01, peaks 1-2.6 DFT lines wide) x output noise 2 % and 10 % x
seeds 100-105, each one record of 1024 samples from rest driven by band-limited noise, simulated by
scipy.signal.lsim 8x oversampled (the test module's simulator); LPM R = 2, n = 4, rational (4, 4)
over 0.005-0.195 cycles per sample. Per cell: records whose modes were not all found, z RMS and the
largest |z| of the 8 frequencies and damping ratios, the largest relative frequency error.

    python benchmarks/bench_frf_single.py [--seeds 6]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "ident"))

from test_frf_single import ARM, ARM2, _simulate  # noqa: E402

from mocapfj.ident.frf_single import estimate_frf_lpm, fit_rational  # noqa: E402

LIGHT = (("antiresonance", 0.03, 0.01), ("resonance", 0.06, 0.01), ("resonance", 0.13, 0.008),
         ("antiresonance", 0.18, 0.01))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6)
    a = ap.parse_args()
    print("| modes | noise | not found | z RMS | max abs z | max f err % |")
    print("|---|---|---|---|---|---|")
    for name, modes in (("ARM", ARM), ("ARM2", ARM2), ("LIGHT", LIGHT)):
        for noise in (0.02, 0.1):
            zs, errs, fail = [], [], 0
            for seed in range(100, 100 + a.seeds):
                u, y, _ = _simulate(seed, modes=modes, noise=noise)
                fit = fit_rational(estimate_frf_lpm(u, y, 1.0), 4, 4, f_band_hz=(0.005, 0.195))
                if [m.kind for m in fit.modes] != [m[0] for m in modes]:
                    fail += 1
                    continue
                for m, (_, f0, z0) in zip(fit.modes, modes):
                    zs += [(m.f_hz - f0) / m.f_hz_std, (m.zeta - z0) / m.zeta_std]
                    errs.append(abs(m.f_hz / f0 - 1))
            zs = np.array(zs)
            print(f"| {name} | {noise:.0%} | {fail} | {np.sqrt(np.mean(zs ** 2)):.2f} | {np.abs(zs).max():.1f} | "
                  f"{100 * max(errs):.2f} |")


if __name__ == "__main__":
    main()
