"""Writing views: PNG files, an animated GIF turntable and a contact sheet (numpy, OpenCV, Pillow); a
snapshot as the restore graphs take it (`snapshot_nchw`). Reading an image file with nothing written to
stderr: `snapshot3d.image_decode`.

Views are (N, H, W, 3) float32 RGB in [0, 1] or uint8 RGB."""
from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

__all__ = ["to_uint8", "snapshot_nchw", "fit_square", "write_png", "write_views", "write_gif", "contact_sheet"]


def to_uint8(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint8:
        return img
    return (np.clip(img, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def snapshot_nchw(rgb: np.ndarray) -> np.ndarray:
    """A snapshot (H, W, 3) uint8 RGB -> the restore graphs' `snapshot` input (1, 3, H, W) float32 in [0, 1]."""
    return np.ascontiguousarray((rgb.astype(np.float32) / 255.0).transpose(2, 0, 1)[None])


def fit_square(img: np.ndarray, size: int) -> np.ndarray:
    """(H, W, C) image -> its centred square crop resized to (size, size, C) (area filter when shrinking)."""
    h, w = img.shape[:2]
    s = min(h, w)
    y0, x0 = (h - s) // 2, (w - s) // 2
    crop = np.ascontiguousarray(img[y0:y0 + s, x0:x0 + s])
    interp = cv2.INTER_AREA if s >= size else cv2.INTER_CUBIC
    out = cv2.resize(crop, (size, size), interpolation=interp)
    return out.reshape(size, size, *img.shape[2:])


def write_png(path, rgb: np.ndarray) -> None:
    """Atomic PNG write of an (H, W, 3) RGB image."""
    path = Path(path)
    tmp = path.with_name(path.name + ".partial.png")
    if not cv2.imwrite(str(tmp), cv2.cvtColor(to_uint8(rgb), cv2.COLOR_RGB2BGR)):
        raise OSError(f"cannot write {path}")
    tmp.replace(path)


def write_views(folder, views: np.ndarray) -> list[Path]:
    """`folder/000.png`, `001.png`, ... for views (N, H, W, 3)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / f"{i:03d}.png" for i in range(len(views))]
    for p, v in zip(paths, views):
        write_png(p, v)
    return paths


def write_gif(path, views: np.ndarray, fps: float = 10.0) -> None:
    """Looping animated GIF of views (N, H, W, 3)."""
    path = Path(path)
    frames = [Image.fromarray(to_uint8(v)) for v in views]
    tmp = path.with_name(path.name + ".partial.gif")
    frames[0].save(tmp, save_all=True, append_images=frames[1:], duration=int(1000 / fps), loop=0, optimize=False)
    tmp.replace(path)


def contact_sheet(views: np.ndarray, cols: int | None = None) -> np.ndarray:
    """Tile views (N, H, W, 3) into one uint8 RGB image."""
    views = np.stack([to_uint8(v) for v in views])
    n, h, w, _ = views.shape
    cols = cols or math.ceil(math.sqrt(n))
    rows = math.ceil(n / cols)
    sheet = np.full((rows * h, cols * w, 3), 255, np.uint8)
    for i, v in enumerate(views):
        r, c = divmod(i, cols)
        sheet[r * h:(r + 1) * h, c * w:(c + 1) * w] = v
    return sheet
