"""What the rerun recording adds to a run: RUN_DIR/recording.rrd of a 60 s recording (250 Hz mocap,
20 markers, 1 kHz controller log, 8 cameras), timed part by part.

The run is simulated here (the PA-10 joint 2 scenario, 60 s; its joints and identify stages), or
given with --run DIR (e.g. one with a discover stage too). Goal (issue 17): under 5 s in all,
reading the run's files included. Prints a table: seconds per part, total, file size.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mocapfj.pipeline import default_scenario, run_identify, run_joints, run_simulate  # noqa: E402
from mocapfj.viz.rrd import write_recording_file  # noqa: E402
from mocapfj.viz.rrd_data import load_run  # noqa: E402

GOAL_S = 5.0


def make_run(d: Path, duration_s: float) -> Path:
    rec, out = d / "rec", d / "run"
    tic = time.perf_counter()
    run_simulate(default_scenario("pa10_joint2"), rec, duration_s=duration_s, concealment=False)
    run_joints(rec, out / "joints")
    run_identify([rec], out / "identify")
    (out / "run.json").write_text('{"format": "mocapfj.run/1", "recording": "%s", "stages": []}' % rec.resolve())
    print(f"(run prepared in {time.perf_counter() - tic:.1f} s: simulate, joints, identify)")
    return out


def measure(run: Path, magnify: float) -> tuple[dict, int, str]:
    import rerun  # noqa: F401  (imported once, outside the timing, as in a run that logs)

    timings = {}
    tic = time.perf_counter()
    contents = load_run(run)
    timings["read the run's files"] = time.perf_counter() - tic
    m = contents.markers
    what = (f"{m.xyz.shape[0]} frames x {m.xyz.shape[1]} markers at {m.rate_hz:g} Hz" if m is not None else "no markers")
    if contents.recording is not None and contents.recording.controller is not None:
        what += f", controller {contents.recording.controller.t.size} samples"
    if contents.rig is not None:
        what += f", {len(contents.rig.cameras)} cameras"
    out = Path(tempfile.mkdtemp()) / "recording.rrd"
    tic = time.perf_counter()
    write_recording_file(contents, out, magnify=magnify, timings=timings)
    timings["blueprint and file set-up"] = time.perf_counter() - tic - sum(
        v for k, v in timings.items() if k != "read the run's files")
    size = out.stat().st_size
    out.unlink()
    return timings, size, what


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, default=None, help="an existing run directory (default: simulate one)")
    ap.add_argument("--duration", type=float, default=60.0, help="simulated duration, s (default 60)")
    ap.add_argument("--magnify", type=float, default=1.0, help="deflection magnification (default 1: not drawn)")
    args = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory() as tmp:
        run = args.run if args.run is not None else make_run(Path(tmp), args.duration)
        measure(run, args.magnify)                      # warm-up: numba/pyarrow first calls, file cache
        timings, size, what = measure(run, args.magnify)
    total = sum(timings.values())
    print(f"\nrerun recording of {run if args.run else f'a simulated {args.duration:g} s run'}: {what}\n")
    print("| part | s |\n|---|---:|")
    for k, v in timings.items():
        print(f"| {k} | {v:.3f} |")
    print(f"| **total** | **{total:.3f}** |")
    print(f"\nfile size {size / 1e6:.1f} MB; goal under {GOAL_S:g} s: {'met' if total < GOAL_S else 'NOT met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
