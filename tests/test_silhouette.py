"""The object's silhouettes in the photos and the cells outside them (train/field/silhouette.py, issue 40's
floaters): GrabCut started from the planes' opacity drops what shows the ground's colours, the votes find the cells
outside the silhouettes, and the object-alone step cuts a fin of ground-coloured density that the photos do not
show."""
import cv2
import numpy as np
import pytest
import torch

from snapshot3d.bundle import projection
from snapshot3d.cameras import orbit_poses
from snapshot3d.errors import UserError
from snapshot3d.train.field.config import FitConfig, check_fit_config
from snapshot3d.train.field.silhouette import outside_share, photo_silhouettes


def _ground(h: int, w: int, seed: int = 0) -> np.ndarray:
    """(h, w, 3) RGB a mottled green-grey texture, like the composites' ground and backdrop."""
    noise = cv2.GaussianBlur(np.random.default_rng(seed).random((h, w, 3)).astype(np.float32), (0, 0), 2.0)
    return np.clip(np.array([0.35, 0.45, 0.3], np.float32) + 0.5 * (noise - 0.5), 0, 1)


def test_the_cut_keeps_the_body_and_its_legs_and_drops_the_ground_between_them():
    """A white body on two legs over a textured ground; the planes' opacity also covers the gap between the legs
    (the skirt), where the photo shows the ground: the cut keeps the body and legs and drops the gap's core."""
    h, w = 96, 128
    photo = _ground(h, w)
    body = np.zeros((h, w), bool)
    body[20:60, 40:90] = True
    body[60:78, 40:48] = body[60:78, 82:90] = True   # legs
    photo[body] = (0.92, 0.9, 0.88)
    skirt = np.zeros((h, w), bool)
    skirt[60:78, 48:82] = True
    cover = (body | skirt).astype(np.float32)
    (mask,) = photo_silhouettes(photo[None], cover[None])
    assert mask[body].mean() > 0.99, mask[body].mean()
    core = cv2.erode(skirt.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0   # farther than the grown 3 px
    assert core.any() and mask[core].mean() < 0.1, mask[core].mean()
    assert not mask[:10].any(), "the ground far from the planes is not the object"


def test_a_cut_not_grown_lies_inside_the_grown_one_by_the_grow():
    """The same photo cut with grow=0 and the default grow (GROW of the longer side, 2 px at 128): the grown mask is
    the tight one dilated by 2 px, so it holds it, and holds no pixel farther than 2 px from it."""
    h, w = 96, 128
    photo = _ground(h, w)
    body = np.zeros((h, w), bool)
    body[20:60, 40:90] = True
    photo[body] = (0.92, 0.9, 0.88)
    cover = body.astype(np.float32)[None]
    (tight,), (grown,) = photo_silhouettes(photo[None], cover, grow=0), photo_silhouettes(photo[None], cover)
    assert tight[body].mean() > 0.99 and (tight & ~body).mean() < 0.01
    assert np.array_equal(grown, cv2.dilate(tight.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0)


def test_a_view_with_nothing_opaque_or_nothing_shown_has_no_silhouette():
    photo = _ground(32, 32)[None]
    assert photo_silhouettes(photo, np.zeros((1, 32, 32), np.float32)) == [None]
    assert photo_silhouettes(photo, np.ones((1, 32, 32), np.float32)) == [None]   # nothing to learn the ground from
    disc = (np.hypot(*np.mgrid[-16:16, -16:16]) < 8).astype(np.float32)[None]
    assert photo_silhouettes(photo, disc) == [None]   # the photo shows nothing of it: the cut keeps too little


def test_points_outside_the_silhouettes_are_voted_out_and_views_without_one_do_not_vote():
    """A ring of cameras round a sphere of radius 0.5: its centre and a point inside it are in every silhouette, a
    point 1.2 to the side is outside in most views; a view without a mask does not count, a point in no image
    scores 0."""
    c2w = orbit_poses(12, 3.5, 30.0)
    intr = np.tile([40.0, 40.0, 24.0, 24.0], (12, 1))
    rng = np.random.default_rng(0)
    ball = rng.normal(size=(4000, 3))
    ball = 0.5 * ball / np.linalg.norm(ball, axis=1, keepdims=True) * rng.random((4000, 1)) ** (1 / 3)
    masks = []
    for pose, k in zip(c2w, intr):
        x = np.c_[ball, np.ones(len(ball))] @ projection(pose, k).T
        uv = np.floor(x[:, :2] / x[:, 2:]).astype(int)
        m = np.zeros((48, 48), bool)
        m[uv[:, 1].clip(0, 47), uv[:, 0].clip(0, 47)] = True
        masks.append(m)
    points = np.array([[0.0, 0.0, 0.0], [0.1, -0.2, 0.2], [1.2, 0.0, 0.0], [0.0, 0.0, 40.0]])
    share = outside_share(points, c2w, intr, masks)
    assert share[0] == 0 and share[1] == 0 and share[2] > 0.5 and share[3] == 0, share
    masks[0] = None
    fewer = outside_share(points, c2w, intr, masks)
    assert fewer[0] == 0 and fewer[2] > 0.5 and fewer[2] != share[2], (fewer, share)


def test_the_object_alone_step_cuts_a_skirt_under_the_belly_the_photos_do_not_show():
    """Planes fitted to a red body on two legs, a skirt in the floor band between the legs under the belly and a
    fin beside the body over the band; the photos show the body and legs alone over a textured ground. With
    --object-silhouette 0.2 the skirt's cells are cut and the body's and legs' kept; the fin, over the band, stays
    (there the object's thin parts are not left to the photos' cuts); with 1 (off) all stay. Where the photos show
    nothing of the planes, nothing is cut. With --object-halo 0.2 too, the solid cells all stay and most of what
    growing added round the fin, which no photo shows, is cut."""
    from dataclasses import replace

    from snapshot3d.posed import PosedImages
    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.fit import fit
    from snapshot3d.train.field.object_carve import object_views
    from snapshot3d.train.field.render import render_views

    box = np.array([[-1, -1, -1], [1, 1, 1]], np.float32)
    decoder = load_decoder()
    c2w = np.asarray(orbit_poses(12, 3.5, 10.0), np.float32)   # low, so that the gap under the belly shows
    intr = np.tile(np.array([[160.0, 160.0, 48.0, 48.0]], np.float32), (len(c2w), 1))
    body, skirt, fin = (torch.zeros(64, 64, 64, dtype=torch.bool) for _ in range(3))
    body[16:48, 26:38, 9:36] = True                                # the belly at z 9, over the band (0..6)
    body[16:24, 26:38, 0:9] = body[40:48, 26:38, 0:9] = True       # legs
    skirt[24:40, 26:38, 0:6] = True
    fin[48:60, 30:34, 14:30] = True
    red = np.broadcast_to(np.array([0.7, 0.2, 0.2], np.float32), (len(c2w), 96, 96, 3)).copy()
    shape = PosedImages(images=red, alpha=None, c2w=c2w, intrinsics=intr, box=box, train=np.arange(len(c2w)),
                        test=np.arange(0), name="cow")
    cfg = FitConfig(steps=60, batch_rays=1024, plane_res=32, plane_channels=4, occ_warmup=8, background="white")
    planes = fit(shape, decoder, cfg, hull=body | skirt | fin).state.planes.planes.detach()
    views, cover = render_views(planes, decoder, box, c2w, intr, 96, 96, occ=body, with_opacity=True)
    ground = np.stack([_ground(96, 96, seed) for seed in range(len(c2w))])
    cover = np.clip(cover, 0, 1)[..., None]
    photos = (views - (1 - cover) + (1 - cover) * ground).clip(0, 1).astype(np.float32)
    posed = PosedImages(images=photos, alpha=None, c2w=c2w, intrinsics=intr, box=box, train=np.arange(len(c2w)),
                        test=np.arange(0), name="cow")
    _, cut = object_views(planes, decoder, posed, silhouette=0.2)
    _, kept = object_views(planes, decoder, posed, silhouette=1.0)
    at_skirt, at_fin = (slice(28, 36), slice(28, 36), slice(1, 5)), (slice(50, 58), slice(30, 34), slice(18, 26))
    at_body, at_legs = (slice(20, 44), slice(28, 36), slice(12, 32)), (slice(18, 22), slice(28, 36), slice(1, 5))
    assert kept[at_skirt].float().mean() > 0.9 and kept[at_fin].float().mean() > 0.9, "not solid before the cut"
    assert cut[at_skirt].float().mean() < 0.2, cut[at_skirt].float().mean()   # measured 0.09
    assert cut[at_body].all() and cut[at_legs].all() and torch.equal(cut[at_fin], kept[at_fin])
    # --object-halo: what growing added round the fin, which no photo shows, is cut; the solid cells all stay
    from snapshot3d.formats import OCC_RES
    from snapshot3d.train.field.object_carve import object_cells
    from snapshot3d.train.field.render import cell_alpha
    _, haloed = object_views(planes, decoder, posed, silhouette=0.2, halo=0.2)
    core = torch.from_numpy(object_cells(*cell_alpha(planes, decoder, box, OCC_RES, with_rgb=True), near=0))
    assert not (haloed & ~cut).any() and not (cut & core & ~haloed).any()
    assert haloed[at_body].all() and haloed[at_legs].all() and haloed[at_fin].float().mean() > 0.5
    round_fin = torch.zeros_like(cut)
    round_fin[51:62, 27:37, 12:32] = True   # past the body's own growth
    round_fin &= ~fin
    assert (haloed & round_fin).sum() < 0.5 * (cut & round_fin).sum()   # measured 271 of 1602
    # photos of the ground alone: every cut fails (keeps less than half the opaque pixels), and no view votes
    _, none_seen = object_views(planes, decoder, replace(posed, images=ground.astype(np.float32)), silhouette=0.2)
    assert torch.equal(none_seen, kept)


def test_the_silhouette_share_is_checked_in_one_line():
    with pytest.raises(UserError, match="--object-silhouette must be in"):
        check_fit_config(FitConfig(background="outer", object_silhouette=1.5))
    assert check_fit_config(FitConfig(background="outer", object_silhouette=1.0)).object_silhouette == 1.0


def test_the_band_vote_cuts_a_skirt_and_keeps_back_a_broad_base_the_photos_hold():
    """In the floor band (the lowest 2 of 6 layers): a kept cell outside the silhouettes in 30% of its views is cut,
    one outside in 10% stays; a base cell the band's rule dropped comes back only with --object-base-keep over 0
    and only where it is outside in fewer than that share of its views; nothing over the band changes."""
    from snapshot3d.train.field.object_carve import band_vote

    cells = np.zeros((4, 4, 6), bool)
    cells[1, 1, :] = cells[2, 2, 0] = cells[3, 3, 0] = True
    loose = cells.copy()
    loose[0, 0, :2] = loose[0, 1, 0] = True          # a broad base the band's rule dropped
    outside = np.zeros((4, 4, 2))
    outside[2, 2, 0], outside[3, 3, 0] = 0.3, 0.1    # a skirt, and a cell the photos mostly hold
    outside[0, 1, 0] = 0.1                           # a base cell the photos hold less often
    got = band_vote(cells, loose, outside, 0.2, 0.0)
    assert not got[2, 2, 0] and got[3, 3, 0] and got[1, 1].all() and not got[0].any()
    assert np.array_equal(band_vote(cells, None, outside, 0.2, 0.05), got)
    back = band_vote(cells, loose, outside, 0.2, 0.05)
    assert back[0, 0, :2].all() and not back[0, 1, 0] and np.array_equal(back[1:], got[1:])
    assert np.array_equal(back[:, :, 2:], cells[:, :, 2:])


def test_the_base_keep_option_is_checked():
    with pytest.raises(UserError, match="--object-base-keep must be in"):
        check_fit_config(FitConfig(object_base_keep=1.5))


def test_the_halo_vote_cuts_only_what_growing_added():
    """A core of cells and what growing added round it: an added cell outside the silhouettes in 30% of its views is
    cut at any height, one outside in 10% stays, and a core cell stays however often the photos miss it (a dark
    hoof that GrabCut gives to its shadow); cells that were not the object's stay out."""
    from snapshot3d.train.field.object_carve import halo_vote

    core = np.zeros((5, 5, 5), bool)
    core[2, 2, :] = True
    cells = core.copy()
    cells[1, 2, :] = cells[3, 2, :] = True            # what growing added
    outside = np.zeros((5, 5, 5))
    outside[1, 2, :] = 0.3                            # a halo the photos do not hold, at every height
    outside[3, 2, :] = 0.1
    outside[2, 2, 0] = 0.9                            # a core cell the photos' cut misses
    outside[0, 0, 0] = 0.0                            # not the object's: stays out
    got = halo_vote(cells, core, outside, 0.2)
    assert not got[1, 2].any() and got[3, 2].all() and got[2, 2].all() and not got[0, 0, 0]
    assert np.array_equal(halo_vote(cells, core, outside, 1.0), cells)


def test_the_halo_option_is_checked():
    with pytest.raises(UserError, match="--object-halo must be in"):
        check_fit_config(FitConfig(object_halo=-0.1))
