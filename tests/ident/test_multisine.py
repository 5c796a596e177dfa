"""Multisine design (Makarov et al. 2012, eq. 21-22): line plan, exact spectrum, crest factor,
shaping, the reference the simulator plays, realisations, bad input."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from mocapfj.errors import InputError
from mocapfj.ident.multisine import (crest_factor, design_multisine, multisine_realisations, schroeder_phases,
                                     write_multisine_reference)
from mocapfj.synth.scenario import reference_trajectory

FS, N = 1 / 0.003, 1024


def test_odd_line_plan_with_detection_lines():
    ms = design_multisine(FS, N, 0.5, 12.0, kind="odd", detection_group=3, seed=4)
    f0 = FS / N
    band = np.arange(int(np.ceil(0.5 / f0)), int(12.0 / f0) + 1)
    assert np.all(ms.lines % 2 == 1) and np.all(ms.detection_odd % 2 == 1) and np.all(ms.detection_even % 2 == 0)
    assert ms.lines.min() >= band.min() and ms.lines.max() <= band.max()
    inside = np.arange(ms.lines.min(), ms.lines.max() + 1)
    assert np.array_equal(np.sort(np.concatenate([ms.lines, ms.detection_odd, ms.detection_even])), inside)
    odd = band[band % 2 == 1]
    assert ms.detection_odd.size >= odd.size // 3 - 2          # one odd line left out per group of three
    assert np.allclose(ms.f_hz, ms.lines * f0)


def test_spectrum_is_exactly_the_design():
    ms = design_multisine(FS, N, 1.0, 20.0, kind="odd", rms=0.02, seed=1)
    X = np.fft.rfft(ms.period()) * 2 / N
    assert np.allclose(np.abs(X[ms.lines]), ms.amplitudes, rtol=1e-10)
    others = np.setdiff1d(np.arange(X.size), ms.lines)
    assert np.abs(X[others]).max() < 1e-12 * ms.amplitudes.max()
    assert np.std(ms.period()) == pytest.approx(0.02, rel=1e-10)
    t, u = ms.signal(3)
    assert u.size == 3 * N and np.allclose(ms.evaluate(t)[0], u, atol=1e-12)


def test_crest_factor_minimisation():
    raw = design_multisine(FS, N, 0.5, 30.0, kind="random", crest="none", seed=2)
    clip = design_multisine(FS, N, 0.5, 30.0, kind="random", crest="clip", seed=2)
    sch = design_multisine(FS, N, 0.5, 30.0, kind="random", crest="schroeder", seed=2)
    assert raw.crest_factor > 2.5                               # random phases: ~3-4
    assert clip.crest_factor < 1.8 and sch.crest_factor < 2.0   # sqrt(2) is a single sine's
    assert np.allclose(clip.amplitudes, raw.amplitudes)         # the amplitude spectrum untouched
    assert crest_factor(np.sin(np.linspace(0, 2 * np.pi, 1000, endpoint=False))) == pytest.approx(np.sqrt(2))
    assert schroeder_phases(np.ones(4)).shape == (4,)


def test_amplitude_shaping():
    ms = design_multisine(FS, N, 1.0, 40.0, kind="odd", shape=lambda f: 1.0 / f, rms=1.0, seed=0)
    assert np.allclose(ms.amplitudes * ms.f_hz, ms.amplitudes[0] * ms.f_hz[0])
    assert ms.rms == pytest.approx(1.0)


def test_reference_played_by_the_simulator(tmp_path):
    ms = design_multisine(FS, N, 0.5, 12.0, rms=0.01, seed=3)
    ref = ms.to_reference(q0_rad=0.2, ramp_s=0.0)
    t = np.arange(2 * N) / FS
    q, qd = reference_trajectory(ref)(t)
    x, xd = ms.evaluate(t)
    assert np.allclose(q - q[:N].mean(), x, atol=1e-12)        # the multisine plus a constant
    assert np.allclose(qd, xd, atol=1e-10)
    write_multisine_reference(tmp_path / "ref.toml", ms, q0_rad=0.2)
    back = tomllib.loads((tmp_path / "ref.toml").read_text())["joints"]["reference"]
    assert back["f0_hz"] == pytest.approx(FS / N) and back["ramp_s"] == pytest.approx(N / FS)
    assert np.allclose(back["amplitudes_rad"], ref["amplitudes_rad"])


def test_realisations_differ_in_phase_only_and_are_seeded():
    ms = design_multisine(FS, N, 0.5, 12.0, seed=3)
    a = multisine_realisations(ms, 3, seed=10)
    b = multisine_realisations(ms, 3, seed=10)
    assert all(np.array_equal(x.phases, y.phases) for x, y in zip(a, b))
    assert not np.allclose(a[0].phases, a[1].phases)
    assert all(np.array_equal(x.amplitudes, ms.amplitudes) and np.array_equal(x.lines, ms.lines) for x in a)


@pytest.mark.parametrize("kw, field", [
    (dict(n_samples=1023), "n_samples"),
    (dict(f_max_hz=200.0), "f_min_hz, f_max_hz"),
    (dict(kind="pink"), "kind"),
    (dict(shape=lambda f: -f), "shape"),
    (dict(f_min_hz=0.5, f_max_hz=0.6), "f_min_hz, f_max_hz"),
])
def test_bad_input(kw, field):
    args = dict(fs_hz=FS, n_samples=N, f_min_hz=0.5, f_max_hz=12.0)
    args.update(kw)
    with pytest.raises(InputError) as e:
        design_multisine(**args)
    assert e.value.field == field
