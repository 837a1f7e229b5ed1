"""Anti-aliased rectification of the sheet from a photo, given the fitted geometry.

The photo's region of the sheet is first shrunk by area averaging (an integer factor) until it
holds at most about OVERSAMPLE photo pixels per layout unit, then resampled (bilinear, through the
homography and lens model) to OVERSAMPLE pixels per layout unit; callers area-average that down to
one pixel per layout unit. Each output pixel therefore averages the photo over its own footprint."""
from __future__ import annotations

import cv2
import numpy as np

from snapshot3d import formats

from . import layout
from .camera import apply_h, distort, quad_area
from .fit import Fit

__all__ = ["OVERSAMPLE", "rectify_sheet", "rectify_box", "photo_px_per_unit"]

OVERSAMPLE = 2
_MAP_STEP = 8


def photo_px_per_unit(fit: Fit) -> float:
    """Mean photo pixels per layout unit over the snapshot."""
    return float(np.sqrt(quad_area(fit.to_photo(layout.snapshot_corners())))) / formats.SNAPSHOT_SIZE


def rectify_sheet(image_bgr: np.ndarray, fit: Fit) -> np.ndarray:
    """(H, W, 3) uint8 BGR photo -> (h * OVERSAMPLE, w * OVERSAMPLE, 3) uint8 BGR sheet, (w, h) =
    `layout.sheet_size()`; output pixel (i, j) is centred on layout ((j + 0.5) / OVERSAMPLE + x0, ...)."""
    x0, y0, x1, y1 = formats.SHEET_BOX
    sheet_q = fit.to_photo(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64))
    H_img, W_img = image_bgr.shape[:2]
    r = max(1, int(photo_px_per_unit(fit) / OVERSAMPLE))
    rx0, ry0 = np.maximum(np.floor(sheet_q.min(0)).astype(int) - 2 * r, 0)
    rx1, ry1 = np.minimum(np.ceil(sheet_q.max(0)).astype(int) + 2 * r, [W_img, H_img])
    rx1 = rx0 + max(r, (rx1 - rx0) // r * r)
    ry1 = ry0 + max(r, (ry1 - ry0) // r * r)
    roi = image_bgr[ry0:ry1, rx0:rx1]
    if r > 1:
        roi = cv2.resize(roi, (roi.shape[1] // r, roi.shape[0] // r), interpolation=cv2.INTER_AREA)
    # photo pixel (x, y) -> pixel of the shrunk ROI
    S = np.array([[1 / r, 0, (0.5 - rx0) / r - 0.5], [0, 1 / r, (0.5 - ry0) / r - 0.5], [0, 0, 1]], np.float64)
    w, h = layout.sheet_size()
    out_w, out_h = w * OVERSAMPLE, h * OVERSAMPLE
    M = np.array([[1 / OVERSAMPLE, 0, x0 + 0.5 / OVERSAMPLE], [0, 1 / OVERSAMPLE, y0 + 0.5 / OVERSAMPLE], [0, 0, 1]])
    if fit.camera.k1 == 0.0:
        T = S @ fit.H @ M  # output pixel -> ROI pixel
        return cv2.warpPerspective(roi, T, (out_w, out_h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                   borderMode=cv2.BORDER_REPLICATE)
    mx, my = _coarse_map(lambda out: apply_h(S, distort(apply_h(fit.H, apply_h(M, out)), fit.camera)), out_w, out_h)
    return cv2.remap(roi, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def _coarse_map(to_source, out_w: int, out_h: int) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap's (map_x, map_y) float32 (out_h, out_w) for `to_source` (output pixels (..., 2) float64 ->
    source pixels (..., 2)), evaluated every _MAP_STEP output pixels and interpolated between (the lens model
    is smooth; evaluating it per pixel costs far more)."""
    gx, gy = np.meshgrid(np.arange(0, out_w + _MAP_STEP, _MAP_STEP, dtype=np.float64),
                         np.arange(0, out_h + _MAP_STEP, _MAP_STEP, dtype=np.float64))
    src = to_source(np.stack([gx, gy], -1)).astype(np.float32)
    A = np.array([[1.0 / _MAP_STEP, 0, 0], [0, 1.0 / _MAP_STEP, 0]], np.float32)
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    mx = cv2.warpAffine(src[..., 0], A, (out_w, out_h), flags=flags, borderMode=cv2.BORDER_REPLICATE)
    my = cv2.warpAffine(src[..., 1], A, (out_w, out_h), flags=flags, borderMode=cv2.BORDER_REPLICATE)
    return mx, my


def rectify_box(image_bgr: np.ndarray, fit: Fit, box, scale: int) -> np.ndarray:
    """A box (x0, y0, x1, y1) of the layout straight from the photo at `scale` pixels per unit, bicubic through
    the homography and lens model (no shrinking first: for small print, where the photo holds fewer pixels per
    unit than `scale`) -> ((y1 - y0) * scale, (x1 - x0) * scale) uint8 grey."""
    x0, y0, x1, y1 = box
    w, h = (x1 - x0) * scale, (y1 - y0) * scale
    M = np.array([[1 / scale, 0, x0 + 0.5 / scale], [0, 1 / scale, y0 + 0.5 / scale], [0, 0, 1]])
    mx, my = _coarse_map(lambda out: fit.to_photo(apply_h(M, out).reshape(-1, 2)).reshape(out.shape), w, h)
    out = cv2.remap(image_bgr, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    return cv2.cvtColor(out, cv2.COLOR_BGR2GRAY)
