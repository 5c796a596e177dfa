"""Synthetic recording speed: the 60 s pa10_joint2 scenario (Lightcap and Banks (2007), Table I, joint 2).

Goal (issue: simulator and synthetic recordings): simulate and render a 60 s single-joint
scenario in under 20 s on 2 cores. Peers measured in the same run:
- integration with solve_ivp's tight defaults (LSODA, rtol 1e-8, max_step = one 1 ms sample);
- occlusion by trimesh's pure-Python ray intersector instead of Embree (timed on 100 frames
  and scaled to 15,000: its cost is linear in the number of rays).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mocapfj.dynamics import simulate  # noqa: E402
from mocapfj.synth.record import _pid, record_scenario, write_scenario_bundle  # noqa: E402
from mocapfj.synth.render import render_markers  # noqa: E402
from mocapfj.synth.scenario import joint_models, load_scenario  # noqa: E402


def main() -> None:
    scn = load_scenario(ROOT / "datasets" / "pa10_joint2.toml")
    t0 = time.perf_counter()
    sr = record_scenario(scn, with_concealment=False)
    t_record = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        write_scenario_bundle(sr, d)
        t_write = time.perf_counter() - t0
    tim = sr.timings_s
    total = t_record + t_write

    # peer 1: tight integration settings
    m = joint_models(scn)["j2"]
    t = sr.sim["j2"].t
    t0 = time.perf_counter()
    simulate(m, t, _pid(scn, scn.joints), rtol=1e-8, atol=1e-10)
    t_tight = time.perf_counter() - t0

    # peer 2: pure-Python ray casting on 100 frames, scaled
    from mocapfj.synth.record import marker_layout, scenario_rngs
    from mocapfj.synth.cameras import ring_rig
    from mocapfj.synth.robot_mesh import base_pose, forward_kinematics, pa10_geometry

    geometry = pa10_geometry()
    layout = marker_layout(scn, geometry, scenario_rngs(scn)[0])
    q = np.tile(np.asarray(scn.pose_rad), (100, 1))
    q[:, 1] = sr.q_true_mocap[:100, 0]
    T = forward_kinematics(q, T_world_base=base_pose())
    rig = ring_rig(8, rng=scenario_rngs(scn)[1])
    times = {}
    for backend in ("embree", "triangle"):
        t0 = time.perf_counter()
        render_markers(np.arange(100) / 250.0, T, layout, geometry, rig, np.random.default_rng(0), backend=backend)
        times[backend] = (time.perf_counter() - t0) * 150  # 15,000 / 100 frames

    print("60 s single-joint scenario (pa10_joint2): 60,001 controller samples, 15,000 mocap frames, 20 markers, 8 cameras")
    print(f"| {'stage':<34} | {'mocapfj (s)':>11} | {'peer (s)':>9} | {'speed-up':>8} |")
    print(f"|{'-' * 36}|{'-' * 13}|{'-' * 11}|{'-' * 10}|")
    print(f"| {'simulate (LSODA, 5 ms steps)':<34} | {tim['simulate']:>11.2f} | {t_tight:>9.2f} | {t_tight / tim['simulate']:>7.1f}x |")
    print(f"| {'render (Embree, per-link frames)':<34} | {tim['render']:>11.2f} | {times['triangle']:>9.1f} | {times['triangle'] / tim['render']:>7.1f}x |")
    print(f"| {'controller log':<34} | {tim['log']:>11.2f} | {'-':>9} | {'-':>8} |")
    print(f"| {'write bundle':<34} | {t_write:>11.2f} | {'-':>9} | {'-':>8} |")
    print(f"| {'total (goal < 20 s)':<34} | {total:>11.2f} | {'-':>9} | {20.0 / total:>6.2f}x under |")
    print(f"peer 1: solve_ivp rtol 1e-8, max_step 1 ms; peer 2: trimesh pure-Python rays, 100 frames x 150 "
          f"(Embree on the same 100 frames: {times['embree'] / 150:.2f} s)")


if __name__ == "__main__":
    main()
