"""Decoding image file bytes with nothing written to file descriptor 2, so that a process with many threads
(the `serve` server's decode threads) never needs to point stderr elsewhere while an image is read.

What would otherwise print beside a one-line error, and how each is kept off:
- libjpeg's warnings ("Corrupt JPEG data: 291 extraneous bytes before marker 0xd9", "premature end of data
  segment"): its default message handler writes to stderr and OpenCV keeps it. JPEG is decoded by Pillow
  instead (the same libjpeg-turbo, same IDCT: bit-identical pixels), whose handler drops the messages.
- libpng's errors and warnings ("libpng error: IDAT: CRC error", "libpng warning: iCCP: too short"):
  OpenCV keeps libpng's default handlers, which write to stderr. `_png_checked` reads the file's chunks
  first (CRCs, the header's numbers, the whole zlib stream and its exact size, each row's filter byte)
  and names what is wrong; the bytes OpenCV then decodes hold only the chunks it uses, each valid.
- OpenCV's own log ("[ WARN:0@0.08] ... PNG input buffer is incomplete", libtiff's and OpenJPEG's errors,
  which OpenCV routes to its log): set to silent. A decoder's failure is its return value, which the
  callers turn into a one-line error.
Pillow's warnings (a damaged EXIF block, a large image) are ignored, once per process."""
from __future__ import annotations

import io
import warnings
import zlib
from functools import lru_cache

import cv2
import numpy as np

__all__ = ["decode_image"]

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_DEPTHS = {0: (1, 2, 4, 8, 16), 2: (8, 16), 3: (1, 2, 4, 8), 4: (8, 16), 6: (8, 16)}   # colour type -> bits
_PNG_SAMPLES = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
_PNG_SIDE_MAX = 1_000_000   # libpng's default limit on width and height
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2), (0, 1, 1, 2))
_INFLATE_PIECE = 1 << 22


def decode_image(data: bytes, unchanged: bool = False) -> np.ndarray:
    """Image file bytes -> pixels as `cv2.imdecode` gives them: (H, W, 3) uint8 **BGR** with the EXIF
    orientation applied, or with `unchanged` as stored: (H, W), (H, W, 3) BGR or (H, W, 4) BGRA, uint8 or
    uint16, no orientation. ValueError with a short cause ("CRC error in its IDAT chunk") when the data
    cannot be decoded; nothing is written to stderr either way."""
    _quiet_decoders()
    data = bytes(data)
    if data[:2] == b"\xff\xd8":
        return _jpeg(data, unchanged)
    if data[:8] == _PNG_SIGNATURE:
        data = _png_checked(data, keep_exif=not unchanged)
    try:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED if unchanged else cv2.IMREAD_COLOR)
    except cv2.error as e:
        raise ValueError(f"OpenCV: {str(e).strip().splitlines()[-1][:80]}") from None
    if img is None or img.size == 0:
        raise ValueError("its decoder cannot read it")
    return img


def _quiet_decoders() -> None:
    """OpenCV's log silent (checked on each call: another module may have set it to errors); Pillow's
    warnings ignored, once."""
    if cv2.utils.logging.getLogLevel() != cv2.utils.logging.LOG_LEVEL_SILENT:
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    _ignore_pillow_warnings()


@lru_cache(maxsize=1)
def _ignore_pillow_warnings() -> None:
    from PIL import Image

    warnings.filterwarnings("ignore", module=r"PIL(\.|$)")
    warnings.filterwarnings("ignore", category=Image.DecompressionBombWarning)   # our own limits apply


def _jpeg(data: bytes, unchanged: bool) -> np.ndarray:
    from PIL import Image, ImageOps

    try:
        with Image.open(io.BytesIO(data), formats=["JPEG"]) as im:
            im.load()
            if not unchanged:
                try:
                    ImageOps.exif_transpose(im, in_place=True)
                except Exception:  # a damaged EXIF block: no orientation, as OpenCV does
                    pass
            if im.mode not in ("L", "RGB"):
                im = im.convert("RGB")   # CMYK (Pillow's conversion, not OpenCV's)
            pixels = np.asarray(im)
    except Image.UnidentifiedImageError:
        raise ValueError("its JPEG header cannot be read") from None
    except Exception as e:  # Pillow raises OSError, SyntaxError, ValueError, struct.error, ...
        first = (str(e).splitlines() or [type(e).__name__])[0][:80]
        raise ValueError(f"JPEG data: {first}") from None
    if pixels.ndim == 2:
        return pixels if unchanged else cv2.cvtColor(pixels, cv2.COLOR_GRAY2BGR)
    return cv2.cvtColor(pixels, cv2.COLOR_RGB2BGR)


def _chunk(kind: bytes, body: bytes) -> bytes:
    return len(body).to_bytes(4, "big") + kind + body + zlib.crc32(body, zlib.crc32(kind)).to_bytes(4, "big")


def _png_chunks(data: bytes):
    """(type, body) of each chunk up to IEND, CRCs checked."""
    view, pos = memoryview(data), 8
    while True:
        if pos + 12 > len(data):
            raise ValueError("truncated (it ends before its IEND chunk)")
        n, kind = int.from_bytes(data[pos:pos + 4], "big"), data[pos + 4:pos + 8]
        if not kind.isalpha() or not kind.isascii():
            raise ValueError(f"not a PNG chunk at byte {pos}")
        name, end = kind.decode("ascii"), pos + 12 + n
        if end > len(data):
            raise ValueError(f"truncated (its {name} chunk is cut off)")
        if zlib.crc32(view[pos + 4:end - 4]) != int.from_bytes(data[end - 4:end], "big"):
            raise ValueError(f"CRC error in its {name} chunk")
        yield kind, view[pos + 8:end - 4]
        if kind == b"IEND":
            return
        pos = end


def _png_checked(data: bytes, keep_exif: bool) -> bytes:
    """A PNG file -> the same image as a PNG of only IHDR, PLTE, tRNS, (eXIf), IDAT and IEND, each checked so
    that libpng finds nothing to say; ValueError naming the first fault."""
    chunks = _png_chunks(data)
    kind, ihdr = next(chunks)
    if kind != b"IHDR" or len(ihdr) != 13:
        raise ValueError("no valid IHDR chunk first")
    w, h = int.from_bytes(ihdr[:4], "big"), int.from_bytes(ihdr[4:8], "big")
    depth, ctype, method, filt, interlace = ihdr[8:13]
    if not (0 < w <= _PNG_SIDE_MAX and 0 < h <= _PNG_SIDE_MAX):
        raise ValueError(f"its header declares {w}x{h} pixels")
    if depth not in _PNG_DEPTHS.get(ctype, ()) or method or filt or interlace > 1:
        raise ValueError(f"its header is invalid (colour type {ctype}, bit depth {depth})")
    palette = trns = exif = None
    idat = []
    for kind, body in chunks:
        if kind == b"IEND":
            break
        if kind == b"IDAT":
            idat.append(body)
        elif kind == b"IHDR" or (kind == b"PLTE" and ctype == 3 and (palette is not None or idat)):
            raise ValueError(f"a misplaced {kind.decode()} chunk")
        elif kind == b"PLTE":
            if ctype != 3:   # a suggested palette (colour) or a misplaced one (grey): libpng ignores it
                continue
            if len(body) % 3 or not 3 <= len(body) <= 768:
                raise ValueError(f"its palette has {len(body)} bytes")
            palette = bytes(body)
        elif kind == b"tRNS" and not idat and trns is None and (ctype != 3 or palette is not None):
            trns = bytes(body)
        elif kind == b"eXIf" and exif is None and keep_exif and bytes(body[:4]) in (b"II*\x00", b"MM\x00*"):
            exif = bytes(body)
        elif not kind[0] & 0x20:   # an unknown critical chunk (bit 5 of its first letter clear)
            raise ValueError(f"an unknown critical chunk {kind.decode()}")
    if not idat:
        raise ValueError("no image data (no IDAT chunk)")
    out = [_PNG_SIGNATURE, _chunk(b"IHDR", bytes(ihdr))]
    if ctype == 3:
        if palette is None:
            raise ValueError("a palette image without a PLTE chunk")
        if len(palette) // 3 > 1 << depth:
            raise ValueError(f"its palette has {len(palette) // 3} entries for {depth}-bit indices")
        out.append(_chunk(b"PLTE", palette.ljust(3 << depth, b"\0")))   # indices past the palette: black
    if trns is not None and _trns_valid(trns, ctype, depth, palette):
        out.append(_chunk(b"tRNS", trns))
    if exif is not None:
        out.append(_chunk(b"eXIf", exif))
    stream = _inflate_checked(b"".join(idat), w, h, depth * _PNG_SAMPLES[ctype], interlace)
    out += [_chunk(b"IDAT", stream), _chunk(b"IEND", b"")]
    return b"".join(out)


def _trns_valid(trns: bytes, ctype: int, depth: int, palette: bytes | None) -> bool:
    """A tRNS chunk libpng takes without a word (one that it would warn of and ignore is left out)."""
    if ctype == 3:
        return 0 < len(trns) <= len(palette) // 3
    if ctype not in (0, 2) or len(trns) != 2 * _PNG_SAMPLES[ctype]:
        return False
    return all(int.from_bytes(trns[i:i + 2], "big") < 1 << depth for i in range(0, len(trns), 2))


def _rows(w: int, h: int, bits: int, interlace: int) -> list[tuple[int, int]]:
    """(rows, bytes a row including its filter byte) of each pass of the image's data."""
    passes = _ADAM7 if interlace else ((0, 0, 1, 1),)
    out = []
    for x0, y0, dx, dy in passes:
        pw, ph = (w - x0 + dx - 1) // dx, (h - y0 + dy - 1) // dy
        if pw > 0 and ph > 0:
            out.append((ph, 1 + (pw * bits + 7) // 8))
    return out


def _inflate_checked(stream: bytes, w: int, h: int, bits: int, interlace: int) -> bytes:
    """The IDAT data's zlib stream (bytes after its end cut off), once it is known to inflate to exactly the
    image's size with a valid filter byte (0-4) at the start of each row."""
    starts = []   # (first byte, end, step) of each pass's filter bytes
    at = 0
    for rows, size in _rows(w, h, bits, interlace):
        starts.append((at, at + rows * size, size))
        at += rows * size
    need, got = at, 0
    z = zlib.decompressobj()
    try:
        piece = z.decompress(stream, _INFLATE_PIECE)
        while True:
            if got + len(piece) > need:
                raise ValueError("more image data than its header declares")
            if piece:
                _check_filters(piece, got, starts)
            got += len(piece)
            if z.eof or not (z.unconsumed_tail or len(piece) == _INFLATE_PIECE):
                break
            piece = z.decompress(z.unconsumed_tail, _INFLATE_PIECE)   # more input, or output still held
    except zlib.error as e:
        raise ValueError(f"its image data is damaged (zlib: {e})") from None
    if not z.eof or got < need:
        raise ValueError(f"truncated image data ({got} of {need} bytes)")
    return stream[:len(stream) - len(z.unused_data)]


def _check_filters(piece: bytes, offset: int, starts) -> None:
    buf = np.frombuffer(piece, np.uint8)
    end = offset + len(buf)
    for first, stop, step in starts:
        lo, hi = max(first, offset), min(stop, end)
        if lo >= hi:
            continue
        k0 = first + -(-(lo - first) // step) * step   # the first filter byte at or after lo
        if k0 < hi and (buf[k0 - offset:hi - offset:step] > 4).any():
            raise ValueError("its image data is damaged (a row's filter type is not 0-4)")
