"""Markers smoothed before export, told from their own residuals (:mod:`mocapfj.joints.smoothing`),
and what discovery does with it: compares below the smoothing's corner."""

from __future__ import annotations

from dataclasses import replace

import pytest

import mocapfj
from mocapfj.discover import engine
from mocapfj.joints.smoothing import smoothing_corner_hz
from mocapfj.synth.hinge import sample_cases, simulate_hinge
from mocapfj.synth.markers import vendor_smoothed

from ..discover.conftest import nominal_of


def smoothed(rec, fc_hz: float, order: int = 4):
    """`rec` with its markers smoothed as a mocap vendor's export does (:func:`vendor_smoothed`)."""
    return replace(rec, markers=vendor_smoothed(rec.markers, fc_hz, order))


@pytest.fixture(scope="module")
def cobot():
    """A light cobot of the hinge grid (seed 43000, case 3: 21.5 s at 200 frames/s, comparison band
    10.4 Hz) and a second noise draw of it."""
    case = sample_cases(6, 43000)[3]
    return case, simulate_hinge(case)[0], simulate_hinge(replace(case, seed=case.seed + 7))[0]


def test_white_markers_are_not_taken_for_smoothed(cobot):
    _, rec, _ = cobot
    assert smoothing_corner_hz(mocapfj.joints(rec).joints[0].angles) is None


@pytest.mark.parametrize("fc, order", [(6.0, 4), (12.0, 4), (20.0, 2)])
def test_a_smoothing_corner_is_found_and_not_above_the_filter(cobot, fc, order):
    """Zero-phase Butterworth smoothing of order 4 at 6 and 12 Hz and order 2 at 20 Hz: the corner
    comes out at 0.35-1.0 of the filter's (below it: the residuals carry the cluster template's error
    too, which makes them look smoother; measured 0.73, 0.67 and 0.70)."""
    _, rec, _ = cobot
    got = smoothing_corner_hz(mocapfj.joints(smoothed(rec, fc, order)).joints[0].angles)
    assert got is not None and 0.35 * fc < got <= fc, got


def test_discovery_compares_a_smoothed_recording_below_its_corner(cobot):
    """The true model of the cobot, its markers smoothed at 6 Hz: compared up to 10.4 Hz it was 1.44
    points below its trial's floor (5.5 floor SDs: the filter, not the joint) and a clock offset of
    -0.03 ms was named for the filter; below the corner, within 0.5 points of both floors and none."""
    case, rec, val = cobot
    s = mocapfj.signals(smoothed(rec, 6.0))["j1"]
    v = mocapfj.signals(smoothed(val, 6.0))["j1"]
    assert s.smoothing_hz is not None and v.smoothing_hz is not None
    d = engine.discover({"j1": s}, {"j1": nominal_of(case)}, fs_hz=s.fs_hz, reidentify=False, validation={"j1": v})
    assert d.effects == [], [e["name"] for e in d.effects]
    f, vf = d.fits["j1"]["before"], d.validation["fits"]["j1"]["before"]
    assert f["band_hz"] <= 0.5 * s.smoothing_hz + 1e-9 and f["markers_smoothed_hz"] == s.smoothing_hz
    assert abs(f["floor"] - f["fit"]) < 0.5 and abs(vf["floor"] - vf["fit"]) < 0.5, (f, vf)
