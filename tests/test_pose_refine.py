"""fit --refine-poses (train/field/pose_refine.py): the rotation, the rays' correction, the gauge, and a fit that
finds a known pose error from views of the shipped scene."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from snapshot3d.cameras import orbit_cameras  # noqa: E402
from snapshot3d.errors import UserError  # noqa: E402
from snapshot3d.paths import asset  # noqa: E402
from snapshot3d.posed import PosedImages  # noqa: E402
from snapshot3d.scene import load_scene_file  # noqa: E402
from snapshot3d.train.field.config import FitConfig, check_fit_config  # noqa: E402
from snapshot3d.train.field.decoder import load_decoder  # noqa: E402
from snapshot3d.train.field.fit import new_state, train_step  # noqa: E402
from snapshot3d.train.field.pose_refine import PoseRefine, axis_angle_matrix, correct_rays  # noqa: E402
from snapshot3d.train.field.render import occupancy_from_planes, render_views  # noqa: E402


def test_axis_angle_matches_opencv_rodrigues():
    rng = np.random.default_rng(0)
    r = np.concatenate([rng.normal(size=(5, 3)), 1e-6 * rng.normal(size=(3, 3)), np.zeros((1, 3))])
    got = axis_angle_matrix(torch.from_numpy(r)).numpy()
    want = np.stack([cv2.Rodrigues(v)[0] for v in r])
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_zero_correction_is_identity_and_rotation_keeps_unit_dirs():
    o, d = torch.randn(50, 3), torch.nn.functional.normalize(torch.randn(50, 3), dim=1)
    view = torch.randint(4, (50,), dtype=torch.int32)
    o2, d2 = correct_rays(torch.zeros(4, 6), view, o, d)
    assert torch.equal(o2, o) and torch.allclose(d2, d, atol=1e-7)
    params = torch.randn(4, 6) * 0.1
    o3, d3 = correct_rays(params, view, o, d)
    assert torch.allclose(d3.norm(dim=1), torch.ones(50), atol=1e-6)
    assert torch.allclose(o3 - o, params[view.long(), 3:], atol=1e-7)


def test_gauge_holds_the_mean_at_zero():
    p = PoseRefine(5)
    with torch.no_grad():
        p.params.copy_(torch.randn(5, 6) + 3.0)
    before = p.params.detach().clone()
    p.hold_gauge()
    assert torch.allclose(p.params.mean(0), torch.zeros(6), atol=1e-6)
    assert torch.allclose(p.params - p.params[0], before - before[0], atol=1e-5)   # differences kept


def test_bad_pose_settings_are_one_line_errors():
    with pytest.raises(UserError, match="--pose-lr"):
        check_fit_config(FitConfig(pose_lr=0.0))
    with pytest.raises(UserError, match="--refine-poses must be auto, on or off"):
        check_fit_config(FitConfig(refine_poses="yes"))
    with pytest.raises(UserError, match="--pose-start"):
        check_fit_config(FitConfig(pose_start=1.0))


def _rotation_error_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    rel = np.einsum("nij,nkj->nik", a[:, :3, :3], b[:, :3, :3])
    return np.rad2deg(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))


def test_refinement_finds_a_known_pose_error():
    """Views of the shipped scene rendered at true poses, given to the fit at poses 1 degree off (planes start at
    the scene's own and barely move): the corrections must take most of the error away."""
    scene = load_scene_file(asset("spot.s3d"))
    planes = torch.from_numpy(scene.planes())
    decoder = load_decoder(scene.decoder_version)
    c2w, intr = orbit_cameras(scene.orbit, 5, 48)
    images = render_views(planes, decoder, scene.box, c2w, intr, 48, 48)
    rv = np.deg2rad(1.0) / np.sqrt(3) * np.random.default_rng(3).normal(size=(5, 3))
    rv -= rv.mean(0)   # a common turn of every camera is the gauge the refinement leaves alone
    noisy = c2w.copy()
    noisy[:, :3, :3] = np.stack([cv2.Rodrigues(v)[0] for v in rv]).astype(np.float32) @ c2w[:, :3, :3]
    posed = PosedImages(images=images, alpha=None, c2w=noisy, intrinsics=intr, box=np.asarray(scene.box, np.float32),
                        train=np.arange(5), test=np.arange(0), name="spot-pose")
    cfg = FitConfig(steps=30, batch_rays=1024, occ_warmup=10 ** 6, qat_fraction=0.0, tv_weight=0.0, empty_weight=0.0,
                    lr=1e-5, lr_final=1e-5, refine_poses="on", pose_lr=3e-3, pose_start=0.0,
                    decoder=scene.decoder_version)
    st = new_state(posed, cfg, init_planes=planes)
    st.occ.occ = occupancy_from_planes(planes, decoder, st.frame)   # the scene's own, kept
    gen = torch.Generator().manual_seed(0)
    for _ in range(cfg.steps):
        train_step(st, decoder, cfg, gen)
    rot = axis_angle_matrix(st.poses.params.detach().double()[:, :3]).numpy()
    fixed = noisy.astype(np.float64).copy()
    fixed[:, :3, :3] = rot @ fixed[:, :3, :3]
    before, after = _rotation_error_deg(noisy, c2w), _rotation_error_deg(fixed, c2w)
    assert np.median(before) > 0.5
    print("rotation error before", before.round(3), "after", after.round(3))
    assert np.median(after) < 0.35 * np.median(before), (before, after)
