"""Snapshot metadata in the pixels: what `restore` needs (the QR payload's fields, see `qr`) travels inside
the snapshot image itself, so that a shared copy restores after a messaging app stripped its text chunk,
re-encoded it as JPEG and resized it.

The mark: a fixed 72-byte frame (format byte, codec id, the fields, CRC-32), convolutionally coded (rate
1/2, constraint length 7, the 133/171 code), each coded bit repeated over `REPEAT` slots scattered by a
fixed permutation; a slot is one low-frequency DCT coefficient ((0,1), (1,0), (1,1)) of the luma of one 8x8
block (the JPEG grid at the snapshot's origin), written by dither-modulation QIM with step `STEP`.
Coefficients at those frequencies survive JPEG quality 60 (its step there is about 10, under `STEP`/2) and
resizing; the step was raised from 24 to 40 when a 256-px JPEG-75 copy of a textured host lost the mark
(README "Metadata in the pixels"), and marks of the old step (`LEGACY_STEPS`) are still read. The reader
sums soft decisions over the repetitions, decodes them with the Viterbi algorithm and accepts the frame
only when its CRC holds, so a damaged mark is refused, never misread. The writer marks the host before the
codec embeds the planes (the codec's residual is noise to the mark, not the other way round).

Reading a copy: a square of another size is resized to the snapshot's; an image within `MAX_SHIFT` pixels
of it (cropped or padded) is searched over offsets, nearest first. `find_meta` returns the metadata and
the snapshot realigned to the grid the codec needs.

Images: (380, 380, 3) uint8 RGB in, (H, W, 3) uint8 RGB read back."""
from __future__ import annotations

import struct
import zlib
from functools import lru_cache

import cv2
import numpy as np

from snapshot3d import formats

from .qr import SheetMeta

__all__ = ["FRAME_BYTES", "STEP", "LEGACY_STEPS", "REPEAT", "MAX_SHIFT", "pack", "unpack", "mark", "read_at", "find_meta"]

FRAME_BYTES = 72   # the whole frame (fields, padding, CRC-32)
STEP = 40.0        # QIM step on an orthonormal 8x8 DCT coefficient of luma (0-255 scale)
LEGACY_STEPS = (24.0,)   # steps of marks written by earlier versions, still read (never written)
BLOCK = 8
COEFS = ((0, 1), (1, 0), (1, 1))   # (row, column) frequencies written in every block
MAX_SHIFT = 8      # crop or padding searched, in pixels, on each axis
_SEED = 0x53334D   # the permutation and dithers ("S3M")
_VERSION = 1       # of the mark's frame (not the sheet format, which is a field inside it)
_N = formats.SNAPSHOT_SIZE // BLOCK                  # 47 blocks per side
_K = 7                                              # the convolutional code's constraint length
_GEN = (0o133, 0o171)
_CODED = 2 * (FRAME_BYTES * 8 + _K - 1)            # coded bits (the frame and a zero tail)
REPEAT = (_N * _N * len(COEFS)) // _CODED           # 5 slots per coded bit


def pack(meta: SheetMeta) -> bytes:
    """The frame's bytes: version, sheet format, codec id (length + ASCII), a presence byte, the fields as
    float32 / uint16, zero padding and the CRC-32 of all before it."""
    codec = meta.codec.encode("ascii")
    if len(codec) > 15:
        raise ValueError(f"codec id {meta.codec!r} is too long for the pixel mark")
    fields = [meta.box, meta.orbit, meta.target, meta.planes, None if meta.strength is None else (meta.strength,)]
    body = struct.pack("<BBB", _VERSION, meta.version, len(codec)) + codec
    body += bytes([sum(1 << i for i, f in enumerate(fields) if f is not None)])
    for f, fmt in zip(fields, ("<6f", "<3f", "<3f", "<2H", "<f")):
        if f is not None:
            body += struct.pack(fmt, *f)
    if len(body) > FRAME_BYTES - 4:
        raise ValueError("metadata too long for the pixel mark")
    body += bytes(FRAME_BYTES - 4 - len(body))
    return body + struct.pack("<I", zlib.crc32(body))


def unpack(frame: bytes) -> SheetMeta | None:
    """The metadata of a frame, or None when its CRC or its layout does not hold."""
    body, (crc,) = frame[:-4], struct.unpack("<I", frame[-4:])
    if len(frame) != FRAME_BYTES or zlib.crc32(body) != crc or body[0] != _VERSION:
        return None
    version, n = body[1], body[2]
    codec, flags, pos = body[3:3 + n], body[3 + n], 4 + n
    values = []
    for i, fmt in enumerate(("<6f", "<3f", "<3f", "<2H", "<f")):
        if flags >> i & 1:
            values.append(tuple(round(float(v), 6) for v in struct.unpack_from(fmt, body, pos)))
            pos += struct.calcsize(fmt)
        else:
            values.append(None)
    box, orbit, target, planes, strength = values
    try:
        return SheetMeta(version, codec.decode("ascii"), box, orbit, target,
                         tuple(int(v) for v in planes) if planes else None, strength[0] if strength else None)
    except UnicodeDecodeError:
        return None


@lru_cache(maxsize=4)
def _code(step: float = STEP) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(basis (3, 8, 8) orthonormal DCT, slot of each (coded bit, repeat) (_CODED, REPEAT), dither per slot
    for a QIM step)."""
    k = np.arange(BLOCK)
    c = np.sqrt(np.where(k == 0, 1.0, 2.0) / BLOCK)[:, None] * np.cos((2 * k[None] + 1) * k[:, None] * np.pi / 16)
    basis = np.stack([np.outer(c[u], c[v]) for u, v in COEFS])
    rng = np.random.default_rng(_SEED)
    slots = rng.permutation(_N * _N * len(COEFS))[:_CODED * REPEAT].reshape(_CODED, REPEAT)
    dither = rng.uniform(0, step, _N * _N * len(COEFS))
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
    """The most likely input bits for (2 * T,) soft values (> 0: a coded 0), the tail of six zeros dropped."""
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


def mark(rgb: np.ndarray, meta: SheetMeta, step: float = STEP) -> np.ndarray:
    """(380, 380, 3) uint8 RGB with the metadata written into its luma (the same change on R, G and B);
    `step` other than STEP only to test that old marks still read."""
    basis, slots, dither = _code(step)
    bits = conv_encode(np.unpackbits(np.frombuffer(pack(meta), np.uint8)))
    want = np.zeros(dither.shape)
    want[slots.reshape(-1)] = np.repeat(bits, REPEAT) * step / 2
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


def _soft(coefs: np.ndarray, step: float = STEP) -> np.ndarray:
    """(_CODED,) soft values (> 0: a coded 0) from the (47*47*3,) marked coefficients."""
    _, slots, dither = _code(step)
    return np.cos(2 * np.pi * (coefs - dither) / step)[slots].sum(axis=1)


def read_at(luma: np.ndarray) -> SheetMeta | None:
    """The metadata marked in (H>=376, W>=376) luma whose top-left is the snapshot's (at the current step,
    then the legacy ones), or None."""
    coefs = _coefs(luma)
    for step in (STEP, *LEGACY_STEPS):
        meta = unpack(np.packbits(viterbi(_soft(coefs, step))).tobytes())
        if meta is not None:
            return meta
    return None


def find_meta(rgb: np.ndarray, tries: int = 6) -> tuple[SheetMeta, np.ndarray] | None:
    """(metadata, (380, 380, 3) uint8 RGB realigned) from a snapshot copy (H, W, 3) uint8 RGB: the same size,
    a resized square, or cropped/padded by up to MAX_SHIFT pixels; None when no mark reads. Every offset is
    ranked by how well its repetitions agree (cheap: the block coefficients at all offsets are one filter
    per frequency); the frame is decoded at the `tries` best."""
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
    for step in (STEP, *LEGACY_STEPS):
        scored = []
        for dy in range(-m, m + 1):
            for dx in range(-m, m + 1):
                # the snapshot's pixel (y, x) sits at the copy's (y + dy, x + dx), i.e. padded (y + dy + m, x + dx + m)
                y0, x0 = dy + m, dx + m
                coefs = np.stack([c[y0:y0 + span:BLOCK, x0:x0 + span:BLOCK] for c in maps], axis=-1).reshape(-1)
                soft = _soft(coefs.astype(np.float64), step)
                scored.append((-float(np.mean(np.abs(soft))), abs(dy) + abs(dx), y0, x0, soft))
        for _, _, y0, x0, soft in sorted(scored, key=lambda t: t[:2])[:tries]:
            meta = unpack(np.packbits(viterbi(soft)).tobytes())
            if meta is not None:
                return meta, np.ascontiguousarray(padded[y0:y0 + n, x0:x0 + n])
    return None
