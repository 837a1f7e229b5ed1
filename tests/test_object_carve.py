"""The object alone out of a fit with the background model (train/field/object_carve.py, issue 40's floaters): the
object's cells keep what stands on the floor and drop the ground round it, far haze and a separate floater; the
planes fitted to the object's own views empty the other cells and keep the object's."""
import numpy as np
import pytest
import torch

from snapshot3d.errors import UserError
from snapshot3d.train.field.config import FitConfig, check_fit_config
from snapshot3d.train.field.object_carve import FOOTPRINT, NEAR, object_cells


def _scene(g: int = 64) -> np.ndarray:
    """(g, g, g) opacity [ix, iy, iz]: faint haze, a ground slab over the floor band, a column standing on it and a
    small dense floater far from it."""
    alpha = np.full((g, g, g), 0.05, np.float32)
    alpha[:, :, :3] = 0.9                 # the ground's texture painted into the lowest layers
    alpha[20:28, 20:28, :40] = 0.95       # the object, from the floor up
    alpha[50:53, 50:53, 50:53] = 0.9      # a floater
    return alpha


def test_the_object_keeps_its_foot_and_loses_the_ground_the_haze_and_a_floater():
    keep = object_cells(_scene())
    assert keep[20:28, 20:28, :40].all()                  # the column, its foot in the floor band included
    assert not keep[5, 5, 1] and not keep[60, 40, 0]      # the ground away from it
    assert not keep[51, 51, 51]                           # the floater, apart from the object
    assert not keep[5, 60, 30]                            # haze far from the object
    assert keep[27 + NEAR, 24, 20] and not keep[28 + NEAR, 24, 20]   # grown by NEAR cells, not more ...
    assert keep[28, 24, 1] and not keep[29, 24, 1]        # ... and in the floor band only by REACH (1)
    assert keep.mean() < (8 + 2 * NEAR) ** 2 * (40 + NEAR) / 64 ** 3   # the column grown by NEAR cells, nothing else


def _wide_base(base_rgb) -> tuple[np.ndarray, np.ndarray]:
    """The column of `_scene` under a round body and on a round base as wide, in the floor band's lower layers, a
    shadow ring round the base: (alpha (g, g, g), rgb (g, g, g, 3) RGB); the object tan, the ground and the shadow
    grey, the base `base_rgb`."""
    alpha = _scene()
    rgb = np.empty(alpha.shape + (3,), np.float32)
    rgb[:] = (0.8, 0.6, 0.4)                      # the object (and the haze) tan
    rgb[:, :, :3] = (0.2, 0.2, 0.2)               # the ground grey
    x, y = np.meshgrid(np.arange(64), np.arange(64), indexing="ij")
    r = np.hypot(x - 23.5, y - 23.5)              # from the column's axis
    base, shadow = r <= 8.5, (r > 8.5) & (r <= 11.5)
    alpha[base, 14:30] = 0.95                     # a body as wide as the base, on the column
    alpha[base, 2:5], rgb[base, 2:5] = 0.95, base_rgb   # over the ground's texture, as a fit paints it
    alpha[shadow, :6], rgb[shadow, :6] = 0.9, (0.2, 0.2, 0.2)   # painted a few layers up
    return alpha, rgb


def test_a_base_wider_than_what_stands_over_it_is_kept_where_its_colour_is_the_bodys():
    alpha, rgb = _wide_base((0.75, 0.55, 0.4))
    keep = object_cells(alpha, rgb)
    assert keep[16, 24, 2] and keep[31, 24, 3] and keep[24, 29, 4]   # the base, beyond what stands over the band
    assert not keep[15, 24, 3] and not keep[24, 35, 4]    # the shadow round it, solid too, in the ground's colour
    assert not keep[5, 5, 1] and not keep[60, 40, 0]      # the ground away from it
    assert not object_cells(alpha)[16, 24, 2]              # without the colours, the band keeps what stands only
    assert (object_cells(alpha) <= keep).all()             # the colours only add cells


def test_a_base_in_the_grounds_colour_stays_to_what_stands():
    alpha, rgb = _wide_base((0.22, 0.2, 0.2))
    np.testing.assert_array_equal(object_cells(alpha, rgb), object_cells(alpha))


def test_a_base_is_not_widened_beyond_the_objects_footprint():
    alpha, rgb = _wide_base((0.8, 0.6, 0.4))
    alpha[24:, 20:28, 2:5], rgb[24:, 20:28, 2:5] = 0.95, (0.8, 0.6, 0.4)   # a strip in the body's colour, to the side
    band = object_cells(alpha, rgb)[:, :, :5]
    x, y = np.nonzero(band.any(axis=2))
    assert np.hypot(x - 23.5, y - 23.5).max() <= 8.5 + FOOTPRINT + 1   # the body's footprint, grown as the rule says
    assert band[31, 24, 2] and not band[40:, 24].any()


def test_the_colours_decide_nothing_where_the_ground_is_the_bodys_colour():
    alpha, rgb = _wide_base((0.8, 0.6, 0.4))
    rgb[:, :, :3] = (0.8, 0.6, 0.4)               # the ground tan too: its colours are not told from the body's
    np.testing.assert_array_equal(object_cells(alpha, rgb), object_cells(alpha))


def test_nothing_solid_keeps_nothing():
    assert not object_cells(np.full((16, 16, 16), 0.1, np.float32)).any()


def test_a_ground_with_nothing_standing_on_it_keeps_nothing():
    alpha = np.full((64, 64, 64), 0.05, np.float32)
    alpha[:, :, :3] = 0.9                 # the ground's texture alone (skimage dilates an empty mask to one cell)
    assert not object_cells(alpha).any()


def test_the_steps_are_checked_in_one_line():
    with pytest.raises(UserError, match="--object-steps"):
        check_fit_config(FitConfig(background="outer", object_steps=-0.5))


def test_the_object_only_planes_empty_the_other_cells_and_keep_the_object():
    """Planes with a column and a ground slab: fitted to their own views with the slab cut, the slab's opacity
    falls to a small part of what it was and the column's stays."""
    from snapshot3d.cameras import orbit_poses
    from snapshot3d.posed import PosedImages
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.fit import fit
    from snapshot3d.train.field.object_carve import object_config, object_views
    from snapshot3d.train.field.render import cell_alpha

    box = np.array([[-1, -1, -1], [1, 1, 1]], np.float32)
    decoder = load_decoder()
    c2w = np.asarray(orbit_poses(12, 3.5, 30.0), np.float32)
    intr = np.tile(np.array([[40.0, 40.0, 24.0, 24.0]], np.float32), (len(c2w), 1))
    # a first fit to the shape: views of a column on a slab, given as the hull
    hull = torch.zeros(64, 64, 64, dtype=torch.bool)
    hull[24:40, 24:40, :48] = True
    hull[:, :, :4] = True
    posed = PosedImages(images=np.full((len(c2w), 48, 48, 3), 0.3, np.float32), alpha=None, c2w=c2w,
                        intrinsics=intr, box=box, train=np.arange(len(c2w)), test=np.arange(0), name="column")
    cfg = FitConfig(steps=60, batch_rays=1024, plane_res=32, plane_channels=4, occ_warmup=8, background="white")
    planes = fit(posed, decoder, cfg, hull=hull).state.planes.planes.detach()
    before = cell_alpha(planes, decoder, box, 64)
    column = (slice(24, 40), slice(24, 40), slice(10, 48))
    # measured (2026-11-26): the ground 0.92 -> 0.12 away from the column, the column 0.36 -> 0.33
    assert before[4:60, 4:60, 1].mean() > 0.5 and before[column].mean() > 0.25, "the first fit is not dense"
    target, keep = object_views(planes, decoder, posed)
    assert target.images.shape == (12, 48, 48, 3) and keep[30, 30, 20] and not keep[5, 5, 1]
    solid, _ = object_views(planes, decoder, posed, opaque=0.02)   # the same views, their opacity made solid
    soft = target.alpha
    assert np.all(solid.alpha[soft >= 0.52] == 1) and np.all(solid.alpha[soft <= 0.48] == 0)   # off the ramp's ends
    assert ((soft > 0.05) & (soft < 0.95)).mean() > 0.01, "the teacher has no soft pixels to make solid"
    alone = fit(target, decoder, object_config(FitConfig(steps=100, batch_rays=1024, plane_res=32, plane_channels=4)),
                init_planes=planes, hull=keep)
    after = cell_alpha(alone.state.planes.planes.detach(), decoder, box, 64)
    ground = np.ones((64, 64), bool)
    ground[20:44, 20:44] = False   # away from the column's foot
    assert after[:, :, 1][ground].mean() < 0.3 * before[:, :, 1][ground].mean(), (after[:, :, 1][ground].mean(),
                                                                                    before[:, :, 1][ground].mean())
    assert after[column].mean() > 0.8 * before[column].mean(), (after[column].mean(), before[column].mean())


def test_a_fit_whose_box_found_no_ground_skips_the_step():
    """The automatic box looked for the ground and did not find it (ground_z None): the fit ends as without the
    step; with the ground found, the step changes the planes."""
    from dataclasses import replace

    from snapshot3d.cameras import orbit_poses
    from snapshot3d.posed import PosedImages
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.fit import fit

    c2w = np.asarray(orbit_poses(6, 3.5, 30.0), np.float32)
    rng = np.random.default_rng(0)
    posed = PosedImages(images=rng.random((6, 24, 24, 3), dtype=np.float32), alpha=None, c2w=c2w,
                        intrinsics=np.tile(np.array([[20.0, 20.0, 12.0, 12.0]], np.float32), (6, 1)),
                        box=np.array([[-1, -1, -1], [1, 1, 1]], np.float32), train=np.arange(6), test=np.arange(0))
    cfg = FitConfig(steps=20, batch_rays=256, plane_res=16, plane_channels=4, occ_warmup=4, background="outer",
                    refine_poses="off")
    decoder = load_decoder()
    codes, bars = {}, []
    for name, ground, steps in (("lost", None, 0.5), ("off", None, 0.0), ("found", -1.0, 0.5)):
        bar = lambda n, name=name: bars.append((name, n)) or (lambda step, psnr: None)  # noqa: E731
        codes[name] = fit(replace(posed, info={"ground_z": ground}), decoder, replace(cfg, object_steps=steps),
                          object_bar=bar).codes
    assert np.array_equal(codes["lost"], codes["off"])
    assert not np.array_equal(codes["found"], codes["off"])
    assert bars == [("found", 10)]   # the step's own progress, for its 10 steps


def test_a_pixel_over_white_is_recomposited_over_another_colour():
    from snapshot3d.train.field.rays import recomposite

    colour, cover = torch.tensor([[0.2, 0.5, 0.9], [0.7, 0.1, 0.3]]), torch.tensor([0.25, 1.0])
    behind = torch.tensor([[0.0, 0.3, 1.0], [0.6, 0.6, 0.6]])
    over_white = colour * cover[:, None] + (1 - cover[:, None])
    assert torch.allclose(recomposite(over_white, cover, behind), colour * cover[:, None] + (1 - cover[:, None]) * behind)


def test_a_random_background_acts_where_the_images_carry_coverage_and_nowhere_else():
    """--random-background: a fit of images with coverage trains over random colours (other planes); one of images
    without coverage (a capture without masks) is the plain fit, bit for bit."""
    from dataclasses import replace

    from snapshot3d.cameras import orbit_poses
    from snapshot3d.posed import PosedImages
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.fit import fit

    c2w = np.asarray(orbit_poses(6, 3.5, 30.0), np.float32)
    rng = np.random.default_rng(0)
    cover = np.zeros((6, 24, 24), np.float32)
    cover[:, 8:16, 8:16] = 1.0
    posed = PosedImages(images=np.where(cover[..., None] > 0, rng.random((6, 24, 24, 3), dtype=np.float32), 1.0),
                        alpha=cover, c2w=c2w, intrinsics=np.tile(np.array([[20.0, 20.0, 12.0, 12.0]], np.float32), (6, 1)),
                        box=np.array([[-1, -1, -1], [1, 1, 1]], np.float32), train=np.arange(6), test=np.arange(0))
    cfg = FitConfig(steps=12, batch_rays=256, plane_res=16, plane_channels=4, occ_warmup=4, background="white")
    hull = torch.ones(64, 64, 64, dtype=torch.bool)
    decoder = load_decoder()
    codes = {(name, rb): fit(p, decoder, replace(cfg, random_background=rb), hull=hull).codes
             for name, p in (("cover", posed), ("none", replace(posed, alpha=None))) for rb in (False, True)}
    assert not np.array_equal(codes["cover", True], codes["cover", False])
    assert np.array_equal(codes["none", True], codes["none", False])


def test_the_object_takes_the_photos_colour_where_it_is_opaque_and_its_own_at_its_edge():
    from snapshot3d.train.field.object_carve import PHOTO_RAMP, photo_colours

    own, photo = np.array([0.2, 0.4, 0.6], np.float32), np.array([0.7, 0.1, 0.3], np.float32)
    cover = np.array([[[1.0, 0.3, 0.0, PHOTO_RAMP[0] / 2 + PHOTO_RAMP[1] / 2]]], np.float32)   # (1, 1, 4)
    views = (cover[..., None] * own + (1 - cover[..., None])).astype(np.float32)   # the render over white
    out = photo_colours(views, cover, np.broadcast_to(photo, views.shape))
    assert out.shape == views.shape and out.dtype == np.float32
    np.testing.assert_allclose(out[0, 0, 0], photo, rtol=1e-6, atol=1e-6)            # opaque: the photo's colour
    np.testing.assert_allclose(out[0, 0, 1], views[0, 0, 1], rtol=1e-6, atol=1e-6)   # a soft edge: its own
    np.testing.assert_allclose(out[0, 0, 2], 1.0, rtol=1e-6, atol=1e-6)              # nothing: white
    a = cover[0, 0, 3]
    half = a * (own + photo) / 2 + 1 - a   # half way up the ramp: half the photo's colour, half its own
    np.testing.assert_allclose(out[0, 0, 3], half, rtol=1e-5, atol=1e-5)


def test_the_views_made_solid_keep_their_colour_and_their_half_way_outline():
    from snapshot3d.train.field.object_carve import photo_colours, solid_cover

    cover = np.array([[[0.0, 0.2, 0.25, 0.5, 0.6, 0.75, 0.92, 1.0]]], np.float32)   # (1, 1, 8)
    np.testing.assert_array_equal(solid_cover(cover, 1.0), cover)
    solid = solid_cover(cover, 0.5)
    np.testing.assert_allclose(solid[0, 0], [0, 0, 0, 0.5, 0.7, 1, 1, 1], rtol=1e-6, atol=1e-6)
    own, photo = np.array([0.2, 0.4, 0.6], np.float32), np.array([0.7, 0.1, 0.3], np.float32)
    views = (cover[..., None] * own + (1 - cover[..., None])).astype(np.float32)
    photos = np.broadcast_to(photo, views.shape)
    plain, pushed = photo_colours(views, cover, photos), photo_colours(views, cover, photos, solid=solid)
    both = (cover[0, 0] > 1e-3) & (solid[0, 0] > 1e-3)   # the colour under each opacity: the same either way
    under = [(out[0, 0, both] - (1 - a[0, 0, both, None])) / a[0, 0, both, None] for out, a in ((plain, cover),
                                                                                               (pushed, solid))]
    np.testing.assert_allclose(under[0], under[1], rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(pushed[0, 0, ~(solid[0, 0] > 0)], 1.0, rtol=1e-6, atol=1e-6)   # below the ramp: white
    np.testing.assert_allclose(pushed[0, 0, 6], photo, rtol=1e-6, atol=1e-6)   # 0.92 opaque now, the photo's colour


def test_the_views_made_solid_on_a_finer_grid_keep_an_anti_aliased_outline():
    from snapshot3d.train.field.object_carve import solid_cover

    h = w = 40
    y, x = np.mgrid[0:h, 0:w] + 0.5                      # pixel centres
    radius, centre = 11.3, (20.2, 19.7)
    dist = np.hypot(x - centre[0], y - centre[1])
    cover = np.clip(0.5 - (dist - radius) / 3, 0, 1).astype(np.float32)[None]   # (1, H, W): a soft disc, half at r
    k = 16                                               # the disc's true share of each pixel
    fy, fx = (np.mgrid[0:h * k, 0:w * k] + 0.5) / k
    truth = (np.hypot(fx - centre[0], fy - centre[1]) < radius).reshape(h, k, w, k).mean(axis=(1, 3))
    step, fine = solid_cover(cover, 0.02), solid_cover(cover, 0.02, subpixel=8)
    assert fine.shape == cover.shape and fine.dtype == np.float32
    np.testing.assert_allclose(solid_cover(cover[..., None], 0.02, subpixel=8)[..., 0], fine, rtol=1e-6, atol=1e-6)
    edge = (truth > 0) & (truth < 1)
    np.testing.assert_allclose(fine[0][truth == 1], 1.0, rtol=1e-6, atol=1e-3)   # inside: solid
    np.testing.assert_allclose(fine[0][dist > radius + 2], 0.0, rtol=1e-6, atol=1e-6)   # outside: nothing
    err_fine, err_step = np.abs(fine[0] - truth)[edge].mean(), np.abs(step[0] - truth)[edge].mean()
    assert err_fine < 0.03 and err_step > 5 * err_fine, (err_fine, err_step)   # measured 0.007 and 0.185
    assert abs(fine.sum() - np.pi * radius ** 2) < 0.01 * np.pi * radius ** 2
    np.testing.assert_array_equal(solid_cover(cover, 1.0, subpixel=8), cover)   # width 1: as it is


def test_the_finer_grid_is_chosen_for_coarse_planes_unless_given():
    from snapshot3d.errors import UserError
    from snapshot3d.train.field.config import FitConfig, check_fit_config
    from snapshot3d.train.field.object_carve import COARSE_RES, SUBPIXEL, subpixel_for

    assert [subpixel_for(0, r) for r in (16, 24, COARSE_RES, 48, 64)] == [SUBPIXEL] * 3 + [1, 1]   # auto
    assert subpixel_for(1, 16) == 1 and subpixel_for(8, 64) == 8   # given: as it is
    for bad in (-1, 17):
        with pytest.raises(UserError, match="--object-subpixel"):
            check_fit_config(FitConfig(object_subpixel=bad))


def test_the_refined_cameras_give_the_corrected_rays():
    from snapshot3d.cameras import orbit_poses
    from snapshot3d.train.field.object_carve import refined_c2w
    from snapshot3d.train.field.pose_refine import correct_rays
    from snapshot3d.train.field.rays import view_rays
    from snapshot3d.train.field.sampler import BoxFrame

    frame = BoxFrame.from_box(np.array([[-1, -2, -1], [3, 2, 1]], np.float32))   # scale 2: shifts are in q units
    c2w = np.asarray(orbit_poses(3, 6.0, 20.0), np.float32)
    params = np.array([[0.02, -0.01, 0.03, 0.05, 0.0, -0.02], [0, 0, 0, 0, 0, 0], [-0.04, 0.02, 0.0, 0.0, 0.1, 0.0]],
                      np.float32)
    intr = np.array([30.0, 30.0, 16.0, 12.0], np.float32)
    moved = refined_c2w(c2w, params, frame.scale)
    for v in range(3):
        o, d = view_rays(c2w[v], intr, 32, 24, frame)
        view = torch.full((o.shape[0],), v, dtype=torch.long)
        want_o, want_d = correct_rays(torch.from_numpy(params), view, o.float(), d.float())
        got_o, got_d = view_rays(moved[v], intr, 32, 24, frame)
        torch.testing.assert_close(got_o.float(), want_o, rtol=1e-4, atol=1e-4)
        torch.testing.assert_close(got_d.float(), want_d, rtol=1e-4, atol=1e-4)


def test_the_object_fit_runs_through_the_channel_only_as_asked():
    """--object-channel F trains the object fit's last F of steps through the print channel's noise; 0 leaves it to
    --channel-fraction, as before; auto is --qat-fraction for a print, else 0."""
    from dataclasses import replace

    from snapshot3d.errors import UserError
    from snapshot3d.train.field.commands import resolve_autos
    from snapshot3d.train.field.config import FitConfig, check_fit_config
    from snapshot3d.train.field.object_carve import object_config

    cfg = FitConfig(steps=100, background="outer", object_channel=0.0)
    assert object_config(cfg).channel_fraction == 0.0
    assert object_config(FitConfig(steps=100)).channel_fraction == 0.0   # auto left unresolved: off
    assert object_config(replace(cfg, object_channel=0.15)).channel_fraction == 0.15
    assert object_config(replace(cfg, channel_fraction=0.2)).channel_fraction == 0.2
    assert [resolve_autos(FitConfig(qat_fraction=0.2), "nerfstudio", m).object_channel
            for m in ("print", "file", None)] == [0.2, 0.0, 0.0]
    assert resolve_autos(FitConfig(object_channel=0.3), "nerfstudio", "print").object_channel == 0.3   # given
    for bad in (1.5, -0.5):
        with pytest.raises(UserError, match=rf"--object-channel must be in \[0, 1\], or -1 \(auto\), not {bad}"):
            check_fit_config(FitConfig(object_channel=bad))
