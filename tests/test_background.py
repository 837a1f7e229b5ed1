"""fit --background outer (issue 40 item 2): the outer field is empty inside the box and never reaches the
snapshot; a fit with it leaves less density outside the object than the same fit on white; the automatic box
holds the object and is much smaller than the box placed by the cameras alone."""
import json

import numpy as np
import pytest
import torch
from helpers import run_cli

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
    for bg in ("white", "outer"):
        out = tmp_path / f"{bg}.s3d"
        proc = run_cli("fit", str(capture / "transforms.json"), "-o", str(out), "--steps", "4", "--batch-rays", "256",
                       "--plane-res", "16", "--plane-channels", "4", "--background", bg, "--up", "0,0,1")
        assert proc.returncode == 0, proc.stderr
        sizes[bg] = out.stat().st_size
        with np.load(out) as z:
            assert sorted(z.files) == ["box", "codes", "header"]
            assert z["codes"].shape == (3, 4, 16, 16)
        assert load_scene_file(out).codes.shape == (3, 4, 16, 16)
    assert abs(sizes["outer"] - sizes["white"]) < 200   # the header's text differs (the box), never an array


def _share_outside(capture, background):
    from snapshot3d.train.field.commands import fit_scene
    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.object_score import density_share_outside_box
    cfg = FitConfig(steps=60, batch_rays=1024, plane_res=32, plane_channels=4, occ_warmup=16, background=background)
    scene, _, _ = fit_scene(str(capture / "transforms.json"), cfg, quiet=True,
                            capture=CaptureOptions(up=(0.0, 0.0, 1.0), box="auto" if background == "outer" else None))
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


def test_an_unknown_background_is_refused_in_one_line():
    from snapshot3d.errors import UserError
    from snapshot3d.train.field.config import FitConfig, check_fit_config
    with pytest.raises(UserError, match="--background must be white or outer, not 'black'"):
        check_fit_config(FitConfig(background="black"))
    with pytest.raises(UserError, match="--background-samples >= 2"):
        check_fit_config(FitConfig(background="outer", background_samples=1))
