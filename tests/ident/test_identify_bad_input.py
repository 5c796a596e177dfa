"""Identification's bad-input list (issue 5): gaps in the link angle, NaN in the controller log,
a recording too short for the filters, signals of different lengths, no excitation."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocapfj import InputError
from mocapfj.io import read_csv_columns, write_csv_columns

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """A 6 s pa10_joint2 bundle and its angles CSV."""
    from mocapfj.pipeline import run_joints
    from mocapfj.synth.record import record_scenario, write_scenario_bundle
    from mocapfj.synth.scenario import load_scenario

    d = tmp_path_factory.mktemp("bad")
    sr = record_scenario(load_scenario(ROOT / "datasets" / "pa10_joint2.toml").with_duration(6.0), with_concealment=False)
    write_scenario_bundle(sr, d / "bundle")
    run_joints(d / "bundle", d / "out")
    return d, sr.recording


def _with_gap(d: Path, start: int, n: int) -> Path:
    cols = read_csv_columns(d / "out" / "j2.angles.csv")
    cols["q"] = cols["q"].copy()
    cols["q"][start:start + n] = np.nan
    path = d / f"gap_{start}_{n}.csv"
    write_csv_columns(path, cols)
    return path


def test_a_short_gap_is_filled_and_counted(short):
    from mocapfj.pipeline import joint_signals

    d, rec = short
    t, q, *_ , n_filled = joint_signals(rec, _with_gap(d, 500, 10), 0)
    full = joint_signals(rec, d / "out" / "j2.angles.csv", 0)
    assert n_filled == 10 + full[4]
    assert np.isfinite(q).all()
    # linear interpolation over 44 ms of a smooth motion: within the angle noise (0.43 mrad) of the
    # angles it replaced, and every other sample untouched
    assert np.abs(q - full[1])[500:510].max() < 4 * 0.43e-3
    assert np.array_equal(np.delete(q, np.s_[500:510]), np.delete(full[1], np.s_[500:510]))


def test_a_long_gap_is_refused_with_where_it_is(short):
    from mocapfj.pipeline import joint_signals

    d, rec = short
    path = _with_gap(d, 500, 50)       # 50 frames at 250 Hz: 0.204 s between the angles around it
    with pytest.raises(InputError, match=r"gap_500_50\.csv: q \(joint j2\): expected gaps in the link angle of at most "
                                         r"0\.1 s, got 0\.204 s without an angle from t = 2\.000 s"):
        joint_signals(rec, path, 0)


def test_nan_in_the_controller_log_is_refused_with_its_time(short):
    from mocapfj.pipeline import joint_signals

    d, rec = short
    tau = rec.controller.tau.copy()
    tau[3000:3005, 0] = np.nan
    bad = replace(rec, controller=replace(rec.controller, tau=tau))
    with pytest.raises(InputError, match=r"controller log tau \(joint j2\): expected finite samples, got 5 NaN, the "
                                         r"first at t = 3\.0000 s"):
        joint_signals(bad, d / "out" / "j2.angles.csv", 0)


def test_a_recording_too_short_for_the_filters_is_named(short):
    """3 s: the 1 s trims and the 2 Hz split filter need 4 s at 250 Hz."""
    from mocapfj.pipeline import identify_signals, joint_signals

    d, rec = short
    t, q, q_m, u, _ = joint_signals(rec, d / "out" / "j2.angles.csv", 0)
    n = int(3.0 * 250)
    with pytest.raises(InputError, match=r"t: expected at least 1000 samples \(4\.0 s\) for the filters and the trim, "
                                         r"got 750 samples \(3\.00 s\)"):
        identify_signals(t[:n], q[:n], q_m[:n], u[:n], 250.0)


def test_signals_of_different_lengths_and_no_excitation_are_named():
    from mocapfj.pipeline import identify_signals

    t = np.arange(5000) / 250.0
    q = 0.3 * np.sin(2 * np.pi * 0.2 * t)
    with pytest.raises(InputError, match=r"t, q, q_m, u: expected four \(T,\) arrays"):
        identify_signals(t, q[:-3], q, q, 250.0)
    # the motor stands still: the motor equation cannot see J and b
    with pytest.raises(InputError, match=r"no independent excitation of \[.*'J'.*\]"):
        identify_signals(t, q, np.zeros_like(q), np.zeros_like(q), 250.0)
