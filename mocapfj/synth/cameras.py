"""A ring of motion-capture cameras around the robot (Lightcap and Banks (2007), §IV.A: eight cameras).

Cameras stand on a circle around the workspace, alternately high and low, and look at a common
target point. Defaults are those of a typical 1.3 MP mocap camera: 1280 x 1024 px, about 60 deg
horizontal field of view (fx = 1100 px), small barrel distortion.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..types import Rig
from ..vision.camera import look_at_camera

__all__ = ["ring_rig"]


def ring_rig(n_cameras: int = 8, *, radius_m: float = 2.6, heights_m=(2.3, 1.5),
             target_world=(0.0, 0.0, 1.2), size: tuple[int, int] = (1280, 1024), fx: float = 1100.0,
             dist=(-0.04, 0.015, 0.0, 0.0, 0.0), azimuth0_rad: float = np.pi / 8,
             rng: np.random.Generator | None = None, jitter_m: float = 0.05) -> Rig:
    """A ring of `n_cameras` cameras looking at `target_world`.

    Camera i stands at azimuth azimuth0 + 2 pi i / n on a horizontal circle of `radius_m` about
    the world z axis, at height heights_m[i % len(heights_m)], with world z up in its image.

    Parameters
    ----------
    n_cameras : int
        Number of cameras (6-8 is typical; at least 2).
    radius_m : float
        Horizontal distance of the cameras from the world z axis, metres.
    heights_m : sequence of float
        Camera heights, used in turn, metres.
    target_world : (3,) float
        Point every optical axis passes through (without jitter), world frame, metres.
    size : (width, height) int
        Image size, pixels.
    fx : float
        Focal length, pixels (fy = fx).
    dist : (k,) float
        OpenCV distortion coefficients shared by all cameras (before jitter).
    azimuth0_rad : float
        Azimuth of camera 0, rad.
    rng : numpy.random.Generator, optional
        When given, each camera's position and aim point move by N(0, jitter_m) per axis, its
        focal length by N(0, 1 %) and its principal point by N(0, 5 px), and its k1, k2 by
        N(0, 0.005). Without it the rig is exactly regular.
    jitter_m : float
        Standard deviation of the position and aim jitter, metres.

    Returns
    -------
    Rig with cameras "cam_0" .. "cam_{n-1}"; metadata records how it was made.
    """
    if int(n_cameras) < 2:
        raise InputError(None, "n_cameras", "at least 2 cameras", n_cameras)
    heights = np.atleast_1d(np.asarray(heights_m, dtype=np.float64))
    target = np.asarray(target_world, dtype=np.float64).reshape(3)
    w, h = int(size[0]), int(size[1])
    cams = []
    for i in range(int(n_cameras)):
        az = azimuth0_rad + 2.0 * np.pi * i / n_cameras
        pos = np.array([radius_m * np.cos(az), radius_m * np.sin(az), heights[i % heights.size]])
        aim = target.copy()
        f = float(fx)
        cxy = ((w - 1) / 2.0, (h - 1) / 2.0)
        d = np.array(dist, dtype=np.float64)
        if rng is not None:
            pos = pos + rng.normal(0.0, jitter_m, 3)
            aim = aim + rng.normal(0.0, jitter_m, 3)
            f *= 1.0 + rng.normal(0.0, 0.01)
            cxy = (cxy[0] + rng.normal(0.0, 5.0), cxy[1] + rng.normal(0.0, 5.0))
            d[:2] += rng.normal(0.0, 0.005, 2)
        cams.append(look_at_camera(f"cam_{i}", pos, aim, fx=f, size=(w, h), principal_px=cxy, dist=d))
    meta = {"source": "mocapfj.synth.cameras.ring_rig", "radius_m": float(radius_m),
            "heights_m": heights.tolist(), "target_world_m": target.tolist(), "jittered": rng is not None}
    return Rig(cameras=tuple(cams), metadata=meta)
