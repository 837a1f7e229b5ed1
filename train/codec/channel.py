"""The differentiable print-and-capture channel the codec trains through (kornia).

It models what is left of a photographed print after `snapshot3d scan` has rectified it and
corrected its colour: the scanner removes the homography, lens distortion and most of the
illumination and tone, so the channel only carries the *residuals*. One `level` t in [0, 1] scales
every range; t = 1 is a little beyond what `scan` leaves on `moderate` photos (measured by
`snapshot3d bench channel`, bench/results/channel.json: on `moderate` photos the scanner leaves
corner misregistration of about 0.4 px, blur sigma about 0.6 px, per-channel gain errors about 0.17,
a smooth residual shading of std 0.05-0.075 and a fine-grained residual (halftone, noise) of std
about 0.04-0.05). Ranges at level t (drawn per image):

- 8-bit rounding of the snapshot (the PNG file), straight-through gradient: always;
- misregistration: each corner of the image moved by up to `shift_px * t` pixels (a random
  homography, sub-pixel to a few pixels), bilinear resampling;
- resampling and defocus blur: Gaussian sigma in [0, blur_px * t] pixels;
- residual tone and colour: per-channel gain 1 +- gain * t, offset +- offset * t, gamma 1 +- gamma * t,
  saturation 1 +- saturation * t;
- residual shading (uneven light the patches' correction misses): a smooth random field (a 3x3 grid
  bicubically upsampled), per channel, std up to shading * t, added;
- halftone-like texture: a 2x2-pixel-periodic pattern of random phase and sign per channel, amplitude
  up to texture * t, plus white noise with std up to noise * t;
- JPEG (for t > 0.05): with probability `jpeg_prob`, quality drawn in [max(jpeg_min, 95 - (95 - jpeg_min) * t), 95]
  (kornia's differentiable JPEG);
- the result clipped to [0, 1].

Images: (B, 3, H, W) RGB float in [0, 1].
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import kornia
import numpy as np
import torch
from torch import Tensor

__all__ = ["ChannelRanges", "SharingRanges", "round_8bit", "apply_channel", "apply_sharing", "curriculum_level"]


@dataclass(frozen=True)
class ChannelRanges:
    """Ranges of the channel at level t = 1 (see the module docstring)."""

    shift_px: float = 1.5
    """largest corner displacement of the misregistration homography (pixels of the 380 snapshot)"""
    blur_px: float = 1.0
    """largest Gaussian blur sigma (pixels)"""
    gain: float = 0.15
    """largest relative per-channel gain error"""
    offset: float = 0.08
    """largest per-channel offset"""
    gamma: float = 0.15
    """largest per-channel gamma deviation from 1"""
    saturation: float = 0.15
    """largest saturation deviation from 1"""
    shading: float = 0.07
    """largest std of the smooth residual shading field"""
    texture: float = 0.04
    """largest amplitude of the periodic halftone-like texture"""
    noise: float = 0.04
    """largest white-noise std"""
    jpeg_min: float = 60.0
    """lowest JPEG quality (at t = 1)"""
    jpeg_prob: float = 0.6
    """probability that an image goes through JPEG"""

    def as_dict(self) -> dict:
        return asdict(self)


def round_8bit(x: Tensor) -> Tensor:
    """Clip to [0, 1] and round to 1/255 steps, identity gradient (straight-through)."""
    q = torch.round(x.clamp(0, 1) * 255) / 255
    return x + (q - x).detach()


def curriculum_level(step: int, steps: int, ramp: float = 0.5) -> float:
    """Largest level at `step`: from 0 up to 1 over the first `ramp` of the run, then 1."""
    return min(1.0, step / max(1.0, ramp * steps))


def _rand(*shape, gen, like: Tensor) -> Tensor:
    """Uniform [0, 1) of `shape`, drawn on the CPU from `gen` (reproducible on any device), on `like`'s device."""
    return torch.rand(*shape, generator=gen).to(like.device)


def _u(n: int, lo, hi, gen, like: Tensor) -> Tensor:
    return lo + (hi - lo) * _rand(n, gen=gen, like=like)


def _misregister(x: Tensor, t: Tensor, r: ChannelRanges, gen) -> Tensor:
    b, _, h, w = x.shape
    src = torch.tensor([[0.0, 0.0], [w - 1.0, 0.0], [w - 1.0, h - 1.0], [0.0, h - 1.0]], device=x.device).expand(b, 4, 2)
    dst = src + (_rand(b, 4, 2, gen=gen, like=x) * 2 - 1) * (r.shift_px * t).view(b, 1, 1)
    m = kornia.geometry.transform.get_perspective_transform(src, dst)
    return kornia.geometry.transform.warp_perspective(x, m, (h, w), mode="bilinear", padding_mode="reflection",
                                                      align_corners=True)


def _blur(x: Tensor, t: Tensor, r: ChannelRanges, gen) -> Tensor:
    sigma = (_rand(x.shape[0], gen=gen, like=x) * r.blur_px * t).clamp(min=1e-3)
    k = 2 * int(torch.ceil(3 * sigma.max()).item()) + 1
    return kornia.filters.gaussian_blur2d(x, (k, k), torch.stack([sigma, sigma], 1), border_type="reflect")


def _tone(x: Tensor, t: Tensor, r: ChannelRanges, gen) -> Tensor:
    b = x.shape[0]
    tt = t.view(b, 1)
    gain = 1 + (_rand(b, 3, gen=gen, like=x) * 2 - 1) * r.gain * tt
    off = (_rand(b, 3, gen=gen, like=x) * 2 - 1) * r.offset * tt
    gam = 1 + (_rand(b, 3, gen=gen, like=x) * 2 - 1) * r.gamma * tt
    y = x.clamp(1e-4, 1).pow(gam[..., None, None]) * gain[..., None, None] + off[..., None, None]
    sat = 1 + (_rand(b, gen=gen, like=x) * 2 - 1) * r.saturation * t
    grey = y.mean(1, keepdim=True)
    return grey + (y - grey) * sat.view(b, 1, 1, 1)


def _shading(x: Tensor, t: Tensor, r: ChannelRanges, gen) -> Tensor:
    b, c, h, w = x.shape
    field = torch.randn(b, c, 3, 3, generator=gen).to(x.device) * (_rand(b, 1, 1, 1, gen=gen, like=x) * r.shading
                                                                    * t.view(b, 1, 1, 1))
    return x + torch.nn.functional.interpolate(field, size=(h, w), mode="bicubic", align_corners=True)


def _texture(x: Tensor, t: Tensor, r: ChannelRanges, gen) -> Tensor:
    b, c, h, w = x.shape
    yy, xx = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
    phase = torch.randint(0, 2, (b, c, 2), generator=gen)
    pattern = 1.0 - 2.0 * (((yy + phase[..., 0, None, None]) % 2) ^ ((xx + phase[..., 1, None, None]) % 2)).float()
    amp = _rand(b, c, gen=gen, like=x) * r.texture * t.view(b, 1)
    std = _rand(b, 1, gen=gen, like=x) * r.noise * t.view(b, 1)
    noise = torch.randn(x.shape, generator=gen).to(x.device) * std[..., None, None]
    pattern = pattern.to(x.device)
    return x + pattern * amp[..., None, None] + noise


def _jpeg(x: Tensor, t: Tensor, r: ChannelRanges, gen) -> Tensor:
    b = x.shape[0]
    lo = torch.clamp(95 - (95 - r.jpeg_min) * t, min=r.jpeg_min)
    q = _u(b, lo, torch.full_like(lo, 95.0), gen, x)
    use = (_rand(b, gen=gen, like=x) < r.jpeg_prob) & (t > 0.05)
    if not bool(use.any()):
        return x
    y = x.clone()
    y[use] = kornia.enhance.jpeg_codec_differentiable(x[use].clamp(0, 1), q[use])
    return y


def apply_channel(x: Tensor, level: Tensor, ranges: ChannelRanges = ChannelRanges(),
                  generator: torch.Generator | None = None) -> Tensor:
    """Snapshot (B, 3, H, W) in [0, 1] -> what the restore network sees after print, photo and scan.
    `level` (B,) in [0, 1]; level 0 leaves only the 8-bit rounding."""
    y = round_8bit(x)
    if float(level.max()) <= 0:
        return y
    y = _misregister(y, level, ranges, generator)
    y = _blur(y, level, ranges, generator)
    y = _tone(y, level, ranges, generator)
    y = _shading(y, level, ranges, generator)
    y = _texture(y, level, ranges, generator)
    y = _jpeg(y, level, ranges, generator)
    return y.clamp(0, 1)


@dataclass(frozen=True)
class SharingRanges:
    """What sharing a snapshot *file* does (the `file` medium; no print, no lens), at level t = 1. Per image:
    8-bit rounding always; with probability `resize_prob` a square resize by a factor drawn log-uniformly in
    [1 - (1 - resize_min) * t, 1 + (resize_max - 1) * t] (area-like when smaller, bicubic when larger), the
    JPEG below at that size, and the reader's resize back (bicubic up, area-like down, as
    `scanner.pixelmeta` does); JPEG (4:2:0, kornia) with probability `jpeg_prob`, quality drawn in
    [95 - (95 - jpeg_min) * t, 95], a second JPEG after it with probability `twice_prob`."""

    jpeg_min: float = 60.0
    """lowest JPEG quality (at t = 1)"""
    jpeg_prob: float = 0.85
    """probability that an image goes through JPEG"""
    twice_prob: float = 0.2
    """probability of a second JPEG (a re-shared copy)"""
    resize_prob: float = 0.3
    """probability that an image is resized and back"""
    resize_min: float = 0.6
    """smallest resize factor (380 -> 228 px)"""
    resize_max: float = 2.8
    """largest resize factor (380 -> 1064 px)"""

    def as_dict(self) -> dict:
        return asdict(self)


def _resize_to(x: Tensor, n: int) -> Tensor:
    """(1, 3, h, w) -> (1, 3, n, n): area-like (antialiased bilinear) when smaller, bicubic when larger."""
    if n < x.shape[-1]:
        return torch.nn.functional.interpolate(x, size=(n, n), mode="bilinear", antialias=True, align_corners=False)
    return torch.nn.functional.interpolate(x, size=(n, n), mode="bicubic", align_corners=False)


def apply_sharing(x: Tensor, level: Tensor, ranges: SharingRanges = SharingRanges(),
                  generator: torch.Generator | None = None) -> Tensor:
    """Snapshot (B, 3, H, W) in [0, 1], square -> what `restore` sees of a shared copy of it, resized back to
    H x W. `level` (B,) in [0, 1]; level 0 leaves only the 8-bit rounding."""
    y = round_8bit(x)
    out = []
    for i in range(y.shape[0]):
        t, yi, n = float(level[i]), y[i:i + 1], y.shape[-1]
        u = torch.rand(6, generator=generator).tolist()
        if t <= 0.05:
            out.append(yi)
            continue
        if u[0] < ranges.resize_prob:
            lo, hi = np.log(1 - (1 - ranges.resize_min) * t), np.log(1 + (ranges.resize_max - 1) * t)
            yi = round_8bit(_resize_to(yi, max(16, int(round(n * np.exp(lo + (hi - lo) * u[1]))))))
        jpegs = 0 if u[2] >= ranges.jpeg_prob else 2 if u[5] < ranges.twice_prob else 1
        for draw in u[3:3 + jpegs]:
            q = torch.tensor([95 - (95 - ranges.jpeg_min) * t * draw], device=x.device)
            yi = round_8bit(kornia.enhance.jpeg_codec_differentiable(yi.clamp(0, 1), q))
        if yi.shape[-1] != n:
            yi = round_8bit(_resize_to(yi, n))
        out.append(yi)
    return torch.cat(out).clamp(0, 1)
