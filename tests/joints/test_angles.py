"""Per-frame link angles (mocapfj.joints.angles) against least squares, the Cramér-Rao bound and
the hinge model's truth (Lightcap and Banks (2007), eq. 13; shared/notes/methods.md)."""

from __future__ import annotations


import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.stats import chi2, norm

from mocapfj.errors import InputError
from mocapfj.joints.angles import joint_angles, outlier_threshold, predict_markers
from mocapfj.rotations import matrix_from_axis_angle as rotate
from mocapfj.types import JointGeometry

SIGMA = 0.5e-3  # m


def make_geometry(rng, P=4, sigma=SIGMA, r_range=(0.08, 0.14)) -> JointGeometry:
    """A random hinge: unit axis, point, and P markers at radii r_range (m) with axial offsets."""
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    e1 = np.cross(n, rng.normal(size=3))
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    r = rng.uniform(*r_range, P)
    phi = rng.uniform(0, 2 * np.pi, P)
    h = rng.uniform(-0.05, 0.05, P)
    template = (r * np.cos(phi))[:, None] * e1 + (r * np.sin(phi))[:, None] * e2 + h[:, None] * n
    return JointGeometry(axis=n, point=rng.uniform(-1, 1, 3), template=template,
                         labels=tuple(f"m{p}" for p in range(P)), radii=r, radius_rms=np.zeros(P),
                         marker_rms=sigma, cov_axis=np.zeros((3, 3)), cov_point=np.zeros((3, 3)),
                         sigma_m=sigma, method="ml", n_frames=0)


def wrap(x):
    return np.angle(np.exp(1j * x))


def crlb(geo, sigma=SIGMA, w=None):
    w = np.ones(len(geo.labels)) if w is None else w
    return sigma / np.sqrt(np.sum(w * geo.radii**2))


def test_closed_form_equals_least_squares_minimiser():
    """The closed form is the minimiser of Lightcap and Banks (2007), eq. (13), weighted and not (methods.md: 6e-9)."""
    rng = np.random.default_rng(0)
    worst = 0.0
    for P in (2, 3, 4, 6):
        geo = make_geometry(rng, P)
        q_true = rng.uniform(-np.pi, np.pi, 15)
        v = predict_markers(geo, q_true) + rng.normal(scale=2e-3, size=(15, P, 3))
        for w in (None, rng.uniform(0.2, 3.0, P)):
            res = joint_angles(v, geo, weights=w, outlier_sigma=None)
            sw = np.sqrt(np.ones(P) if w is None else w)[:, None]
            for i in range(15):
                def cost(q, i=i):
                    return ((v[i] - predict_markers(geo, q)[0]) * sw).ravel()
                ls = least_squares(cost, [q_true[i]], method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
                worst = max(worst, abs(wrap(res.q[i] - ls.x[0])))
    print(f"max |closed form - least_squares| = {worst:.2e} rad")
    assert worst < 1e-8


def test_monte_carlo_sd_and_bias_match_crlb():
    """Known geometry, isotropic noise: SD = sigma / sqrt(sum r_p^2) within 2 %, bias < 1 % of it."""
    rng = np.random.default_rng(1)
    geo = make_geometry(rng)
    N = 200_000  # SE of the SD 0.16 %, of the mean 0.22 % of the bound
    q_true = np.cumsum(rng.normal(scale=0.02, size=N))
    v = predict_markers(geo, q_true) + rng.normal(scale=SIGMA, size=(N, 4, 3))
    res = joint_angles(v, geo)
    err = wrap(res.q - q_true)
    bound = crlb(geo)
    sd, bias = err.std(), err.mean()
    print(f"SD {np.degrees(sd):.5f} deg, bound {np.degrees(bound):.5f} deg (ratio {sd / bound:.4f}), "
          f"bias {bias / bound * 100:.3f} % of bound, rejected {res.n_rejected.sum()} of {4 * N}")
    kept = res.n_rejected == 0
    assert np.allclose(res.sigma_q[kept], bound, rtol=1e-12) and np.all(res.sigma_q[~kept] > bound)
    assert abs(sd / bound - 1) < 0.02
    assert abs(bias) < 0.01 * bound
    # residual per marker: E sum_p d_p^2 = (3P - 1) sigma^2 (one parameter fitted)
    ms = np.mean(res.marker_rms**2) / SIGMA**2
    assert abs(ms / (11 / 4) - 1) < 0.02, ms
    # the chi-square outlier test keeps its nominal false-alarm rate (about 6.3e-5 per marker)
    assert res.n_rejected.sum() < 3 * 6.3e-5 * 4 * N


def test_weighted_angle_matches_weighted_crlb():
    """Unequal marker noise: weights 1/sigma_p^2 reach I = sum w_p r_p^2; unweighted does not."""
    rng = np.random.default_rng(2)
    geo = make_geometry(rng)
    sig_p = np.array([0.25, 0.5, 1.0, 2.0]) * 1e-3
    N = 100_000
    q_true = np.cumsum(rng.normal(scale=0.02, size=N))
    v = predict_markers(geo, q_true) + rng.normal(size=(N, 4, 3)) * sig_p[:, None]
    w = (SIGMA / sig_p) ** 2
    res = joint_angles(v, geo, sigma=SIGMA, weights=w)
    sd, bound = wrap(res.q - q_true).std(), crlb(geo, SIGMA, w)
    r2 = geo.radii**2
    sd_u = wrap(joint_angles(v, geo, outlier_sigma=None).q - q_true).std()
    expect_u = np.sqrt(np.sum(r2 * sig_p**2)) / r2.sum()  # variance of the unweighted estimator
    print(f"weighted SD/CRLB {sd / bound:.4f}; unweighted SD {np.degrees(sd_u):.4f} deg "
          f"(predicted {np.degrees(expect_u):.4f}, CRLB {np.degrees(bound):.4f})")
    assert np.allclose(res.sigma_q[res.n_rejected == 0], bound, rtol=1e-12)
    assert abs(sd / bound - 1) < 0.02
    assert abs(sd_u / expect_u - 1) < 0.02 and sd_u > 1.3 * bound
    # per-frame weights (T, P) give the same answer as per-marker weights
    res2 = joint_angles(v[:1000], geo, sigma=SIGMA, weights=np.tile(w, (1000, 1)))
    assert np.array_equal(res2.q, res.q[:1000])


def test_gross_marker_error_is_rejected():
    """A 20 mm error on one marker in 10 % of the frames is rejected; angles stay within 4 sigma_q."""
    rng = np.random.default_rng(3)
    geo = make_geometry(rng)
    N = 5000
    q_true = np.cumsum(rng.normal(scale=0.02, size=N))
    v = predict_markers(geo, q_true) + rng.normal(scale=SIGMA, size=(N, 4, 3))
    bad = rng.random(N) < 0.1
    d = rng.normal(size=(N, 3))
    v[bad, 1] += 0.020 * d[bad] / np.linalg.norm(d[bad], axis=1)[:, None]
    res = joint_angles(v, geo)
    z = np.abs(wrap(res.q - q_true)) / res.sigma_q
    print(f"max |error| / sigma_q {z.max():.2f}; rejected on bad frames {res.n_rejected[bad].mean():.3f}, "
          f"on clean frames {res.n_rejected[~bad].sum()}")
    assert np.all(res.n_rejected[bad] == 1) and np.all(res.n_markers[bad] == 3)
    assert res.n_rejected[~bad].sum() <= 3
    assert z.max() < 4.0
    without = joint_angles(v, geo, outlier_sigma=None)
    assert (np.abs(wrap(without.q - q_true)) / without.sigma_q).max() > 10  # the test has teeth


def test_too_few_markers_give_nan_and_are_counted():
    rng = np.random.default_rng(4)
    geo = make_geometry(rng)
    N = 1000
    q_true = np.linspace(0, 2, N)
    v = predict_markers(geo, q_true) + rng.normal(scale=SIGMA, size=(N, 4, 3))
    n_missing = rng.integers(0, 5, N)  # 0..4 markers missing
    for k in range(1, 5):
        rows = np.flatnonzero(n_missing == k)
        v[rows, :k, rng.integers(0, 3)] = np.nan  # one NaN coordinate is a missing marker
    res = joint_angles(v, geo)
    few = n_missing >= 3
    assert np.all(np.isnan(res.q[few])) and np.all(np.isnan(res.sigma_q[few]))
    assert np.all(np.isnan(res.marker_rms[few]))
    assert res.n_invalid == few.sum()
    assert np.array_equal(res.n_markers + res.n_rejected, 4 - n_missing)
    two = np.flatnonzero(n_missing == 2)
    assert np.allclose(res.sigma_q[two], SIGMA / np.sqrt(np.sum(geo.radii[2:] ** 2)))
    assert np.all(np.abs(res.q[~few] - q_true[~few]) < 5 * res.sigma_q[~few])
    one = joint_angles(v, geo, min_markers=1)
    assert one.n_invalid == (n_missing == 4).sum()


def test_unwrap_over_several_turns_and_seed_alignment():
    rng = np.random.default_rng(5)
    geo = make_geometry(rng)
    N = 3000
    q_true = 4 * np.pi + 0.3 + 5 * np.pi * (1 - np.cos(np.linspace(0, 2 * np.pi, N)))  # 5 turns out, back
    v = predict_markers(geo, q_true) + rng.normal(scale=SIGMA, size=(N, 4, 3))
    v[100:140] = np.nan  # a gap of 40 frames
    res = joint_angles(v, geo)
    ok = ~np.isnan(res.q)
    shift = res.q[ok] - q_true[ok]
    assert -np.pi < res.q[ok][0] <= np.pi
    assert np.ptp(shift) < 10 * res.sigma_q[ok].max()  # one 2 pi offset over all frames: no slips
    assert abs(shift.mean() + 4 * np.pi) < 1e-3
    seeded = joint_angles(v, geo, q_seed=q_true[0] + 0.5)  # e.g. the first motor angle
    assert np.abs(seeded.q[ok] - q_true[ok]).max() < 5 * seeded.sigma_q[ok].max()
    motor = q_true + 0.2 * np.sin(np.arange(N))  # a motor angle that leads and lags the link
    seeded = joint_angles(v, geo, q_seed=motor)
    assert np.abs(seeded.q[ok] - q_true[ok]).max() < 5 * seeded.sigma_q[ok].max()


def test_invariant_to_rigid_motion_and_relabelling():
    rng = np.random.default_rng(6)
    geo = make_geometry(rng, P=5)
    q_true = rng.uniform(-3, 3, 200)
    v = predict_markers(geo, q_true) + rng.normal(scale=SIGMA, size=(200, 5, 3))
    base = joint_angles(v, geo, outlier_sigma=None, q_seed=0.0)
    R = Rotation.random(random_state=7).as_matrix()
    tr = np.array([1.0, -2.0, 0.5])
    moved = JointGeometry(axis=R @ geo.axis, point=R @ geo.point + tr, template=geo.template @ R.T,
                          labels=geo.labels, radii=geo.radii, radius_rms=geo.radius_rms, marker_rms=0.0,
                          cov_axis=geo.cov_axis, cov_point=geo.cov_point, sigma_m=SIGMA, method="ml",
                          n_frames=0)
    res = joint_angles(v @ R.T + tr, moved, outlier_sigma=None, q_seed=0.0)
    assert np.abs(res.q - base.q).max() < 1e-12
    perm = rng.permutation(5)
    relabelled = JointGeometry(axis=geo.axis, point=geo.point, template=geo.template[perm],
                               labels=tuple(np.array(geo.labels)[perm]), radii=geo.radii[perm],
                               radius_rms=geo.radius_rms, marker_rms=0.0, cov_axis=geo.cov_axis,
                               cov_point=geo.cov_point, sigma_m=SIGMA, method="ml", n_frames=0)
    res = joint_angles(v[:, perm], relabelled, outlier_sigma=None, q_seed=0.0)
    assert np.abs(res.q - base.q).max() < 1e-12 and np.allclose(res.marker_rms, base.marker_rms)


def test_noise_free_data_are_exact():
    rng = np.random.default_rng(8)
    geo = make_geometry(rng)
    q_true = np.linspace(-3, 3, 500)
    res = joint_angles(predict_markers(geo, q_true), geo, t=np.arange(500) / 250.0)
    assert np.abs(res.q - q_true).max() < 1e-12 and res.marker_rms.max() < 1e-9
    assert np.array_equal(res.t, np.arange(500) / 250.0) and res.n_rejected.sum() == 0


def test_rotate_and_predict_markers():
    rng = np.random.default_rng(9)
    axes = rng.normal(size=(50, 3))
    q = rng.uniform(-4, 4, 50)
    unit = axes / np.linalg.norm(axes, axis=1)[:, None]
    expect = Rotation.from_rotvec(unit * q[:, None]).as_matrix()
    assert np.abs(rotate(axes, q) - expect).max() < 1e-14
    assert rotate(unit[0], 0.3).shape == (3, 3) and rotate(unit[0], q).shape == (50, 3, 3)
    geo = make_geometry(rng)
    pred = predict_markers(geo, q)
    direct = geo.point + np.einsum("tij,pj->tpi", rotate(geo.axis, q), geo.template)
    assert np.abs(pred - direct).max() < 1e-14
    # chi-square, 3 dof, with the false-alarm rate of a two-sided 4-sigma test (6.3e-5)
    assert abs(outlier_threshold(4.0) - chi2.isf(2 * norm.sf(4.0), 3)) < 1e-9


def test_degenerate_input_raises():
    rng = np.random.default_rng(10)
    geo = make_geometry(rng)
    v = predict_markers(geo, np.zeros(10))
    with pytest.raises(InputError, match="valid markers"):
        joint_angles(np.full((10, 4, 3), np.nan), geo)
    with pytest.raises(InputError, match=r"shape \(T, 4, 3\)"):
        joint_angles(v[:, :3], geo)
    with pytest.raises(InputError, match="off the joint axis"):
        on_axis = JointGeometry(axis=geo.axis, point=geo.point, template=np.outer([0.1, 0.2], geo.axis),
                                labels=("a", "b"), radii=np.zeros(2), radius_rms=np.zeros(2), marker_rms=0.0,
                                cov_axis=geo.cov_axis, cov_point=geo.cov_point, sigma_m=SIGMA, method="ml",
                                n_frames=0)
        joint_angles(v[:, :2], on_axis)
    with pytest.raises(InputError, match="pass sigma="):
        joint_angles(v, geo, sigma=float("nan"))
    with pytest.raises(InputError, match="weights"):
        joint_angles(v, geo, weights=[1, 1, -1, 1])
    with pytest.raises(InputError, match="parent frame"):
        joint_angles(v + 0.05, geo)  # every marker 50 mm off: all frames rejected
