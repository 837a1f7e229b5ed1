"""Scene inputs: Blender and nerfstudio round trips, missing frames, distortion, malformed files."""
import json

import cv2
import numpy as np
import pytest

from snapshot3d.builtin import builtin_scene, shared_data_dir
from snapshot3d.errors import UserError
from snapshot3d.loaders import load_scene


@pytest.fixture(scope="module")
def source():
    return builtin_scene("procedural", n_train=16, n_test=2, size=48, seed=3)


def _write_rgba(path, rgb, alpha):
    """Un-composite from white: straight (non-premultiplied) RGBA, 8-bit."""
    a = np.clip(alpha, 1e-6, 1)[..., None]
    straight = np.clip((rgb - (1 - a)) / a, 0, 1)
    rgba = np.concatenate([straight, alpha[..., None]], -1)
    cv2.imwrite(str(path), cv2.cvtColor((rgba * 255 + 0.5).astype(np.uint8), cv2.COLOR_RGBA2BGRA))


def _blender_folder(tmp_path, s, missing=()):
    fov = 2 * np.arctan(0.5 * s.width / s.intrinsics[0, 0])
    for split, idx in (("train", s.train), ("test", s.test)):
        frames = []
        (tmp_path / split).mkdir()
        for i in idx:
            frames.append({"file_path": f"./{split}/r_{i}", "transform_matrix": s.c2w[i].tolist()})
            if i not in missing:
                _write_rgba(tmp_path / split / f"r_{i}.png", s.images[i], s.alpha[i])
        (tmp_path / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": float(fov), "frames": frames}))
    return tmp_path


def test_blender_round_trip(tmp_path, source):
    s = source
    p = load_scene(str(_blender_folder(tmp_path, s, missing=(s.train[1],))))
    assert p.skipped == 1 and len(p.train) == len(s.train) - 1 and len(p.test) == len(s.test)
    keep = np.delete(s.train, 1)
    np.testing.assert_allclose(p.c2w[: len(keep)], s.c2w[keep], atol=1e-6)
    np.testing.assert_allclose(p.intrinsics[:, :2], s.intrinsics[keep[0], :2][None].repeat(len(p.c2w), 0), rtol=1e-5)
    assert np.abs(p.images[: len(keep)] - s.images[keep]).max() < 2.5 / 255  # 8-bit round trip, on white
    assert np.abs(p.alpha[: len(keep)] - s.alpha[keep]).max() < 1 / 255
    # the visual hull box holds the true box and is not much larger
    assert np.all(p.box[0] <= s.box[0] + 0.05) and np.all(p.box[1] >= s.box[1] - 0.05)
    assert np.all(p.box[1] - p.box[0] < 1.6 * (s.box[1] - s.box[0]))  # the start box was 3 units wide


def test_blender_downscale(tmp_path, source):
    p = load_scene(str(_blender_folder(tmp_path, source)), downscale=2)
    assert p.images.shape[1:3] == (24, 24) and abs(p.intrinsics[0, 0] - source.intrinsics[0, 0] / 2) < 1e-3


def _nerfstudio(tmp_path, s, **extra):
    (tmp_path / "images").mkdir()
    frames = []
    for i in range(len(s.c2w)):
        cv2.imwrite(str(tmp_path / "images" / f"{i}.png"), cv2.cvtColor((s.images[i] * 255).astype(np.uint8), cv2.COLOR_RGB2BGR))
        frames.append({"file_path": f"images/{i}.png", "transform_matrix": s.c2w[i].tolist()})
    fx, fy, cx, cy = s.intrinsics[0].tolist()
    data = {"fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": s.width, "h": s.height, "frames": frames, **extra}
    (tmp_path / "transforms.json").write_text(json.dumps(data))
    return tmp_path / "transforms.json"


def test_nerfstudio_round_trip_and_undistortion(tmp_path, source):
    p = load_scene(str(_nerfstudio(tmp_path, source)))
    assert len(p.train) + len(p.test) == 18 and p.alpha is None and p.skipped == 0
    assert np.abs(p.images - source.images).max() < 1.5 / 255
    (tmp_path / "d").mkdir()
    q = load_scene(str(_nerfstudio(tmp_path / "d", source, k1=0.2)))
    # undistorting with k1 > 0 moves content: the images differ from the distorted input
    assert np.abs(q.images - source.images).mean() > 1e-3


def test_nerfstudio_unknown_camera_model_is_refused(tmp_path, source):
    """OPENCV_FISHEYE is undistorted now (tests/test_capture_input.py); a model no loader knows is refused."""
    with pytest.raises(UserError, match="camera model 'EQUIRECTANGULAR' is not supported"):
        load_scene(str(_nerfstudio(tmp_path, source, camera_model="EQUIRECTANGULAR")))


@pytest.mark.parametrize("text,match", [("{not json", "not valid JSON"), ('{"frames": 3}', "no 'frames' list"),
                                        ('{"frames": [{"file_path": "a.png"}]}', "fewer than 2 images")])
def test_malformed_transforms(tmp_path, text, match):
    (tmp_path / "transforms.json").write_text(text)
    with pytest.raises(UserError, match=match):
        load_scene(str(tmp_path))


def test_missing_scene_path():
    with pytest.raises(UserError, match="scene not found"):
        load_scene("/nonexistent/scene")


def test_lego_subset_skips_missing_frames():
    root = shared_data_dir()
    if root is None:
        pytest.skip("../shared/data is absent: the lego subset is not available")
    p = load_scene(str(root / "scenes" / "lego_subset"), downscale=4)
    assert p.skipped == 75 and len(p.train) == 20 and len(p.test) == 5 and p.images.shape[1:] == (200, 200, 3)
    assert p.images.max() <= 1.0 and p.images[:, 0, 0].min() > 0.99  # white background
