"""Snapshot files: the 380x380 image plus the metadata decoding needs (the QR payload, see `qr`), kept twice:
as text (a PNG text chunk or a JPEG comment, the fast path) and as a mark in the pixels (`pixelmeta`,
written by `embed`), so that a shared copy whose text was stripped, re-encoded or resized still restores.
When both are there they must agree.

Images: (380, 380, 3) uint8 RGB. A file-medium snapshot is written at `formats.FILE_SCALE` times that size,
each pixel a square (so a shared copy's JPEG blocks and chroma subsampling fall on several snapshot pixels);
a file read back of another size is resized or realigned to 380x380 by `snapshot_in_image`."""
from __future__ import annotations

import io
import struct
import warnings
from pathlib import Path

import cv2
import numpy as np
from PIL import Image, PngImagePlugin

from snapshot3d import formats
from snapshot3d.errors import UserError

from .imageio_safe import read_image_bgr, write_atomic
from .pixelmeta import MAX_SHIFT, find_meta
from .qr import SheetMeta, check_meta, decode_payload, encode_payload

__all__ = ["META_KEY", "encode_snapshot", "write_snapshot", "file_pixels", "snapshot_pixels", "read_snapshot", "snapshot_in_image", "metas_agree",
           "metadata_text"]

META_KEY = "snapshot3d"
"""name of the PNG text chunk holding the payload"""


def encode_snapshot(rgb: np.ndarray, meta: SheetMeta, ext: str = ".png", jpeg_quality: int = 95,
                    scale: int = 1) -> bytes:
    """File bytes of a snapshot with its metadata; `ext` .png (lossless) or .jpg; the image written at `scale`
    times its size (each pixel a `scale` x `scale` square)."""
    if rgb.dtype != np.uint8 or rgb.shape != (formats.SNAPSHOT_SIZE, formats.SNAPSHOT_SIZE, 3):
        raise ValueError(f"a snapshot is ({formats.SNAPSHOT_SIZE}, {formats.SNAPSHOT_SIZE}, 3) uint8 RGB, got "
                         f"{rgb.shape} {rgb.dtype}")
    text = encode_payload(meta)
    rgb = file_pixels(rgb, scale)
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


def write_snapshot(path, rgb: np.ndarray, meta: SheetMeta, jpeg_quality: int = 95, scale: int = 1) -> None:
    write_atomic(path, encode_snapshot(rgb, meta, Path(path).suffix, jpeg_quality, scale))


def file_pixels(rgb: np.ndarray, scale: int) -> np.ndarray:
    """A snapshot (380, 380, 3) uint8 as a file holds it at `scale` times its size: (380 s, 380 s, 3), each
    pixel a `scale` x `scale` square."""
    return np.repeat(np.repeat(rgb, scale, 0), scale, 1) if scale > 1 else rgb


def snapshot_pixels(rgb: np.ndarray) -> np.ndarray:
    """An image (H, W, 3) uint8 that is a snapshot written at an integer multiple of its size (the file
    medium's) -> (380, 380, 3) by block means; any other image unchanged. Only exact multiples, whose squares
    start at (0, 0): a copy cropped or padded by a few pixels is shrunk by `pixelmeta.shrink_squares`, which
    first finds the squares' phase from their edges (a flat image has none, and that search would guess)."""
    n, (h, w) = formats.SNAPSHOT_SIZE, rgb.shape[:2]
    if h == w and h > n and h % n == 0:
        return cv2.resize(rgb, (n, n), interpolation=cv2.INTER_AREA)
    return rgb


def metadata_text(path) -> str | None:
    """The snapshot3d metadata text a file carries (PNG text chunk or JPEG comment), or None. Pillow's
    warnings (a large image, odd EXIF) are not printed."""
    old = Image.MAX_IMAGE_PIXELS
    try:
        Image.MAX_IMAGE_PIXELS = None   # the caller has checked the size (`imageio_safe.image_size`)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                text = im.info.get(META_KEY) or im.info.get("comment")
    except (OSError, ValueError, SyntaxError, EOFError, struct.error):
        return None
    finally:
        Image.MAX_IMAGE_PIXELS = old
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    return text if isinstance(text, str) and text else None


def metas_agree(a: SheetMeta, b: SheetMeta) -> bool:
    """The same metadata up to the text's four significant digits."""
    def close(x, y):
        return (x is None) == (y is None) and (x is None or np.allclose(x, y, rtol=1e-3, atol=1e-4))
    return (a.version, a.codec, a.planes, a.decoder_version) == (b.version, b.codec, b.planes, b.decoder_version) and all(
        close(getattr(a, k), getattr(b, k)) for k in ("box", "orbit", "target", "strength"))


def _maybe_snapshot(h: int, w: int) -> bool:
    """A snapshot copy is square (resized or not) or within MAX_SHIFT pixels of the snapshot's size."""
    n = formats.SNAPSHOT_SIZE
    return (abs(h - n) <= MAX_SHIFT and abs(w - n) <= MAX_SHIFT) or (abs(h - w) <= 0.02 * max(h, w) and h <= 8192)


def snapshot_in_image(name: str, rgb: np.ndarray, text: str | None, trust_text: bool = False
                      ) -> tuple[np.ndarray, SheetMeta, str] | None:
    """(snapshot (380, 380, 3) uint8 RGB, metadata, where the metadata came from: "text" or "pixels") of an
    image file's (H, W, 3) uint8 RGB and its metadata text (None when it has none); None when the image is
    no snapshot (no text, no readable mark). With `trust_text` (a QR text the user passed) the mark is not
    consulted for the metadata, only for the alignment of a resized or cropped copy."""
    n = formats.SNAPSHOT_SIZE
    found = find_meta(rgb) if _maybe_snapshot(*rgb.shape[:2]) else None
    if text is None and found is None:
        return None
    if text is None:
        return found[1], check_meta(found[0], f"{name}: the mark in its pixels", require_codec=False), "pixels"
    try:
        meta = decode_payload(text)
    except ValueError as e:
        raise UserError(f"{name}: {e}") from None
    if found is not None and not trust_text and not metas_agree(meta, found[0]):
        raise UserError(f"{name}: its metadata text and the mark in its pixels disagree (an edited or "
                        f"mislabelled file); pass the sheet's QR text with --meta to choose")
    check_meta(meta, f"{name}: its metadata", require_codec=False)
    if found is not None:
        return found[1], meta, "text"
    rgb = snapshot_pixels(rgb)
    if rgb.shape[:2] != (n, n):
        raise UserError(f"{name} is {rgb.shape[1]}x{rgb.shape[0]} and no snapshot mark reads in its pixels; a "
                        f"snapshot is {n}x{n} (for a photo of a printed sheet use 'snapshot3d decode')")
    return rgb, meta, "text"


def read_snapshot(path, meta_text: str | None = None) -> tuple[np.ndarray, SheetMeta]:
    """(380, 380, 3) uint8 RGB and its metadata, from the file's text or the mark in its pixels (a copy that
    was re-encoded, resized or cropped is realigned); `meta_text` (a QR payload) overrides both."""
    path = Path(path)
    rgb = cv2.cvtColor(read_image_bgr(path, "snapshot"), cv2.COLOR_BGR2RGB)
    got = snapshot_in_image(path.name, rgb, meta_text or metadata_text(path), trust_text=meta_text is not None)
    if got is None:
        size = "" if rgb.shape[:2] == (formats.SNAPSHOT_SIZE,) * 2 else f" ({rgb.shape[1]}x{rgb.shape[0]})"
        raise UserError(f"{path.name}{size} carries no snapshot3d metadata: no text chunk, and no mark readable in its "
                        f"pixels (not a snapshot, or damaged past reading); pass the sheet's QR text with --meta")
    rgb, meta, _ = got
    if meta.planes is None or meta.box is None:
        raise UserError(f"{path.name}: its metadata lacks the plane size or the scene box")
    return rgb, meta
