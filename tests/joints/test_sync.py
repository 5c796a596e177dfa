"""Stream synchronisation and deflection (mocapfj.joints.sync)."""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj import ControllerLog, InputError, JointAngles
from mocapfj.joints.sync import deflection, resolver_quantum


def test_declared_offset_is_applied_and_nothing_else():
    tc = np.arange(0, 10.001, 1e-3)
    q_m = 0.5 * np.sin(tc) + 0.01
    ctl = ControllerLog(t=tc, q_m=q_m[:, None], tau=np.cos(tc)[:, None], joint_names=("j",))
    tm = np.arange(0, 9.0, 4e-3)
    lag = 1.5e-3  # the link lags the motor physically: that must survive synchronisation
    offset = 0.25  # declared: t_controller = t_mocap + 0.25
    q = 0.5 * np.sin(tm + offset - lag) - 0.2  # mocap zero differs from the motor's by 0.21 rad
    ang = JointAngles(t=tm, q=q, sigma_q=np.full(tm.size, 4e-4), marker_rms=np.zeros(tm.size),
                      n_markers=np.full(tm.size, 4), n_rejected=np.zeros(tm.size, int))
    d = deflection(ang, ctl, "j", clock_offset_s=offset)
    np.testing.assert_allclose(d.t, tm + offset)
    want = 0.5 * (np.sin(tm + offset) - np.sin(tm + offset - lag))  # what the lag leaves in delta
    np.testing.assert_allclose(d.delta - np.mean(d.delta), want - np.mean(want), atol=1e-6)
    np.testing.assert_allclose(d.tau, np.cos(tm + offset), atol=1e-6)
    assert d.q_offset_rad == pytest.approx(0.21 + np.mean(want), abs=1e-6)


def test_samples_outside_the_controller_log_are_nan_and_quantum_enters_sigma():
    tc = np.arange(0, 2.0001, 1e-3)
    quantum = 1.9e-6
    q_m = np.round(0.3 * np.sin(3 * tc) / quantum) * quantum
    ctl = ControllerLog(t=tc, q_m=q_m[:, None], tau=np.zeros((tc.size, 1)), joint_names=("j",))
    assert resolver_quantum(q_m) == pytest.approx(quantum, rel=1e-6)
    tm = np.arange(-0.5, 2.5, 4e-3)
    ang = JointAngles(t=tm, q=0.3 * np.sin(3 * tm), sigma_q=np.full(tm.size, 1e-6), marker_rms=np.zeros(tm.size),
                      n_markers=np.full(tm.size, 4), n_rejected=np.zeros(tm.size, int))
    d = deflection(ang, ctl, 0)
    outside = (tm < 0) | (tm > 2.0)
    assert np.isnan(d.delta[outside]).all() and np.isfinite(d.delta[~outside]).all()
    np.testing.assert_allclose(d.sigma_delta, np.sqrt(1e-12 + quantum**2 / 12))


def test_no_overlap_is_an_error():
    tc = np.arange(0, 1.0, 1e-3)
    ctl = ControllerLog(t=tc, q_m=np.zeros((tc.size, 1)), tau=np.zeros((tc.size, 1)), joint_names=("j",))
    tm = np.arange(5.0, 6.0, 4e-3)
    ang = JointAngles(t=tm, q=np.zeros(tm.size), sigma_q=np.ones(tm.size), marker_rms=np.zeros(tm.size),
                      n_markers=np.full(tm.size, 4), n_rejected=np.zeros(tm.size, int))
    with pytest.raises(InputError, match="inside the controller log's time span.*clock_offset_s"):
        deflection(ang, ctl, 0)
