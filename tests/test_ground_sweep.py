"""fit --ground-sweep: the pixels that show the ground, found by warping each view's neighbours onto it through the
ground plane (snapshot3d/ground_sweep.py)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from snapshot3d.cameras import look_at, pixel_rays, project
from snapshot3d.ground_sweep import SweepConfig, ground_sweep, plane_homography, window_ncc

W, H = 128, 96
INTR = np.array([110.0, 110.0, 64.3, 47.8])
PLANE = (0.02, -0.01, -1.0)   # z = a x + b y + c, a little tilted
SQUARE = 0.4                  # the raised block: a textured top at z = c + 0.5 over |x|, |y| < SQUARE


def _cameras(n: int = 24) -> np.ndarray:
    """n OpenGL cameras on a 120 deg arc, 5 units from the origin, 25 deg over it."""
    az = np.radians(np.linspace(-60, 60, n))
    el = np.radians(25.0)
    eyes = 5.0 * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.full(n, np.sin(el))], axis=1)
    return np.stack([look_at(e, np.zeros(3)) for e in eyes])


def _texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A grey texture of world x, y that no window of a few pixels repeats."""
    return (0.5 + 0.2 * np.sin(7.1 * x + 2.3 * np.sin(3.1 * y)) * np.cos(5.3 * y - 1.7 * np.cos(2.9 * x))
            + 0.1 * np.sin(17.0 * x * y)).astype(np.float32)


def _render(c2w: np.ndarray) -> tuple[np.ndarray, ...]:
    """One camera -> (image (H, W, 3) RGB: the textured ground plane, with the block's textured top standing
    over the origin, its sides dark, a plain sky over the horizon; the block's pixels (H, W) bool; its top's;
    the ground's)."""
    o, d = (a.astype(np.float64) for a in pixel_rays(c2w, *INTR, W, H))
    a, b, c = PLANE
    n = np.array([-a, -b, 1.0])
    t = (c - o @ n) / (d @ n)
    p = o + t[:, None] * d
    grey = np.where(t > 0, _texture(p[:, 0], p[:, 1]), 0.9)
    top = c + 0.5
    tt = (top - o[:, 2]) / d[:, 2]
    q = o + tt[:, None] * d
    on_top = (tt > 0) & (np.abs(q[:, 0]) < SQUARE) & (np.abs(q[:, 1]) < SQUARE)
    # the block's sides: rays that pass its footprint between the ground and the top without meeting the top
    side = np.zeros_like(on_top)
    for z in np.linspace(c + 0.02 * (abs(a) + abs(b)) + 0.02, top, 24):
        tz = (z - o[:, 2]) / d[:, 2]
        qz = o + tz[:, None] * d
        side |= (tz > 0) & (np.abs(qz[:, 0]) < SQUARE) & (np.abs(qz[:, 1]) < SQUARE)
    grey = np.where(on_top, _texture(q[:, 0] + 3.0, q[:, 1] - 2.0), np.where(side & ~on_top, 0.25, grey))
    block = (on_top | side).reshape(H, W)
    gain = 1.0 + 0.2 * np.sin(c2w[0, 3])   # each frame its own exposure
    image = np.repeat((grey.reshape(H, W) * gain)[..., None], 3, axis=2).clip(0, 1)
    return image, block, on_top.reshape(H, W), (t > 0).reshape(H, W) & ~block


def test_the_plane_homography_maps_a_point_of_the_plane_between_two_views():
    c2w = _cameras(5)
    a, b, c = PLANE
    pts = np.array([[0.7, -0.4, 0.0], [-1.1, 0.3, 0.0], [0.2, 1.3, 0.0]])
    pts[:, 2] = a * pts[:, 0] + b * pts[:, 1] + c
    hm = plane_homography(c2w[1], INTR, c2w[4], INTR, PLANE)
    for p in pts:
        (ud, vd), (us, vs) = (project(p[None], c, *INTR)[0][0] for c in (c2w[1], c2w[4]))
        got = hm @ np.array([ud - 0.5, vd - 0.5, 1.0])   # OpenCV's integer pixel centres
        np.testing.assert_allclose(got[:2] / got[2], [us - 0.5, vs - 0.5], atol=1e-6)


def test_window_correlation_ignores_exposure_and_reads_no_texture_as_flat(rng):
    x = rng.uniform(0, 1, (40, 50)).astype(np.float32)
    ncc, std = window_ncc(x, 0.6 * x + 0.1, 7)
    assert np.all(ncc[5:-5, 5:-5] > 0.999)
    assert np.all(std[5:-5, 5:-5] > 0.1)
    flat = np.full_like(x, 0.4)
    ncc, std = window_ncc(flat, x, 7)
    assert np.all(np.abs(ncc) < 1e-2) and np.all(std < 1e-3)


def test_the_sweep_finds_the_ground_and_never_the_block_standing_on_it():
    c2w = _cameras()
    views = [_render(c) for c in c2w]
    images = np.stack([v[0] for v in views]).astype(np.float32)
    block, top, ground = (np.stack([v[k] for v in views]) for k in (1, 2, 3))
    found = ground_sweep(images, c2w, np.tile(INTR, (len(c2w), 1)), PLANE, np.zeros(3))
    assert found.ndim == 2 and found.shape[1] == 3 and found.dtype == np.int64
    hit = np.zeros(block.shape, bool)
    hit[found[:, 0], found[:, 1], found[:, 2]] = True
    # the block's textured top agrees with its neighbours only at its own height, not at the ground's
    assert top.sum() > 1000 and not (hit & top).any()
    # its plain sides only at their foot, where a window (7 px) straddles them and the ground they meet
    inside = np.stack([cv2.distanceTransform(b.astype(np.uint8), cv2.DIST_L2, 5) for b in block])
    assert (hit & block).sum() < 0.03 * block.sum()
    assert np.all(inside[hit & block] <= SweepConfig().window // 2 + 1.5), inside[hit & block].max()
    assert not (hit & ~block & ~ground).any()   # the sky has no texture
    assert hit[ground].mean() > 0.12, hit[ground].mean()   # 0.18 here; a wrong homography finds none


def test_a_stricter_agreement_finds_fewer_pixels():
    c2w = _cameras(12)
    images = np.stack([_render(c)[0] for c in c2w]).astype(np.float32)
    intr = np.tile(INTR, (len(c2w), 1))
    loose = ground_sweep(images, c2w, intr, PLANE, np.zeros(3), SweepConfig(agree=0.5))
    strict = ground_sweep(images, c2w, intr, PLANE, np.zeros(3), SweepConfig(agree=0.95))
    assert len(strict) < len(loose)


@pytest.mark.parametrize("border", [0, 2])
def test_the_border_takes_pixels_off_the_found_set(border):
    c2w = _cameras(12)
    images = np.stack([_render(c)[0] for c in c2w]).astype(np.float32)
    intr = np.tile(INTR, (len(c2w), 1))
    base = ground_sweep(images, c2w, intr, PLANE, np.zeros(3), SweepConfig(border=0))
    got = ground_sweep(images, c2w, intr, PLANE, np.zeros(3), SweepConfig(border=border))
    assert {tuple(r) for r in got} <= {tuple(r) for r in base}
    assert (len(got) < len(base)) == (border > 0)


def test_the_fit_adds_the_swept_pixels_to_the_matched_features_ones():
    """box_tighten._swept: the sparse box's pixels (frame, row, col) and the sweep's, each once; the count the
    sweep found is reported."""
    from snapshot3d.posed import PosedImages
    from snapshot3d.train.field.box_tighten import _swept

    c2w = _cameras(12)
    images = np.stack([_render(c)[0] for c in c2w]).astype(np.float32)
    intr = np.tile(INTR, (len(c2w), 1)).astype(np.float32)
    posed = PosedImages(images=images, alpha=None, c2w=c2w.astype(np.float32), intrinsics=intr,
                        box=np.array([[-1.5, -1.5, -1.5], [1.5, 1.5, 1.5]], np.float32), train=np.arange(12),
                        test=np.arange(0), name="block")
    dense = ground_sweep(images, c2w, intr, PLANE, np.zeros(3))
    sparse = np.array([[0, 1, 2], [3, 90, 100], *dense[:5]], np.int64)
    got = _swept(posed, c2w, {"ground_plane": PLANE, "ground_pixels": sparse})
    assert got["ground_sweep_pixels"] == len(dense)
    assert got["ground_pixels"].dtype == np.int64
    assert {tuple(r) for r in got["ground_pixels"]} == {tuple(r) for r in sparse} | {tuple(r) for r in dense}
    assert len(got["ground_pixels"]) == len({tuple(r) for r in got["ground_pixels"]})   # each once
