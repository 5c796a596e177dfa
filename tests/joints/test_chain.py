"""Per-frame angles of a kinematic chain (mocapfj.joints.chain) against Pinocchio and the CRLB."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from mocapfj import InputError
from mocapfj.joints.chain import ChainModel, solve_chain
from mocapfj.synth.markers import place_markers
from mocapfj.synth.robot_mesh import pa10_geometry
from mocapfj.synth.urdf import pa10_urdf

SIGMA = 2e-4  # m, 0.2 mm marker noise

_LIMIT = '<limit lower="-3" upper="3" effort="1" velocity="1"/>'
TREE_URDF = f"""<robot name="tree"><link name="world"/>
<joint name="a" type="revolute"><parent link="world"/><child link="l1"/>
  <origin xyz="0.1 -0.2 0.5" rpy="0.1 0.2 0.3"/><axis xyz="1 1 0"/>{_LIMIT}</joint><link name="l1"/>
<joint name="b" type="revolute"><parent link="l1"/><child link="l2"/>
  <origin xyz="0.3 0 0" rpy="0 0.4 0"/><axis xyz="0 1 0"/>{_LIMIT}</joint><link name="l2"/>
<joint name="c" type="revolute"><parent link="l2"/><child link="l3"/>
  <origin xyz="0.25 0.05 0"/><axis xyz="1 0 0"/>{_LIMIT}</joint><link name="l3"/>
<joint name="d" type="revolute"><parent link="l1"/><child link="l4"/>
  <origin xyz="0 0.2 0.1" rpy="-0.3 0 0.2"/><axis xyz="0 0 -1"/>{_LIMIT}</joint><link name="l4"/>
<joint name="fix" type="fixed"><parent link="l3"/><child link="tool"/>
  <origin xyz="0.1 0 0.05" rpy="0.5 0 0"/></joint><link name="tool"/>
</robot>"""
"""Axes x+y (unaligned), y, x and -z; joint d branches off l1; markers on `tool` ride a fixed joint."""


def _templates(layout, links):
    return {f"link{k}": ([layout.labels[i] for i in layout.cluster(k)], layout.p_link[layout.cluster(k)])
            for k in links}


def _build(urdf, templates, **kw):
    return ChainModel.from_urdf(urdf, templates, **kw), pin.buildModelFromXML(urdf), templates


@pytest.fixture(scope="module")
def layout():
    return place_markers(pa10_geometry(), np.random.default_rng(7), clusters={1: 3, 2: 4, 3: 3, 4: 4, 6: 3})


@pytest.fixture(scope="module")
def arm6(layout):
    """All six joints free; 17 markers on links 1, 2, 3, 4 and 6 (link 5 has no marker surface)."""
    return _build(pa10_urdf([1, 2, 3, 4, 5, 6], np.zeros(6)), _templates(layout, (1, 2, 3, 4, 6)))


@pytest.fixture(scope="module")
def arm2(layout):
    """Joints 2 and 4 free, the others braked at a pose; the braked link 1 carries no markers."""
    return _build(pa10_urdf([2, 4], [0.3, 0.0, -0.4, 0.0, 0.7, 0.2]), _templates(layout, (2, 3, 4, 6)))


@pytest.fixture(scope="module")
def tree():
    rng = np.random.default_rng(3)
    tm = {name: ([f"{name}_{i}" for i in range(3)], rng.uniform(-0.08, 0.08, (3, 3)) + [0.05, 0.04, 0.03])
          for name in ("l1", "l2", "tool", "l4")}
    return _build(TREE_URDF, tm)


def _pin_markers(pm, templates, q):
    """Marker positions (M, 3) and Jacobians dy/dq (M, 3, n) from Pinocchio: for a point of frame f,
    J = J_lin - [y - o_f]x J_ang with the LOCAL_WORLD_ALIGNED frame Jacobian [J_lin; J_ang]."""
    data = pm.createData()
    pin.computeJointJacobians(pm, data, q)
    pin.updateFramePlacements(pm, data)
    y, J = [], []
    for link, (_, pos) in templates.items():
        fid = pm.getFrameId(link)
        Jf = pin.getFrameJacobian(pm, data, fid, pin.LOCAL_WORLD_ALIGNED)
        for p in np.asarray(pos):
            d = data.oMf[fid].rotation @ p
            y.append(d + data.oMf[fid].translation)
            J.append(Jf[:3] - np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]]) @ Jf[3:])
    return np.array(y), np.array(J)


def _crlb(pm, templates, q, sigma, used=None):
    """Cramér-Rao SD of each angle for isotropic noise: sigma sqrt(diag(I^-1)), I = sum_p J_p^T J_p."""
    J = _pin_markers(pm, templates, q)[1]
    J = J if used is None else J[used]
    return sigma * np.sqrt(np.diag(np.linalg.inv(np.einsum("mai,maj->ij", J, J))))


def _smooth(rng, T, n, scale=1.0):
    """Smooth joint trajectories (T, n) rad starting near zero."""
    t = np.linspace(0.0, 1.0, T)[:, None]
    f, ph = rng.uniform(0.3, 1.0, n), rng.uniform(0, 2 * np.pi, n)
    return scale * (np.sin(2 * np.pi * f * t + ph) - np.sin(ph))


# --- forward kinematics against Pinocchio ---------------------------------------------------------

@pytest.mark.parametrize("name", ["arm6", "arm2", "tree"])
def test_forward_kinematics_matches_pinocchio(name, request):
    model, pm, tm = request.getfixturevalue(name)
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (8, pm.nq))
    R, t = model.joint_poses(q)
    y = model.marker_positions(q)
    data = pm.createData()
    for f in range(len(q)):
        pin.forwardKinematics(pm, data, q[f])
        pin.updateFramePlacements(pm, data)
        for j in range(model.n_joints):
            np.testing.assert_allclose(R[f, j], data.oMi[j + 1].rotation, rtol=0, atol=1e-12)
            np.testing.assert_allclose(t[f, j], data.oMi[j + 1].translation, rtol=0, atol=1e-12)
        np.testing.assert_allclose(y[f], _pin_markers(pm, tm, q[f])[0], rtol=0, atol=1e-12)
    assert model.joint_names == tuple(pm.names[1:])


# --- recovery, noise-free ------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["arm2", "arm6", "tree"])
def test_noise_free_random_angles_are_recovered(name, request):
    model, pm, _ = request.getfixturevalue(name)
    rng = np.random.default_rng(1)
    q_true = rng.uniform(-np.pi, np.pi, (300, pm.nq))
    v = model.marker_positions(q_true)
    res = solve_chain(model, v, q0=q_true + rng.normal(0, 0.2, q_true.shape), sigma=SIGMA)
    assert np.abs(res.q - q_true).max() < 1e-10
    assert res.converged.all() and res.n_invalid == 0 and res.n_rejected.sum() == 0
    assert res.marker_rms.max() < 1e-9  # residuals of the last evaluation, within tol of q
    assert (res.n_iter <= 10).all()


@pytest.mark.parametrize("name", ["arm2", "arm6"])
def test_without_seeds_blocks_follow_a_smooth_trajectory(name, request):
    model, pm, _ = request.getfixturevalue(name)
    rng = np.random.default_rng(2)
    q_true = _smooth(rng, 500, pm.nq, 1.5)                               # up to ~3 rad, ~0.02 rad per frame
    res = solve_chain(model, model.marker_positions(q_true), sigma=SIGMA)
    assert np.abs(res.q - q_true).max() < 1e-10 and res.converged.all()


# --- noise: Monte Carlo SD and the Cramér-Rao bound -------------------------------------------------

def test_monte_carlo_sd_matches_sigma_q_and_the_crlb(arm6):
    model, pm, tm = arm6
    rng = np.random.default_rng(11)
    q_true = np.array([0.4, -0.7, 1.1, 0.5, -0.9, 2.0])
    T = 2000                                                               # trials, solved as one batch
    v = model.marker_positions(np.tile(q_true, (T, 1))) + rng.normal(0, SIGMA, (T, len(model.labels), 3))
    res = solve_chain(model, v, q0=q_true + rng.normal(0, 0.01, (T, 6)), sigma=SIGMA)
    crlb = _crlb(pm, tm, q_true, SIGMA)
    sd = (res.q - q_true).std(axis=0)
    rel = sd / res.sigma_q.mean(axis=0) - 1.0
    print("MC SD / sigma_q - 1:", np.round(rel, 4), " sigma_q deg:", np.round(np.degrees(crlb), 4))
    assert np.all(np.abs(rel) < 0.10)
    # sigma_q is evaluated at each estimate (off the truth by ~sigma_q), the CRLB at the truth
    np.testing.assert_allclose(res.sigma_q, np.broadcast_to(crlb, res.sigma_q.shape), rtol=5e-3)
    np.testing.assert_allclose(np.abs((res.q - q_true).mean(axis=0)) / crlb, 0, atol=4 / np.sqrt(T))
    # the same frames with sigma estimated: the pooled inlier estimate and the same sigma_q
    est = solve_chain(model, v, q0=q_true + rng.normal(0, 0.01, (T, 6)))
    assert est.sigma_m == pytest.approx(SIGMA, rel=0.02)
    assert est.n_rejected.sum() <= 5                                       # chi2(3) tail at 4 SD: ~2 expected


def test_sigma_q_is_the_crlb_at_the_truth(arm6, tree):
    for model, pm, tm in (arm6, tree):
        rng = np.random.default_rng(4)
        q = rng.uniform(-np.pi, np.pi, (5, pm.nq))
        v = model.marker_positions(q)
        v[0, 2] = np.nan                                                   # a missing marker changes I
        res = solve_chain(model, v, q0=q, sigma=SIGMA, outlier_sigma=None)
        for f in range(5):
            np.testing.assert_allclose(res.sigma_q[f], _crlb(pm, tm, q[f], SIGMA, res.used[f]), rtol=1e-9)


def test_rigid_motion_of_the_world_leaves_the_angles(tree):
    model, _, tm = tree
    rng = np.random.default_rng(8)
    q = rng.uniform(-2, 2, (50, 4))
    T = np.eye(4)
    T[:3, :3] = pin.rpy.rpyToMatrix(0.3, -1.2, 2.0)
    T[:3, 3] = [1.0, -2.0, 0.5]
    moved = ChainModel.from_urdf(TREE_URDF, tm, T_world_root=T)
    v = model.marker_positions(q) @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(moved.marker_positions(q), v, atol=1e-12)
    res = solve_chain(moved, v, q0=q + 0.1, sigma=SIGMA)
    assert np.abs(res.q - q).max() < 1e-10


# --- outliers and missing markers ------------------------------------------------------------------

def test_gross_outliers_are_rejected(arm6):
    model, _, _ = arm6
    rng = np.random.default_rng(5)
    T, M = 1000, len(model.labels)
    q_true = rng.uniform(-np.pi, np.pi, (T, 6))
    v = model.marker_positions(q_true) + rng.normal(0, SIGMA, (T, M, 3))
    bad = rng.random(T) < 0.1
    which = rng.integers(0, M, T)
    kick = rng.normal(size=(T, 3))
    v[bad, which[bad]] += 0.02 * kick[bad] / np.linalg.norm(kick[bad], axis=1, keepdims=True)    # 20 mm
    q0 = q_true + rng.normal(0, 0.01, (T, 6))
    for sigma in (SIGMA, None):
        res = solve_chain(model, v, q0=q0, sigma=sigma)
        assert not res.used[bad, which[bad]].any()                        # every displaced marker dropped
        assert res.n_rejected[~bad].sum() <= 3                             # clean frames keep their markers
        z = np.abs(res.q - q_true) / res.sigma_q
        assert z.max() < 5.5
    plain = solve_chain(model, v, q0=q0, sigma=SIGMA, outlier_sigma=None)
    assert (np.abs(plain.q - q_true) / plain.sigma_q)[bad].max() > 20     # what the outliers did before


def test_missing_markers_and_undetermined_frames(arm6):
    model, _, _ = arm6
    rng = np.random.default_rng(6)
    T, M = 400, len(model.labels)
    q_true = rng.uniform(-np.pi, np.pi, (T, 6))
    v = model.marker_positions(q_true) + rng.normal(0, SIGMA, (T, M, 3))
    v[rng.random((T, M)) < 0.1] = np.nan                                   # 10 % occlusion
    link6 = np.array([s.startswith("L6_") for s in model.labels])
    v[:20, link6] = np.nan                                                 # joints 5, 6 move no marker
    v[20] = np.nan                                                         # an empty frame
    lone = np.flatnonzero(link6)
    v[21:30, lone[1:]] = np.nan                                            # one marker left on link 6
    v[21:30, lone[0]] = model.marker_positions(q_true[21:30])[:, lone[0]]
    res = solve_chain(model, v, q0=q_true + rng.normal(0, 0.01, (T, 6)), sigma=SIGMA)
    nan_rows = np.isnan(res.q).all(axis=1)
    assert np.isnan(res.q).any(axis=1).sum() == nan_rows.sum()            # whole rows only
    assert nan_rows[:21].all() and res.n_invalid >= 21
    assert res.n_invalid <= 21 + np.isnan(v).all(axis=2)[21:].sum()        # only starved frames fail
    ok = ~nan_rows
    assert np.abs((res.q - q_true)[ok] / res.sigma_q[ok]).max() < 5.5
    assert np.isnan(res.sigma_q[nan_rows]).all() and not res.converged[nan_rows].any()
    strict = solve_chain(model, v, q0=q_true, sigma=SIGMA, min_markers_per_link=2)
    assert np.isfinite(res.q[21:30]).all() and np.isnan(strict.q[21:30]).all()


# --- degenerate input ---------------------------------------------------------------------------

def test_degenerate_input_raises(arm6, layout):
    model, _, tm = arm6
    urdf = pa10_urdf([1, 2, 3, 4, 5, 6], np.zeros(6))
    T, M = 5, len(model.labels)
    v = model.marker_positions(np.zeros((T, 6)))
    cases = [
        (lambda: solve_chain(model, v[:, :-1]), "shape"),
        (lambda: solve_chain(model, np.full_like(v, np.nan)), "all NaN"),
        (lambda: solve_chain(model, v, q0=np.zeros(5)), "q0"),
        (lambda: solve_chain(model, v, q0=np.full((T, 6), np.nan)), "non-finite"),
        (lambda: solve_chain(model, v, sigma=0.0), "sigma"),
        (lambda: solve_chain(model, v, max_iter=0), "max_iter"),
        (lambda: solve_chain(model, np.where(np.arange(M)[None, :, None] < 2, v, np.nan)), "determine every joint"),
        (lambda: ChainModel.from_urdf(urdf, {}), "templates"),
        (lambda: ChainModel.from_urdf(urdf, {"link9": (["x"], np.ones((1, 3)))}), "link9"),
        (lambda: ChainModel.from_urdf(urdf, {"link2": (["a", "b"], np.ones((3, 3)))}), "shape"),
        (lambda: ChainModel.from_urdf(urdf, {"link2": tm["link2"], "link3": tm["link2"]}), "unique"),
        (lambda: ChainModel.from_urdf(urdf, _templates(layout, (1, 2, 3))), "joint4"),
        (lambda: ChainModel.from_urdf(urdf, {"link6": (["x"], [[0.05, 0.0, 0.1]])}), "determine every joint"),
        (lambda: ChainModel.from_urdf(pa10_urdf([1], np.zeros(6)), {"link1": (["a", "b"], [[0, 0, 0.1], [0, 0, -0.1]])}),
         "determine every joint"),
        (lambda: ChainModel.from_urdf(TREE_URDF.replace('type="revolute"><parent link="l2"', 'type="continuous">'
                                                        '<parent link="l2"'), {}), "revolute"),
        (lambda: ChainModel.from_urdf(TREE_URDF.replace('type="revolute"><parent link="l2"', 'type="prismatic">'
                                                        '<parent link="l2"'), {}), "revolute"),
    ]
    for call, words in cases:
        with pytest.raises(InputError, match=words):
            call()
