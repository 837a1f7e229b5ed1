"""fit --object-rays: the rays that see the object without masks, from the object-box fit's cells."""
import numpy as np
import pytest

from snapshot3d.cameras import look_at
from snapshot3d.train.field.object_rays import object_pixels, object_ray_index

BOX = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
K = np.array([[50.0, 50.0, 32.0, 24.0]])   # fx, fy, cx, cy of a 64x48 frame


def _one_cell():
    """An 8^3 grid with the cell whose centre is (0.125, 0.125, 0.125) set."""
    cells = np.zeros((8, 8, 8), bool)
    cells[4, 4, 4] = True
    return cells


def test_a_cell_lands_on_its_pixel_grown_by_the_margin():
    """A camera on the -y axis at z = 0 looking along +y: the cell's centre, 4.125 ahead, projects 0.125 * 50 / 4.125
    px right of the centre and as far above it (row 22, column 33 of the pixels with centres at +0.5)."""
    c2w = look_at(np.array([0.0, -4.0, 0.0]), np.array([0.0, 0.0, 0.0]))[None]
    px = object_pixels(_one_cell(), BOX, c2w, K, 48, 64, grow=0)
    assert np.argwhere(px[0]).tolist() == [[22, 33]]
    grown = object_pixels(_one_cell(), BOX, c2w, K, 48, 64, grow=2)
    assert grown.sum() == 25 and grown[0, 20:25, 31:36].all()


def test_cells_behind_the_camera_or_off_the_frame_land_nowhere():
    c2w = look_at(np.array([0.0, -4.0, 0.0]), np.array([0.0, -8.0, 0.0]))[None]   # looking away
    assert not object_pixels(_one_cell(), BOX, c2w, K, 48, 64).any()
    c2w = look_at(np.array([0.0, -4.0, 0.0]), np.array([8.0, 0.0, 0.0]))[None]   # the cell far left, off the frame
    assert not object_pixels(_one_cell(), BOX, c2w, K, 48, 64).any()


def test_the_index_runs_view_by_view_row_major():
    c2w = np.stack([look_at(np.array([0.0, -4.0, 0.0]), np.zeros(3))] * 2)
    px = object_pixels(_one_cell(), BOX, c2w, np.repeat(K, 2, 0), 48, 64)
    idx = object_ray_index(_one_cell(), BOX, c2w, np.repeat(K, 2, 0), 48, 64)
    assert len(idx) == 50 and np.array_equal(idx[25:] - idx[:25], np.full(25, 48 * 64))
    (r, c), = np.argwhere(object_pixels(_one_cell(), BOX, c2w[:1], K, 48, 64, grow=0)[0])
    assert r * 64 + c in idx and px[0].sum() == 25


@pytest.mark.parametrize("grow", [0, 1])
def test_a_full_grid_covers_the_box_s_silhouette(grow):
    """Every cell set: the pixels of the box's projected centre region, a solid patch with no holes."""
    c2w = look_at(np.array([0.0, -6.0, 0.0]), np.zeros(3))[None]
    px = object_pixels(np.ones((16, 16, 16), bool), BOX, c2w, K, 48, 64, grow=grow + 1)[0]
    rows, cols = np.nonzero(px)
    assert px[rows.min():rows.max() + 1, cols.min():cols.max() + 1].all()


def test_a_fit_without_masks_draws_its_object_rays_only_when_asked(tmp_path):
    """new_state of a capture without masks whose info holds the object's cells: with --object-rays the bank's
    foreground is the cells' rays, without it there is none."""
    from dataclasses import replace

    from snapshot3d.capture import CaptureOptions
    from snapshot3d.loaders import load_scene
    from snapshot3d.make_capture import make_capture
    from snapshot3d.make_capture_config import SynthCaptureConfig
    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.fit import new_state
    cap = make_capture("builtin:spot", tmp_path / "cap", SynthCaptureConfig(size=32, views=4))
    posed = load_scene(str(cap / "transforms.json"), capture=CaptureOptions(up=(0.0, 0.0, 1.0)))
    assert posed.alpha is None
    cells = np.zeros((16, 16, 16), bool)
    cells[6:10, 6:10, 6:10] = True
    posed = replace(posed, info={**posed.info, "object_cells": cells, "object_cells_box": posed.box})
    cfg = FitConfig(background="outer", plane_res=16, plane_channels=4)
    assert new_state(posed, cfg).bank.fg is None
    fg = new_state(posed, replace(cfg, object_rays=True)).bank.fg
    tr = posed.train
    expected = object_ray_index(cells, posed.box, posed.c2w[tr], posed.intrinsics[tr], posed.height, posed.width)
    assert 0 < len(fg) < len(tr) * posed.height * posed.width and np.array_equal(fg.numpy(), expected)
