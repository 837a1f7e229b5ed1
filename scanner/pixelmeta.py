"""Snapshot metadata in the pixels: what `restore` needs (the QR payload's fields, see `qr`) travels inside
the snapshot image itself, so that a shared copy restores after a messaging app stripped its text chunk,
re-encoded it as JPEG and resized it.

The mark: a frame of bytes (the fields, then a CRC-32), convolutionally coded (rate 1/2, constraint length 7,
the 133/171 code), each coded bit repeated over the frame's repeat count of slots scattered by a fixed
permutation; a slot is one low-frequency DCT coefficient ((0,1), (1,0), (1,1)) of the luma of one 8x8 block
(the JPEG grid at the snapshot's origin), written by dither-modulation QIM with the frame's step.
Coefficients at those frequencies survive JPEG quality 60 and resizing. `FRAME` is written: version 2, 38
bytes (the codec as an index into `formats.MARK_CODECS`, the numbers as float16, as precise as the QR
text's four significant digits), 10 repetitions at step 32. The presence byte's top three bits hold the
shared decoder's number minus one (`tri-dec-1` to `tri-dec-8`; zero in marks written before there were two). `LEGACY_FRAMES` are still read: version 1, 72
bytes (the codec id as text, float32), 5 repetitions, at step 40 and at step 24. The shorter frame buys
twice the repetitions, so the same copies read at a smaller step: the mark costs 42.4 dB of host PSNR
instead of 40.7 (docs/file-codec.md "The metadata mark"). A meta that the short frame cannot hold (a codec id
not in the table, a number beyond float16) is written in a version-1 frame at step 40. The reader sums
soft decisions over the repetitions, decodes them with the Viterbi algorithm and accepts the frame only
when its CRC holds, so a damaged mark is refused, never misread. The writer marks the host before the
codec embeds the planes (the codec's residual is noise to the mark, not the other way round).

Reading a copy: an image within k * `MAX_SHIFT` pixels of k times the snapshot's size (k from 2 to
`formats.FILE_SCALE`: a file-medium file or a copy halved, perhaps cropped or padded) is first shrunk k times
along its own squares (`shrink_squares`); a square of another size is
resized to the snapshot's; an image within `MAX_SHIFT` pixels of it (cropped or padded) is searched over
offsets, nearest first. `find_meta` returns the metadata and
the snapshot realigned to the grid the codec needs.

Images: (380, 380, 3) uint8 RGB in, (H, W, 3) uint8 RGB read back."""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from snapshot3d import formats

from .qr import SheetMeta

__all__ = ["Frame", "FRAME", "LEGACY_FRAMES", "MAX_SHIFT", "pack", "unpack", "mark", "read_at", "find_meta",
           "conv_encode", "viterbi"]

BLOCK = 8
COEFS = ((0, 1), (1, 0), (1, 1))   # (row, column) frequencies written in every block
MAX_SHIFT = 8      # crop or padding searched, in pixels, on each axis
_SEED = 0x53334D   # the permutation and dithers ("S3M")
_N = formats.SNAPSHOT_SIZE // BLOCK                  # 47 blocks per side
_K = 7                                              # the convolutional code's constraint length
_GEN = (0o133, 0o171)
_FIELDS = ("box", "orbit", "target", "planes", "strength")


@dataclass(frozen=True)
class Frame:
    """One layout of the mark."""

    version: int
    """first byte of the frame (1: text codec id and float32; 2: codec index and float16)"""
    nbytes: int
    """the whole frame (fields, padding, CRC-32)"""
    step: float
    """QIM step on an orthonormal 8x8 DCT coefficient of luma (0-255 scale)"""

    @property
    def coded(self) -> int:
        """coded bits (the frame and a zero tail)"""
        return 2 * (self.nbytes * 8 + _K - 1)

    @property
    def repeat(self) -> int:
        """slots per coded bit"""
        return (_N * _N * len(COEFS)) // self.coded


FRAME = Frame(2, 38, 32.0)
"""the frame `mark` writes"""
LEGACY_FRAMES = (Frame(1, 72, 40.0), Frame(1, 72, 24.0))
"""frames of marks written by earlier versions, still read (the first also for metas FRAME cannot hold)"""
_FORMATS = {1: ("<6f", "<3f", "<3f", "<2H", "<f"), 2: ("<6e", "<3e", "<3e", "<2H", "<e")}
_F16_MAX = 65000.0
_DECODER_SHIFT = 5   # the presence byte: bits 0-4 the fields, bits 5-7 the decoder's number minus one


def _values(meta: SheetMeta) -> list:
    return [meta.box, meta.orbit, meta.target, meta.planes, None if meta.strength is None else (meta.strength,)]


def _fits_short_frame(meta: SheetMeta) -> bool:
    """Whether FRAME can hold `meta`: its codec in `formats.MARK_CODECS`, every number within float16's range."""
    box, orbit, target, _, strength = _values(meta)   # the plane size is uint16 in either frame
    nums = [v for f in (box, orbit, target, strength) if f is not None for v in f]
    return meta.codec in formats.MARK_CODECS and all(np.isfinite(v) and abs(v) < _F16_MAX for v in nums)


def pack(meta: SheetMeta, frame: Frame = FRAME) -> bytes:
    """The frame's bytes: mark version, sheet format, codec (version 1: length + ASCII; version 2: index into
    `formats.MARK_CODECS`), a presence byte, the fields (float32 or float16; plane size uint16), zero padding
    and the CRC-32 of all before it."""
    if frame.version == 2:
        if not _fits_short_frame(meta):
            raise ValueError(f"codec id {meta.codec!r} or a number of the metadata does not fit a version-2 mark")
        codec = bytes([formats.MARK_CODECS.index(meta.codec)])
    else:
        codec = meta.codec.encode("ascii")
        if len(codec) > 15:
            raise ValueError(f"codec id {meta.codec!r} is too long for the pixel mark")
        codec = bytes([len(codec)]) + codec
    fields = _values(meta)
    decoder = (1 if meta.decoder is None else meta.decoder) - 1
    if not 0 <= decoder < 8:
        raise ValueError(f"decoder tri-dec-{meta.decoder} does not fit the pixel mark (tri-dec-1 to tri-dec-8)")
    body = bytes([frame.version, meta.version]) + codec
    body += bytes([sum(1 << i for i, f in enumerate(fields) if f is not None) | decoder << _DECODER_SHIFT])
    for f, fmt in zip(fields, _FORMATS[frame.version]):
        if f is not None:
            body += struct.pack(fmt, *f)
    if len(body) > frame.nbytes - 4:
        raise ValueError("metadata too long for the pixel mark")
    body += bytes(frame.nbytes - 4 - len(body))
    return body + struct.pack("<I", zlib.crc32(body))


def unpack(frame: bytes) -> SheetMeta | None:
    """The metadata of a frame (either version), or None when its CRC or its layout does not hold. A codec
    index beyond this build's table comes back as the id `mark-codec-<i>`, which decoding refuses as unknown."""
    if len(frame) < 8:
        return None
    body, (crc,) = frame[:-4], struct.unpack("<I", frame[-4:])
    known = {f.version: f.nbytes for f in (FRAME, *LEGACY_FRAMES)}
    if zlib.crc32(body) != crc or known.get(body[0]) != len(frame):
        return None
    version = body[1]
    if body[0] == 1:
        n = body[2]
        if 4 + n > len(body):   # a codec id longer than the frame: not a frame this build wrote
            return None
        codec_bytes, flags, pos = body[3:3 + n], body[3 + n], 4 + n
        try:
            codec = codec_bytes.decode("ascii")
        except UnicodeDecodeError:
            return None
    else:
        i, flags, pos = body[2], body[3], 4
        codec = formats.MARK_CODECS[i] if i < len(formats.MARK_CODECS) else f"mark-codec-{i}"
    values = []
    for i, fmt in enumerate(_FORMATS[body[0]]):
        if flags >> i & 1:
            if pos + struct.calcsize(fmt) > len(body):
                return None
            values.append(tuple(round(float(v), 6) for v in struct.unpack_from(fmt, body, pos)))
            pos += struct.calcsize(fmt)
        else:
            values.append(None)
    box, orbit, target, planes, strength = values
    decoder = (flags >> _DECODER_SHIFT) + 1
    return SheetMeta(version, codec, box, orbit, target, tuple(int(v) for v in planes) if planes else None,
                     strength[0] if strength else None, None if decoder == 1 else decoder)


@lru_cache(maxsize=4)
def _code(frame: Frame = FRAME) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(basis (3, 8, 8) orthonormal DCT, slot of each (coded bit, repeat) (coded, repeat), dither per slot
    for the frame's step)."""
    k = np.arange(BLOCK)
    c = np.sqrt(np.where(k == 0, 1.0, 2.0) / BLOCK)[:, None] * np.cos((2 * k[None] + 1) * k[:, None] * np.pi / 16)
    basis = np.stack([np.outer(c[u], c[v]) for u, v in COEFS])
    rng = np.random.default_rng(_SEED)
    slots = rng.permutation(_N * _N * len(COEFS))[:frame.coded * frame.repeat].reshape(frame.coded, frame.repeat)
    dither = rng.uniform(0, frame.step, _N * _N * len(COEFS))
    return basis, slots, dither


@lru_cache(maxsize=1)
def _trellis() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(next state (64, 2), output bits (64, 2, 2), predecessors (64, 2, 2) as (state, input)) of the code;
    a state is the last six inputs, the newest in its top bit."""
    states = 1 << (_K - 1)
    nxt, out = np.zeros((states, 2), int), np.zeros((states, 2, 2), int)
    prev = [[] for _ in range(states)]
    for s in range(states):
        for b in (0, 1):
            window = (b << (_K - 1)) | s
            out[s, b] = [bin(window & g).count("1") & 1 for g in _GEN]
            nxt[s, b] = window >> 1
            prev[nxt[s, b]].append((s, b))
    return nxt, out, np.array(prev)


def conv_encode(bits: np.ndarray) -> np.ndarray:
    """(2 * (len + 6),) coded bits of (len,) bits followed by a zero tail."""
    nxt, out, _ = _trellis()
    coded, s = [], 0
    for b in np.concatenate([bits, np.zeros(_K - 1, int)]):
        coded.extend(out[s, b])
        s = nxt[s, b]
    return np.array(coded, np.uint8)


def viterbi(soft: np.ndarray) -> np.ndarray:
    """The most likely input bits for (2 * T,) soft values (> 0: a coded 0), the tail of six zeros dropped.

    Kept rather than `komm` (pure Python, 2.7 MB; `ViterbiDecoder(TerminatedConvolutionalCode(ConvolutionalCode(
    [[0o155, 0o117]]), T - 6), input_type="soft")`, the generators bit-reversed to its order, decodes the same
    bits: 400 of 400 noisy frames identical, errors included): komm takes 6.2 ms per 38-byte frame and 11.1 ms
    per 72-byte frame against 3.3 and 6.1 ms here, adds 73-119 ms of import to the decode path, and the encoder
    (`conv_encode`, `_trellis`) that `mark` needs stays either way; this is 20 lines. scikit-commpy 0.8 imports
    in 0.92 s (matplotlib, sympy). Measured 2026-11-25 on 2 cores (AMD EPYC): `pip install --target /tmp/komm
    komm`, then both decoders timed on 200 random frames per frame size with Gaussian noise added."""
    _, out, prev = _trellis()
    sign = 1 - 2 * out                                     # (64, 2, 2): +1 where the coded bit is 0
    metric = np.full(len(prev), -np.inf)
    metric[0] = 0.0
    choice = []
    ps, pb = prev[..., 0], prev[..., 1]                    # (64, 2) each
    for pair in soft.reshape(-1, 2):
        branch = sign @ pair                               # (64, 2)
        cand = metric[ps] + branch[ps, pb]                 # (64 next states, 2 predecessors)
        k = np.argmax(cand, axis=1)
        choice.append(k)
        metric = cand[np.arange(len(prev)), k]
    bits, s = [], 0
    for k in reversed(choice):
        bits.append(pb[s, k[s]])
        s = ps[s, k[s]]
    return np.array(bits[::-1][:-(_K - 1)], np.uint8)


def _luma(rgb: np.ndarray) -> np.ndarray:
    return rgb.astype(np.float64) @ np.array([0.299, 0.587, 0.114])


def _coefs(luma: np.ndarray) -> np.ndarray:
    """(47*47*3,) the marked coefficients of the top-left 376x376 of (H>=376, W>=376) luma."""
    basis = _code()[0]
    blocks = luma[:_N * BLOCK, :_N * BLOCK].reshape(_N, BLOCK, _N, BLOCK)
    return np.einsum("iyjx,kyx->ijk", blocks, basis).reshape(-1)


def mark(rgb: np.ndarray, meta: SheetMeta, frame: Frame | None = None) -> np.ndarray:
    """(380, 380, 3) uint8 RGB with the metadata written into its luma (the same change on R, G and B), in
    `frame` (None: FRAME, or the first legacy frame for a meta FRAME cannot hold; others to test that old
    marks still read)."""
    frame = frame or (FRAME if _fits_short_frame(meta) else LEGACY_FRAMES[0])
    basis, slots, dither = _code(frame)
    step = frame.step
    bits = conv_encode(np.unpackbits(np.frombuffer(pack(meta, frame), np.uint8)))
    want = np.zeros(dither.shape)
    want[slots.reshape(-1)] = np.repeat(bits, frame.repeat) * step / 2
    out = rgb.astype(np.float64)
    for _ in range(3):  # clipping at black and white undoes part of a change: write again what it undid
        c = _coefs(_luma(np.clip(out, 0, 255).round()))
        offset = want + dither
        target = np.round((c - offset) / step) * step + offset
        delta = np.zeros(c.shape)
        delta[slots.reshape(-1)] = (target - c)[slots.reshape(-1)]
        change = np.einsum("ijk,kyx->iyjx", delta.reshape(_N, _N, len(COEFS)), basis)
        out[:_N * BLOCK, :_N * BLOCK] += change.reshape(_N * BLOCK, _N * BLOCK)[..., None]
    return np.clip(out, 0, 255).round().astype(np.uint8)


def _soft(coefs: np.ndarray, frame: Frame) -> np.ndarray:
    """(frame.coded,) soft values (> 0: a coded 0) from the (47*47*3,) marked coefficients."""
    _, slots, dither = _code(frame)
    return np.cos(2 * np.pi * (coefs - dither) / frame.step)[slots].sum(axis=1)


def read_at(luma: np.ndarray) -> SheetMeta | None:
    """The metadata marked in (H>=376, W>=376) luma whose top-left is the snapshot's (in FRAME, then the
    legacy frames), or None."""
    coefs = _coefs(luma)
    for frame in (FRAME, *LEGACY_FRAMES):
        meta = unpack(np.packbits(viterbi(_soft(coefs, frame))).tobytes())
        if meta is not None:
            return meta
    return None


def shrink_squares(rgb: np.ndarray, k: int) -> np.ndarray:
    """An image (H, W, 3) uint8 written with each pixel a k x k square, perhaps cropped or padded by a few
    pixels -> (about H/k, W/k, 3): the means of its own squares. Their phase is found where neighbouring
    columns (rows) differ most, at the squares' edges, over a band of 256 rows (columns) through the middle;
    the partial squares at the borders are dropped."""
    h, w = rgb.shape[:2]
    rows, cols = rgb[:, w // 2 - 128: w // 2 + 128].astype(np.float32), rgb[h // 2 - 128: h // 2 + 128].astype(np.float32)
    start = []
    for d in (np.abs(np.diff(rows, axis=0)).mean((1, 2)), np.abs(np.diff(cols, axis=1)).mean((0, 2))):
        edge = int(np.argmax([d[p::k].mean() for p in range(k)]))     # an edge after index p (mod k)
        start.append((edge + 1) % k)
    y0, x0 = start
    crop = rgb[y0: y0 + (h - y0) // k * k, x0: x0 + (w - x0) // k * k]
    return cv2.resize(crop, (crop.shape[1] // k, crop.shape[0] // k), interpolation=cv2.INTER_AREA)


def find_meta(rgb: np.ndarray, tries: int = 6) -> tuple[SheetMeta, np.ndarray] | None:
    """(metadata, (380, 380, 3) uint8 RGB realigned) from a snapshot copy (H, W, 3) uint8 RGB: the same size,
    a resized square, or cropped/padded by up to MAX_SHIFT pixels; None when no mark reads. Every offset is
    ranked by how well its repetitions agree (cheap: the block coefficients at all offsets are one filter
    per frequency); the frame is decoded at the `tries` best. A copy near k times the snapshot's size (a
    file-medium file, perhaps cropped or padded) is first read shrunk along its own squares, then, if no
    mark reads there (a copy resized to near that size), as any other."""
    n = formats.SNAPSHOT_SIZE
    h, w = rgb.shape[:2]
    k = round(max(h, w) / n)
    if 2 <= k <= formats.FILE_SCALE and abs(h - k * n) <= k * MAX_SHIFT and abs(w - k * n) <= k * MAX_SHIFT:
        found = _find_meta(shrink_squares(rgb, k), tries)
        if found is not None:
            return found
    return _find_meta(rgb, tries)


def _find_meta(rgb: np.ndarray, tries: int) -> tuple[SheetMeta, np.ndarray] | None:
    """`find_meta` without the squares of a file written larger."""
    n = formats.SNAPSHOT_SIZE
    h, w = rgb.shape[:2]
    if abs(h - n) > MAX_SHIFT or abs(w - n) > MAX_SHIFT:
        if abs(h - w) > 0.02 * max(h, w):
            return None
        rgb = cv2.resize(rgb, (n, n), interpolation=cv2.INTER_AREA if h > n else cv2.INTER_CUBIC)
        h = w = n
    if h == w == n:  # the usual case: a same-size copy, read at its own grid first
        meta = read_at(_luma(rgb))
        if meta is not None:
            return meta, rgb
    m = MAX_SHIFT
    padded = cv2.copyMakeBorder(rgb, m, m + max(0, n - h), m, m + max(0, n - w), cv2.BORDER_REFLECT_101)
    luma = _luma(padded).astype(np.float32)
    maps = [cv2.filter2D(luma, cv2.CV_32F, b.astype(np.float32), anchor=(0, 0), borderType=cv2.BORDER_REFLECT_101)
            for b in _code()[0]]                          # (H, W) each: the coefficient of the block at (y, x)
    span = _N * BLOCK
    offsets = []   # (distance, y0, x0, the marked coefficients there): the snapshot's pixel (y, x) sits at the copy's
    for dy in range(-m, m + 1):   # (y + dy, x + dx), i.e. padded (y + dy + m, x + dx + m)
        for dx in range(-m, m + 1):
            y0, x0 = dy + m, dx + m
            coefs = np.stack([c[y0:y0 + span:BLOCK, x0:x0 + span:BLOCK] for c in maps], axis=-1).reshape(-1)
            offsets.append((abs(dy) + abs(dx), y0, x0, coefs.astype(np.float64)))
    for frame in (FRAME, *LEGACY_FRAMES):
        scored = []
        for dist, y0, x0, coefs in offsets:
            soft = _soft(coefs, frame)
            scored.append((-float(np.mean(np.abs(soft))), dist, y0, x0, soft))
        for _, _, y0, x0, soft in sorted(scored, key=lambda t: t[:2])[:tries]:
            meta = unpack(np.packbits(viterbi(soft)).tobytes())
            if meta is not None:
                return meta, np.ascontiguousarray(padded[y0:y0 + n, x0:x0 + n])
    return None
