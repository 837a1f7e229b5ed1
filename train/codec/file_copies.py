"""The sharing channel of the file as `embed` writes it: copies of a snapshot file written at
`formats.FILE_SCALE` times its size (each pixel a square), as messaging apps make them, read back to the
snapshot's size the way `restore` reads them (differentiable; `train codec --file-copies`).

`channel.SharingRanges` resizes and codes the snapshot at its own size, as the file was written before the
4x file; a copy of the 4x file differs: its JPEG codes 2x2 snapshot pixels per 8x8 block, and a copy an app
shrinks to 256 px is an area average of the squares. Here, per image (drawn with `FileCopyRanges`):

- 8-bit rounding (the PNG), always;
- kept as it is (the PNG), or a JPEG copy of the 4x file (`jpeg.jpeg_420` at scale 4, quality drawn in
  [jpeg_min, 95], sometimes twice), or a resized copy: the 4x file resized by OpenCV's `INTER_AREA` to a
  square of f x 380 px (f log-uniform in [resize_min, 1] or [1, resize_max]), JPEG at that size with
  probability `jpeg_prob`, and the reader's resize back to 380 (`INTER_CUBIC` up, `INTER_AREA` down, as
  `scanner.pixelmeta` does).

The resizes are OpenCV's own: each is the exact linear operator `cv2.resize` applies along one axis
(read off by resizing an identity matrix), so the channel's copies are what the bench's copies are, on
crops as on whole snapshots.

Images: (B, 3, H, W) RGB float in [0, 1], square, H a multiple of 4."""
from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

import cv2
import numpy as np
import torch
from torch import Tensor

from snapshot3d import formats

from .channel import round_8bit
from .jpeg import jpeg_420

__all__ = ["FileCopyRanges", "apply_file_copies", "resize_operator", "copy_of"]


@dataclass(frozen=True)
class FileCopyRanges:
    """How often each kind of copy is drawn, and its ranges (see the module docstring)."""

    png_prob: float = 0.1
    """probability of the lossless file itself"""
    resize_prob: float = 0.55
    """probability of a resized copy (else a JPEG copy of the 4x file)"""
    shrink_share: float = 0.75
    """share of the resized copies that are smaller than the snapshot (f < 1)"""
    resize_min: float = 0.6
    """smallest resize factor against the 380-px snapshot (228 px)"""
    resize_max: float = 3.0
    """largest resize factor (1140 px)"""
    jpeg_min: float = 60.0
    """lowest JPEG quality"""
    jpeg_prob: float = 0.85
    """probability that a resized copy is saved as JPEG"""
    twice_prob: float = 0.2
    """probability that a JPEG copy is coded a second time"""

    def as_dict(self) -> dict:
        return asdict(self)


@lru_cache(maxsize=256)
def _operator(n_in: int, n_out: int, interp: int, repeat: int) -> np.ndarray:
    eye = np.repeat(np.eye(n_in, dtype=np.float64), repeat, axis=0)        # (repeat * n_in, n_in): the squares
    return cv2.resize(eye, (n_in, n_out), interpolation=interp).astype(np.float32)


def resize_operator(n_in: int, n_out: int, interp: int, repeat: int = 1) -> Tensor:
    """(n_out, n_in): what `cv2.resize` with `interp` does along one axis to a line of n_in pixels, each first
    repeated `repeat` times (a file written at `repeat` times the size)."""
    return torch.from_numpy(_operator(n_in, n_out, interp, repeat))


def _resize(x: Tensor, op: Tensor) -> Tensor:
    op = op.to(x.device, x.dtype)
    return torch.einsum("ph,bchw,qw->bcpq", op, x, op)


def copy_of(x: Tensor, size: int | None, qualities: tuple[float, ...], scale: int = formats.FILE_SCALE) -> Tensor:
    """One copy of snapshots x (B, 3, n, n) in [0, 1] written as a file at `scale` times their size (the 4x
    file): resized by `INTER_AREA` to size x size (None: not resized; a size relative to n, as f x n) and
    JPEG-coded at each of `qualities` in turn, then read back to n x n -> (B, 3, n, n), 8-bit values."""
    n = x.shape[-1]
    y = round_8bit(x)
    if size is not None:    # the app resizes the file, then codes the copy at its own size
        y = round_8bit(_resize(y, resize_operator(n, size, cv2.INTER_AREA, scale)))
    for q in qualities:
        y = round_8bit(jpeg_420(y, torch.full((y.shape[0],), float(q), device=y.device),
                                scale if size is None else 1))
    if size is None:
        return y
    return round_8bit(_resize(y, resize_operator(size, n, cv2.INTER_CUBIC if size < n else cv2.INTER_AREA)))


def _draw(r: FileCopyRanges, t: float, n: int, u: list[float]) -> tuple[int | None, tuple[float, ...]]:
    """(size or None, JPEG qualities) of one copy from uniforms u (7 of them) at level t."""
    quality = lambda v: 95 - (95 - r.jpeg_min) * t * v   # noqa: E731
    times = 2 if u[6] < r.twice_prob else 1
    if u[0] < r.png_prob:
        return None, ()
    if u[1] >= r.resize_prob:
        return None, tuple(quality(v) for v in u[3:3 + times])
    lo, hi = (1 - (1 - r.resize_min) * t, 1.0) if u[2] < r.shrink_share else (1.0, 1 + (r.resize_max - 1) * t)
    f = float(np.exp(np.log(lo) + (np.log(hi) - np.log(lo)) * u[5]))
    size = max(16, int(round(n * f)))
    jpegs = tuple(quality(v) for v in u[3:3 + times]) if u[4] < r.jpeg_prob else ()
    return (None if size == n else size), jpegs


def apply_file_copies(x: Tensor, level: Tensor, ranges: FileCopyRanges = FileCopyRanges(),
                      generator: torch.Generator | None = None) -> Tensor:
    """Snapshots (B, 3, n, n) in [0, 1] -> what `restore` reads of a shared copy of each one's 4x file,
    (B, 3, n, n). `level` (B,) in [0, 1] scales the ranges; at most 0.05 leaves the PNG."""
    out = []
    for i in range(x.shape[0]):
        u = torch.rand(7, generator=generator).tolist()
        t = float(level[i])
        size, qualities = (None, ()) if t <= 0.05 else _draw(ranges, t, x.shape[-1], u)
        out.append(copy_of(x[i:i + 1], size, qualities))
    return torch.cat(out).clamp(0, 1)
