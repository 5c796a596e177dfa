"""Cramér-Rao bounds of the hinge against a brute-force Fisher matrix and closed forms (methods.md)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocapfj.errors import InputError
from mocapfj.joints.crlb import angle_crlb, angle_crlb_cov, hinge_crlb, tangent_basis
from mocapfj.rotations import rotate

SIGMA = 0.5e-3


def coplanar(radii, phi_deg, R=np.eye(3)):
    """Template (P, 3) in the plane normal to R[:, 2] through the point."""
    r, phi = np.asarray(radii, float), np.radians(phi_deg)
    return np.stack([r * np.cos(phi), r * np.sin(phi), 0 * r], 1) @ R.T


def full_circle(n_frames):
    return np.linspace(0, 2 * np.pi, n_frames, endpoint=False)


def test_matches_brute_force_fisher_matrix():
    """Dense finite-difference Jacobian over every parameter, gauge fixed by holding q_0."""
    rng = np.random.default_rng(0)
    n = np.array([0.2, 0.3, 0.9]) / np.linalg.norm([0.2, 0.3, 0.9])
    E = tangent_basis(n)
    P, N = 3, 25
    a = 0.1 * rng.normal(size=(P, 3))
    q = np.linspace(-0.6, 0.9, N)
    w = np.array([1.0, 4.0, 0.5])
    mask = rng.random((N, P)) > 0.2
    mask[0] = True

    def model(th):
        nn = n + E @ th[:2]
        nn /= np.linalg.norm(nn)
        qq = np.concatenate([[q[0]], th[4 + 3 * P:]])
        return E @ th[2:4] + rotate(nn, qq[:, None], th[4:4 + 3 * P].reshape(P, 3)[None])

    th0 = np.concatenate([np.zeros(4), a.ravel(), q[1:]])
    J = np.empty((N, P, 3, th0.size))
    for k in range(th0.size):
        d = np.zeros_like(th0)
        d[k] = 1e-7
        J[..., k] = (model(th0 + d) - model(th0 - d)) / 2e-7
    Jw = J * np.sqrt(w * mask)[:, :, None, None]
    cov = SIGMA**2 * np.linalg.inv(np.einsum("ipkg,ipkh->gh", Jw, Jw))[:4, :4]
    cr = hinge_crlb(n, np.zeros(3), a, q, SIGMA, weights=w, mask=mask)
    np.testing.assert_allclose(cr.cov, cov, rtol=1e-6, atol=1e-6 * np.abs(cov).max())
    np.testing.assert_allclose(cr.cov_axis, E @ cov[:2, :2] @ E.T, atol=1e-6 * np.abs(cov).max())
    assert np.abs(cr.cov_point @ n).max() < 1e-20


def test_full_circle_closed_forms():
    N, R = 180, Rotation.from_rotvec([0.4, 1.0, -0.3]).as_matrix()
    n = R[:, 2]
    # any coplanar markers: tilt SD sigma sqrt(2 / (N sum r^2)) per direction (methods.md)
    radii = np.array([0.08, 0.10, 0.12, 0.14])
    cr = hinge_crlb(n, np.ones(3), coplanar(radii, [-20, -7, 7, 20], R), full_circle(N), SIGMA)
    np.testing.assert_allclose(np.sqrt(np.linalg.eigvalsh(cr.cov[:2, :2])),
                               SIGMA * np.sqrt(2 / (N * (radii**2).sum())), rtol=1e-9)
    # equal radii on one ray: in-plane centre sigma sqrt(2 / (N P)) per coordinate (methods.md)
    cr = hinge_crlb(n, np.ones(3), coplanar([0.1] * 4, [30] * 4, R), full_circle(N), SIGMA)
    np.testing.assert_allclose(np.sqrt(np.linalg.eigvalsh(cr.cov[2:, 2:])),
                               SIGMA * np.sqrt(2 / (N * 4)), rtol=1e-9)
    # general coplanar markers (derived here: eliminating the angle of each frame removes
    # |sum_p a_p|^2 / (2 sum r^2) of the P markers' in-plane information N / sigma^2):
    # centre SD sigma / sqrt(N (P - |sum a_p|^2 / (2 sum r_p^2)))
    for phi in ([-20, -7, 7, 20], [0, 90, 180, 270], [0, 0, 0, 0]):
        a = coplanar(radii, phi, R)
        cr = hinge_crlb(n, np.ones(3), a, full_circle(N), SIGMA)
        p_eff = 4 - (a.sum(0) @ a.sum(0)) / (2 * (radii**2).sum())
        np.testing.assert_allclose(np.sqrt(np.linalg.eigvalsh(cr.cov[2:, 2:])),
                                   SIGMA / np.sqrt(N * p_eff), rtol=1e-9)
        assert abs(cr.cov[:2, 2:]).max() < 1e-12 * abs(cr.cov).max()      # decoupled


def test_partial_arcs_are_worse():
    # methods.md table (CRLB SD, mm): 0.43, 0.19, 0.087, 0.0245 at 20, 45, 90, 360 deg;
    # this cluster (40 deg spread, +-20 mm along the axis): 0.55, 0.24, 0.11, 0.024
    a = coplanar([0.08, 0.10, 0.12, 0.14], [-20, -7, 7, 20])
    a[:, 2] = [0.01, -0.01, 0.02, -0.02]
    sds = []
    for rom in (20, 45, 90):
        q = np.radians(np.linspace(-rom / 2, rom / 2, 200))
        sds.append(hinge_crlb([0, 0, 1], np.zeros(3), a, q, SIGMA).sd_point_max)
    sds.append(hinge_crlb([0, 0, 1], np.zeros(3), a, full_circle(200), SIGMA).sd_point_max)
    np.testing.assert_allclose(np.array(sds) * 1e3, [0.55, 0.238, 0.109, 0.0238], rtol=0.02)
    assert sds[0] > 20 * sds[3]


def test_invariances_and_point_height():
    rng = np.random.default_rng(1)
    n = np.array([0.0, 0.0, 1.0])
    a = 0.1 * rng.normal(size=(4, 3))
    q = np.radians(np.linspace(-30, 40, 150))
    cr = hinge_crlb(n, np.zeros(3), a, q, SIGMA)
    eig = lambda C: np.linalg.eigvalsh(C)[-2:]
    # rigid motion of the scene
    R = Rotation.from_rotvec([1.0, -2.0, 0.5]).as_matrix()
    cr_r = hinge_crlb(R @ n, R @ np.ones(3), a @ R.T, q, SIGMA)
    np.testing.assert_allclose(cr_r.cov_point, R @ cr.cov_point @ R.T, atol=1e-9 * cr.cov_point.max())
    np.testing.assert_allclose(cr_r.cov_axis, R @ cr.cov_axis @ R.T, atol=1e-9 * cr.cov_axis.max())
    # angle gauge: shift every angle, rotate the template back
    cr_g = hinge_crlb(n, np.zeros(3), rotate(n, -0.7, a), q + 0.7, SIGMA)
    np.testing.assert_allclose(cr_g.cov, cr.cov, rtol=1e-8, atol=1e-8 * abs(cr.cov).max())
    # units: millimetres
    cr_mm = hinge_crlb(n, np.zeros(3), 1e3 * a, q, 1e3 * SIGMA)
    np.testing.assert_allclose(eig(cr_mm.cov_point), 1e6 * eig(cr.cov_point), rtol=1e-8)
    np.testing.assert_allclose(eig(cr_mm.cov_axis), eig(cr.cov_axis), rtol=1e-8)
    # centre at height h on the axis is c + h * tilt: cov_h = C_cc + h (C_ct + C_tc) + h^2 C_tt
    h = 0.05
    cr_h = hinge_crlb(n, h * n, a - h * n, q, SIGMA)
    C = cr.cov
    expect = C[2:, 2:] + h * (C[2:, :2] + C[:2, 2:]) + h**2 * C[:2, :2]
    np.testing.assert_allclose(cr_h.cov[2:, 2:], expect, rtol=1e-7)
    np.testing.assert_allclose(cr_h.cov[:2, :2], C[:2, :2], rtol=1e-7)


def test_angle_crlb_against_monte_carlo():
    rng = np.random.default_rng(2)
    n, radii = np.array([0.0, 0.0, 1.0]), np.array([0.08, 0.10, 0.12, 0.14])
    a = coplanar(radii, [-20, -7, 7, 20])
    a[:, 2] = [0.01, -0.01, 0.02, -0.02]
    q = rng.uniform(-np.pi, np.pi, 4000)
    y = rotate(n, q[:, None], a[None])
    bound = angle_crlb(radii, SIGMA)
    assert bound == pytest.approx(SIGMA / np.sqrt(0.0504))
    # isotropic: the closed-form angle of methods.md (true geometry) reaches the bound
    v = y + SIGMA * rng.standard_normal(y.shape)
    S = np.einsum("ipk,pk->i", v, np.cross(n, a))
    C = np.einsum("ipk,pk->i", v, a - np.outer(a @ n, n))
    err = np.angle(np.exp(1j * (np.arctan2(S, C) - q)))
    assert abs(err.std() / bound - 1) < 0.03                      # measured 1.00
    assert angle_crlb_cov(n, np.zeros(3), y[:3], SIGMA**2 * np.eye(3)) == pytest.approx(bound)
    assert angle_crlb(np.r_[radii, np.nan], SIGMA) == bound     # a missing marker adds nothing
    # per-marker covariances: weighted Gauss-Newton per frame reaches 1 / sqrt(sum t^T Sigma^-1 t)
    L = rng.normal(size=(4, 3, 3)) * 0.6e-3
    cov = L @ np.swapaxes(L, 1, 2) + 1e-8 * np.eye(3)
    v = y + np.einsum("pkl,ipl->ipk", np.linalg.cholesky(cov), rng.standard_normal(y.shape))
    Si = np.linalg.inv(cov)
    qh = q.copy()
    for _ in range(6):
        t = np.cross(n, rotate(n, qh[:, None], a[None]))
        r = v - rotate(n, qh[:, None], a[None])
        Sit = np.einsum("pkl,ipl->ipk", Si, t)
        qh = qh + (Sit * r).sum((1, 2)) / (Sit * t).sum((1, 2))
    sd = angle_crlb_cov(n, np.zeros(3), y, cov)
    assert sd.shape == (4000,)
    assert abs(np.sqrt(np.mean(((qh - q) / sd) ** 2)) - 1) < 0.03
    missing = y[:1].copy()
    missing[0, :] = np.nan
    assert np.isinf(angle_crlb_cov(n, np.zeros(3), missing, cov))[0]


@pytest.mark.parametrize("kw, field", [
    (dict(axis=[0, 1]), "axis"),
    (dict(template=np.zeros(3)), "template"),
    (dict(q=[0.0, np.nan]), "q"),
    (dict(weights=[1, 0]), "weights"),
    (dict(mask=np.ones((3, 2), bool)), "mask"),
    (dict(sigma=0.0), "sigma"),
])
def test_hinge_crlb_rejects_bad_input(kw, field):
    args = dict(axis=[0, 0, 1], point=np.zeros(3), template=coplanar([0.1, 0.2], [0, 40]),
                q=np.linspace(0, 1, 10), sigma=SIGMA)
    args.update(kw)
    with pytest.raises(InputError, match=field):
        hinge_crlb(**args)
