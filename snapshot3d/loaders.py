"""Scene inputs -> `PosedImages`: Blender/NeRF-Synthetic folders, nerfstudio `transforms.json`, COLMAP text
models, `builtin:NAME` (docs/capture.md).

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
from .capture import CaptureOptions, assemble, box_from_cameras, builtin_options, check_holdout, fit_box, shrink
from .errors import UserError
from .image_decode import decode_image
from .lens import check_model, lens_coeffs, undistort
from .posed import PosedImages

__all__ = ["load_scene", "load_blender", "load_nerfstudio", "load_colmap", "fit_box"]

MAX_MATRIX_ENTRY = 1e6     # |entries| of a camera-to-world matrix (world units)
MAX_FOCAL = 1e6            # focal length and principal point, pixels
MAX_DISTORTION = 100.0     # |k1|, |k2|, |p1|, |p2|, |k3|



def load_scene(spec: str, downscale: int = 1, capture: CaptureOptions | None = None, **builtin_kw) -> PosedImages:
    """`builtin:NAME`, a Blender folder (with `transforms_train.json`), a nerfstudio folder or
    `transforms.json` file, or a COLMAP sparse text model (a folder with `cameras.txt` and `images.txt`, or
    with `sparse/0/` holding them). `capture` (`snapshot3d.capture.CaptureOptions`): the held-out split, box,
    up axis and image size limit; what was read is in `info["capture"]` (`capture.describe`)."""
    if downscale < 1:
        raise UserError(f"--downscale must be >= 1, not {downscale}")
    opts = capture or CaptureOptions()
    if opts.holdout is not None:
        check_holdout(opts.holdout)
    if opts.max_size is not None:
        validate.integer(opts.max_size, "--max-size", 8, 1 << 16)
    if spec.startswith("builtin:"):
        from .builtin import builtin_scene  # lazy: renders meshes
        size = builtin_kw.pop("size", 200)
        posed = builtin_scene(spec.split(":", 1)[1], size=max(8, size // downscale), **builtin_kw)
        return builtin_options(posed, opts)
    path = Path(spec)
    if not path.exists():
        raise UserError(f"scene not found: {spec} (give a folder, a transforms.json, a COLMAP model or builtin:NAME)")
    if path.suffix == ".s3d":
        from .scene import load_scene_file
        load_scene_file(path)  # a scene for another decoder or a corrupt file is refused with its own reason
        raise UserError(f"{spec} is an already fitted scene; fit takes posed images (a folder, transforms.json "
                        "or builtin:NAME)")
    if path.is_dir() and (path / "transforms_train.json").is_file():
        return load_blender(path, downscale, opts)
    if path.is_file() and path.suffix == ".json":
        return load_nerfstudio(path, downscale, opts)
    if path.is_dir() and (path / "transforms.json").is_file():
        return load_nerfstudio(path / "transforms.json", downscale, opts)
    from . import colmap
    model = path.parent if path.is_file() and path.name in ("cameras.txt", "images.txt") else \
        colmap.find_model(path) if path.is_dir() else None
    if model is not None:
        return load_colmap(model, downscale, opts)
    raise UserError(f"{spec}: no transforms_train.json (Blender), transforms.json (nerfstudio) or cameras.txt + "
                    "images.txt (COLMAP text model) found")


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
    `validate.MAX_PIXELS` before decoding; nothing is written to stderr (`image_decode.decode_image`)."""
    _check_header(path)
    try:
        img = decode_image(path.read_bytes(), unchanged=True)
    except (OSError, ValueError) as e:   # ValueError names the fault: "CRC error in its IDAT chunk"
        raise UserError(f"{path}: cannot read image ({getattr(e, 'strerror', None) or e})") from None
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
        raise UserError(f"{where}: no valid 'transform_matrix' (the frame's pose)") from None
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


def load_blender(folder: Path, downscale: int = 1, capture: CaptureOptions | None = None) -> PosedImages:
    """NeRF-Synthetic layout: `transforms_{train,val,test}.json`, `camera_angle_x`, file paths without
    extension. Frames whose image is missing are skipped and counted. With no test split on disk,
    every 5th training frame is held out (or as `capture.holdout` says, over all frames read)."""
    opts = capture or CaptureOptions()
    splits, skipped = {}, 0
    for split_name in ("train", "test"):
        jpath = folder / f"transforms_{split_name}.json"
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
            rows.append((img_path, _matrix(fr, f"{jpath} ({rel})"), fov))
        splits[split_name] = rows
    train_rows = splits.get("train", [])
    test_rows = splits.get("test", [])
    how = "the test split"
    if not test_rows:
        test_rows = train_rows[2::5]
        train_rows = [r for i, r in enumerate(train_rows) if i % 5 != 2]
        how = "every 5th training frame"
    rows = train_rows + test_rows
    if len(train_rows) < 2 and opts.holdout is None:
        raise UserError(f"{folder}: fewer than 2 training images found ({skipped} listed frames missing)")
    frames = []
    for img_path, m, fov in rows:
        rgb, a = _read_image(img_path, downscale)
        rgb, a, _, _ = shrink(rgb, a, 1, opts.max_size, str(img_path))
        h, w = rgb.shape[:2]
        f = 0.5 * w / np.tan(0.5 * fov)
        frames.append((rgb, a, m, (f, f, w / 2, h / 2)))
    default = (np.arange(len(train_rows)), np.arange(len(train_rows), len(rows)), how)
    return assemble(frames, opts, where=str(folder), name=folder.name, layout="blender", default_up=None,
                     default_split=default, skipped={"image missing": skipped}, box_start=None)


def _read_mask(path: Path, size: tuple[int, int], where: str) -> np.ndarray:
    """A frame's `mask_path` image (single channel; nonzero = keep) -> (H, W) float32 in {0, 1} at `size`
    (W, H); a mask of another size with the same aspect is resized (nearest)."""
    if not path.is_file():
        raise UserError(f"{path}: mask not found (named by a frame's mask_path in {where})")
    _check_header(path)
    try:
        m = decode_image(path.read_bytes(), unchanged=True)
    except (OSError, ValueError) as e:
        raise UserError(f"{path}: cannot read mask image ({getattr(e, 'strerror', None) or e})") from None
    if m is None or m.size == 0 or m.ndim not in (2, 3):
        raise UserError(f"{path}: cannot read mask image")
    m = (m.reshape(m.shape[0], m.shape[1], -1)[..., :3] > 0).any(-1).astype(np.float32)
    h, w = m.shape
    if (w, h) != size:
        if abs(w / h - size[0] / size[1]) > 0.01 * size[0] / size[1]:
            raise UserError(f"{path}: the mask is {w}x{h} but its image is {size[0]}x{size[1]}")
        m = cv2.resize(m, size, interpolation=cv2.INTER_NEAREST)
    return m


def _read_frame(img_path: Path, mask_path: Path | None, k: tuple, model: str, coeffs: np.ndarray,
                size: tuple | None, downscale: int, max_size: int | None, where: str):
    """One frame: read (RGB on white, alpha from RGBA times the mask), undo the lens at full size, shrink.
    k: (fx, fy, cx, cy) of the full-size image; size: the camera's (W, H) or None. -> rgb, alpha, k scaled."""
    rgb, a = _read_image(img_path, 1)
    h, w = rgb.shape[:2]
    if size is not None and tuple(size) != (w, h):
        raise UserError(f"{img_path}: the image is {w}x{h} but its camera says {size[0]}x{size[1]}")
    if mask_path is not None:
        m = _read_mask(mask_path, (w, h), where)
        rgb = rgb * m[..., None] + (1.0 - m[..., None])   # outside the mask is background: white
        a = m if a is None else a * m
    rgb = undistort(rgb, *k, model, coeffs)
    a = None if a is None else undistort(a, *k, model, coeffs)
    rgb, a, sx, sy = shrink(rgb, a, downscale, max_size, str(img_path))
    return rgb, a, (k[0] * sx, k[1] * sy, k[2] * sx, k[3] * sy)


def load_nerfstudio(jpath: Path, downscale: int = 1, capture: CaptureOptions | None = None) -> PosedImages:
    """nerfstudio layout: `fl_x fl_y cx cy w h` and distortion (global, or per frame overriding them),
    `camera_model` (PINHOLE, OPENCV: k1 k2 p1 p2 [k3], OPENCV_FISHEYE: k1..k4; undone on load),
    `transform_matrix` and optional `mask_path` per frame. Every 8th frame is held out unless `capture` says."""
    opts = capture or CaptureOptions()
    data = _read_json(jpath)
    model = check_model(data.get("camera_model", "OPENCV"), str(jpath))
    has_mask = [("mask_path" in fr) for fr in data["frames"]]
    if any(has_mask) and not all(has_mask):
        raise UserError(f"{jpath}: {sum(has_mask)} of {len(has_mask)} frames give a mask_path; give one for every "
                        "frame or none")
    frames, skipped = [], {"image missing": 0}
    for fr in data["frames"]:
        get = lambda k, d=None: fr.get(k, data.get(k, d))  # noqa: E731 - per-frame overrides
        rel = _file_path(fr, str(jpath))
        img_path = jpath.parent / rel
        if not img_path.is_file():
            skipped["image missing"] += 1
            continue
        if any(get(k) is None for k in ("fl_x", "fl_y", "cx", "cy")):
            raise UserError(f"{jpath}: intrinsics fl_x, fl_y, cx, cy are required (none for frame {rel})")
        fx, fy = (validate.number(get(k), f"{jpath}: {k}", 1e-3, MAX_FOCAL) for k in ("fl_x", "fl_y"))
        cx, cy = (validate.number(get(k), f"{jpath}: {k}", -MAX_FOCAL, MAX_FOCAL) for k in ("cx", "cy"))
        size = None
        if get("w") is not None and get("h") is not None:
            size = tuple(validate.integer(get(k), f"{jpath}: {k}", 1, 1 << 16) for k in ("w", "h"))
        coeffs = lens_coeffs(model, {k: validate.number(get(k, 0.0), f"{jpath}: {k}", -MAX_DISTORTION, MAX_DISTORTION)
                                     for k in ("k1", "k2", "k3", "k4", "p1", "p2")})
        m = _matrix(fr, f"{jpath} (frame {rel})")
        mask = None
        if "mask_path" in fr:
            mrel = fr["mask_path"]
            if not isinstance(mrel, str) or "\0" in mrel:
                raise UserError(f"{jpath}: a frame's 'mask_path' must be a text, got {validate.show(mrel)}")
            mask = jpath.parent / mrel
        rgb, a, k = _read_frame(img_path, mask, (fx, fy, cx, cy), model, coeffs, size, downscale, opts.max_size,
                                str(jpath))
        frames.append((rgb, a, m, k))
    return assemble(frames, opts, where=str(jpath), name=jpath.parent.name, layout="nerfstudio", default_up="auto",
                     default_split=8, skipped=skipped, box_start=box_from_cameras)


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp")


def load_colmap(model_dir: Path, downscale: int = 1, capture: CaptureOptions | None = None) -> PosedImages:
    """COLMAP sparse text model in `model_dir` (`snapshot3d.colmap`) with its images in `images/` beside it
    (or two folders up, for `sparse/0`). Lenses are undone on load; every 8th image (sorted by name) is held
    out and the world turned so that up (`capture.cameras_up`) is +z, unless `capture` says otherwise."""
    from . import colmap

    opts = capture or CaptureOptions()
    cams = colmap.read_cameras(model_dir / "cameras.txt")
    ims = colmap.read_images(model_dir / "images.txt", cams)
    img_dir = next((d for d in (model_dir / "images", model_dir.parent / "images", model_dir.parent.parent / "images")
                    if d.is_dir()), None)
    if img_dir is None:
        raise UserError(f"{model_dir}: no images/ folder beside the COLMAP model (nor one or two folders up)")
    listed = {im.name for im in ims}
    on_disk = [p.relative_to(img_dir).as_posix() for p in img_dir.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES]
    skipped = {"image missing": 0, "without a pose in images.txt": sum(n not in listed for n in on_disk)}
    frames = []
    for im in ims:
        path = img_dir / im.name
        if not path.is_file():
            skipped["image missing"] += 1
            continue
        cam = cams[im.camera_id]
        rgb, a, k = _read_frame(path, None, (cam.fx, cam.fy, cam.cx, cam.cy), cam.model, cam.coeffs,
                                (cam.width, cam.height), downscale, opts.max_size, str(model_dir))
        frames.append((rgb, a, im.c2w, k))
    return assemble(frames, opts, where=str(model_dir), name=img_dir.parent.name, layout="colmap",
                     default_up="auto", default_split=8, skipped=skipped, box_start=box_from_cameras)
