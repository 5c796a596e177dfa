"""Shape checks of the shared data types (mocapfj.types): every constructor validates its arrays
through mocapfj.validate and stores read-only copies."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj import Camera, ControllerLog, InputError, JointAngles, MarkerTrajectories
from mocapfj.types import Deflection, JointSignals, LSResult


def test_marker_shapes_are_checked_and_arrays_frozen():
    m = MarkerTrajectories(t=np.arange(3) / 10, xyz=np.zeros((3, 2, 3)), labels=("a", "b"), rate_hz=10)
    assert not m.xyz.flags.writeable
    assert m.select(["b"]).shape == (3, 1, 3)
    with pytest.raises(InputError, match=r"xyz: expected an array of shape \(T=3, M=3, 3\), got shape \(3, 2, 3\)"):
        MarkerTrajectories(t=np.arange(3), xyz=np.zeros((3, 2, 3)), labels=("a", "b", "c"), rate_hz=10)
    with pytest.raises(InputError, match=r"labels: expected unique marker labels, got duplicates \['a'\]"):
        MarkerTrajectories(t=np.arange(3), xyz=np.zeros((3, 2, 3)), labels=("a", "a"), rate_hz=10)
    with pytest.raises(InputError, match=r"marker label: expected one of \['a', 'b'\], got 'z'"):
        m.index("z")
    with pytest.raises(InputError, match=r"rate_hz: expected a positive number, got inf"):
        MarkerTrajectories(t=np.arange(3), xyz=np.zeros((3, 2, 3)), labels=("a", "b"), rate_hz=np.inf)


def test_controller_shapes():
    with pytest.raises(InputError, match=r"tau: expected an array of shape \(T=4, J=1\), got shape \(4,\)"):
        ControllerLog(t=np.arange(4.0), q_m=np.zeros((4, 1)), tau=np.zeros(4), joint_names=("j",))


def test_camera_shapes():
    with pytest.raises(InputError, match=r"camera 'c' K: expected an array of shape \(3, 3\), got shape \(2, 2\)"):
        Camera("c", (10, 10), np.eye(2), np.zeros(5), np.eye(3), np.zeros(3))


def test_joint_angles_are_checked_and_frozen():
    """The review's case: t (3,), q (5,) and sigma_q None used to be accepted and writable."""
    with pytest.raises(InputError, match=r"JointAngles.q: expected an array of shape \(T=3,\), got shape \(5,\)"):
        JointAngles(t=np.zeros(3), q=np.zeros(5), sigma_q=None, marker_rms=np.zeros(3), n_markers=np.zeros(3),
                    n_rejected=np.zeros(3))
    with pytest.raises(InputError, match=r"JointAngles.sigma_q: expected an array of shape \(T=3,\), got shape \(\)"):
        JointAngles(t=np.zeros(3), q=np.zeros(3), sigma_q=None, marker_rms=np.zeros(3), n_markers=np.zeros(3),
                    n_rejected=np.zeros(3))
    a = JointAngles(t=np.arange(3.0), q=[0.1, 0.2, np.nan], sigma_q=np.ones(3), marker_rms=np.zeros(3),
                    n_markers=[4, 4, 0], n_rejected=[0, 0, 0])
    assert a.n_invalid == 1 and a.n_markers.dtype == np.int64
    for arr in (a.t, a.q, a.sigma_q, a.marker_rms, a.n_markers, a.n_rejected):
        assert not arr.flags.writeable


def test_deflection_lsresult_and_signals_are_checked():
    z = np.zeros(4)
    with pytest.raises(InputError, match=r"Deflection.tau: expected an array of shape \(T=4,\)"):
        Deflection(t=z, q=z, q_m=z, delta=z, sigma_delta=z, tau=np.zeros(3), q_offset_rad=0.0, q_m_quantum_rad=0.0)
    with pytest.raises(InputError, match=r"Deflection.q_m_quantum_rad: expected a non-negative number"):
        Deflection(t=z, q=z, q_m=z, delta=z, sigma_delta=z, tau=z, q_offset_rad=0.0, q_m_quantum_rad=-1.0)
    with pytest.raises(InputError, match=r"LSResult.cov: expected an array of shape \(p=2, p=2\), got shape \(3, 3\)"):
        LSResult(names=("a", "b"), values=np.ones(2), std=np.ones(2), rel_std_pct=np.ones(2), cov=np.eye(3), cond=1.0,
                 residual_rms=0.0, rel_error_pct=0.0, r2=1.0, n_samples=10)
    r = LSResult(names=("a", "b"), values=[1.0, 2.0], std=[0.1, 0.2], rel_std_pct=[10.0, 10.0], cov=np.diag([0.01, 0.04]),
                 cond=1.0, residual_rms=0.0, rel_error_pct=0.0, r2=1.0, n_samples=10)
    assert r["b"] == 2.0 and r.std_of("b") == 0.2 and not r.cov.flags.writeable
    with pytest.raises(InputError, match=r"j2: u: expected finite values, got 1 NaN or infinite of 4"):
        JointSignals(t=np.arange(4.0), q=z, q_m=z, u=[0, 0, np.nan, 0], fs_hz=1.0, name="j2")
