"""Axis and centre fits against analytic truth and the Cramér-Rao bound (methods.md, "Axis and centre").

Design of the Monte Carlo (methods.md's table): sigma 0.5 mm, 4 markers at r 80-140 mm spread
over 40 deg around the axis and +-20 mm along it, N = 200 frames evenly over the range of motion.
Biases are measured with antithetic pairs (noise e and -e): the first-order error cancels in the
pair mean, so 40 pairs pin the O(sigma^2) bias to ~0.005 mm, far below the 0.1 x CRLB-SD limit.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mocapfj.errors import InputError
from mocapfj.joints.axis import fit_gamage_lasenby, fit_halvorsen, fit_hinge_ml
from mocapfj.joints.crlb import hinge_crlb
from mocapfj.rotations import rotate

SIGMA = 0.5e-3
R_WORLD_HINGE = Rotation.from_rotvec([0.3, -0.5, 0.8]).as_matrix()
AXIS = R_WORLD_HINGE[:, 2]
C_WORLD = np.array([0.4, -0.2, 1.1])


def template(radii=(0.08, 0.10, 0.12, 0.14), phi_deg=(-20, -7, 7, 20), h=(0.01, -0.01, 0.02, -0.02)):
    r, phi = np.asarray(radii), np.radians(phi_deg)
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.asarray(h, float)], 1) @ R_WORLD_HINGE.T


def design(rom_deg, n_frames=200):
    if rom_deg >= 360:
        return np.linspace(0.0, 2 * np.pi, n_frames, endpoint=False)
    return np.radians(np.linspace(-rom_deg / 2, rom_deg / 2, n_frames))


def truth(rom_deg, tmpl=None, n_frames=200):
    """Noise-free markers (N, P, 3), angles, template, the reported point (foot of the centroid)
    and the CRLB of the in-plane centre at that point."""
    tmpl = template() if tmpl is None else tmpl
    q = design(rom_deg, n_frames)
    y = C_WORLD + rotate(AXIS, q[:, None], tmpl[None])
    foot = C_WORLD + ((y.mean((0, 1)) - C_WORLD) @ AXIS) * AXIS
    return y, q, tmpl, foot, hinge_crlb(AXIS, foot, tmpl - (foot - C_WORLD), q, SIGMA)


def errors(g, foot, E):
    """In-plane point error (2,) m and axis tilt (2,) rad in the CRLB basis."""
    return (g.point - foot) @ E, (g.axis * np.sign(g.axis @ AXIS)) @ E


def fit(name, v, **kw):
    if name == "ml":
        return fit_hinge_ml(v, **kw)[0]
    return {"gl": fit_gamage_lasenby, "halvorsen": fit_halvorsen}[name](v, n_boot=0, **kw)


# ------------------------------------------------------------------ noise-free truth
@pytest.mark.parametrize("name", ["gl", "halvorsen", "ml"])
@pytest.mark.parametrize("rom, n_markers, dropout", [(20, 4, 0.0), (90, 3, 0.2), (360, 2, 0.1)])
def test_noise_free_recovery(name, rom, n_markers, dropout):
    y, q, tmpl, foot, _ = truth(rom, template()[:n_markers] if n_markers < 4 else None)
    v = y.copy()
    drop = np.random.default_rng(rom).random(v.shape[:2]) < dropout
    drop[0] = False
    v[drop] = np.nan
    g = fit_hinge_ml(v)[0] if name == "ml" else fit(name, v)
    assert np.linalg.norm(np.cross(g.axis, AXIS)) < 1e-9
    assert np.linalg.norm(np.cross(g.point - C_WORLD, AXIS)) < 1e-9          # on the true axis
    assert np.linalg.norm(g.point - foot) < 1e-9
    r_true = np.linalg.norm(tmpl - np.outer(tmpl @ AXIS, AXIS), axis=1)
    np.testing.assert_allclose(g.radii, r_true, atol=1e-9)
    assert g.marker_rms < 1e-9 and np.all(g.radius_rms < 1e-9)
    # the template at q = 0 is the first frame, seen from the reported point
    sign = np.sign(g.axis @ AXIS)
    np.testing.assert_allclose(g.template, y[0] - g.point, atol=1e-9)
    if name == "ml":
        _, q_fit = fit_hinge_ml(v)
        seen = ~np.all(drop[:, :n_markers], axis=1)
        assert np.array_equal(np.isfinite(q_fit), seen)
        np.testing.assert_allclose(sign * q_fit[seen], (q - q[0])[seen], atol=1e-9)


# ------------------------------------------------------------------ bias (methods.md table)
def antithetic(name, rom, sigma=SIGMA, pairs=40, seed=0):
    """Pair-mean error (bias samples, (pairs, 2) m) and half-difference (first-order error)."""
    y, _, _, foot, cr = truth(rom)
    rng = np.random.default_rng(seed)
    pm, hd = [], []
    for _ in range(pairs):
        e = sigma * rng.standard_normal(y.shape)
        a, b = errors(fit(name, y + e), foot, cr.basis)[0], errors(fit(name, y - e), foot, cr.basis)[0]
        pm.append((a + b) / 2)
        hd.append((a - b) / 2)
    return np.array(pm), np.array(hd), cr


@pytest.mark.parametrize("rom", [20, 45, 90, 360])
@pytest.mark.parametrize("name", ["halvorsen", "ml"])
def test_centre_bias_below_tenth_of_crlb(name, rom):
    # measured (|bias| / CRLB SD): halvorsen 20 deg 0.001, 45 deg 0.004; ml 20 deg 0.002, 45 deg 0.001
    pm, _, cr = antithetic(name, rom)
    bias = np.linalg.norm(pm.mean(0))
    se = np.sqrt(np.trace(np.cov(pm.T)) / len(pm))
    assert se < 0.03 * cr.sd_point_max                 # the measurement resolves the limit
    assert bias < 0.1 * cr.sd_point_max, (bias, cr.sd_point_max)


def test_centre_bias_at_noise_one_percent_of_radius():
    sigma = 0.01 * 0.08                                 # sigma / r_min = 0.01
    for name in ("halvorsen", "ml"):
        pm, _, cr = antithetic(name, 20, sigma=sigma, pairs=30, seed=1)
        assert np.linalg.norm(pm.mean(0)) < 0.1 * cr.sd_point_max * sigma / SIGMA


def test_gamage_lasenby_centre_bias_fails_at_20_deg():
    # measured: bias 1.56 mm, SD 0.47 mm (3.3 SD) at 20 deg; 0.29 mm at 45 deg; ~0 at 360 deg
    pm, hd, cr = antithetic("gl", 20)
    bias, sd = np.linalg.norm(pm.mean(0)), np.sqrt(np.linalg.eigvalsh(hd.T @ hd / len(hd))[-1])
    assert bias > 3 * sd and bias > 30 * 0.1 * cr.sd_point_max
    biases = [np.linalg.norm(antithetic("gl", rom, pairs=5)[0].mean(0)) for rom in (45, 90, 360)]
    assert bias > biases[0] > biases[1] > 10 * biases[2]
    assert biases[2] < 0.01 * truth(360)[4].sd_point_max


# ------------------------------------------------------------------ efficiency and reported covariance
@pytest.mark.parametrize("rom", [20, 360])
def test_ml_reaches_crlb_and_reports_its_covariance(rom):
    # measured at 20 deg: centre SD 1.03 x CRLB, axis SD 1.02-1.06 x CRLB; sigma_m 0.999 sigma
    y, _, _, foot, cr = truth(rom)
    rng = np.random.default_rng(7)
    ep, ea, cp, ca, sm = [], [], [], [], []
    for _ in range(400):
        g = fit_hinge_ml(y + SIGMA * rng.standard_normal(y.shape))[0]
        p, a = errors(g, foot, cr.basis)
        ep.append(p), ea.append(a), sm.append(g.sigma_m)
        cp.append(cr.basis.T @ g.cov_point @ cr.basis), ca.append(cr.basis.T @ g.cov_axis @ cr.basis)
    ep, ea = np.array(ep), np.array(ea)
    sd_p = np.sqrt(np.linalg.eigvalsh(np.cov(ep.T))[-1])
    sd_a = np.sqrt(np.linalg.eigvalsh(np.cov(ea.T))[-1])
    assert 0.9 < sd_p / cr.sd_point_max < 1.1
    assert 0.9 < sd_a / cr.sd_axis_max < 1.1
    assert abs(np.mean(sm) / SIGMA - 1) < 0.01
    for err, rep in ((ep, np.mean(cp, 0)), (ea, np.mean(ca, 0))):
        w, V = np.linalg.eigh(rep)                       # SD along the reported principal axes
        ratio = np.sqrt(np.var(err @ V, axis=0, ddof=1) / w)
        assert np.all(np.abs(ratio - 1) < 0.15), ratio


def test_halvorsen_bootstrap_covariance_matches_monte_carlo():
    # measured: bootstrap / Monte Carlo mean-square error 0.99 and 1.00 (centre), 0.95 (axis)
    y, _, _, foot, cr = truth(20)
    rng = np.random.default_rng(3)
    ep = np.array([errors(fit("halvorsen", y + SIGMA * rng.standard_normal(y.shape)), foot, cr.basis)[0]
                   for _ in range(300)])
    g = fit_halvorsen(y + SIGMA * rng.standard_normal(y.shape))
    rep = cr.basis.T @ g.cov_point @ cr.basis
    w, V = np.linalg.eigh(rep)
    ratio = np.sqrt(np.mean((ep @ V) ** 2, axis=0) / w)
    assert np.all(np.abs(ratio - 1) < 0.2), ratio
    assert np.linalg.matrix_rank(g.cov_point, tol=1e-12) == 2 and abs(g.cov_point @ g.axis).max() < 1e-15


def test_gamage_lasenby_reports_its_bias_in_cov_point():
    y, _, _, foot, cr = truth(20)
    g = fit_gamage_lasenby(y + SIGMA * np.random.default_rng(4).standard_normal(y.shape))
    rms = np.sqrt(np.trace(g.cov_point))
    assert rms > 2 * np.sqrt(np.trace(cr.cov_point))
    assert np.linalg.norm(np.cross(g.point - foot, g.axis)) < 3 * rms


def test_ml_weights_use_unequal_noise():
    sig_p = np.array([0.3, 0.3, 1.5, 1.5]) * 1e-3
    y, q, tmpl, foot, _ = truth(45)
    cr_w = hinge_crlb(AXIS, foot, tmpl - (foot - C_WORLD), q, 1.0, weights=1 / sig_p**2)
    rng = np.random.default_rng(5)
    ew, eu = [], []
    for _ in range(150):
        v = y + sig_p[:, None] * rng.standard_normal(y.shape)
        gw = fit_hinge_ml(v, weights=1 / sig_p**2)[0]
        ew.append(errors(gw, foot, cr_w.basis)[0]), eu.append(errors(fit("ml", v), foot, cr_w.basis)[0])
    sd_w = np.sqrt(np.linalg.eigvalsh(np.cov(np.array(ew).T))[-1])
    sd_u = np.sqrt(np.linalg.eigvalsh(np.cov(np.array(eu).T))[-1])
    assert 0.85 < sd_w / cr_w.sd_point_max < 1.15 and sd_w < 0.8 * sd_u
    # sigma_m is the SD of a marker of mean weight
    assert abs(gw.sigma_m / np.sqrt(np.mean(1 / sig_p**2) ** -1) - 1) < 0.1


# ------------------------------------------------------------------ missing data, invariance
def test_nan_dropouts_are_handled():
    y, q, tmpl, foot, _ = truth(45)
    rng = np.random.default_rng(6)
    v = y + SIGMA * rng.standard_normal(y.shape)
    v[rng.random(v.shape[:2]) < 0.2] = np.nan            # 20 % random dropouts
    v[50:90, 1] = np.nan                                  # a marker hidden for 40 frames
    v[120] = np.nan                                       # a frame with no marker
    v[7, 2, 1] = np.nan                                   # one coordinate missing
    v = np.concatenate([v, np.full((len(q), 1, 3), np.nan)], axis=1)   # a marker never seen
    mask = np.all(np.isfinite(v[:, :4]), axis=2)
    cr = hinge_crlb(AXIS, foot, tmpl - (foot - C_WORLD), q, SIGMA, mask=mask)
    labels = ("a", "b", "c", "d", "dead")
    for name in ("gl", "halvorsen", "ml"):
        g = fit(name, v, labels=labels)
        assert g.labels == ("a", "b", "c", "d") and g.n_frames == mask.any(axis=1).sum() < len(q)
        e_p, e_a = errors(g, foot, cr.basis)
        assert np.linalg.norm(e_p) < 5 * cr.sd_point_max + (2e-3 if name == "gl" else 0)
        assert np.linalg.norm(e_a) < 5 * cr.sd_axis_max
    g, q_fit = fit_hinge_ml(v, labels=labels)
    seen = mask.any(axis=1)
    assert np.array_equal(np.isfinite(q_fit), seen) and np.isnan(q_fit[120])
    r2 = (mask * g.radii**2).sum(1)                      # per-frame angle CRLB: sigma / sqrt(r2)
    err = (np.sign(g.axis @ AXIS) * q_fit - (q - q[0]))[seen]
    assert np.all(np.abs(err) < 5 * SIGMA / np.sqrt(r2[seen]) + 2e-3)


@settings(max_examples=8, deadline=None)
@given(rotvec=st.lists(st.floats(-3, 3), min_size=3, max_size=3),
       shift=st.lists(st.floats(-2, 2), min_size=3, max_size=3), perm_seed=st.integers(0, 100))
def test_ml_is_equivariant_under_rigid_motion_relabelling_and_units(rotvec, shift, perm_seed):
    y, *_ = truth(60, n_frames=80)
    v = y + SIGMA * np.random.default_rng(8).standard_normal(y.shape)
    g0, q0 = fit_hinge_ml(v)
    R, t = Rotation.from_rotvec(rotvec).as_matrix(), np.asarray(shift)
    perm = np.random.default_rng(perm_seed).permutation(4)
    g1, q1 = fit_hinge_ml(1e3 * (v[:, perm] @ R.T + t), labels=[f"m{p}" for p in perm])
    s = np.sign(g1.axis @ (R @ g0.axis))
    np.testing.assert_allclose(s * g1.axis, R @ g0.axis, atol=1e-8)
    np.testing.assert_allclose(g1.point, 1e3 * (R @ g0.point + t), atol=1e-5)
    np.testing.assert_allclose(s * q1, q0, atol=1e-8)
    np.testing.assert_allclose(g1.radii, 1e3 * g0.radii[perm], rtol=1e-8)
    np.testing.assert_allclose(g1.cov_point, 1e6 * R @ g0.cov_point @ R.T, atol=1e-8 * 1e6 * g0.cov_point.max())


def test_init_seed_gives_same_ml_fit():
    y, *_ = truth(45)
    v = y + SIGMA * np.random.default_rng(9).standard_normal(y.shape)
    g, q = fit_hinge_ml(v)
    g2, q2 = fit_hinge_ml(v, init=fit_gamage_lasenby(v, n_boot=0))
    np.testing.assert_allclose(g2.point, g.point, atol=1e-9)
    np.testing.assert_allclose(q2, q, atol=1e-9)


# ------------------------------------------------------------------ degenerate input
@pytest.mark.parametrize("fitter", [fit_gamage_lasenby, fit_halvorsen, lambda v, **k: fit_hinge_ml(v, **k)])
def test_degenerate_inputs_raise_with_reasons(fitter):
    y, *_ = truth(45)
    rng = np.random.default_rng(10)
    cases = [
        (y[:, :, :2], r"shape \(N frames, P markers, 3\)"),
        (y[0], r"shape \(N frames, P markers, 3\)"),
        (np.full_like(y, np.nan), "all NaN"),
        (y[:, :1], "a single marker"),
        (np.concatenate([y[:, :1], np.full_like(y[:, 1:], np.nan)], 1), "at least 2 markers seen"),
    ]
    for v, msg in cases:
        with pytest.raises(InputError, match=msg):
            fitter(v)
    with pytest.raises(InputError, match="unique marker labels"):
        fitter(y, labels=["a", "a", "b", "c"])
    small, *_ = truth(3)                                   # noise-free 3 deg
    with pytest.raises(InputError, match=r"at least 5 deg .* got 2\.9\d* deg .*move the joint further"):
        fitter(small)
    static = np.repeat(y[:1], 200, axis=0) + SIGMA * rng.standard_normal(y.shape)
    with pytest.raises(InputError, match="range of motion"):
        fitter(static)
    on_axis = template()[:3].copy()
    on_axis[:2] = on_axis[:2] @ np.outer(AXIS, AXIS)       # two markers on the axis
    with pytest.raises(InputError, match="at least 2 markers more than .* from the joint axis"):
        fitter(truth(90, on_axis)[0] + 1e-6 * rng.standard_normal(y.shape[:1] + (3, 3)))


def test_halvorsen_refuses_noise_that_swamps_the_arc():
    y, *_ = truth(6)
    v = y + 3e-3 * np.random.default_rng(11).standard_normal(y.shape)
    with pytest.raises(InputError, match="bias correction below half the signal"):
        fit_halvorsen(v, min_range_deg=0.0)
    with pytest.raises(InputError, match="weights"):
        fit_hinge_ml(y, weights=[1, 1, 0, 1])
