"""The printer: digital sheet (sRGB) -> linear reflectance of the printed paper, at printer dot resolution.

Model: sRGB decoding to linear; gamut compression toward each colour's grey; a tone curve (dot gain);
CMY ordered-dither halftoning with one screen phase per ink; ink on paper (paper white, ink black);
multiplicative paper fibre texture."""
from __future__ import annotations

import cv2
import numpy as np

from .presets import Preset

__all__ = ["srgb_to_linear", "linear_to_srgb_u8", "print_sheet"]

_BAYER4 = (np.array([[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]], np.float32) + 0.5) / 16.0


def srgb_to_linear(u8: np.ndarray) -> np.ndarray:
    """uint8 sRGB (any shape) -> float32 linear in [0, 1]."""
    x = np.arange(256, dtype=np.float64) / 255.0
    lut = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)
    return lut[u8]


def linear_to_srgb_u8(lin: np.ndarray) -> np.ndarray:
    """float32 linear in [0, 1] (clipped) -> uint8 sRGB, through a 4096-entry table."""
    x = np.arange(4096, dtype=np.float64) / 4095.0
    lut = np.round(255.0 * np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)).astype(np.uint8)
    q = (np.clip(lin, 0.0, 1.0) * 4095.0 + 0.5).astype(np.uint16)
    return lut[q]


def print_sheet(sheet_rgb: np.ndarray, preset: Preset, dots_per_sheet_px: int, rng: np.random.Generator) -> np.ndarray:
    """Print a sheet. sheet_rgb: (H, W, 3) uint8 sRGB. Returns (H*d, W*d, 3) float32 linear reflectance
    in [0, 1] (RGB), d = dots_per_sheet_px."""
    lin = srgb_to_linear(sheet_rgb)
    grey = lin @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    lin = grey[..., None] + preset.gamut * (lin - grey[..., None])
    lin = np.clip(lin, 0.0, 1.0) ** preset.tone_gamma
    d = max(1, int(dots_per_sheet_px))
    if d > 1:
        lin = cv2.resize(lin, None, fx=d, fy=d, interpolation=cv2.INTER_NEAREST)
    h, w = lin.shape[:2]
    if preset.halftone:
        cover = 1.0 - lin  # ink coverage of C, M, Y
        ink = np.empty_like(cover)
        for c in range(3):  # one screen phase per ink, as printers rotate or shift their screens
            dy, dx = rng.integers(0, 4, size=2)
            thr = np.tile(np.roll(_BAYER4, (dy, dx), (0, 1)), (h // 4 + 1, w // 4 + 1))[:h, :w]
            ink[..., c] = cover[..., c] > thr
        lin = 1.0 - ink
    refl = (preset.ink_black + (1.0 - preset.ink_black) * lin) * np.asarray(preset.paper_white, np.float32)
    if preset.paper_texture > 0:
        fibre = np.empty((h, w), np.float32)
        cv2.setRNGSeed(int(rng.integers(2**31)))
        cv2.randn(fibre, 0.0, 1.0)
        fibre = cv2.GaussianBlur(fibre, (0, 0), 1.2) * 2.0  # blurred unit noise has std ~0.24: rescale
        refl *= (1.0 + preset.paper_texture * fibre)[..., None]
    return np.clip(refl, 0.0, 1.0).astype(np.float32)
