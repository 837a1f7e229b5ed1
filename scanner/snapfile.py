"""Snapshot files: the 380x380 image plus the metadata text decoding needs (the QR payload, see `qr`),
kept in a PNG text chunk or a JPEG comment so that a snapshot file restores on its own.

Images: (380, 380, 3) uint8 RGB."""
from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np
from PIL import Image, PngImagePlugin

from snapshot3d import formats
from snapshot3d.errors import UserError

from .imageio_safe import read_image_bgr, write_atomic
from .qr import SheetMeta, decode_payload, encode_payload

__all__ = ["META_KEY", "encode_snapshot", "write_snapshot", "read_snapshot"]

META_KEY = "snapshot3d"
"""name of the PNG text chunk holding the payload"""


def encode_snapshot(rgb: np.ndarray, meta: SheetMeta, ext: str = ".png", jpeg_quality: int = 95) -> bytes:
    """File bytes of a snapshot with its metadata; `ext` .png (lossless) or .jpg."""
    if rgb.dtype != np.uint8 or rgb.shape != (formats.SNAPSHOT_SIZE, formats.SNAPSHOT_SIZE, 3):
        raise ValueError(f"a snapshot is ({formats.SNAPSHOT_SIZE}, {formats.SNAPSHOT_SIZE}, 3) uint8 RGB, got "
                         f"{rgb.shape} {rgb.dtype}")
    text = encode_payload(meta)
    buf = io.BytesIO()
    if ext.lower() == ".png":
        info = PngImagePlugin.PngInfo()
        info.add_text(META_KEY, text)
        Image.fromarray(rgb).save(buf, format="PNG", pnginfo=info)
    elif ext.lower() in (".jpg", ".jpeg"):
        Image.fromarray(rgb).save(buf, format="JPEG", quality=int(jpeg_quality), comment=text.encode())
    else:
        raise UserError(f"cannot write a snapshot as {ext!r}: use .png or .jpg")
    return buf.getvalue()


def write_snapshot(path, rgb: np.ndarray, meta: SheetMeta, jpeg_quality: int = 95) -> None:
    write_atomic(path, encode_snapshot(rgb, meta, Path(path).suffix, jpeg_quality))


def _payload(path: Path) -> str | None:
    try:
        with Image.open(path) as im:
            text = im.info.get(META_KEY) or im.info.get("comment")
    except (OSError, ValueError):
        return None
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    return text or None


def read_snapshot(path, meta_text: str | None = None) -> tuple[np.ndarray, SheetMeta]:
    """(380, 380, 3) uint8 RGB and its metadata; `meta_text` (a QR payload) overrides the file's."""
    path = Path(path)
    rgb = cv2.cvtColor(read_image_bgr(path), cv2.COLOR_BGR2RGB)
    n = formats.SNAPSHOT_SIZE
    if rgb.shape[:2] != (n, n):
        raise UserError(f"{path.name} is {rgb.shape[1]}x{rgb.shape[0]}; a snapshot is {n}x{n} "
                        f"(for a photo of a printed sheet use 'snapshot3d decode')")
    text = meta_text or _payload(path)
    if text is None:
        raise UserError(f"{path.name} carries no snapshot3d metadata; pass the sheet's QR text with --meta")
    try:
        meta = decode_payload(text)
    except ValueError as e:
        raise UserError(f"{path.name}: {e}") from None
    if meta.planes is None or meta.box is None:
        raise UserError(f"{path.name}: its metadata lacks the plane size or the scene box")
    return rgb, meta
