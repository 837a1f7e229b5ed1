"""fit --background outer (issue 40 item 2): the outer field is empty inside the box and never reaches the
snapshot; a fit with it leaves less density outside the object than the same fit on white; the automatic box
holds the object and is much smaller than the box placed by the cameras alone."""
import json

import numpy as np
import pytest
import torch
from helpers import assert_one_line_error, run_cli

from snapshot3d.auto_box import frustum_margins, overlap_box
from snapshot3d.capture import CaptureOptions, box_from_cameras
from snapshot3d.loaders import load_scene
from snapshot3d.make_capture import make_capture
from snapshot3d.make_capture_config import SynthCaptureConfig
from snapshot3d.scene import load_scene_file
from snapshot3d.train.field.background import OuterField, contract, outer_query, render_with_background
from snapshot3d.train.field.box_tighten import box_from_density
from snapshot3d.train.field.sampler import BoxFrame

KEEP = CaptureOptions(up=(0.0, 0.0, 1.0))


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    return make_capture("builtin:spot", tmp_path_factory.mktemp("bg") / "cap", SynthCaptureConfig(size=48, views=8))


def test_outer_field_is_zero_inside_the_box():
    g = torch.Generator().manual_seed(0)
    bg = OuterField(8)
    with torch.no_grad():
        bg.grid.copy_(torch.randn(bg.grid.shape, generator=g) * 3 + 2)   # dense everywhere the grid can say
    inside = torch.rand(4000, 3, generator=g) * 2 - 1
    outside = inside / inside.abs().amax(1, keepdim=True) * (1.01 + 10 * torch.rand(4000, 1, generator=g))
    with torch.no_grad():
        assert float(outer_query(bg.grid, inside)[0].abs().max()) == 0.0
        assert float(outer_query(bg.grid, outside)[0].min()) > 0.0
    c = contract(outside)
    assert torch.equal(contract(inside), inside)
    assert float(c.abs().amax(1).min()) > 1.0 and float(c.abs().amax(1).max()) < 2.0


def test_a_ray_that_misses_the_box_sees_the_background_alone():
    """No density anywhere: a ray past the box ends on the colour per direction; with the box opaque, a ray
    through it ends on the planes (the order before / box / after / beyond)."""
    from snapshot3d.train.field.decoder import load_decoder
    frame = BoxFrame.from_box(np.array([[-1, -1, -1], [1, 1, 1]], np.float32))
    bg = OuterField(8, init_density=-60.0)
    with torch.no_grad():
        bg.env.fill_(2.0)   # sigmoid(2) = 0.881
    o = torch.tensor([[0.0, 3.0, -5.0], [0.0, 0.0, -5.0]])
    d = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    dec = load_decoder()
    empty = torch.full((3, 8, 4, 4), -1.0)
    colour, acc, _ = render_with_background(empty, dec, frame, None, bg, o, d, 8)
    assert float(acc[0]) == 0.0
    assert torch.allclose(colour[0], torch.full((3,), float(torch.sigmoid(torch.tensor(2.0)))), atol=1e-5)


def test_the_snapshot_carries_the_planes_alone(capture, tmp_path):
    sizes = {}
    for bg in ("white", "auto"):   # auto: a room without masks gets the background model
        out = tmp_path / f"{bg}.s3d"
        proc = run_cli("fit", str(capture / "transforms.json"), "-o", str(out), "--steps", "4", "--batch-rays", "256",
                       "--plane-res", "16", "--plane-channels", "4", "--background", bg, "--up", "0,0,1",
                       "--report", str(tmp_path / f"{bg}.json"))
        assert proc.returncode == 0, proc.stderr
        report = json.loads((tmp_path / f"{bg}.json").read_text())
        assert not [k for k in report if k.startswith("_")]   # the benches' private entries stay out of it
        if bg == "auto":
            assert "background: outer (auto: no masks" in proc.stdout and report["background_mode"].startswith("outer")
            assert "object's own pixels" in report["field_psnr_on"] and report["capture"]["box_from"].startswith("auto")
        else:
            assert "background_mode" not in report and "object's" not in report["field_psnr_on"]
        sizes[bg] = out.stat().st_size
        with np.load(out) as z:
            assert sorted(z.files) == ["box", "codes", "header"]
            assert z["codes"].shape == (3, 4, 16, 16)
        assert load_scene_file(out).codes.shape == (3, 4, 16, 16)
    assert abs(sizes["auto"] - sizes["white"]) < 200   # the header's text differs (the box), never an array


def _share_outside(capture, background):
    from snapshot3d.train.field.commands import fit_scene
    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.object_score import density_share_outside_box
    cfg = FitConfig(steps=60, batch_rays=1024, plane_res=32, plane_channels=4, occ_warmup=16, background=background)
    scene = fit_scene(str(capture / "transforms.json"), cfg, quiet=True,
                      capture=CaptureOptions(up=(0.0, 0.0, 1.0), box="auto" if background == "outer" else None)).scene
    true_box = json.loads((capture / "gt/truth.json").read_text())["box"]
    return density_share_outside_box(torch.from_numpy(scene.planes()), load_decoder(), scene.box, true_box)


@pytest.mark.slow
def test_the_background_model_leaves_less_density_outside_the_object(capture):
    white, outer = _share_outside(capture, "white"), _share_outside(capture, "outer")
    # measured (2026-11-26, 2 cores): white 0.967, outer 0.868 (the room fills the box on white)
    assert white > 0.9, white
    assert outer < white - 0.05, (outer, white)


def test_the_automatic_box_holds_the_object_and_is_much_smaller(capture):
    posed = load_scene(str(capture / "transforms.json"), capture=CaptureOptions(up=(0.0, 0.0, 1.0), box="auto"))
    true_box = np.array(json.loads((capture / "gt/truth.json").read_text())["box"])
    cams = box_from_cameras(posed.c2w)
    assert posed.info["capture"]["box_from"].startswith("auto")
    assert np.all(posed.box[0] <= true_box[0]) and np.all(posed.box[1] >= true_box[1])
    vol = lambda b: float(np.prod(b[1] - b[0]))  # noqa: E731
    assert vol(posed.box) < 0.4 * vol(cams), (posed.box, cams)
    assert np.allclose(overlap_box(posed.c2w, posed.intrinsics, posed.width, posed.height), posed.box)


def test_frustum_margins_of_a_camera_looking_at_the_point():
    c2w = np.eye(4)[None].copy()
    c2w[0, 2, 3] = 5.0   # at z = 5 looking down -z at the origin
    intr = np.array([[50.0, 50.0, 50.0, 50.0]])   # 100 x 100 px, half-angle atan(1) = 45 degrees
    m = frustum_margins(np.zeros(3), c2w, intr, 100, 100)
    assert m[0] == pytest.approx(5 * np.sin(np.pi / 4), rel=1e-6)
    assert frustum_margins(np.array([0, 0, 6.0]), c2w, intr, 100, 100)[0] == -np.inf   # behind the camera


def test_the_ground_is_found_and_cut_away():
    g = 32
    alpha = np.full((g, g, g), 0.02)
    alpha[:, :, :9] = 0.6              # a floor up to cell 9 of 32 (and what lies under it)
    alpha[12:20, 10:22, 9:20] = 1.0    # an object standing on it
    box = np.array([[-1, -1, -1], [1, 1, 1]], np.float64)
    out, ground = box_from_density(alpha, box, looks_down=True)
    assert ground == pytest.approx(-1 + 9 * 2 / g)
    assert out[0, 2] == pytest.approx(ground) and np.allclose(out[1], 1) and np.allclose(out[0, :2], -1)
    assert box_from_density(alpha, box, looks_down=False)[1] is None
    alpha[:, :, :9] = 0.02             # no floor: the object's base alone is not taken for one
    assert box_from_density(alpha, box, looks_down=True)[1] is None


def test_a_ray_that_leaves_through_the_ground_floor_ends_on_its_texture():
    """With the floor texture (the box's floor is the ground found), a ray down through the empty box ends on the
    texture at the point where it leaves, whatever lies beyond; a ray out of a side does not."""
    from snapshot3d.train.field.decoder import load_decoder
    frame = BoxFrame.from_box(np.array([[-1, -1, -1], [1, 1, 1]], np.float32))
    bg = OuterField(8, init_density=-60.0, floor=4)
    with torch.no_grad():
        bg.floor.copy_(torch.tensor([[-3.0, -1.0, 1.0, 3.0]]).expand(1, 3, 4, 4))   # the colour varies with x
        bg.env.fill_(-8.0)   # beyond: dark
    o = torch.tensor([[-0.75, 0.0, 5.0], [0.75, 0.0, 5.0], [-5.0, 0.0, 0.5]])
    d = torch.tensor([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    empty = torch.full((3, 8, 4, 4), -1.0)
    colour, acc, _ = render_with_background(empty, load_decoder(), frame, None, bg, o, d, 8)
    floor = torch.sigmoid(torch.tensor([-3.0, 3.0]))   # texel centres at x = -0.75 and 0.75
    assert float(acc.max()) < 1e-3
    assert torch.allclose(colour[:2, 0], floor, atol=1e-3) and torch.allclose(colour[2], torch.zeros(3), atol=0.02)
    # a slanted ray meets a plane `depth` below the floor further along: x = 0.25 at the floor, 0.75 at depth 1
    from snapshot3d.train.field.background import floor_colour
    o1, d1 = torch.tensor([[-2.25, 0.0, 4.0]]), torch.nn.functional.normalize(torch.tensor([[0.5, 0.0, -1.0]]), dim=1)
    t_out = torch.tensor([5.0 * float(1 / d1[0, 2].abs())])
    for depth, logit in ((0.0, 1.0), (1.0, 3.0)):   # the texel centres at x = 0.25 and 0.75
        down, c = floor_colour(bg.floor, frame, o1, d1, t_out, torch.tensor([True]), depth)
        want = float(torch.sigmoid(torch.tensor(logit)))
        assert bool(down[0]) and abs(float(c[0, 0].detach()) - want) < 1e-3, (depth, float(c[0, 0].detach()), want)
    colour_before = colour.clone()
    bg.floor = None   # without the texture, the same downward rays end on the dark colour per direction
    colour, _, _ = render_with_background(empty, load_decoder(), frame, None, bg, o, d, 8)
    assert float(colour[:2].detach().max()) < 0.02 and not torch.allclose(colour, colour_before)


def test_an_unknown_background_is_refused_in_one_line():
    from snapshot3d.errors import UserError
    from snapshot3d.train.field.config import FitConfig, check_fit_config
    with pytest.raises(UserError, match="--background must be auto, white or outer, not 'black'"):
        check_fit_config(FitConfig(background="black"))
    with pytest.raises(UserError, match="--background-samples must be >= 2, not 1"):
        check_fit_config(FitConfig(background="outer", background_samples=1))


def test_the_distortion_loss_is_the_pairwise_sum_and_prefers_one_lump():
    from snapshot3d.train.field.background import distortion_loss
    g = torch.Generator().manual_seed(1)
    w = torch.rand(5, 30, generator=g, dtype=torch.float64) / 30
    t = torch.arange(30, dtype=torch.float64) * 0.07
    pairs = (w[:, :, None] * w[:, None, :] * (t[:, None] - t[None, :]).abs()).sum((1, 2)) + 0.07 / 3 * (w ** 2).sum(1)
    assert torch.allclose(distortion_loss(w, 0.07), pairs, rtol=1e-10)
    lump, spread = torch.zeros(1, 30), torch.zeros(1, 30)
    lump[0, 10:12], spread[0, ::6] = 0.45, 0.18   # the same opacity (0.9), on a surface or strewn along the ray
    assert float(distortion_loss(spread, 0.07)) > 10 * float(distortion_loss(lump, 0.07))   # 0.548 vs 0.038


def test_the_opacity_entropy_is_zero_at_the_ends_and_largest_halfway():
    from snapshot3d.train.field.background import opacity_entropy
    h = opacity_entropy(torch.tensor([0.0, 1.0, 0.5, 0.1]))
    assert float(h[:2].max()) < 2e-3
    assert float(h[2]) == pytest.approx(np.log(2), rel=1e-4) and 0.3 < float(h[3]) < float(h[2])


def test_wall_points_lie_near_the_sides_and_top_never_the_floor():
    from snapshot3d.train.field.background import wall_points
    u = wall_points(5000, 0.2, torch.Generator().manual_seed(0))
    assert float(u.abs().max()) <= 1.0
    side = (u[:, :2].abs() >= 0.8).any(1)
    top = u[:, 2] >= 0.8
    assert bool((side | top).all())
    assert float((u[:, 2] < -0.8).float().mean()) < 0.1   # only where a side band reaches down
    assert 0.1 < float(top.float().mean()) < 0.35          # one face in five


def test_floor_points_lie_in_the_floor_band_under_their_column():
    from snapshot3d.train.field.background import floor_points
    pts, above = floor_points(2000, 0.1, torch.Generator().manual_seed(0))
    assert float(pts[:, 2].min()) >= -1 and float(pts[:, 2].max()) <= -0.9
    assert float(pts[:, :2].abs().max()) <= 1 and float(pts[:, :2].std()) > 0.5   # the whole footprint
    assert torch.equal(above[:, :, :2], pts[:, None, :2].expand(-1, 3, -1))
    assert torch.allclose(above[0, :, 2], torch.tensor([-0.8, -0.7, -0.6]))


def test_the_weights_path_renders_the_same_colour():
    from snapshot3d.train.field.decoder import load_decoder
    frame = BoxFrame.from_box(np.array([[-1, -1, -1], [1, 1, 1]], np.float32))
    g = torch.Generator().manual_seed(3)
    bg, dec = OuterField(8), load_decoder()
    planes = torch.randn(3, 8, 16, 16, generator=g) * 0.5
    o = torch.randn(64, 3, generator=g) * 0.3 + torch.tensor([0.0, 0.0, -4.0])
    d = torch.nn.functional.normalize(torch.tensor([0.0, 0.0, 4.0]) - o + torch.randn(64, 3, generator=g) * 0.3, dim=1)
    a = render_with_background(planes, dec, frame, None, bg, o, d, 8)
    b = render_with_background(planes, dec, frame, None, bg, o, d, 8, extras=True)
    assert torch.allclose(a[0], b[0], atol=1e-6) and torch.allclose(a[1], b[1], atol=1e-6) and a[2] == b[2]
    assert b[3]["weights"].shape[0] == 64 and torch.allclose(b[3]["weights"].sum(1), b[1], atol=1e-5)
    empty = torch.full((3, 8, 4, 4), -1.0)   # no density in the box: the colour is the background's alone
    c = render_with_background(empty, dec, frame, None, bg, o, d, 8, extras=True)
    assert float(c[1].max()) < 1e-4 and torch.allclose(c[0], c[3]["background_alone"], atol=1e-4)


def test_negative_regulariser_weights_are_refused_in_one_line():
    from snapshot3d.errors import UserError
    from snapshot3d.train.field.config import FitConfig, check_fit_config
    with pytest.raises(UserError, match=r"^--distortion-weight must be >= 0, not -1.0$"):   # only the option that is wrong
        check_fit_config(FitConfig(background="outer", distortion_weight=-1.0))
    with pytest.raises(UserError, match=r"^--ground-depth must be >= 0, or -1 \(where the ground is\), not nan; "
                                        r"--wall-margin must be in \(0, 0.25\], not 0.5$"):
        check_fit_config(FitConfig(background="outer", ground_depth=float("nan"), wall_margin=0.5))
    with pytest.raises(UserError, match=r"^--ground-depth must be >= 0, or -1 \(where the ground is\), not -0.5$"):
        check_fit_config(FitConfig(background="outer", ground_depth=-0.5))


def test_the_ground_texture_lies_as_far_under_the_floor_as_the_floor_was_lifted():
    """The sparse box lifts its floor over the ground its points found (train/field/box_tighten.py reports by how
    much, `ground_depth`); by default the ground's texture lies that far under the floor, in q units; an explicit
    --ground-depth wins; no texture without a ground under the box or with --ground-texture 0."""
    from snapshot3d.posed import PosedImages
    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.fit import new_state
    c2w = np.tile(np.eye(4, dtype=np.float32), (2, 1, 1))
    c2w[:, 2, 3] = 4.0
    box = np.array([[-1, -1, -0.9], [1, 1, 1.1]], np.float32)

    def floor(info: dict, **fields):
        posed = PosedImages(images=np.ones((2, 8, 8, 3), np.float32), alpha=None, c2w=c2w,
                            intrinsics=np.tile(np.float32([8, 8, 4, 4]), (2, 1)), box=box, train=np.arange(2),
                            test=np.arange(0), name="ground", info=info)
        bg = new_state(posed, FitConfig(background="outer", **fields)).background
        return None if bg.floor is None else (tuple(bg.floor.shape), bg.floor_depth)

    scale = float(BoxFrame.from_box(box).scale)
    shape, depth = floor({"ground_z": -0.9, "ground_depth": 0.05})
    assert shape == (1, 3, 128, 128) and abs(depth - 0.05 / scale) < 1e-6
    assert floor({"ground_z": -0.9, "ground_depth": 0.05}, ground_depth=0.0)[1] == 0.0
    assert floor({"ground_z": -0.9})[1] == 0.0   # the ground a pre-fit's density found: the floor is on it
    assert floor({"ground_z": None}) is None and floor({"ground_z": -0.9}, ground_texture=0) is None


def test_bench_fit_captures_is_parsed_and_an_unknown_mode_refused(tmp_path):
    proc = run_cli("bench", "fit", "--help")
    assert proc.returncode == 0 and "--captures" in proc.stdout
    proc = run_cli("bench", "capture-background", "--modes", "outer,bogus", "--out", str(tmp_path))
    assert_one_line_error(proc, "unknown fit 'bogus'")
    assert not list(tmp_path.iterdir())
    proc = run_cli("bench", "capture-background", "--modes", "outer", "--fit-seeds", "0,x", "--out", str(tmp_path))
    assert_one_line_error(proc, "--fit-seeds must be comma-separated integers, not '0,x'")
    assert not list(tmp_path.iterdir())
    from snapshot3d.bench.capture_background import _fit_seeds
    assert _fit_seeds("", 2) == [2] and _fit_seeds("0,1,2", 2) == [0, 1, 2]


def test_bench_capture_chain_refuses_a_fit_with_masks_and_bad_photo_seeds_before_it_writes(tmp_path):
    out = tmp_path / "out"
    proc = run_cli("bench", "capture-chain", "--modes", "outer,masked", "--out", str(out))
    assert_one_line_error(proc, "unknown fit 'masked' (choose from the photos' fits")
    proc = run_cli("bench", "capture-chain", "--photo-seeds", "0,x", "--out", str(out))
    assert_one_line_error(proc, "--photo-seeds must be comma-separated integers, not '0,x'")
    assert not out.exists()
    from snapshot3d.bench.capture_chain import _cli
    from snapshot3d.errors import UserError
    with pytest.raises(UserError, match=r"^snapshot3d embed failed: .*missing\.s3d"):   # a step's own one line
        _cli("embed", str(tmp_path / "missing.s3d"), "-o", str(tmp_path / "x.png"))


def test_the_sides_and_top_are_cut_round_the_dense_cells_with_a_margin():
    g = 32
    rng = np.random.default_rng(0)
    alpha = rng.uniform(0, 0.3, (g, g, g))       # diffuse floaters everywhere
    alpha[:, :, :9] = 0.6                        # the floor
    alpha[12:20, 10:22, 9:20] = 0.95             # the object on it
    alpha[0, 0, 30] = 0.9                        # one dense speck in a corner does not hold the box open
    box = np.array([[-1, -1, -1], [1, 1, 1]], np.float64)
    out, ground = box_from_density(alpha, box, looks_down=True, sides=True)
    cell = 2 / g
    obj = np.array([[-1 + 12 * cell, -1 + 10 * cell, ground], [-1 + 20 * cell, -1 + 22 * cell, -1 + 20 * cell]])
    assert np.all(out[0] <= obj[0] + 1e-6) and np.all(out[1] >= obj[1] - 1e-6)   # the object is kept whole
    assert out[0, 2] == pytest.approx(ground)
    assert np.prod(out[1] - out[0]) < 0.4 * np.prod(box[1] - box[0]) * (1 - (ground + 1) / 2)
    assert np.allclose(box_from_density(alpha, box, True, sides=False)[0][[0, 1], :2], box[:, :2])


def test_the_background_regularisers_leave_a_fit_on_white_unchanged():
    """The regularisers act with --background outer alone: the default fit's steps are the same with them set."""
    from dataclasses import replace

    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.fit import fit
    posed = load_scene("builtin:spot", size=24)
    cfg = FitConfig(steps=3, batch_rays=128, plane_res=8, plane_channels=4)
    a = fit(posed, load_decoder(), cfg).state.planes.planes.detach()
    b = fit(posed, load_decoder(), replace(cfg, distortion_weight=1.0, opacity_weight=1.0, wall_weight=1.0,
                                           floor_weight=1.0)).state.planes.planes.detach()
    assert torch.equal(a, b)


def test_each_regulariser_adds_a_finite_term_with_a_gradient_into_the_planes():
    from snapshot3d.train.field.background import render_and_regularise
    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.decoder import load_decoder
    frame = BoxFrame.from_box(np.array([[-1, -1, -1], [1, 1, 1]], np.float32))
    g = torch.Generator().manual_seed(4)
    planes = (torch.randn(3, 8, 16, 16, generator=g) * 0.5).requires_grad_()
    o = torch.randn(64, 3, generator=g) * 0.3 + torch.tensor([0.0, 0.0, -4.0])
    d = torch.nn.functional.normalize(torch.tensor([0.0, 0.0, 4.0]) - o, dim=1)
    target = torch.rand(64, 3, generator=g)
    base = FitConfig(background="outer", background_samples=8, batch_rays=64)
    assert render_and_regularise(planes, load_decoder(), frame, None, OuterField(8), base, o, d, target, g)[2] is None
    for field in ("distortion_weight", "opacity_weight", "wall_weight", "floor_weight"):
        cfg = FitConfig(**{**base.__dict__, field: 1.0})
        _, _, term = render_and_regularise(planes, load_decoder(), frame, None, OuterField(8), cfg, o, d, target, g)
        grad, = torch.autograd.grad(term, planes)
        assert float(term.detach()) > 0 and np.isfinite(float(term.detach())), field
        assert float(grad.abs().sum()) > 0, field


def test_the_object_box_holds_the_objects_cells_with_a_margin_and_keeps_the_floor():
    from snapshot3d.train.field.box_tighten import OBJECT_MARGIN, cells_box
    box = np.array([[-2.0, -2.0, -1.0], [2.0, 2.0, 3.0]])   # 16 cells: 0.25 per cell on every axis
    cells = np.zeros((16, 16, 16), bool)
    cells[6:10, 5:12, 0:8] = True
    m = OBJECT_MARGIN * 0.25
    out = cells_box(cells, box)
    assert out.dtype == np.float32 and out.shape == (2, 3)
    np.testing.assert_allclose(out, [[-0.5 - m, -0.75 - m, -1.0], [0.5 + m, 1.0 + m, 1.0 + m]], rtol=1e-6,
                               atol=1e-6)
    cells[:, 15, 3] = True   # cells at the box's side: the box is not grown past it
    assert cells_box(cells, box)[1, 1] == 2.0
    np.testing.assert_array_equal(cells_box(np.zeros((16, 16, 16), bool), box), box.astype(np.float32))


def test_the_object_box_share_is_checked_in_one_line():
    from snapshot3d.errors import UserError
    from snapshot3d.train.field.config import FitConfig, check_fit_config
    with pytest.raises(UserError, match="--object-box"):
        check_fit_config(FitConfig(background="outer", object_box=1.5))


def test_a_bench_row_says_how_far_the_poses_lie_from_the_truth(capture):
    """bench capture-background's row on a capture of exact poses: the poses as written and as fitted (no adjustment
    with the true masks) lie on the truth (bench/pose_error.py)."""
    from snapshot3d.bench.capture_background import fit_and_score
    from snapshot3d.train.field.config import FitConfig
    row = fit_and_score(capture, "masked", FitConfig(steps=30, batch_rays=1024, plane_res=32, plane_channels=4,
                                                     occ_warmup=8))
    assert row["pose_px_written"] < 1e-3 and row["pose_px_fit"] < 1e-3, row
    assert row["object_psnr"] > 12, row
    assert 0 < row["object_coverage"] <= 1 and min(row["object_ring_psnr"], row["object_inner_psnr"]) > 8, row
    # scored against the object alone over white too (gt/transforms_white.json): the inside is the same pixels
    assert abs(row["object_clean_inner_psnr"] - row["object_inner_psnr"]) < 0.05, row
    assert row["object_clean_psnr"] > 12 and row["object_clean_ring_psnr"] != row["object_ring_psnr"], row
    # the opacity just outside the outline, by what lies behind it (the capture's cameras look down at the ground)
    assert all(0 <= row[k] <= 1 for k in ("edge_opacity_near", "edge_opacity_far", "edge_near_share")), row


def test_the_outline_split_counts_the_ring_and_the_inside_apart():
    """A 20x20 square object in a 40x40 view: errors on its two outer pixel rows and columns fall in the ring alone,
    errors at its centre in the inside alone; coverage is the mean opacity over the mask."""
    from snapshot3d.train.field.object_score import inner_mask, outline_split
    mask = np.zeros((40, 40), bool)
    mask[10:30, 10:30] = True
    gt = np.full((40, 40, 3), 0.5, np.float32)
    acc = np.where(mask, 1.0, 0.0).astype(np.float32)
    acc[10:20, 10:30] = 0.5
    rgb = gt.copy()
    rgb[10:30, 10:12] += 0.1   # the ring's left two columns
    s = outline_split(rgb, acc, gt, mask)
    ring = 20 * 20 - 16 * 16   # 144 pixels, 40 of them wrong by 0.1
    assert s["object_ring_psnr"] == pytest.approx(-10 * np.log10(0.01 * 40 / ring), rel=1e-6, abs=1e-3)
    assert s["object_inner_psnr"] == 100.0 and s["object_coverage"] == pytest.approx(0.75)
    rgb = gt.copy()
    rgb[19:21, 19:21] -= 0.2   # four pixels at the centre
    s = outline_split(rgb, acc, gt, mask)
    assert s["object_ring_psnr"] == 100.0
    assert s["object_inner_psnr"] == pytest.approx(-10 * np.log10(0.04 * 4 / 256), rel=1e-6, abs=1e-3)
    # the inside handed in (score_object erodes each mask once for both truths) reads the same; the 16x16 centre
    inner = inner_mask(mask)
    assert inner.sum() == 16 * 16 and outline_split(rgb, acc, gt, mask, inner=inner) == s


def test_the_edge_split_tells_the_ground_near_the_object_from_the_rest():
    """A camera 1 over the ground z = 0 at y = -5, looking level along +y: the rows under the horizon see the ground,
    those over it the room; with a footprint, only the rays that meet the ground inside it count (the bottom rows
    meet it nearest the camera). A 20x20 object in the middle of a 40x40 view with opacity 0.5 on the column just
    left of it and 0.25 on the row just under it: the near side holds the row under it and the column's lower half."""
    from snapshot3d.cameras import look_at
    from snapshot3d.train.field.object_score import _edges, edge_split, ground_pixels
    c2w = look_at(np.array([0.0, -5.0, 1.0]), np.array([0.0, 0.0, 1.0]))
    intr = (40.0, 40.0, 20.0, 20.0)
    ground = ground_pixels(c2w, intr, 40, 40, 0.0)
    assert ground[20:].all() and not ground[:20].any()
    assert not ground_pixels(c2w, intr, 40, 40, 2.0).any()   # the camera under the plane
    # row v meets the ground at y = -5 + 40 / (v + 0.5 - 20): row 39 at -2.95, row 24 at +3.89
    near = ground_pixels(c2w, intr, 40, 40, 0.0, np.array([[-10.0, -3.0], [10.0, 3.0]]))
    ys = -5 + 40 / (np.arange(40) + 0.5 - 20)
    assert np.array_equal(near[:, 20], (np.arange(40) >= 20) & (np.abs(ys) <= 3))
    mask = np.zeros((40, 40), bool)
    mask[10:30, 10:30] = True
    acc = mask.astype(np.float32)
    acc[10:30, 9] = 0.5
    acc[30, 10:30] = 0.25
    e = edge_split(acc, mask, ground)
    assert e["edge_near_n"] + e["edge_far_n"] == 4 * 20 + 4   # the ring of 8-neighbours, corners included
    assert e["edge_near_n"] == 2 * 11 + 20 and e["edge_far_n"] == 2 * 11 + 20   # rows 20-30 / 9-19 of the columns
    assert e["edge_near_sum"] == pytest.approx(10 * 0.5 + 20 * 0.25) and e["edge_far_sum"] == pytest.approx(5.0)
    out = _edges([e, e])
    assert out["edge_opacity_near"] == pytest.approx(10.0 / 42) and out["edge_opacity_far"] == pytest.approx(5.0 / 42)
    assert out["edge_near_share"] == pytest.approx(10.0 / 15.0)


def test_the_object_alone_scores_below_perfect_only_along_its_outline(capture):
    """The clean ceiling of a capture: the object over white taken as the render matches the masked photos inside
    the outline's ring (the same pixels) and not along it, where the photos blend in the room."""
    from snapshot3d.bench.capture_background import _ceiling
    c = _ceiling(capture)
    assert c["object_inner_psnr"] > 45, c
    assert 12 < c["object_ring_psnr"] < 35 and c["object_ring_psnr"] < c["object_psnr"] < c["object_inner_psnr"], c


def test_a_wider_ground_ends_the_rays_that_leave_through_the_box_s_sides():
    """The box [-1, 1]^3 (q = unit), the ground 0.5 under its floor: a ray leaving through a side, going down,
    meets the plane at x = 1.75 (within a reach of 2, past it at 1.5); the texture there is read at x / 2. A ray
    through the floor ends there at any reach; one going up never does."""
    from snapshot3d.train.field.background import floor_colour
    frame = BoxFrame.from_box(np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]), "cpu")
    assert torch.allclose(frame.half_unit, torch.ones(3))
    floor = torch.zeros(1, 3, 8, 8)
    floor[0, 0, :, 7] = 5.0   # red in the texture's last column: x in (0.75, 1] of its span
    d = torch.nn.functional.normalize(torch.tensor([[1.0, 0.0, -1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 1.0]]), dim=-1)
    o = torch.tensor([[0.25, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    t_out = torch.tensor([0.75 * 2 ** 0.5, 1.0, 2 ** 0.5])   # the side x = 1, the floor, the side
    hit = torch.ones(3, dtype=torch.bool)
    down, rgb = floor_colour(floor, frame, o, d, t_out, hit, depth=0.5, reach=2.0)
    assert down.tolist() == [True, True, False]
    assert rgb[0, 0] > 0.99 and rgb[1, 0] == pytest.approx(0.5)   # x = 1.75 -> 0.875 of the span: red; x = 0: not
    down, _ = floor_colour(floor, frame, o, d, t_out, hit, depth=0.5, reach=1.5)
    assert down.tolist() == [False, True, False]
    down, _ = floor_colour(floor, frame, o, d, t_out, hit, depth=0.5)   # reach 1: the floor alone, as before
    assert down.tolist() == [False, True, False]


def test_the_chain_figure_shows_the_photo_the_truth_and_each_scene(capture, tmp_path):
    """`bench capture-chain --figure`: per held-out frame a row of the capture's photo, the object alone over white,
    and each scene rendered at the frame's true pose."""
    import cv2

    from snapshot3d.bench.capture_chain import capture_truth, chain_figure
    from snapshot3d.images import to_uint8
    from snapshot3d.loaders import load_scene
    from snapshot3d.paths import asset

    truth = capture_truth(capture)
    scene = load_scene_file(asset("spot-print.s3d"))
    chain_figure(tmp_path / "f.png", capture, truth, [scene, scene], views=2)
    fig = cv2.imread(str(tmp_path / "f.png"))[..., ::-1]
    photos, clean, _ = truth
    h, w, first, rows = photos.height, photos.width, photos.test[0], len(photos.test[:2])
    assert fig.shape == (rows * h, 4 * w, 3)
    np.testing.assert_array_equal(fig[:h, :w], to_uint8(load_scene(str(capture / "transforms.json"),
                                                                    capture=KEEP).images[first]))
    np.testing.assert_array_equal(fig[:h, w:2 * w], to_uint8(clean.images[first]))
    np.testing.assert_array_equal(fig[:, 2 * w:3 * w], fig[:, 3 * w:])   # the same scene twice
    assert (fig[:, 2 * w:3 * w] < 200).any(1).sum() > 0.05 * rows * h   # the scene is drawn, not blank
