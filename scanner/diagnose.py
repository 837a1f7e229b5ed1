"""Why a scan failed, in one line: the photo's exposure, sharpness and what the detector did see."""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["exposure_problem", "sharpness", "SHARPNESS_MIN"]

SHARPNESS_MIN = 0.06  # below: the sharpest edges of the photo are spread over more than ~10 pixels


def exposure_problem(gray: np.ndarray) -> str | None:
    """A cause when the (H, W) uint8 grey photo is washed out, too dark or flat; else None."""
    p1, p50, p99 = np.percentile(gray[::2, ::2], (1, 50, 99))
    if (gray >= 250).mean() > 0.5:
        return "the photo is washed out (over half of it is blown-out white)"
    if p99 < 40:
        return "the photo is too dark (nothing brighter than 16% grey)"
    if p99 - p1 < 30:
        return f"the photo is washed out or flat (contrast {int(p99 - p1)} of 255 grey levels)"
    return None


def sharpness(gray: np.ndarray) -> float:
    """The strongest edges' steepness relative to the photo's contrast: 99.9th percentile of the
    gradient magnitude (Sobel, per pixel) / (99th - 1st percentile of grey). About 0.3-0.5 for a sharp
    photo at the detection scale, falling as 1 / blur width."""
    g = gray.astype(np.float32)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    mag = cv2.magnitude(gx, gy)
    p1, p99 = np.percentile(g[::2, ::2], (1, 99))
    return float(np.percentile(mag, 99.9) / max(p99 - p1, 1.0))
