"""``mocapfj triangulate`` through the command line: detections CSV (labelled and unlabelled) or
images per camera -> markers.c3d (labels, residuals, camera masks) and a summary; bad input exits 2
with one line and writes nothing (mocapfj.pipeline.triangulate)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from mocapfj.cli import main
from mocapfj.io import read_c3d, write_detections
from mocapfj.io.calib import write_rig
from mocapfj.io.clusters import write_clusters
from mocapfj.synth.cameras import ring_rig
from mocapfj.synth.images import render_blob_clip
from mocapfj.synth.markers import place_markers
from mocapfj.synth.render import render_markers
from mocapfj.synth.robot_mesh import base_pose, forward_kinematics, pa10_geometry
from mocapfj.types import Detections, MarkerCluster, Rig


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A PA-10 clip (100 frames at 250 Hz, 8 cameras, occlusion, 0.15 px) written as a rig, a
    labelled and an unlabelled detections CSV (with a spurious blob per camera and frame and a
    non-finite row), and a clusters file of its 20 markers."""
    d = tmp_path_factory.mktemp("tri")
    rng = np.random.default_rng(8)
    geometry = pa10_geometry()
    layout = place_markers(geometry, rng)
    n = 100
    t = np.arange(n) / 250.0
    q = np.zeros((n, 6))
    q[:, 0] = 0.5 * np.sin(2 * np.pi * 0.6 * t)
    q[:, 1] = 0.3 + 0.3 * np.sin(2 * np.pi * 0.4 * t)
    q[:, 3] = 0.8 * np.sin(2 * np.pi * 0.5 * t)
    rig = ring_rig(8, rng=rng)
    r = render_markers(t, forward_kinematics(q, T_world_base=base_pose()), layout, geometry, rig, rng,
                       pixel_noise_px=0.15)
    write_rig(d / "rig.toml", Rig(rig.cameras, {"units": "m", "sigma_px": 0.15}))
    det = r.detections
    write_detections(d / "labelled.csv", det)
    k = rng.poisson(1.0, (n, 8))
    gf, gc = np.nonzero(k)
    gf, gc = np.repeat(gf, k[gf, gc]), np.repeat(gc, k[gf, gc])
    xy = np.r_[det.xy_px, rng.uniform([0, 0], [1280, 1024], (gf.size, 2)), [[np.nan, 3.0]]]
    unl = Detections(np.r_[det.frame, gf, 0], np.r_[det.camera, gc, 0], xy, np.full(xy.shape[0], -1))
    write_detections(d / "unlabelled.csv", unl)
    clusters = [MarkerCluster(f"link{li}", [layout.labels[i] for i in layout.cluster(li)],
                              layout.p_link[layout.cluster(li)]) for li in np.unique(layout.link)]
    write_clusters(d / "clusters.toml", clusters)
    return d, r, layout, rig


def _run(args, capsys):
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.filterwarnings("ignore:No analog data found")
def test_labelled_csv(scene, capsys, tmp_path):
    d, r, layout, rig = scene
    code, out, err = _run(["triangulate", str(d / "labelled.csv"), "--rig", str(d / "rig.toml"), "--rate", "250",
                           "--out", str(tmp_path / "o"), "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    m = read_c3d(tmp_path / "o" / "markers.c3d")
    assert m.labels == tuple(f"P{k}" for k in range(20)) and m.rate_hz == 250.0 and m.n_frames == 100
    seen = r.n_cameras_seen >= 2
    assert np.array_equal(np.isfinite(m.xyz[..., 0]), seen)                   # occluded: NaN
    err3 = np.linalg.norm(m.xyz - r.xyz_true, axis=2)[seen]
    assert np.max(err3) < 5e-3 and np.sqrt(np.mean(err3**2)) < 1e-3
    assert np.all(m.residual[seen] > 0) and np.nanmax(m.residual) < 2e-3
    assert s["n_unseen"] == int((~seen & (r.n_cameras_seen > 0)).sum())
    assert s["triangulation"]["labelled"]["sigma_source"] == "rig"
    assert abs(s["reprojection_rms_px"] - 0.15) < 0.03 and s["points_per_frame"] == pytest.approx(seen.sum() / 100)
    # camera masks in the fourth word's high byte, read with the c3d package
    import c3d

    with open(tmp_path / "o" / "markers.c3d", "rb") as h:
        frames = np.stack([p.copy() for _, p, _ in c3d.Reader(h).read_frames()])          # (T, M, 5)
    mask = frames[..., 4].astype(int)
    vis7 = (r.visible[:7] * (1 << np.arange(7))[:, None, None]).sum(axis=0)
    assert np.array_equal(mask[seen], vis7[seen])


def test_unlabelled_csv_labelled_from_the_clusters(scene, capsys, tmp_path):
    d, r, layout, rig = scene
    code, out, err = _run(["triangulate", str(d / "unlabelled.csv"), "--rig", str(d / "rig.toml"), "--rate", "250",
                           "--clusters", str(d / "clusters.toml"), "--out", str(tmp_path / "o"), "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    m = read_c3d(tmp_path / "o" / "markers.c3d")
    assert set(m.labels) == set(layout.labels)
    truth = r.xyz_true[:, [layout.labels.index(x) for x in m.labels]]
    have = np.isfinite(m.xyz[..., 0])
    d3 = np.linalg.norm(m.xyz[:, :, None] - truth[:, None], axis=3)
    assert (np.argmin(np.where(np.isfinite(d3), d3, np.inf), axis=2)[have] == np.nonzero(have)[1]).all()
    assert np.nanmax(np.linalg.norm(m.xyz - truth, axis=2)) < 5e-3
    seen = (r.n_cameras_seen >= 2)[:, [layout.labels.index(x) for x in m.labels]]
    assert (have & seen).sum() > 0.98 * seen.sum()
    assert s["n_nonfinite_ignored"] == 1 and s["correspondence"]["ghost_pairs"] > 0
    for key in ("points_per_frame", "reprojection_rms_px", "nan_share", "gaps_filled", "swaps_repaired", "long_gaps"):
        assert key in s
    assert s["files"]["markers"] == "markers.c3d"


def test_images_per_camera(scene, capsys, tmp_path):
    """Blob images rendered for 6 frames of 4 cameras (640 x 512): blobs found, matched, labelled."""
    d, r, layout, _ = scene
    small = ring_rig(4, rng=np.random.default_rng(3), size=(640, 512), fx=550.0)
    rng = np.random.default_rng(4)
    p = r.xyz_true[:6]
    dirs = []
    for c, cam in enumerate(small.cameras):
        clip = render_blob_clip(cam, p, radius_px=3.0, noise_sd=1.0, supersample=4, rng=rng)
        folder = tmp_path / f"cam{c}"
        folder.mkdir()
        for f, img in enumerate(clip.images):
            cv2.imwrite(str(folder / f"f{f:03d}.png"), img)
        dirs.append(str(folder))
    write_rig(tmp_path / "rig4.toml", Rig(small.cameras, {"units": "m"}))
    code, out, err = _run(["triangulate", *dirs, "--rig", str(tmp_path / "rig4.toml"), "--rate", "100",
                           "--clusters", str(d / "clusters.toml"), "--out", str(tmp_path / "o"), "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    m = read_c3d(tmp_path / "o" / "markers.c3d")
    truth = p[:, [layout.labels.index(x) for x in m.labels]]
    err3 = np.linalg.norm(m.xyz - truth, axis=2)
    assert np.isfinite(err3).mean() > 0.6 and np.nanmax(err3) < 5e-3
    assert len(s["blobs"]) == 4 and s["blobs"][0]["frames"] == 6


@pytest.mark.parametrize("case, needle", [
    ("camera", "camera numbers 0..6"),
    ("rate", "--rate"),
    ("clusters", "--clusters"),
    ("count", "one video or image directory per camera"),
])
def test_bad_input_exits_2_and_writes_nothing(scene, capsys, tmp_path, case, needle):
    d, r, layout, rig = scene
    out = tmp_path / "o"
    base = ["--rig", str(d / "rig.toml"), "--out", str(out)]
    if case == "camera":                        # the rig has 7 cameras, the detections 8
        write_rig(tmp_path / "rig7.toml", Rig(rig.cameras[:7], {"units": "m"}))
        args = [str(d / "labelled.csv"), "--rig", str(tmp_path / "rig7.toml"), "--rate", "250", "--out", str(out)]
    elif case == "rate":
        args = [str(d / "labelled.csv"), *base]
    elif case == "clusters":
        args = [str(d / "unlabelled.csv"), *base, "--rate", "250"]
    else:
        args = [str(d / "cam0"), str(d / "cam1"), *base]
    code, stdout, err = _run(["triangulate", *args], capsys)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1 and err.startswith("mocapfj: error:")
    assert not out.exists()


def test_images_with_an_apriltag_give_its_pose(capsys, tmp_path):
    """A 15 cm tag36h11 tag (id 0) rendered in 3 cameras for 2 frames: its corners are found,
    triangulated from every camera, and tag_poses.csv gives its pose within 2 mm and 1 deg."""
    from mocapfj.io import read_csv_columns
    from mocapfj.rotations import matrix_from_rotvec
    from mocapfj.synth.images import render_board_view
    from mocapfj.types import Board
    from mocapfj.vision.camera import camera_centre_world

    rig = ring_rig(8, rng=np.random.default_rng(5), size=(640, 512), fx=600.0)
    cams = rig.cameras[:3]
    board = Board("aprilgrid", 1, 1, tag_m=0.15, spacing_m=0.03, family="tag36h11")
    toward = camera_centre_world(cams[1]) - np.array([0.0, 0.0, 1.2])
    z = -toward / np.linalg.norm(toward)                           # printed face towards camera 1
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    R0 = np.column_stack([x, np.cross(z, x), z])
    rng = np.random.default_rng(6)
    poses = []
    for f in range(2):
        R = matrix_from_rotvec([0.1 * f, 0.05, 0.0]) @ R0
        t = np.array([0.02 * f, 0.0, 1.2]) - R @ np.array([0.075, 0.075, 0.0])     # tag centre at (0.02 f, 0, 1.2)
        poses.append((R, t))
        for c, cam in enumerate(cams):
            folder = tmp_path / f"cam{c}"
            folder.mkdir(exist_ok=True)
            view = render_board_view(cam, board, R, t, px_per_m=2000, noise_sd=1.0, rng=rng)
            cv2.imwrite(str(folder / f"f{f}.png"), view.image)
    write_rig(tmp_path / "rig.toml", Rig(cams, {"units": "m"}))
    (tmp_path / "tags.toml").write_text('format = "mocapfj.clusters/1"\n[[tags]]\nname = "tag0"\nid = 0\nsize_m = 0.15\n')
    code, out, err = _run(["triangulate", *(str(tmp_path / f"cam{c}") for c in range(3)), "--rig",
                           str(tmp_path / "rig.toml"), "--rate", "30", "--clusters", str(tmp_path / "tags.toml"),
                           "--out", str(tmp_path / "o"), "--json"], capsys)
    assert code == 0, err
    s = json.loads(out)
    assert s["labels"] == ["tag0_0", "tag0_1", "tag0_2", "tag0_3"] and s["files"]["tag_poses"] == "tag_poses.csv"
    cols = read_csv_columns(tmp_path / "o" / "tag_poses.csv")
    for f, (R, t) in enumerate(poses):
        centre = R @ np.array([0.075, 0.075, 0.0]) + t
        got = np.array([cols[f"tag0_t{a}_m"][f] for a in "xyz"])
        assert np.linalg.norm(got - centre) < 2e-3
        Rg = matrix_from_rotvec([cols[f"tag0_r{a}_rad"][f] for a in "xyz"])
        assert np.degrees(np.arccos(np.clip((np.trace(Rg.T @ R) - 1) / 2, -1, 1))) < 1.0
