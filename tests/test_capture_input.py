"""A user's own capture: nerfstudio and COLMAP text models written from a rendered scene and read back (cameras,
images, split, box, up axis, lens undistortion, masks, size limit), and one-line errors for broken captures."""
import json

import cv2
import numpy as np
import pytest
from helpers import assert_one_line_error, run_cli

from snapshot3d.builtin import builtin_scene
from snapshot3d.capture import CaptureOptions, describe, parse_box, parse_up
from snapshot3d.errors import UserError
from snapshot3d.loaders import load_scene

KEEP = (0.0, 0.0, 1.0)   # --up 0,0,1: the world as written


@pytest.fixture(scope="module")
def source():
    return builtin_scene("procedural", n_train=8, n_test=2, size=40, seed=1)


def _png(path, rgb):
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor((np.clip(rgb, 0, 1) * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGB2BGR))


def _nerfstudio(root, s, c2w=None, images=None, frame_extra=None, **extra):
    c2w = s.c2w if c2w is None else c2w
    images = s.images if images is None else images
    frames = []
    for i in range(len(c2w)):
        _png(root / "images" / f"{i:03d}.png", images[i])
        frames.append({"file_path": f"images/{i:03d}.png", "transform_matrix": np.asarray(c2w[i]).tolist(),
                       **(frame_extra(i) if frame_extra else {})})
    fx, fy, cx, cy = s.intrinsics[0].tolist()
    data = {"fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": s.width, "h": s.height, "frames": frames, **extra}
    (root / "transforms.json").write_text(json.dumps(data))
    return root


def _quaternion(r):
    """(qw, qx, qy, qz) of a rotation matrix, through its axis-angle."""
    rvec = cv2.Rodrigues(np.asarray(r, np.float64))[0].ravel()
    angle = np.linalg.norm(rvec)
    axis = rvec / angle if angle > 0 else np.zeros(3)
    return [np.cos(angle / 2), *(axis * np.sin(angle / 2))]


def _colmap(root, s, c2w=None, images=None, camera=None, drop_points=False):
    """COLMAP layout: images/NNN.png and sparse/0/{cameras,images}.txt (world-to-camera, OpenCV axes)."""
    c2w = s.c2w if c2w is None else c2w
    images = s.images if images is None else images
    fx, fy, cx, cy = s.intrinsics[0].tolist()
    (root / "sparse" / "0").mkdir(parents=True)
    (root / "sparse" / "0" / "cameras.txt").write_text(
        "# Camera list\n" + (camera or f"1 PINHOLE {s.width} {s.height} {fx} {fy} {cx} {cy}") + "\n")
    lines = ["# Image list with two lines of data per image:"]
    for i in range(len(c2w)):
        _png(root / "images" / f"{i:03d}.png", images[i])
        w2c = np.linalg.inv(np.asarray(c2w[i], np.float64) @ np.diag([1.0, -1, -1, 1]))
        q, t = _quaternion(w2c[:3, :3]), w2c[:3, 3]
        lines.append(" ".join(str(v) for v in [i + 1, *q, *t, 1, f"{i:03d}.png"]))
        lines.append("" if drop_points or i % 2 else "1.5 2.5 -1 3.0 4.0 7")
    (root / "sparse" / "0" / "images.txt").write_text("\n".join(lines) + "\n")
    return root


@pytest.mark.parametrize("layout", ["nerfstudio", "colmap"])
def test_cameras_and_images_round_trip(tmp_path, source, layout):
    s = source
    root = (_nerfstudio if layout == "nerfstudio" else _colmap)(tmp_path, s)
    p = load_scene(str(root), capture=CaptureOptions(up=KEEP, holdout=0))
    assert p.info["layout"] == layout and p.images.shape == s.images.shape
    np.testing.assert_allclose(p.c2w, s.c2w, atol=1e-4)
    np.testing.assert_allclose(p.intrinsics, s.intrinsics, atol=1e-4)
    assert np.abs(p.images - s.images).max() < 1.5 / 255
    # holdout 0: every frame trains and is scored, and the line says so
    assert list(p.train) == list(p.test) == list(range(10))
    line = describe(p.info["capture"])
    assert "read 10 frames" in line and "scored on the training frames" in line and "images 40x40" in line


def test_colmap_simple_pinhole_and_auto_up(tmp_path, source):
    s = source
    fx, _, cx, cy = s.intrinsics[0].tolist()
    root = _colmap(tmp_path, s, camera=f"1 SIMPLE_PINHOLE {s.width} {s.height} {fx} {cx} {cy}")
    p = load_scene(str(root / "sparse" / "0"))   # the model folder itself; default up: auto
    np.testing.assert_allclose(p.intrinsics, s.intrinsics, atol=1e-4)
    # the builtin orbit's cameras are upright in a z-up world: auto keeps that world (x axes level), though their
    # mean up leans 3.4 degrees off z
    np.testing.assert_allclose(p.c2w[:, 2, 0], 0, atol=1e-5)
    np.testing.assert_allclose(p.c2w, s.c2w, atol=1e-4)
    mean_up = s.c2w[:, :3, 1].mean(0)
    assert mean_up[2] / np.linalg.norm(mean_up) < np.cos(np.deg2rad(3))
    assert p.info["capture"]["up_from"] == "auto: square to the cameras' level x axes, turned to +z"


def test_holdout_splits(tmp_path, source):
    root = _nerfstudio(tmp_path, source)
    p = load_scene(str(root), capture=CaptureOptions(up=KEEP))     # nerfstudio's default: every 8th
    assert list(p.test) == [0, 8] and len(p.train) == 8
    p = load_scene(str(root), capture=CaptureOptions(up=KEEP, holdout=5))
    assert list(p.test) == [0, 5] and list(p.train) == [1, 2, 3, 4, 6, 7, 8, 9]
    assert "8 train / 2 held out (every 5-th frame)" in describe(p.info["capture"])
    with pytest.raises(UserError, match="--holdout 1 would hold out every frame"):
        load_scene(str(root), capture=CaptureOptions(holdout=1))
    b = load_scene("builtin:procedural", size=16, n_train=4, n_test=2, capture=CaptureOptions(holdout=3))
    assert list(b.test) == [0, 3] and len(b.train) == 4


def _turn_z_to_y():
    """Rotation by -90 degrees about x: the world's +z becomes +y."""
    r = np.eye(4)
    r[1:3, 1:3] = [[0, 1], [-1, 0]]
    assert np.allclose(r[:3, :3] @ [0, 0, 1], [0, 1, 0])
    return r


@pytest.mark.parametrize("layout", ["nerfstudio", "colmap"])
def test_up_axis_and_box(tmp_path, source, layout):
    s, write = source, (_nerfstudio if layout == "nerfstudio" else _colmap)
    turned = _turn_z_to_y() @ s.c2w
    (tmp_path / "y").mkdir()
    (tmp_path / "z").mkdir()
    y_up, z_up = write(tmp_path / "y", s, c2w=turned), write(tmp_path / "z", s)
    p = load_scene(str(y_up), capture=CaptureOptions(up=parse_up("0,1,0")))
    np.testing.assert_allclose(p.c2w, s.c2w, atol=1e-4)   # y up was turned back to z up
    # auto: both worlds come out with the cameras' mean up on +z; they differ by a turn about z only
    a, b = (load_scene(str(r), capture=CaptureOptions(up="auto")) for r in (y_up, z_up))
    np.testing.assert_allclose(a.c2w[:, 2, :], b.c2w[:, 2, :], atol=1e-4)
    assert np.abs(a.c2w - s.c2w).max() < 0.5 and np.abs(a.c2w[:, :3, 3] - turned[:, :3, 3]).max() > 0.5
    # the box: from the cameras (around the orbit's centre), or as given
    assert np.all(b.box[0] < -0.5) and np.all(b.box[1] > 0.5) and b.info["capture"]["box_from"] == "from the cameras"
    g = load_scene(str(y_up), capture=CaptureOptions(up=(0, 1, 0), box=parse_box("-1,-2,-0.5,1,2,0.75")))
    np.testing.assert_allclose(g.box, [[-1, -2, -0.5], [1, 2, 0.75]])
    assert "box (-1, -2, -0.5)..(1, 2, 0.75) (--box)" in describe(g.info["capture"])
    assert "up (0, 1, 0) (--up, turned to +z)" in describe(g.info["capture"])


def _smooth_grid(u, v):
    """A smooth grid pattern in [0.1, 0.9] as a function of pinhole pixel coordinates (centres at +0.5)."""
    return 0.5 + 0.2 * np.cos(2 * np.pi * u / 19) + 0.2 * np.cos(2 * np.pi * v / 17)


LENSES = {"OPENCV": {"k1": -0.18, "k2": 0.04, "p1": 0.003, "p2": -0.002},
          "OPENCV_FISHEYE": {"k1": 0.06, "k2": 0.01, "k3": -0.004, "k4": 0.001}}


def _distorted_grid(model, fx, fy, cx, cy, size):
    """The grid as the lens sees it: each distorted pixel looks up its pinhole position (cv2.undistortPoints,
    checked by projecting back with cv2.projectPoints / cv2.fisheye.distortPoints)."""
    c = LENSES[model]
    k = np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1]])
    jj, ii = np.mgrid[:size, :size].astype(np.float64)
    pix = np.stack([ii, jj], -1).reshape(-1, 1, 2)
    if model == "OPENCV_FISHEYE":
        d = np.array([c["k1"], c["k2"], c["k3"], c["k4"]])
        norm = cv2.fisheye.undistortPoints(pix, k, d, criteria=(3, 100, 1e-12))
        back = cv2.fisheye.distortPoints(norm, k, d)
    else:
        d = np.array([c["k1"], c["k2"], c["p1"], c["p2"], 0.0])
        norm = cv2.undistortPoints(pix, k, d, criteria=(3, 100, 1e-12))
        pts = np.concatenate([norm.reshape(-1, 2), np.ones((len(pix), 1))], 1)
        back = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k, d)[0]
    assert np.abs(back.reshape(-1, 2) - pix.reshape(-1, 2)).max() < 1e-3   # the inverse is exact enough
    x, y = norm.reshape(size, size, 2).transpose(2, 0, 1)
    return _smooth_grid(fx * x + cx, fy * y + cy)


def _psnr(a, b):
    return 10 * np.log10(1.0 / np.mean((a - b) ** 2))


@pytest.mark.parametrize("layout", ["nerfstudio", "colmap"])
@pytest.mark.parametrize("model", ["OPENCV", "OPENCV_FISHEYE"])
def test_undistortion_restores_the_grid(tmp_path, source, model, layout):
    size, fx, fy, cx, cy = 64, 46.0, 47.0, 31.0, 33.5
    grid = _distorted_grid(model, fx, fy, cx, cy, size)
    images = np.repeat(grid[None, ..., None], 3, -1).repeat(3, 0)
    s = source
    s3 = type(s)(images=images.astype(np.float32), alpha=None, c2w=s.c2w[:3], intrinsics=np.tile([fx, fy, cx, cy], (3, 1)),
                 box=s.box, train=np.arange(3), test=np.arange(0))
    c = LENSES[model]
    if layout == "nerfstudio":
        root = _nerfstudio(tmp_path, s3, images=images, camera_model=model, **c)
    else:
        params = [c[k] for k in (("k1", "k2", "p1", "p2") if model == "OPENCV" else ("k1", "k2", "k3", "k4"))]
        root = _colmap(tmp_path, s3, images=images, camera=" ".join(map(str, [1, model, size, size, fx, fy, cx, cy,
                                                                                 *params])))
    p = load_scene(str(root), capture=CaptureOptions(up=KEEP, holdout=0))
    np.testing.assert_allclose(p.intrinsics[0], [fx, fy, cx, cy], atol=1e-4)   # the same pinhole camera
    jj, ii = np.mgrid[:size, :size] + 0.5
    truth = _smooth_grid(ii, jj)
    inner = (slice(3, -3), slice(3, -3))
    restored, raw = _psnr(p.images[0, ..., 1][inner], truth[inner]), _psnr(grid[inner], truth[inner])
    assert restored > 47 and raw < 25, (restored, raw)   # a half-pixel error in cx, cy gives 43-45 dB


def test_mask_path_gives_alpha(tmp_path, source):
    s = source
    masks = s.alpha > 0.5
    green = np.where(masks[..., None], s.images, np.array([0.1, 0.8, 0.2]))   # a photo's own background
    for i in range(len(s.c2w)):
        (tmp_path / "masks").mkdir(exist_ok=True)
        cv2.imwrite(str(tmp_path / "masks" / f"{i:03d}.png"), masks[i].astype(np.uint8) * 255)
    root = _nerfstudio(tmp_path, s, images=green, frame_extra=lambda i: {"mask_path": f"masks/{i:03d}.png"})
    p = load_scene(str(root), capture=CaptureOptions(up=KEEP))
    np.testing.assert_array_equal(p.alpha, masks.astype(np.float32))
    assert np.all(p.images[~masks] == 1.0)   # outside the mask: white, as the fit expects
    assert np.abs(p.images[masks] - s.images[masks]).max() < 1.5 / 255
    # the box is carved from the masks: it holds the object and is far smaller than the cameras' cube
    assert p.info["capture"]["box_from"] == "carved from the masks"
    assert np.all(p.box[0] <= s.box[0] + 0.05) and np.all(p.box[1] >= s.box[1] - 0.05)
    assert np.all(p.box[1] - p.box[0] < 1.5 * (s.box[1] - s.box[0]))


def test_max_size_and_downscale(tmp_path, source):
    root = _nerfstudio(tmp_path, source)
    p = load_scene(str(root), capture=CaptureOptions(up=KEEP, max_size=20))
    assert p.images.shape[1:3] == (20, 20)
    np.testing.assert_allclose(p.intrinsics, source.intrinsics / 2, atol=1e-4)
    q = load_scene(str(root), downscale=2, capture=CaptureOptions(up=KEEP, max_size=16))
    assert q.images.shape[1:3] == (16, 16) and abs(q.intrinsics[0, 0] - source.intrinsics[0, 0] * 0.4) < 1e-4


def _break_nerfstudio(root, edit):
    data = json.loads((root / "transforms.json").read_text())
    edit(data)
    (root / "transforms.json").write_text(json.dumps(data))


@pytest.mark.parametrize("edit,match", [
    (lambda d: d.update(camera_model="FANCY_LENS"), "camera model 'FANCY_LENS' is not supported"),
    (lambda d: d["frames"][3].pop("transform_matrix"), "(frame images/003.png): no valid 'transform_matrix'"),
    (lambda d: d["frames"][2].update(mask_path="m.png"), "1 of 10 frames give a mask_path"),
    (lambda d: [fr.update(mask_path="masks/gone.png") for fr in d["frames"]], "gone.png: mask not found"),
    (lambda d: d.update(w=41), "the image is 40x40 but its camera says 41x40"),
    (lambda d: [fr.update(file_path="gone.png") for fr in d["frames"]], "fewer than 2 images found (10 image missing)"),
])
def test_broken_nerfstudio_captures(tmp_path, source, edit, match):
    root = _nerfstudio(tmp_path, source)
    _break_nerfstudio(root, edit)
    with pytest.raises(UserError) as e:
        load_scene(str(root))
    assert match in str(e.value) and "\n" not in str(e.value)


def test_missing_images_are_skipped_and_said(tmp_path, source):
    root = _colmap(tmp_path, source)
    (root / "images" / "004.png").unlink()
    _png(root / "images" / "extra.png", source.images[0])   # on disk, never registered by COLMAP
    p = load_scene(str(root))
    line = describe(p.info["capture"])
    assert p.skipped == 2 and "read 9 frames, skipped 2 (1 image missing, 1 without a pose in images.txt)" in line


def _break_colmap(root, name, edit):
    path = root / "sparse" / "0" / name
    path.write_text(edit(path.read_text()))


@pytest.mark.parametrize("name,edit,match", [
    ("images.txt", lambda t: t.replace(" 1 003.png", " 003.png"), "line 8: expected 10 fields"),
    ("images.txt", lambda t: t.replace("1.5 2.5 -1 3.0", "1.5 2.5 3.0"), "X Y POINT3D_ID triples, got 5 numbers"),
    ("images.txt", lambda t: t.replace(" 1 003.png", " 9 003.png"), "CAMERA_ID 9 is not in cameras.txt"),
    ("cameras.txt", lambda t: t.replace("PINHOLE", "KANNALA"), "line 2: camera model 'KANNALA' is not supported"),
    ("cameras.txt", lambda t: t.rsplit(" ", 1)[0] + "\n", "a PINHOLE camera has 4 parameters (fx fy cx cy), got 3"),
])
def test_broken_colmap_models(tmp_path, source, name, edit, match):
    root = _colmap(tmp_path, source)
    _break_colmap(root, name, edit)
    with pytest.raises(UserError) as e:
        load_scene(str(root))
    assert match in str(e.value) and "\n" not in str(e.value)


def test_binary_colmap_and_no_images_folder(tmp_path, source):
    (tmp_path / "b" / "sparse" / "0").mkdir(parents=True)
    (tmp_path / "b" / "sparse" / "0" / "cameras.bin").write_bytes(b"\0" * 8)
    with pytest.raises(UserError, match="binary COLMAP model; convert it to text first"):
        load_scene(str(tmp_path / "b"))
    root = _colmap(tmp_path / "c", source)
    (root / "images").rename(root / "pictures")
    with pytest.raises(UserError, match="no images/ folder beside the COLMAP model"):
        load_scene(str(root))


@pytest.mark.parametrize("text,parse,match", [("1,2", parse_up, "--up takes 3 numbers"),
                                              ("0,0,0", parse_up, "--up must not be the zero vector"),
                                              ("1,1,1,0,0,0", parse_box, "--box must have x1 > x0"),
                                              ("a,b,c,d,e,f", parse_box, "--box takes 6 numbers")])
def test_option_values(text, parse, match):
    with pytest.raises(UserError, match=match):
        parse(text)


def test_fit_command_refuses_bad_capture_options(tmp_path):
    assert_one_line_error(run_cli("fit", "builtin:procedural", "-o", str(tmp_path / "x.s3d"), "--up", "1,2"),
                          "--up takes 3 numbers")
    assert not (tmp_path / "x.s3d").exists()
