"""Scene inputs -> `PosedImages`: Blender/NeRF-Synthetic folders, nerfstudio `transforms.json`, `builtin:NAME`.

Images come out RGB float32 in [0, 1], RGBA composited on white; cameras in OpenGL c2w axes.
"""
from __future__ import annotations

import json
import logging
import warnings
from pathlib import Path

import cv2
import numpy as np

from . import validate
from .carve import carve, tight_box
from .errors import UserError
from .images import quiet_stderr
from .posed import PosedImages

__all__ = ["load_scene", "load_blender", "load_nerfstudio", "fit_box"]

MAX_MATRIX_ENTRY = 1e6     # |entries| of a camera-to-world matrix (world units)
MAX_FOCAL = 1e6            # focal length and principal point, pixels
MAX_DISTORTION = 100.0     # |k1|, |k2|, |p1|, |p2|, |k3|
DEFAULT_BOX = np.array([[-1.5, -1.5, -1.5], [1.5, 1.5, 1.5]], np.float32)  # NeRF-Synthetic convention


def load_scene(spec: str, downscale: int = 1, **builtin_kw) -> PosedImages:
    """`builtin:NAME`, a Blender folder (with `transforms_train.json`), or a nerfstudio folder or
    `transforms.json` file."""
    if downscale < 1:
        raise UserError(f"--downscale must be >= 1, not {downscale}")
    if spec.startswith("builtin:"):
        from .builtin import builtin_scene  # lazy: renders meshes
        size = builtin_kw.pop("size", 200)
        return builtin_scene(spec.split(":", 1)[1], size=max(8, size // downscale), **builtin_kw)
    path = Path(spec)
    if not path.exists():
        raise UserError(f"scene not found: {spec} (give a folder, a transforms.json, or builtin:NAME)")
    if path.suffix == ".s3d":
        from .scene import load_scene_file
        load_scene_file(path)  # a scene for another decoder or a corrupt file is refused with its own reason
        raise UserError(f"{spec} is an already fitted scene; fit takes posed images (a folder, transforms.json "
                        "or builtin:NAME)")
    if path.is_dir() and (path / "transforms_train.json").is_file():
        return load_blender(path, downscale)
    if path.is_file() and path.suffix == ".json":
        return load_nerfstudio(path, downscale)
    if path.is_dir() and (path / "transforms.json").is_file():
        return load_nerfstudio(path / "transforms.json", downscale)
    raise UserError(f"{spec}: no transforms_train.json (Blender) or transforms.json (nerfstudio) found")


MAX_JSON_BYTES = 64 << 20   # a transforms file (about 1 kB per frame)


def _read_json(path: Path) -> dict:
    try:
        if path.stat().st_size > MAX_JSON_BYTES:
            raise UserError(f"{path}: {path.stat().st_size / 1e6:.0f} MB is too large for a transforms file (limit "
                            f"{MAX_JSON_BYTES / 1e6:.0f} MB)")
        data = json.loads(path.read_text())
    except (OSError, ValueError, RecursionError) as e:   # JSONDecodeError, UnicodeDecodeError are ValueErrors
        first = (str(e).splitlines() or [""])[0][:80]
        raise UserError(f"{path}: not valid JSON ({type(e).__name__}: {first})") from None
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise UserError(f"{path}: malformed transforms file (no 'frames' list)")
    if not all(isinstance(fr, dict) for fr in data["frames"]):
        raise UserError(f"{path}: malformed transforms file (every entry of 'frames' must be an object)")
    return data


def _file_path(frame: dict, where: str) -> str:
    rel = frame.get("file_path", "")
    if not isinstance(rel, str) or "\0" in rel:
        raise UserError(f"{where}: a frame's 'file_path' must be a text, got {validate.show(rel)}")
    return rel


def _read_image(path: Path, downscale: int):
    """-> (H, W, 3) float32 RGB on white, (H, W) alpha or None. The header's size is checked against
    `validate.MAX_PIXELS` before decoding; decoders' messages go to the log (`images.quiet_stderr`)."""
    _check_header(path)
    try:
        with quiet_stderr():
            img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        img = None
    if img is None or img.size == 0 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (3, 4)):
        raise UserError(f"{path}: cannot read image")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    scale = 65535.0 if img.dtype == np.uint16 else 255.0
    img = img.astype(np.float32) / scale
    alpha = img[..., 3] if img.shape[2] == 4 else None
    rgb = img[..., 2::-1] if img.shape[2] == 4 else img[..., ::-1]
    if alpha is not None:
        rgb = rgb * alpha[..., None]  # premultiplied, so that downscaling does not bleed background
    if downscale > 1:
        size = (img.shape[1] // downscale, img.shape[0] // downscale)
        if min(size) < 1:
            raise UserError(f"{path}: --downscale {downscale} leaves nothing of a {img.shape[1]}x{img.shape[0]} image")
        rgb = cv2.resize(np.ascontiguousarray(rgb), size, interpolation=cv2.INTER_AREA)
        alpha = None if alpha is None else cv2.resize(alpha, size, interpolation=cv2.INTER_AREA)
    if alpha is not None:
        rgb = rgb + (1.0 - alpha[..., None])
    return np.ascontiguousarray(rgb, dtype=np.float32), alpha


def _matrix(frame, where: str) -> np.ndarray:
    try:
        m = np.asarray(frame["transform_matrix"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise UserError(f"{where}: a frame has no valid 'transform_matrix'") from None
    if m.shape != (4, 4) or not np.isfinite(m).all() or np.abs(m).max() > MAX_MATRIX_ENTRY:
        raise UserError(f"{where}: 'transform_matrix' must be a 4x4 matrix of finite numbers within "
                        f"+-{MAX_MATRIX_ENTRY:g}, got shape {m.shape}")
    if abs(np.linalg.det(m[:3, :3])) < 1e-6:
        raise UserError(f"{where}: a 'transform_matrix' has a degenerate rotation (determinant ~0)")
    return m


def _check_header(path: Path) -> None:
    """UserError when an image file's header declares more than `validate.MAX_PIXELS` pixels (formats
    Pillow does not know are left to OpenCV's own limit)."""
    from PIL import Image, UnidentifiedImageError

    if path.stat().st_size > validate.MAX_BYTES:
        raise UserError(f"{path}: {path.stat().st_size / 1e6:.0f} MB is over the {validate.MAX_BYTES / 1e6:.0f} MB "
                        f"limit of an image file")
    logging.getLogger("PIL").setLevel(logging.CRITICAL)   # a damaged file is our one-line error, not its log
    old = Image.MAX_IMAGE_PIXELS
    try:
        Image.MAX_IMAGE_PIXELS = None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                w, h = im.size
    except UnidentifiedImageError:
        return
    except (OSError, ValueError, SyntaxError, EOFError) as e:
        raise UserError(f"{path}: corrupt image file ({type(e).__name__})") from None
    finally:
        Image.MAX_IMAGE_PIXELS = old
    validate.check_image_size(w, h, str(path))


def fit_box(images_alpha, c2w, intrinsics, start_box=DEFAULT_BOX) -> np.ndarray:
    """A tight box from coverage masks (visual hull), or `start_box` when there are no masks."""
    if images_alpha is None:
        return start_box.astype(np.float32)
    occ = carve(images_alpha, c2w, intrinsics, start_box, 64)
    return tight_box(occ, start_box)


def load_blender(folder: Path, downscale: int = 1) -> PosedImages:
    """NeRF-Synthetic layout: `transforms_{train,val,test}.json`, `camera_angle_x`, file paths without
    extension. Frames whose image is missing are skipped and counted. With no test split on disk,
    every 5th training frame is held out."""
    splits, skipped = {}, 0
    for split in ("train", "test"):
        jpath = folder / f"transforms_{split}.json"
        if not jpath.is_file():
            continue
        data = _read_json(jpath)
        if "camera_angle_x" not in data:
            raise UserError(f"{jpath}: malformed transforms file (no 'camera_angle_x')")
        rows = []
        fov = validate.number(data["camera_angle_x"], f"{jpath}: camera_angle_x", 1e-3, np.pi - 1e-3)
        for fr in data["frames"]:
            rel = _file_path(fr, str(jpath))
            img_path = folder / (rel if Path(rel).suffix else rel + ".png")
            if not img_path.is_file():
                skipped += 1
                continue
            rows.append((img_path, _matrix(fr, str(jpath)), fov))
        splits[split] = rows
    train_rows = splits.get("train", [])
    test_rows = splits.get("test", [])
    if not test_rows:
        test_rows = train_rows[2::5]
        train_rows = [r for i, r in enumerate(train_rows) if i % 5 != 2]
    rows = train_rows + test_rows
    if len(train_rows) < 2:
        raise UserError(f"{folder}: fewer than 2 training images found ({skipped} listed frames missing)")
    images, alphas, c2ws, intr = [], [], [], []
    for img_path, m, fov in rows:
        rgb, a = _read_image(img_path, downscale)
        h, w = rgb.shape[:2]
        f = 0.5 * w / np.tan(0.5 * fov)
        images.append(rgb), alphas.append(a), c2ws.append(m), intr.append((f, f, w / 2, h / 2))
    alpha = None if any(a is None for a in alphas) else np.stack(alphas)
    c2w, intr = np.stack(c2ws).astype(np.float32), np.asarray(intr, np.float32)
    return PosedImages(images=np.stack(images), alpha=alpha, c2w=c2w, intrinsics=intr,
                       box=validate.check_box(fit_box(alpha, c2w, intr), f"{folder}: the scene box found"), train=np.arange(len(train_rows)),
                       test=np.arange(len(train_rows), len(rows)), name=folder.name, skipped=skipped,
                       info={"layout": "blender"})


def load_nerfstudio(jpath: Path, downscale: int = 1, holdout_every: int = 8) -> PosedImages:
    """nerfstudio layout: `fl_x fl_y cx cy w h` (global or per frame), `transform_matrix` per frame.
    OPENCV radial/tangential distortion is undone with cv2.undistort; fisheye models are refused."""
    data = _read_json(jpath)
    model = data.get("camera_model", "OPENCV")
    if "FISHEYE" in str(model).upper() or "EQUIRECT" in str(model).upper():
        raise UserError(f"{jpath}: camera model {model} is not supported (only pinhole/OPENCV)")
    images, alphas, c2ws, intr, skipped = [], [], [], [], 0
    for fr in data["frames"]:
        get = lambda k, d=None: fr.get(k, data.get(k, d))  # noqa: E731 - per-frame overrides
        img_path = jpath.parent / _file_path(fr, str(jpath))
        if not img_path.is_file():
            skipped += 1
            continue
        if any(get(k) is None for k in ("fl_x", "fl_y", "cx", "cy")):
            raise UserError(f"{jpath}: intrinsics fl_x, fl_y, cx, cy are required")
        fx, fy = (validate.number(get(k), f"{jpath}: {k}", 1e-3, MAX_FOCAL) for k in ("fl_x", "fl_y"))
        cx, cy = (validate.number(get(k), f"{jpath}: {k}", -MAX_FOCAL, MAX_FOCAL) for k in ("cx", "cy"))
        rgb, a = _read_image(img_path, 1)
        dist = np.array([validate.number(get(k, 0.0), f"{jpath}: {k}", -MAX_DISTORTION, MAX_DISTORTION)
                         for k in ("k1", "k2", "p1", "p2", "k3")])
        if np.any(dist != 0):
            k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])
            rgb = cv2.undistort(rgb, k, dist)
            a = None if a is None else cv2.undistort(a, k, dist)
        if downscale > 1:
            size = (rgb.shape[1] // downscale, rgb.shape[0] // downscale)
            if min(size) < 1:
                raise UserError(f"{img_path}: --downscale {downscale} leaves nothing of a {rgb.shape[1]}x"
                                f"{rgb.shape[0]} image")
            rgb = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)
            a = None if a is None else cv2.resize(a, size, interpolation=cv2.INTER_AREA)
            fx, fy, cx, cy = fx / downscale, fy / downscale, cx / downscale, cy / downscale
        images.append(rgb), alphas.append(a), c2ws.append(_matrix(fr, str(jpath))), intr.append((fx, fy, cx, cy))
    if len(images) < 2:
        raise UserError(f"{jpath}: fewer than 2 images found ({skipped} listed frames missing)")
    if len({im.shape for im in images}) > 1:
        raise UserError(f"{jpath}: images differ in size; resize them to one size first")
    n = len(images)
    test = np.arange(0, n, holdout_every)
    train = np.setdiff1d(np.arange(n), test)
    alpha = None if any(a is None for a in alphas) else np.stack(alphas)
    c2w, intr = np.stack(c2ws).astype(np.float32), np.asarray(intr, np.float32)
    start = DEFAULT_BOX if alpha is not None else _box_from_cameras(c2w)
    return PosedImages(images=np.stack(images), alpha=alpha, c2w=c2w, intrinsics=intr,
                       box=validate.check_box(fit_box(alpha, c2w, intr, start), f"{jpath}: the scene box found"),
                       train=train, test=test,
                       name=jpath.parent.name, skipped=skipped, info={"layout": "nerfstudio"})


def _box_from_cameras(c2w: np.ndarray) -> np.ndarray:
    """Cube around the point closest to all optical axes, half the median camera distance wide."""
    o, d = c2w[:, :3, 3].astype(np.float64), -c2w[:, :3, 2].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    proj = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    centre = np.linalg.lstsq(proj.sum(0), np.einsum("nij,nj->i", proj, o), rcond=None)[0]
    half = 0.5 * np.median(np.linalg.norm(o - centre, axis=1))
    return np.stack([centre - half, centre + half]).astype(np.float32)
