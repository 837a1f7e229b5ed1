"""The fast renderer (baked field, probe windows, numpy compositing) against the reference torch
renderer and against exact small cases."""
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from snapshot3d import formats
from snapshot3d.cameras import orbit_cameras
from snapshot3d.metrics import psnr
from snapshot3d.scene import load_scene_file
from snapshot3d.viewer.bake import (
    MAX_RES,
    Baked,
    bake_field,
    dilate3,
    erode3,
    interp_matrix,
    sample_baked,
)
from snapshot3d.viewer.march import Frame
from snapshot3d.viewer.render import RenderConfig, composite, pad_planes, render_views
from snapshot3d.viewer.runtime import field_models

SPOT = Path(str(resources.files("snapshot3d") / "assets")) / "spot.s3d"


def test_fast_renderer_matches_reference_renderer():
    """Spot's views through the baked renderer against the reference (torch, fixed steps)."""
    from snapshot3d.train.field.commands import render_scene
    scene = load_scene_file(SPOT)
    ref = render_scene(scene, 3, 96, show_progress=False)
    c2w, intr = orbit_cameras(scene.orbit, 3, 96)
    got = render_views(field_models(decoder=scene.decoder_version), scene.planes(), scene.box, c2w, intr, 96, 96)
    assert got.shape == (3, 96, 96, 3) and got.dtype == np.float32
    assert psnr(got, ref) >= 30.0  # 32.6 dB here; 36.0 dB at 380x380 (bench decode)


def test_fewer_samples_and_coarser_bake_cost_accuracy():
    """The settings trade accuracy as the chart says: more samples and a finer bake are closer."""
    from snapshot3d.train.field.commands import render_scene
    scene = load_scene_file(SPOT)
    ref = render_scene(scene, 2, 96, show_progress=False)
    c2w, intr = orbit_cameras(scene.orbit, 2, 96)
    score = {}
    for name, cfg in {"default": RenderConfig(), "few": RenderConfig(samples=4), "coarse": RenderConfig(bake=32)}.items():
        score[name] = psnr(render_views(field_models(decoder=scene.decoder_version), scene.planes(), scene.box, c2w, intr, 96, 96, cfg), ref)
    assert score["default"] > score["few"] + 1.0 and score["default"] > score["coarse"] + 1.0, score


def test_baked_grid_reads_back_exactly_and_interpolates_linearly():
    rng = np.random.default_rng(0)
    b = 16
    grid = rng.normal(size=(b, b, b, 4)).astype(np.float32)
    baked = Baked(grid, np.zeros((b // 2,) * 3, np.float32), 0)
    cells = rng.integers(0, b, (50, 3)).astype(np.float32)
    logit, rgb = sample_baked(baked, *(cells[:, k:k + 1] for k in range(3)))
    want = grid[tuple(cells.astype(int).T)]
    np.testing.assert_allclose(logit[:, 0], want[:, 0], atol=1e-5)
    np.testing.assert_allclose(rgb[:, 0], want[:, 1:], atol=1e-5)
    mid = cells.copy()
    mid[:, 2] = np.minimum(mid[:, 2], b - 2) + 0.5  # halfway between two z-slices (two atlas tiles)
    logit, _ = sample_baked(baked, *(mid[:, k:k + 1] for k in range(3)))
    lo, hi = grid[tuple(np.floor(mid).astype(int).T)], grid[tuple((np.floor(mid) + [0, 0, 1]).astype(int).T)]
    np.testing.assert_allclose(logit[:, 0], (lo[:, 0] + hi[:, 0]) / 2, atol=1e-4)
    xy = cells.copy()
    xy[:, :2] = np.minimum(xy[:, :2], b - 2) + 0.25  # inside one tile, between four cells
    logit, _ = sample_baked(baked, *(xy[:, k:k + 1] for k in range(3)))
    i, j, k = np.floor(xy).astype(int).T
    want = sum(wx * wy * grid[i + dx, j + dy, k, 0] for dx, wx in ((0, 0.75), (1, 0.25)) for dy, wy in ((0, 0.75), (1, 0.25)))
    np.testing.assert_allclose(logit[:, 0], want, atol=1e-4)
    edge = np.array([[-1.0, -0.5, b - 0.5], [b, 3, -1], [2, b - 0.5, b]], np.float32)  # up to one cell outside: clamped
    logit, _ = sample_baked(baked, *(edge[:, k:k + 1] for k in range(3)))
    clamped = np.clip(np.rint(edge), 0, b - 1).astype(int)
    np.testing.assert_allclose(logit[:, 0], grid[tuple(clamped.T)][:, 0], atol=1e-5)


def test_atlas_holds_the_largest_bake():
    """OpenCV's maps hold coordinates below 32768: the last slice of a MAX_RES grid still reads right."""
    b = MAX_RES
    grid = np.zeros((b, b, b, 4), np.float32)
    grid[:, :, -1, 0] = np.arange(b, dtype=np.float32)[:, None]
    baked = Baked(grid, np.zeros((b // 2,) * 3, np.float32), 0)
    pts = np.array([[b - 1, 5, b - 1], [b - 1.5, 0, b - 1], [3, b - 1, b - 1]], np.float32)
    logit, _ = sample_baked(baked, *(pts[:, k:k + 1] for k in range(3)))
    np.testing.assert_allclose(logit[:, 0], [b - 1, b - 1.5, 3], atol=1e-3)


def test_interp_matrix_is_bilinear_with_border_clamp():
    m = interp_matrix(np.array([-1.0, 0.0, 1.0, 1.5], np.float32), 5)
    np.testing.assert_allclose(m.sum(1), 1.0, atol=1e-6)
    np.testing.assert_allclose(m[0], [1, 0, 0, 0, 0])
    np.testing.assert_allclose(m[1], [0, 0, 1, 0, 0])
    np.testing.assert_allclose(m[2], [0, 0, 0, 0, 1])
    np.testing.assert_allclose(m[3], m[2])


def test_morphology_and_composite():
    a = np.zeros((5, 5, 5), bool)
    a[2, 2, 2] = True
    assert dilate3(a).sum() == 27 and erode3(dilate3(a)).sum() == 1 and erode3(a).sum() == 0
    logit = np.log(np.array([[0.0, 1e9], [1e-12, 1e-12]], np.float32) + 1e-30)
    rgb = np.array([[[1, 0, 0], [0, 1, 0]], [[0, 0, 1], [0, 0, 1]]], np.float32)
    out = composite(logit, rgb, np.full((2, 1), 0.1, np.float32))
    np.testing.assert_allclose(out[0], [0, 1, 0], atol=1e-5)   # an opaque second sample
    np.testing.assert_allclose(out[1], [formats.BACKGROUND] * 3, atol=1e-5)  # empty: background


def test_bake_refines_only_near_the_surface():
    scene = load_scene_file(SPOT)
    baked = bake_field(field_models(decoder=scene.decoder_version), pad_planes(scene.planes()), Frame.from_box(scene.box), 64)
    assert baked.grid.shape == (64, 64, 64, 4) and baked.sigma.shape == (32, 32, 32)
    assert 16 ** 3 < baked.evaluated < 0.6 * 64 ** 3
    with pytest.raises(ValueError, match="multiple of 8 from 8 to 176"):
        bake_field(field_models(decoder=scene.decoder_version), pad_planes(scene.planes()), Frame.from_box(scene.box), 60)
    with pytest.raises(ValueError, match="from 8 to 176"):
        bake_field(field_models(decoder=scene.decoder_version), pad_planes(scene.planes()), Frame.from_box(scene.box), 184)
