"""`snapshot3d make-capture`: a synthetic capture in the nerfstudio layout that the project's own capture reader
loads (lens undone, poses as written), with ground-truth masks that match the rendered object."""
import json

import cv2
import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli

from snapshot3d.builtin import load_mesh
from snapshot3d.capture import CaptureOptions
from snapshot3d.errors import UserError
from snapshot3d.loaders import load_scene
from snapshot3d.make_capture import make_capture, synth_capture, write_capture
from snapshot3d.make_capture_config import SynthCaptureConfig
from snapshot3d.synth_camera import perturb_poses, walk_poses

LENS = (-0.25, 0.05, 0.002, -0.001)   # strong, so that a missed or wrong undistortion shows at 128 px
CFG = SynthCaptureConfig(views=4, size=128, fov_deg=90.0, lens=LENS, pose_noise_deg=0.5, pose_noise_frac=0.01)
KEEP = CaptureOptions(holdout=0, up=(0.0, 0.0, 1.0))   # every frame, the world as written


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    cap = synth_capture("builtin:procedural", CFG, keep_pinhole=True)
    folder = tmp_path_factory.mktemp("cap")
    write_capture(cap, "builtin:procedural", CFG, folder)
    return cap, folder


def _psnr(a, b, border=4):
    a, b = a[border:-border, border:-border], b[border:-border, border:-border]
    return float(-10 * np.log10(np.mean((a - b) ** 2)))


def _bbox(mask):
    ys, xs = np.nonzero(mask)
    return np.array([xs.min() - 0.5, xs.max() + 0.5, ys.min() - 0.5, ys.max() + 0.5])


def test_loads_through_the_capture_reader_with_the_lens_undone(capture):
    cap, folder = capture
    posed = load_scene(str(folder), capture=KEEP)
    assert len(posed.images) == CFG.views and posed.images.shape[1:3] == (96, 128)
    np.testing.assert_allclose(posed.c2w, cap["c2w_written"], atol=1e-5)
    np.testing.assert_allclose(posed.intrinsics[0], cap["intr"], rtol=1e-6)
    for i in range(CFG.views):
        undone, raw = _psnr(posed.images[i], cap["pinhole"][i]), _psnr(cap["images"][i], cap["pinhole"][i])
        assert undone > 30.0 and undone > raw + 4.0, (i, undone, raw)
    # the masks, given to the reader through gt/transforms_masked.json, are undone with their images
    masked = load_scene(str(folder / "gt" / "transforms_masked.json"), capture=KEEP)
    for i in range(CFG.views):
        truth = cap["pinhole_alpha"][i] >= 0.5
        assert np.abs(_bbox(masked.alpha[i] >= 0.5) - _bbox(truth)).max() <= 1.0
        assert np.mean((masked.alpha[i] >= 0.5) != truth) < 0.01
    # what fits are scored on: the same masked frames at the true poses (the written ones carry the pose noise)
    true = load_scene(str(folder / "gt" / "transforms_true.json"), capture=KEEP)
    np.testing.assert_allclose(true.c2w, cap["c2w_true"], atol=1e-5)
    np.testing.assert_array_equal(true.alpha, masked.alpha)
    assert np.abs(cap["c2w_true"] - cap["c2w_written"]).max() > 1e-3
    # the object alone over white, at the true poses: the photos' own pixels inside the mask (away from the
    # outline, where the photos blend in the room), white outside it (as bright as the frame's exposure lets)
    white = load_scene(str(folder / "gt" / "transforms_white.json"), capture=KEEP)
    np.testing.assert_allclose(white.c2w, cap["c2w_true"], atol=1e-5)
    np.testing.assert_array_equal(white.alpha, masked.alpha)
    for i in range(CFG.views):
        inner = cv2.erode((cap["masks"][i]).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        outside = cv2.dilate((cap["masks"][i]).astype(np.uint8), np.ones((5, 5), np.uint8)) == 0
        assert inner.sum() > 100 and outside.sum() > 100
        assert np.abs(cap["white"][i][inner] - cap["images"][i][inner]).max() < 1e-6
        grey = min(1.0, float(cap["gains"][i].min()) ** (1 / 2.2)) - 1e-3   # white at the frame's exposure
        assert cap["white"][i][outside].min() > grey and cap["images"][i][outside].min() < 0.9


def test_gt_masks_hold_the_projected_mesh(capture):
    """Every vertex of the mesh, projected by OpenCV's own lens model at the true pose, falls on the mask (grown by
    one pixel), and the extremes agree with the mask's box within 0.75 px; without the lens they do not."""
    cap, folder = capture
    truth = json.loads((folder / "gt" / "truth.json").read_text())
    vertices = np.asarray(load_mesh("procedural").vertices)
    np.testing.assert_allclose(truth["box"], [vertices.min(0), vertices.max(0)], atol=1e-6)
    fx, fy, cx, cy = cap["intr"]
    k = np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1]])   # OpenCV: pixel centres at integers
    off = []
    for i, frame in enumerate(truth["frames"]):
        w2c = np.linalg.inv(np.array(frame["transform_matrix"]))
        r, t = np.diag([1, -1, -1]) @ w2c[:3, :3], np.diag([1, -1, -1]) @ w2c[:3, 3]   # OpenGL -> OpenCV axes
        mask = cv2.imread(str(folder / "gt" / "masks" / f"frame_{i + 1:05d}.png"), cv2.IMREAD_UNCHANGED) > 127
        grown = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        for lens in (LENS, (0, 0, 0, 0)):
            p = cv2.projectPoints(vertices, cv2.Rodrigues(r)[0], t, k, np.array(lens, float))[0].reshape(-1, 2)
            q = np.clip(np.round(p).astype(int), 0, [mask.shape[1] - 1, mask.shape[0] - 1])
            box = np.array([p[:, 0].min(), p[:, 0].max(), p[:, 1].min(), p[:, 1].max()])
            off.append(np.abs(box - _bbox(mask)).max())
            if lens == LENS:
                assert grown[q[:, 1], q[:, 0]].mean() > 0.999 and off[-1] <= 0.75, (i, off[-1])
    assert max(off[1::2]) > 1.2   # the lens matters here: the test would see a missing one


def test_exposure_jitter_varies_per_frame():
    """Frame i is frame i of the unjittered capture with its per-channel gain applied in linear light."""
    base = synth_capture("builtin:procedural", SynthCaptureConfig(views=4, size=48, exposure_jitter=0.0))
    jit = synth_capture("builtin:procedural", SynthCaptureConfig(views=4, size=48, exposure_jitter=0.3))
    assert np.all(base["gains"] == 1.0) and np.std(jit["gains"][:, 0]) > 0.05
    for i in range(4):
        a, b = base["images"][i] ** 2.2, jit["images"][i] ** 2.2
        ok = (a < 0.8) & (b < 0.97)   # away from clipping
        ratio = [b[..., c][ok[..., c]].mean() / a[..., c][ok[..., c]].mean() for c in range(3)]
        np.testing.assert_allclose(ratio, jit["gains"][i], rtol=0.03)


def test_views_rendered_in_chunks_match(monkeypatch):
    from snapshot3d import make_capture as mc

    cfg = SynthCaptureConfig(views=5, size=32)
    whole = synth_capture("builtin:procedural", cfg)
    monkeypatch.setattr(mc, "CHUNK", 2)
    chunked = synth_capture("builtin:procedural", cfg)
    np.testing.assert_allclose(chunked["images"], whole["images"], atol=1e-6)
    assert np.array_equal(chunked["masks"], whole["masks"]) and whole["masks"].any(axis=(1, 2)).all()


def test_pose_noise_has_the_rms_asked():
    rng = np.random.default_rng(1)
    c2w = np.tile(np.eye(4), (600, 1, 1))
    c2w[:, :3, 3] = rng.normal(size=(600, 3)) * 4.0
    noisy = perturb_poses(c2w, np.zeros(3), 0.5, 0.01, rng)
    cos = (np.einsum("nij,nij->n", noisy[:, :3, :3], c2w[:, :3, :3]) - 1) / 2
    angle = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    shift = np.linalg.norm(noisy[:, :3, 3] - c2w[:, :3, 3], axis=1) / np.linalg.norm(c2w[:, :3, 3], axis=1)
    assert 0.45 < np.sqrt(np.mean(angle ** 2)) < 0.55 and 0.009 < np.sqrt(np.mean(shift ** 2)) < 0.011


@pytest.mark.parametrize("arc_deg", [720.0, 120.0])
def test_the_walk_turns_the_arc_asked(arc_deg):
    """--arc-deg: the cameras' azimuths round the object step evenly through the arc (two turns by default, a
    frontal arc on request), whatever the hand-held wobble."""
    n, centre = 48, np.array([0.1, -0.2, 0.3])
    c2w = walk_poses(n, centre, 1.0, 1.5, np.random.default_rng(3), np.deg2rad(arc_deg))
    rel = c2w[:, :3, 3] - centre
    az = np.unwrap(np.arctan2(rel[:, 1], rel[:, 0]))
    assert abs(np.degrees(az[-1] - az[0]) - arc_deg * (n - 1) / n) < 0.5
    assert np.all(np.diff(az) > 0)


def test_the_default_walk_is_two_turns_and_the_one_written_before_the_option():
    n, centre = 48, np.array([0.1, -0.2, 0.3])
    two_turns = walk_poses(n, centre, 1.0, 1.5, np.random.default_rng(3), np.deg2rad(720.0))
    assert np.array_equal(two_turns, walk_poses(n, centre, 1.0, 1.5, np.random.default_rng(3)))
    arc = walk_poses(n, centre, 1.0, 1.5, np.random.default_rng(3), np.deg2rad(120.0))
    assert not np.allclose(two_turns, arc)


def test_cli_writes_a_capture_and_falls_back_to_bundled_photos(tmp_path, monkeypatch):
    monkeypatch.setenv("SNAPSHOT3D_SHARED_DATA", str(tmp_path / "absent"))
    out = tmp_path / "cap"
    proc = run_cli("make-capture", "builtin:procedural", "-o", str(out), "--views", "3", "--size", "32", "--no-ground")
    assert proc.returncode == 0, proc.stderr
    data = json.loads((out / "transforms.json").read_text())
    assert data["camera_model"] == "OPENCV" and data["k1"] == -0.08 and len(data["frames"]) == 3
    assert all("mask_path" not in fr for fr in data["frames"])
    truth = json.loads((out / "gt" / "truth.json").read_text())
    assert truth["sources"]["backdrop"].startswith("builtin:") and truth["sources"]["ground"] is None
    assert sorted(p.name for p in (out / "gt" / "masks").iterdir()) == [f"frame_{i:05d}.png" for i in (1, 2, 3)]
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []   # no temporary folder left


@pytest.mark.parametrize("args, match", [
    (["builtin:nope"], "unknown builtin scene"),
    (["procedural"], "make-capture takes builtin:NAME"),
    (["builtin:procedural", "--size", "4"], "--size must be an integer"),
    (["builtin:procedural", "--backdrop", "/nonexistent.jpg"], "backdrop photo not found"),
    (["builtin:procedural", "--lens", "-0.9", "0", "0", "0"], "cannot be inverted"),
    (["builtin:procedural", "--arc-deg", "5"], "--arc-deg must be a finite number in [10, 720]"),
])
def test_bad_input_is_one_line(tmp_path, args, match):
    proc = run_cli("make-capture", *args, "-o", str(tmp_path / "cap"), "--views", "2", "--size", args[-1]
                   if args[-2:-1] == ["--size"] else "16")
    assert_one_line_error(proc, match)
    assert list(tmp_path.iterdir()) == []   # nothing written, no temporary folder left


def test_existing_or_unwritable_output_is_refused(tmp_path):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    with pytest.raises(UserError, match="already exists"):
        make_capture("builtin:procedural", tmp_path / "full", SynthCaptureConfig(views=2, size=16))
    (tmp_path / "file").write_text("x")
    with pytest.raises(UserError, match="cannot write"):
        make_capture("builtin:procedural", tmp_path / "file" / "cap", SynthCaptureConfig(views=2, size=16))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "full"]
