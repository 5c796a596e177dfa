"""Start-up time of the command line and of the Python API (issue 10: `mocapfj --help` in under
1 s): Pinocchio, rerun and matplotlib load only where they are used.

Measured in the same run, best of 5 fresh processes each:
- `mocapfj --help` (goal < 1 s);
- `python -c "import mocapfj"`, and the same importing every stage package (ident, joints,
  dynamics, discover, pipeline), which do not load Pinocchio;
- peer: `python -c "import pinocchio"`, the cost a stage that needs it pays on first use (what
  every command paid before the imports were made lazy).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def best_of(cmd: list[str], n: int = 5) -> float:
    best = float("inf")
    for _ in range(n):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT)
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> int:
    exe = shutil.which("mocapfj") or str(Path(sys.executable).parent / "mocapfj")
    py = sys.executable
    rows = [
        ("mocapfj --help", best_of([exe, "--help"]), 1.0),
        ("import mocapfj", best_of([py, "-c", "import mocapfj"]), None),
        ("import mocapfj and every stage package",
         best_of([py, "-c", "import mocapfj.ident, mocapfj.joints, mocapfj.dynamics, mocapfj.discover, mocapfj.pipeline"]),
         None),
        ("peer: import pinocchio", best_of([py, "-c", "import pinocchio"]), None),
    ]
    print("| start-up (best of 5 processes) | time (s) | goal |")
    print("|---|---|---|")
    ok = True
    for name, t, goal in rows:
        met = goal is None or t < goal
        ok &= met
        print(f"| {name} | {t:.3f} | {'' if goal is None else f'< {goal:g} s'}{'' if met else ' MISSED'} |")
    print(f"\n`mocapfj --help` takes {rows[0][1] / rows[3][1]:.2f}x the time of importing Pinocchio alone")
    print(f"\n{'all goals met' if ok else 'GOAL MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
