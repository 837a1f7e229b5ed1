"""A differentiable JPEG as OpenCV's `imwrite` makes one (libjpeg, baseline, 4:2:0 chroma), for the
embed-time refinement's JPEG copies (the training channel keeps kornia's).

kornia's `jpeg_codec_differentiable` subsamples the chroma with an antialiasing Gaussian before bilinear
resizing; libjpeg averages each 2x2 block, and its decoder upsamples with a triangle filter (bilinear,
half-pixel centres). Here: JFIF colour (full range), 2x2 block means, the IJG quality scaling of the
Annex K tables at integer quality, an orthonormal 8x8 DCT as two small matrix products, kornia's
polynomial rounding (round(x) + (x - round(x))^3, so gradients pass), the triangle upsampling. The image
is padded to a multiple of 16 by repeating its last row and column, as libjpeg does. It is about 3x
faster than kornia's and closer to OpenCV's files (README "Embed-time refinement").

Layouts: x (B, 3, H, W) RGB in [0, 1]; quality (B,) in [1, 100]; the result (B, 3, H, W) RGB, not clipped."""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor

__all__ = ["jpeg_420", "quant_tables"]

_LUMA = (16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
         14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
         49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99)
_CHROMA = (17, 18, 24, 47, 99, 99, 99, 99, 18, 21, 26, 66, 99, 99, 99, 99, 24, 26, 56, 99, 99, 99, 99, 99,
           47, 66, 99, 99, 99, 99, 99, 99) + (99,) * 32
_TO_YCC = ((0.299, 0.587, 0.114), (-0.168736, -0.331264, 0.5), (0.5, -0.418688, -0.081312))
_TO_RGB = ((1.0, 0.0, 1.402), (1.0, -0.344136, -0.714136), (1.0, 1.772, 0.0))


def quant_tables(quality: Tensor) -> Tensor:
    """quality (B,) -> (B, 2, 8, 8) float32 luma and chroma quantisation steps, as libjpeg's
    `jpeg_set_quality` (quality rounded to an integer in [1, 100])."""
    q = quality.detach().round().clamp(1, 100)
    scale = torch.where(q < 50, 5000.0 / q, 200.0 - 2.0 * q)
    base = torch.tensor([_LUMA, _CHROMA], dtype=torch.float32).view(1, 2, 8, 8)
    return torch.floor((base * scale.view(-1, 1, 1, 1) + 50.0) / 100.0).clamp(1, 255)


def _dct_matrix() -> Tensor:
    """(8, 8) orthonormal DCT-II: row k is the k-th basis vector."""
    n = torch.arange(8, dtype=torch.float64)
    d = torch.cos((2 * n[None] + 1) * n[:, None] * math.pi / 16) * math.sqrt(2 / 8)
    d[0] /= math.sqrt(2)
    return d.float()


def _round(x: Tensor) -> Tensor:
    """kornia's polynomial rounding: round(x) + (x - round(x))^3, so that gradients pass (an exact forward
    rounding with this gradient landed 0.1-0.4 dB further from OpenCV's files)."""
    r = x.round()
    return r + (x - r) ** 3


def _code(plane: Tensor, steps: Tensor, dct: Tensor) -> Tensor:
    """One component (B, h, w) (level-shifted, h and w multiples of 8) through DCT, quantisation with
    steps (B, 8, 8) and back."""
    b, h, w = plane.shape
    blocks = plane.reshape(b, h // 8, 8, w // 8, 8).transpose(2, 3)          # (B, h/8, w/8, 8, 8)
    coef = dct @ blocks @ dct.T
    steps = steps[:, None, None]
    blocks = dct.T @ (_round(coef / steps) * steps) @ dct
    return blocks.transpose(2, 3).reshape(b, h, w)


def jpeg_420(x: Tensor, quality: Tensor) -> Tensor:
    """x (B, 3, H, W) RGB in [0, 1], quality (B,) -> the decoded JPEG (B, 3, H, W) RGB (see the module doc)."""
    b, _, h, w = x.shape
    ph, pw = -h % 16, -w % 16
    x = F.pad(x, (0, pw, 0, ph), mode="replicate") if ph or pw else x
    to_ycc, to_rgb = torch.tensor(_TO_YCC, dtype=x.dtype), torch.tensor(_TO_RGB, dtype=x.dtype)
    ycc = torch.einsum("kc,bchw->bkhw", to_ycc * 255.0, x)
    ycc = ycc - torch.tensor([128.0, 0.0, 0.0], dtype=x.dtype).view(1, 3, 1, 1)  # the level shift; Cb, Cr centred
    chroma = F.avg_pool2d(ycc[:, 1:], 2)
    steps, dct = quant_tables(quality).to(x.dtype), _dct_matrix().to(x.dtype)
    luma = _code(ycc[:, 0], steps[:, 0], dct)
    chroma = _code(chroma.reshape(2 * b, *chroma.shape[2:]), steps[:, 1].repeat_interleave(2, 0), dct)
    chroma = F.interpolate(chroma.reshape(b, 2, *chroma.shape[1:]), scale_factor=2, mode="bilinear",
                           align_corners=False)
    ycc = torch.cat([luma[:, None] + 128.0, chroma], 1)
    rgb = torch.einsum("kc,bchw->bkhw", to_rgb / 255.0, ycc)
    return rgb[..., :h, :w]
