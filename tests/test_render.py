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


def _bake_by_cells(models, planes12: np.ndarray, frame: Frame, res: int):
    """The bake written the plain way (the coarse grid repeated, the shell's fine cells scattered in one by one,
    then padded and laid out as tiles): what `bake_field`'s direct writes must reproduce exactly."""
    from snapshot3d.viewer.bake import COARSE, DENSE_ALPHA, grid_field
    nc = res // COARSE
    logit_c, rgb_c = grid_field(models, planes12, nc, np.argwhere(np.ones((nc, nc, nc), bool)))
    alpha = -np.expm1(-np.exp(logit_c) * frame.step).reshape(nc, nc, nc)
    shell = dilate3(alpha > formats.OCC_ALPHA_THRESHOLD) & ~erode3(alpha > DENSE_ALPHA)
    up = lambda a: a.repeat(COARSE, 0).repeat(COARSE, 1).repeat(COARSE, 2)  # noqa: E731
    grid = up(np.concatenate([logit_c[:, None], rgb_c], 1).reshape(nc, nc, nc, 4))
    fine = np.argwhere(up(shell))
    logit_f, rgb_f = grid_field(models, planes12, res, fine)
    grid[tuple(fine.T)] = np.concatenate([logit_f[:, None], rgb_f], 1)
    h = res // 2
    sigma = np.exp(grid[..., 0]).reshape(h, 2, h, 2, h, 2).mean((1, 3, 5), dtype=np.float32)
    b = res + 2
    atlas = np.pad(grid, ((1, 1),) * 3 + ((0, 0),), mode="edge").transpose(1, 2, 0, 3).reshape(b, b * b, 4)
    return grid, sigma, atlas, nc ** 3 + len(fine)


@pytest.mark.parametrize("res", [32, 64])
def test_bake_writes_the_same_grid_as_cell_by_cell(res):
    """bake_field fills the atlas block by block, the grid a view of it (issue 39): every number as the plain
    construction's, and the atlas still the padded grid `Baked` makes from a grid of its own."""
    scene = load_scene_file(SPOT)
    models, frame = field_models(decoder=scene.decoder_version), Frame.from_box(scene.box)
    baked = bake_field(models, pad_planes(scene.planes()), frame, res)
    grid, sigma, atlas, evaluated = _bake_by_cells(models, pad_planes(scene.planes()), frame, res)
    # the same cells through the same graph, in other batches: onnxruntime's kernels may round a batch differently
    # on another CPU, so the numbers are compared relative to their size (bit-identical here, on AMD EPYC)
    close = lambda a, b: a.shape == b.shape and np.allclose(a, b, rtol=1e-6, atol=1e-6)  # noqa: E731
    assert close(baked.grid, grid) and close(baked.sigma, sigma) and close(baked.atlas, atlas)
    assert baked.evaluated == evaluated
    assert np.shares_memory(baked.grid, baked.atlas)  # one copy of the grid, not two
    assert np.array_equal(Baked(np.ascontiguousarray(baked.grid), baked.sigma, 0).atlas, baked.atlas)


def test_view_rays_in_blas_sized_parts_match_one_product():
    """view_rays multiplies in parts below OpenBLAS's threading threshold: the same directions as one product."""
    from snapshot3d.viewer.march import _BLAS_ROWS, _camera_dirs, view_rays
    scene = load_scene_file(SPOT)
    c2w, intr = orbit_cameras(scene.orbit, 3, 380)
    assert 380 * 380 > 2 * _BLAS_ROWS
    for k in range(3):
        _, d = view_rays(c2w[k], intr[k], 380, 380, Frame.from_box(scene.box))
        whole = _camera_dirs(*[float(x) for x in intr[k]], 380, 380) @ np.asarray(c2w[k])[:3, :3].T.astype(np.float32)
        assert d.dtype == np.float32 and np.allclose(d, whole, rtol=1e-6, atol=1e-7)   # BLAS kernels differ by CPU


def test_sessions_do_not_spin():
    """onnxruntime's threads sleep between runs (a spinning one takes a shared core from numpy and OpenCV)."""
    from snapshot3d.viewer.runtime import model_path, session
    opts = session(str(model_path("field"))).get_session_options()
    assert opts.get_session_config_entry("session.intra_op.allow_spinning") == "0"
