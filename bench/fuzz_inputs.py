"""Hostile inputs for `snapshot3d bench fuzz`, crafted and mutated from the bundled seeds, seeded.

An `Input` is one file set and one target: a fast reader called in process (`reader`), or a command
line (`argv`, run through `snapshot3d.cli.main`; `{d}` stands for the input's folder). Classes follow issue
36 (thin images, metadata plane sizes, inf/1e309 and NaN-producing metadata, .s3d headers, np.load
failures, .s3d bombs, non-finite numbers, library warnings) plus truncated, random, empty and bit-flipped
files, huge header dimensions, wrong extensions, unicode and odd paths, option values and transforms.json."""
from __future__ import annotations

import io
import json
import struct
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

__all__ = ["Input", "Seeds"]


@dataclass
class Input:
    cls: str
    label: str
    files: dict = field(default_factory=dict)  # name -> bytes, written into the input's folder
    reader: str | None = None  # "image", "snapshot", "s3d", "transforms" (bench.fuzz_run.READERS)
    arg: str = ""  # the file the reader reads (name in `files`), or a QR text for "snapshot"
    argv: list | None = None  # a command line; "{d}" is the input's folder
    outputs: tuple = ()  # what the command writes (names under {d}): absent after a failure


class Seeds:
    """The valid files every mutation starts from."""

    def __init__(self, root: Path):
        from PIL import Image

        from snapshot3d.paths import asset
        from snapshot3d.scanner.snapfile import metadata_text
        snap = root / "tests" / "data" / "spot-snapshot.png"
        self.snap_png = snap.read_bytes()
        self.meta = metadata_text(snap)
        self.rgb = cv2.cvtColor(cv2.imread(str(snap)), cv2.COLOR_BGR2RGB)
        buf = io.BytesIO()
        Image.fromarray(self.rgb).save(buf, "JPEG", quality=95, comment=self.meta.encode())
        self.snap_jpg = buf.getvalue()
        photo = cv2.imread(str(asset("example-photo.jpg")))
        self.photo_jpg = cv2.imencode(".jpg", cv2.resize(photo, (1600, 1200), interpolation=cv2.INTER_AREA),
                                      [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()
        self.s3d = Path(asset("spot.s3d")).read_bytes()
        self.noise = np.random.default_rng(0).integers(0, 256, (380, 380, 3), np.uint8)


def png_text(rgb: np.ndarray, text: str | None) -> bytes:
    from PIL import Image, PngImagePlugin
    info = PngImagePlugin.PngInfo()
    if text is not None:
        info.add_text("snapshot3d", text)
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, "PNG", pnginfo=info, compress_level=1)
    return buf.getvalue()


def jpeg_comment(rgb: np.ndarray, text: str) -> bytes:
    from PIL import Image
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, "JPEG", quality=92, comment=text.encode("utf-8", "replace"))
    return buf.getvalue()


def _chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def png_header_only(w: int, h: int, depth=8, colour=2, idat=b"") -> bytes:
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, colour, 0, 0, 0))
            + _chunk(b"IDAT", idat or zlib.compress(b"\0" * 64)) + _chunk(b"IEND", b""))


def jpeg_sof(w: int, h: int) -> bytes:
    """A JPEG whose SOF0 declares w x h (the rest is a tiny real image's)."""
    data = bytearray(cv2.imencode(".jpg", np.zeros((8, 8, 3), np.uint8))[1].tobytes())
    i = data.find(b"\xff\xc0")
    data[i + 5:i + 9] = struct.pack(">HH", h, w)
    return bytes(data)


def npy(arr_or_descr, shape=None, body: bytes | None = None, header_text: str | None = None) -> bytes:
    """A .npy member: a real array, or a crafted header (descr, shape) with `body` bytes after it."""
    if isinstance(arr_or_descr, np.ndarray):
        buf = io.BytesIO()
        np.lib.format.write_array(buf, arr_or_descr, allow_pickle=False)
        return buf.getvalue()
    text = header_text or f"{{'descr': '{arr_or_descr}', 'fortran_order': False, 'shape': {tuple(shape)!r}, }}"
    text = text + " " * (63 - (len(text) + 10) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text.encode("latin-1") + (body or b"")


def npz(members: dict, compress=False) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED) as z:
        for name, data in members.items():
            z.writestr(name + ".npy", data)
    return buf.getvalue()


def s3d_parts(seed: bytes) -> dict:
    with np.load(io.BytesIO(seed)) as z:
        return {k: z[k] for k in z.files}


def s3d(parts: dict, header=None, **arrays) -> bytes:
    """A scene file from the seed's arrays with `header` (a JSON value, or raw bytes) and arrays replaced."""
    h = json.loads(bytes(parts["header"]).decode()) if header is None else header
    raw = h if isinstance(h, bytes) else json.dumps(h).encode()
    members = {"codes": npy(parts["codes"]), "box": npy(parts["box"]),
               "header": npy(np.frombuffer(raw, np.uint8))}
    for k, v in arrays.items():
        members[k] = v if isinstance(v, bytes) else npy(v)
    return npz(members)


def mutate(data: bytes, rng, n: int | None = None) -> bytes:
    """Flip, overwrite, insert or delete a few bytes (the first 4 kB more often: headers live there)."""
    b = bytearray(data)
    for _ in range(n or int(rng.integers(1, 9))):
        hi = len(b) if rng.random() < 0.5 else min(len(b), 4096)
        if hi == 0:
            break
        i, op = int(rng.integers(0, hi)), rng.integers(0, 4)
        if op == 0:
            b[i] ^= 1 << int(rng.integers(0, 8))
        elif op == 1:
            b[i] = int(rng.choice([0, 255, 127, 128, 1]))
        elif op == 2:
            b[i:i] = bytes(rng.integers(0, 256, int(rng.integers(1, 16)), np.uint8))
        else:
            del b[i:i + int(rng.integers(1, 16))]
    return bytes(b)
