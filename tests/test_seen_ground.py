"""fit --seen-ground-weight: the pixels whose matched feature lies on the ground (snapshot3d/sparse_box.py) and the
planes' opacity along their rays above the ground's band (train/field/seen_ground.py)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from snapshot3d.bundle import projection
from snapshot3d.cameras import look_at
from snapshot3d.sparse_box import ground_pixels, points_from_matches


def _project(c2w: np.ndarray, intr: np.ndarray, pts: np.ndarray) -> np.ndarray:
    h = projection(c2w, intr) @ np.c_[pts, np.ones(len(pts))].T
    return (h[:2] / h[2]).T


def test_each_triangulated_point_comes_with_the_pixels_it_was_seen_at(rng):
    """Two cameras 30 deg apart over points on a floor and on a box above it: the points come back with (frame, x,
    y) in each of their two frames, and there they project."""
    c2w = np.stack([look_at(np.array([4.0 * np.cos(a), 4.0 * np.sin(a), 2.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]))
                    for a in (0.0, np.radians(30))])
    intr = np.array([[100.0, 100.0, 64.0, 48.0]] * 2)
    pts = np.r_[np.c_[rng.uniform(-1, 1, (40, 2)), np.full(40, -1.0)], rng.uniform(-0.3, 0.3, (20, 3))]
    keypoints = [_project(c, k, pts) for c, k in zip(c2w, intr)]
    idx = np.arange(len(pts))
    got, seen = points_from_matches(keypoints, [(0, 1, idx, idx)], c2w, intr, with_pixels=True)
    assert got.shape == (60, 3) and seen.shape == (60, 2, 3)
    np.testing.assert_allclose(got, pts, atol=1e-6)
    assert np.array_equal(seen[:, :, 0], np.tile([0.0, 1.0], (60, 1)))
    for f in (0, 1):
        np.testing.assert_allclose(seen[:, f, 1:], keypoints[f], atol=1e-9)
    # without with_pixels, the points alone, as before
    np.testing.assert_allclose(points_from_matches(keypoints, [(0, 1, idx, idx)], c2w, intr), got)


def test_the_ground_pixels_are_those_of_points_within_the_band_floored_inside_the_frame_and_unique():
    points = np.array([[0.0, 0.0, -1.0], [0.5, 0.2, -0.99], [0.0, 0.0, -0.5], [0.3, 0.3, -1.0], [0.1, 0.1, -1.2]])
    seen = np.array([[[0, 10.7, 5.2], [1, 3.0, 4.9]],
                     [[0, 10.2, 5.9], [2, 7.5, 2.5]],     # the same pixel of frame 0 as the first: once
                     [[0, 20.0, 20.0], [1, 21.0, 21.0]],  # on the object, 0.5 over the ground
                     [[1, 40.5, 1.0], [2, -0.5, 3.0]],    # its frame-2 pixel lies left of the frame
                     [[0, 30.0, 30.0], [1, 31.0, 31.0]]])  # 0.2 under the ground: out of the band
    got = ground_pixels(points, seen, (0.0, 0.0, -1.0), 0.02, (48, 64))
    assert got.dtype == np.int64
    assert got.tolist() == [[0, 5, 10], [1, 1, 40], [1, 4, 3], [2, 2, 7]]


@pytest.fixture(scope="module")
def small():
    from snapshot3d.loaders import load_scene
    return load_scene("builtin:spot", size=24)


def _fit(posed, weight: float, pixels, cells: dict | None = None, spare: bool = False):
    from dataclasses import replace

    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.fit import fit
    below = float(posed.box[0, 2]) - 1.0   # a ground plane under the whole box: every sample counts
    posed = replace(posed, info={**posed.info, "ground_pixels": pixels, "ground_plane": [0.0, 0.0, below],
                                 "ground_clear": 0.1, **(cells or {})})
    cfg = FitConfig(steps=30, batch_rays=512, plane_res=16, plane_channels=4, background="outer", background_res=8,
                    background_samples=4, occupancy=False, object_steps=0.0, seen_ground_weight=weight,
                    seen_ground_spare=spare)
    return fit(posed, load_decoder(), cfg).state


@pytest.fixture(scope="module")
def plain(small):
    """The fit without the weight and without ground pixels."""
    return _fit(small, 0.0, None)


def _opacity(st, posed, pixels) -> float:
    """Mean opacity of `st`'s planes along the bank's rays of pixels (K, 3) (train frame, row, col)."""
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.render import render_rays
    k = torch.from_numpy((pixels[:, 0] * posed.height + pixels[:, 1]) * posed.width + pixels[:, 2])
    with torch.no_grad():
        return float(render_rays(st.planes.planes, load_decoder(), st.frame, None, st.bank.origins[k],
                                 st.bank.dirs[k])[1].mean())


def test_the_weight_clears_the_planes_along_the_ground_rays_and_zero_changes_nothing(small, plain):
    """Rays said to show the ground (here: the object's own pixels of the first training view, the hardest case)
    end far more transparent with the weight than without; weight 0 gives the fit without the pixels, bit for
    bit."""
    alpha = small.alpha[small.train[0]]
    rows, cols = np.nonzero(alpha > 0.9)
    pixels = np.c_[np.zeros(len(rows), np.int64), rows, cols]
    zero, weighted = _fit(small, 0.0, pixels), _fit(small, 1.0, pixels)
    assert torch.equal(plain.planes.planes, zero.planes.planes)
    before, after = _opacity(plain, small, pixels), _opacity(weighted, small, pixels)
    assert before > 0.5 and after < 0.5 * before, (before, after)


def test_the_opacity_counts_only_the_samples_higher_than_clear_over_the_ground():
    """In a field of even density, over a plane under the whole box the opacity is the renderer's; with the plane at
    the box's middle, only the upper half's samples count (a ray straight down: half the optical depth); above the
    box, none."""
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.render import render_rays
    from snapshot3d.train.field.sampler import BoxFrame
    from snapshot3d.train.field.seen_ground import clear_opacity
    box = np.array([[-1.0, -1.0, 2.0], [1.0, 1.0, 4.0]], np.float32)
    frame = BoxFrame.from_box(box)
    planes = torch.tensor([0.075, -0.015, -0.11, 0.03]).view(1, 4, 1, 1).expand(3, 4, 8, 8).clone()   # even density
    dec = load_decoder()
    o = torch.tensor([[0.1, -0.2, 3.0], [0.3, 0.2, 3.0]])
    d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])

    def at(plane, clear):
        return clear_opacity(planes, dec, frame, None, o, d, plane, clear, torch.Generator().manual_seed(5))

    full = render_rays(planes, dec, frame, None, o, d, jitter=True, generator=torch.Generator().manual_seed(5))[1]
    torch.testing.assert_close(at((0.0, 0.0, 0.0), 1.0), full)   # every sample over 0 + 1 = 1 (the box: 2..4)
    assert 0.15 < float(full.min()) and float(full.max()) < 0.95, full
    half = at((0.0, 0.0, 2.0), 1.0)   # over 3: the upper half
    tau_half, tau_full = -torch.log1p(-half), -torch.log1p(-full)
    torch.testing.assert_close(tau_half, 0.5 * tau_full, rtol=0.1, atol=0.0)
    assert torch.equal(at((0.0, 0.0, 4.0), 0.5), torch.zeros(2))


def test_the_samples_in_the_spared_cells_count_for_nothing():
    """The object's cells (`seen_ground.Spared`) over the box of even density: sparing none changes nothing, the
    upper half leaves a ray straight down half its optical depth, all of them none; points off the box are never
    held."""
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.sampler import BoxFrame
    from snapshot3d.train.field.seen_ground import Spared, clear_opacity
    box = np.array([[-1.0, -1.0, 2.0], [1.0, 1.0, 4.0]], np.float32)
    frame = BoxFrame.from_box(box)
    planes = torch.tensor([0.075, -0.015, -0.11, 0.03]).view(1, 4, 1, 1).expand(3, 4, 8, 8).clone()
    dec = load_decoder()
    o = torch.tensor([[0.1, -0.2, 3.0], [0.3, 0.2, 3.0]])
    d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])

    def at(cells):
        spared = None if cells is None else Spared(torch.from_numpy(cells), torch.from_numpy(box))
        return clear_opacity(planes, dec, frame, None, o, d, (0.0, 0.0, 0.0), 1.0, torch.Generator().manual_seed(5),
                             spared)

    full, none = at(None), np.zeros((4, 4, 4), bool)
    torch.testing.assert_close(at(none), full)
    upper = none.copy()
    upper[:, :, 2:] = True
    tau_half, tau_full = -torch.log1p(-at(upper)), -torch.log1p(-full)
    torch.testing.assert_close(tau_half, 0.5 * tau_full, rtol=0.1, atol=0.0)
    assert torch.equal(at(~none), torch.zeros(2))
    held = Spared(torch.from_numpy(~none), torch.from_numpy(box)).holds(
        torch.tensor([[0.0, 0.0, 3.0], [0.0, 0.0, 4.5], [1.2, 0.0, 3.0], [-0.99, 0.99, 2.01]]))
    assert held.tolist() == [True, False, False, True]


def test_the_fit_spares_the_object_cells_it_is_given(small, plain):
    """The object's own pixels said to show the ground: with every cell of the box spared (--seen-ground-spare) the
    weight clears nothing (the object keeps its opacity); without the option, the default, it ignores the cells."""
    alpha = small.alpha[small.train[0]]
    rows, cols = np.nonzero(alpha > 0.9)
    pixels = np.c_[np.zeros(len(rows), np.int64), rows, cols]
    every = {"object_cells": np.ones((8, 8, 8), bool), "object_cells_box": np.asarray(small.box, np.float32)}
    before = _opacity(plain, small, pixels)
    spared = _opacity(_fit(small, 1.0, pixels, every, spare=True), small, pixels)
    ignored = _opacity(_fit(small, 1.0, pixels, every), small, pixels)
    assert spared > 0.8 * before and ignored < 0.5 * before, (before, spared, ignored)


def test_the_cameras_azimuth_span_is_360_less_the_widest_gap():
    from snapshot3d.cameras import azimuth_span_deg, look_at

    def ring(degrees, centre=(0.5, -0.2, 0.0)):
        c = np.asarray(centre)
        return np.stack([look_at(c + [3 * np.cos(np.radians(a)), 3 * np.sin(np.radians(a)), 1.0], c) for a in degrees])
    assert azimuth_span_deg(ring([170, 190, 230, 290]), (0.5, -0.2, 0.0)) == pytest.approx(120)   # across +-180
    assert azimuth_span_deg(ring(np.arange(0, 360, 30)), (0.5, -0.2, 0.0)) == pytest.approx(330)
    assert azimuth_span_deg(ring([40]), (0.5, -0.2, 0.0)) == 0.0


def test_the_weight_is_on_by_itself_on_an_arc_and_off_on_a_walk_round():
    """--seen-ground-weight -1 (auto): make-capture's walks of 120 and 240 deg get SEEN_GROUND_WEIGHT, its default two
    turns 0; a weight given stays as given; -1 and >= 0 are the only values taken, in one line."""
    from snapshot3d.errors import UserError
    from snapshot3d.synth_camera import walk_poses
    from snapshot3d.train.field.commands import SEEN_GROUND_WEIGHT, seen_ground_auto
    from snapshot3d.train.field.config import FitConfig, check_fit_config
    centre = np.array([0.1, 0.0, -0.2])
    walk = walk_poses(42, centre, 1.0, 2.0, np.random.default_rng(3))
    for degrees in (120, 240):
        arc = walk_poses(42, centre, 1.0, 2.0, np.random.default_rng(3), arc=np.radians(degrees))
        cfg, span = seen_ground_auto(FitConfig(), arc, centre)
        assert cfg.seen_ground_weight == SEEN_GROUND_WEIGHT > 0 and degrees - 20 < span < degrees + 5, (degrees, span)
    cfg, span = seen_ground_auto(FitConfig(), walk, centre)
    assert cfg.seen_ground_weight == 0.0 and span > 340
    assert seen_ground_auto(FitConfig(seen_ground_weight=0.5), walk, centre)[0].seen_ground_weight == 0.5
    with pytest.raises(UserError, match=r"^--seen-ground-weight must be >= 0, or -1 \(auto\), not -0.5$"):
        check_fit_config(FitConfig(seen_ground_weight=-0.5))
