"""Reading a user's photo without trusting it, and writing outputs atomically.

`read_image_bgr` checks, before decoding, that the file exists, is an image (by its header, via
Pillow's lazy open), is within MAX_PIXELS (a decompression bomb is refused before any pixel buffer
is allocated; `snapshot3d.validate` holds the limits), is one of the formats read here and, for JPEG and PNG,
is complete (no truncation); then `snapshot3d.image_decode.decode_image` decodes it with nothing written to
stderr (Pillow's silent libjpeg for JPEG; a PNG's chunks checked before OpenCV reads them; OpenCV's log off),
so no thread ever needs stderr pointed elsewhere. Every failure is a one-line `UserError` naming the cause."""
from __future__ import annotations

import logging
import os
import re
import struct
import tempfile
import warnings
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from snapshot3d.errors import UserError
from snapshot3d.image_decode import decode_image
from snapshot3d.validate import MAX_BYTES, MAX_PIXELS, check_image_size

__all__ = ["MAX_PIXELS", "MAX_BYTES", "read_image_bgr", "image_size", "write_atomic", "write_image"]

_FORMATS = ("JPEG", "MPO", "PNG", "WEBP", "BMP", "TIFF")   # what OpenCV decodes here (MPO: a phone's JPEG)
_MAGIC = ((b"\xff\xd8", "JPEG"), (b"\x89PNG", "PNG"), (b"GIF8", "GIF"), (b"BM", "BMP"), (b"RIFF", "WebP"),
          (b"II*\x00", "TIFF"), (b"MM\x00*", "TIFF"))
_JPEG_MARKER = re.compile(rb"\xff[^\x00\xd0-\xd7\xff]")
_HEIF_BRANDS = {b"heic", b"heix", b"hevc", b"hevx", b"heim", b"heis", b"hevm", b"hevs", b"mif1", b"msf1", b"avif",
                b"avis"}
"""ISO base media brands of HEIF and AVIF stills (bytes 8-12, after "ftyp"): an iPhone's default photo format"""


def image_size(path, what: str = "photo") -> tuple[int, int, str]:
    """(width, height, format) from the file's header, without decoding pixels; UserError if not an image
    (`what` names the file in the message: "photo", "sheet", ...)."""
    from PIL import Image

    path = Path(path)
    _quiet_libraries()
    if path.is_dir():
        raise UserError(f"{path} is a folder; give the {what} file itself")
    if not path.is_file():
        raise UserError(f"{path} is not a regular file (a device, a pipe or a socket); give the {what} file itself"
                        if path.exists() else f"{what} not found: {path}")
    if path.stat().st_size > MAX_BYTES:
        raise UserError(f"{path.name} is too large ({path.stat().st_size / 1e6:.0f} MB; limit {MAX_BYTES / 1e6:.0f} MB)")
    if path.stat().st_size == 0:
        raise UserError(f"{path.name} is empty (0 bytes), not an image")
    old = Image.MAX_IMAGE_PIXELS
    try:
        Image.MAX_IMAGE_PIXELS = None  # we apply our own limit below, with our own message
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                w, h, fmt = im.size[0], im.size[1], im.format or "?"
    except Image.UnidentifiedImageError:
        head = path.open("rb").read(12)
        if head[4:8] == b"ftyp" and head[8:12] in _HEIF_BRANDS:
            raise UserError(f"{path.name} is a HEIF/HEIC or AVIF photo, which is not read here: save it as JPEG (on an "
                            f"iPhone, Settings > Camera > Formats > Most Compatible)") from None
        for magic, kind in _MAGIC:
            if head.startswith(magic):
                raise UserError(f"{path.name} is a corrupt {kind} file (unreadable header)") from None
        raise UserError(f"{path.name} is not an image file (unrecognised content)") from None
    except (OSError, SyntaxError, ValueError, EOFError, struct.error) as e:
        first = (str(e).splitlines() or [type(e).__name__])[0][:80]
        raise UserError(f"{path.name} is a corrupt image file ({first})") from None
    finally:
        Image.MAX_IMAGE_PIXELS = old
    check_image_size(w, h, path.name)
    return w, h, fmt


def _jpeg_complete(data: bytes) -> bool:
    """Walk the JPEG's segments and entropy-coded scans; True when an EOI marker ends the image."""
    if data[:2] != b"\xff\xd8":
        return False
    pos = 2
    while pos + 2 <= len(data):
        if data[pos] != 0xFF:
            return False
        marker = data[pos + 1]
        if marker == 0xD9:
            return True
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if pos + 4 > len(data):
            return False
        seglen = int.from_bytes(data[pos + 2:pos + 4], "big")
        pos += 2 + seglen
        if marker == 0xDA:  # start of scan: skip entropy-coded data to the next real marker
            m = _JPEG_MARKER.search(data, pos)
            if m is None:
                return False
            pos = m.start()
    return False


def read_image_bgr(path, what: str = "photo") -> np.ndarray:
    """Decode an image file to (H, W, 3) uint8 **BGR** (OpenCV order), EXIF orientation applied; `what`
    names the file in error messages."""
    path = Path(path)
    w, h, fmt = image_size(path, what)
    if fmt not in _FORMATS:
        raise UserError(f"{path.name} is a {fmt} image; give a JPEG or PNG file")
    data = path.read_bytes()
    if fmt in ("JPEG", "MPO") and not _jpeg_complete(data):
        raise UserError(f"{path.name} is a corrupt or truncated JPEG file")
    if fmt == "PNG" and b"IEND" not in data[-64:]:
        raise UserError(f"{path.name} is a corrupt or truncated PNG file")
    try:
        img = decode_image(data)
    except ValueError as e:
        raise UserError(f"{path.name} is a corrupt {fmt} file ({e})") from None
    if sorted(img.shape[:2]) != sorted((w, h)):   # the header's size was checked; the decoder must agree
        raise UserError(f"{path.name} decodes to {img.shape[1]}x{img.shape[0]}, not the {w}x{h} its header declares")
    return img


@lru_cache(maxsize=1)
@lru_cache(maxsize=None)
def _quiet_libraries() -> None:
    """OpenCV's own log at errors only, Pillow's `logging` messages off (on a damaged file they would
    print beside the one-line error); once per process."""
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    logging.getLogger("PIL").setLevel(logging.CRITICAL)   # it logs a damaged TIFF at ERROR, then raises


def write_atomic(path, data: bytes) -> None:
    """Write bytes to `path` via a temporary file in the same folder and a rename (no partial file); its folder
    is made when missing. UserError when the path cannot be written (a folder, a file as its folder, no
    permission)."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    except OSError as e:
        raise UserError(f"cannot write {path} ({e.strerror or type(e).__name__})") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
        os.replace(tmp, path)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        raise UserError(f"cannot write {path} ({e.strerror or type(e).__name__})") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_image(path, rgb: np.ndarray, jpeg_quality: int = 95) -> None:
    """Atomically write (H, W, 3) uint8 **RGB** as PNG or JPEG (by the file's extension)."""
    path = Path(path)
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected (H, W, 3) uint8 RGB, got {rgb.shape} {rgb.dtype}")
    ext = path.suffix.lower()
    if ext not in (".png", ".jpg", ".jpeg"):
        raise UserError(f"cannot write {path.name}: use a .png or .jpg file name")
    params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)] if ext != ".png" else []
    ok, buf = cv2.imencode(".png" if ext == ".png" else ".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), params)
    if not ok:
        raise OSError(f"cannot encode {path}")
    write_atomic(path, buf.tobytes())
