"""Marker-file speed: mocapfj's C3D reader and writer against the pure-Python `c3d` package.

A 60 s recording at 250 Hz with 20 markers (15,000 frames), the size of one identification trial.
Prints a table; ratios are measured in the same run on the same file.
"""

from __future__ import annotations

import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mocapfj import MarkerTrajectories  # noqa: E402
from mocapfj.io import read_c3d, read_trc, write_c3d, write_trc  # noqa: E402


def best_of(fn, repeat=3) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def c3d_package_read(path):
    import c3d

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with open(path, "rb") as h:
            return np.stack([p.copy() for _, p, _ in c3d.Reader(h).read_frames()], 0)


def c3d_package_write(path, m: MarkerTrajectories):
    import c3d

    w = c3d.Writer(point_rate=m.rate_hz, point_scale=-0.01)
    w.set_point_labels(list(m.labels))
    xyz_mm = np.nan_to_num(m.xyz * 1e3).astype(np.float32)
    for f in range(m.n_frames):
        p = np.zeros((len(m.labels), 5), np.float32)
        p[:, :3] = xyz_mm[f]
        w.add_frames([(p, np.zeros((0, 0), np.float32))])
    with open(path, "wb") as h:
        w.write(h)


def main() -> None:
    rng = np.random.default_rng(0)
    n_frames, n_markers = 15000, 20
    xyz = rng.normal(0, 0.5, (n_frames, n_markers, 3))
    xyz[rng.random((n_frames, n_markers)) < 0.02] = np.nan
    m = MarkerTrajectories(t=np.arange(n_frames) / 250.0, xyz=xyz, labels=tuple(f"M{i}" for i in range(n_markers)),
                           rate_hz=250.0, residual=np.where(np.isnan(xyz[..., 0]), np.nan, 2e-4))
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        rows = []
        t_ours = best_of(lambda: write_c3d(d / "a.c3d", m))
        t_peer = best_of(lambda: c3d_package_write(d / "b.c3d", m), repeat=1)
        rows.append(("C3D write", t_ours, "c3d package", t_peer))
        t_ours = best_of(lambda: read_c3d(d / "a.c3d"))
        t_peer = best_of(lambda: c3d_package_read(d / "a.c3d"), repeat=1)
        rows.append(("C3D read", t_ours, "c3d package", t_peer))
        t_w = best_of(lambda: write_trc(d / "a.trc", m))
        t_r = best_of(lambda: read_trc(d / "a.trc"))
    print(f"marker files: {n_frames} frames x {n_markers} markers (60 s at 250 Hz)")
    print(f"| {'operation':<10} | {'mocapfj (s)':>11} | {'peer':<12} | {'peer (s)':>8} | {'speed-up':>8} |")
    print(f"|{'-' * 12}|{'-' * 13}|{'-' * 14}|{'-' * 10}|{'-' * 10}|")
    for name, ours, peer, tp in rows:
        print(f"| {name:<10} | {ours:>11.4f} | {peer:<12} | {tp:>8.4f} | {tp / ours:>7.1f}x |")
    print(f"| TRC write  | {t_w:>11.4f} | {'-':<12} | {'-':>8} | {'-':>8} |")
    print(f"| TRC read   | {t_r:>11.4f} | {'-':<12} | {'-':>8} | {'-':>8} |")


if __name__ == "__main__":
    main()
