"""IDIM-LS (mocapfj.ident.idim) on the real EMPS benchmark.

Source: A. Janot, M. Gautier, M. Brunot, "Data set and reference models of EMPS", Nonlinear
System Identification Benchmarks workshop, 2019 (EMPS_Description.pdf, Script_IDIM_LS.m,
Script_IDIM_LS_Asym_Fric.m, Script_IDIM_LS_CVT.m); reference values copied in
../shared/realdata/README.md ("emps"). One real prismatic drive, 1 kHz, closed-loop PD.
Acceptance (the issue): M within 0.5 %, Fv and Fc within 1 %, offset within 3 %, relative
error 4.1 +- 0.2 %, cross-validation 6.0 +- 0.3 %, cond near 25.99, stds within 10 %.
"""

from __future__ import annotations

import numpy as np
import pytest

from mocapfj import InputError
from mocapfj.ident.idim import idim_cross_validation, idim_ls, idim_observation, idim_regressor, load_emps_mat

PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
PUBLISHED_STD = {"M": 0.1085, "Fv": 1.1460, "Fc": 0.1012, "offset": 0.0444}
TOL = {"M": 0.005, "Fv": 0.01, "Fc": 0.01, "offset": 0.03}
ASYM = {"M": 95.154, "Fv+": 166.71, "Fc+": 20.144, "Fv-": 240.42, "Fc-": 20.628}


@pytest.fixture(scope="module")
def emps(realdata):
    return load_emps_mat(realdata / "emps" / "DATA_EMPS.mat")


@pytest.fixture(scope="module")
def emps_pulses(realdata):
    return load_emps_mat(realdata / "emps" / "DATA_EMPS_PULSES.mat")


def test_idim_ls_reproduces_the_published_table(emps, emps_pulses):
    fit = idim_ls(*emps)  # defaults = the benchmark: Butterworth 4 / 100 Hz, border 50, decimate 10
    assert fit.names == ("M", "Fv", "Fc", "offset")
    for name, ref in PUBLISHED.items():
        assert fit[name] == pytest.approx(ref, rel=TOL[name]), name
        assert fit.std[fit.names.index(name)] == pytest.approx(PUBLISHED_STD[name], rel=0.10), name
    # measured: M 95.116, Fv 203.37, Fc 20.409, offset -3.1700; std 0.1074, 1.136, 0.1004, 0.0440
    assert fit.rel_error_pct == pytest.approx(4.08, abs=0.2)  # measured 4.04
    assert fit.cond == pytest.approx(25.99, rel=0.01)          # measured 26.01
    assert fit.n_samples == 2475
    cv, y_pred, y = idim_cross_validation(fit, *emps_pulses)
    assert cv == pytest.approx(5.98, abs=0.3)                 # measured 5.95
    assert y_pred.shape == y.shape == (2475,)


def test_asymmetric_friction_variant(emps):
    fit = idim_ls(*emps, model="asymmetric")
    for name, ref in ASYM.items():
        tol = 0.005 if name == "M" else 0.01
        assert fit[name] == pytest.approx(ref, rel=tol), name  # measured 95.161, 166.71, 20.144, 240.30, 20.642
    assert fit.rel_error_pct == pytest.approx(3.11, abs=0.2)    # measured 3.06
    # the asymmetric model explains the data better than the symmetric one
    assert fit.rel_error_pct < idim_ls(*emps).rel_error_pct - 0.5


def test_butterworth_decimation_agrees_with_the_benchmark_filter(emps):
    ref = idim_ls(*emps)
    bw = idim_ls(*emps, decimation_filter="butterworth")
    np.testing.assert_allclose(bw.values[:3], ref.values[:3], rtol=0.005)  # measured <= 0.3 %
    # the sampling rate may be given instead of t
    t, q, f = emps
    np.testing.assert_allclose(idim_ls(None, q, f, fs_hz=1.0 / np.median(np.diff(t))).values, ref.values, rtol=1e-6)


def test_regressor_rows_and_bad_inputs():
    qd = np.array([-2.0, 0.0, 3.0])
    qdd = np.array([1.0, 2.0, 3.0])
    W, names = idim_regressor(qd, qdd)
    np.testing.assert_array_equal(W, [[1, -2, -1, 1], [2, 0, 0, 1], [3, 3, 1, 1]])
    Wa, names_a = idim_regressor(qd, qdd, "asymmetric")
    np.testing.assert_array_equal(Wa, [[1, 0, 0, -2, -1], [2, 0, 0, 0, 0], [3, 3, 1, 0, 0]])
    assert names_a == ("M", "Fv+", "Fc+", "Fv-", "Fc-")
    rng = np.random.default_rng(3)
    t = np.arange(2000) / 1000.0
    q = np.sin(2 * np.pi * t) + 1e-6 * rng.normal(size=t.size)
    f = rng.normal(size=t.size)
    with pytest.raises(InputError, match="model"):
        idim_regressor(qd, qdd, "stribeck")
    with pytest.raises(InputError, match="same length"):
        idim_observation(t, q, f[:-1])
    with pytest.raises(InputError, match="uniform sampling"):
        idim_observation(np.r_[t[:1000], t[1000:] + 0.5], q, f)
    with pytest.raises(InputError, match="more than 2 x border"):
        idim_observation(t[:300], q[:300], f[:300])
    with pytest.raises(InputError, match="NaN"):
        idim_observation(t, np.where(t > 1, np.nan, q), f)
    with pytest.raises(InputError, match="decimate"):
        idim_observation(t, q, f, decimate=0)
    with pytest.raises(InputError, match="the sample times"):
        idim_observation(None, q, f)
