"""The calibration chart (issue 38 item 1): a sheet whose snapshot square holds content the receiver knows
exactly, so that `snapshot3d calibrate` can measure a printer and phone (numpy and OpenCV only).

The chart is an ordinary sheet (markers, colour patches, QR code with codec id `formats.CALIB_CODEC`) around
a deterministic (380, 380, 3) uint8 sRGB RGB pattern; boxes are (x0, y0, x1, y1) in snapshot pixels:
- EDGE_FIELD: two dark squares on a light field, turned by +-EDGE_ANGLE_DEG, whose eight edges are slanted
  edges for an ISO 12233-style MTF (`EDGE_ROIS`); drawn with exact area coverage in linear light;
- PATCH_BOXES: flat grey patches at PATCH_LEVELS (sRGB codes) for the noise and the colour error left;
- RAMP_BOX: a tone ramp, sRGB code 0 at its left edge to 255 at its right;
- CAPTION_BOX: a strip for the caption the sheet writes at printer resolution (not measured);
- CARRIER_BOXES: two 184 x 184 squares of mid grey carrying known random Gaussian coefficients in every
  detail band the print codec uses (`print_carriers.PRINT_BANDS`, their relative energies), one seed per square.
  Gaussian since `calib-2` (`calib-1` had +-1): through the simulated printer's halftone (a 17-level quantizer
  per snapshot pixel) a +-1 pattern's few distinct pixel values read 14-16 % below the print codec's own
  carriers at the same amplitude in the Y2 bands; Gaussian coefficients read like them (docs/calibration.md)."""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.codecs import bands
from snapshot3d.codecs.print_carriers import PRINT_BANDS

__all__ = ["EDGE_FIELD", "EDGE_ANGLE_DEG", "EDGE_ROIS", "PATCH_BOXES", "PATCH_LEVELS", "RAMP_BOX", "CAPTION_BOX",
           "CARRIER_BOXES", "CARRIER_STD", "chart_snapshot", "chart_meta", "draw_caption", "CAPTION"]

N = formats.SNAPSHOT_SIZE
EDGE_FIELD = (8, 8, 252, 128)
EDGE_ANGLE_DEG = 5.0
_SQUARES = (((68.0, 68.0), EDGE_ANGLE_DEG), ((190.0, 68.0), -EDGE_ANGLE_DEG))   # centre (x, y), turn
_SIDE = 76.0
_LIGHT, _DARK = 190, 60          # sRGB codes of the edge field and the squares
_ROI_ALONG, _ROI_ACROSS = 44, 24
PATCH_LEVELS = (40, 100, 160, 220)
PATCH_BOXES = ((262, 8, 316, 66), (318, 8, 372, 66), (262, 70, 316, 128), (318, 70, 372, 128))
RAMP_BOX = (10, 136, 370, 172)
CAPTION_BOX = (0, 176, 380, 192)
CARRIER_BOXES = ((6, 194, 190, 378), (190, 194, 374, 378))
CARRIER_STD = 0.08               # pixel std of the carrier pattern (sRGB in [0, 1])
_GREY = 128
CAPTION = (f"snapshot3d calibration chart ({formats.CALIB_CODEC}). Print at 100%, lay flat, photograph the whole "
           "sheet square on in even light, then run: snapshot3d calibrate PHOTO")


def _edge_rois() -> tuple:
    """(x0, y0, x1, y1, vertical) windows around each square's edge midpoints; vertical: the edge runs
    near-vertically (its profile is taken along x)."""
    out = []
    for (cx, cy), ang in _SQUARES:
        t = np.deg2rad(ang)
        for nx, ny in ((1, 0), (-1, 0), (0, 1), (0, -1)):   # outward normals before the turn
            ux, uy = nx * np.cos(t) - ny * np.sin(t), nx * np.sin(t) + ny * np.cos(t)
            mx, my = cx + ux * _SIDE / 2, cy + uy * _SIDE / 2
            vertical = nx != 0
            hw, hh = (_ROI_ACROSS / 2, _ROI_ALONG / 2) if vertical else (_ROI_ALONG / 2, _ROI_ACROSS / 2)
            out.append((int(round(mx - hw)), int(round(my - hh)), int(round(mx + hw)), int(round(my + hh)), vertical))
    return tuple(out)


EDGE_ROIS = _edge_rois()


def _srgb_to_lin(code: float) -> float:
    x = code / 255.0
    return x / 12.92 if x <= 0.04045 else ((x + 0.055) / 1.055) ** 2.4


def _lin_to_srgb(lin: np.ndarray) -> np.ndarray:
    lin = np.clip(lin, 0.0, 1.0)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055) * 255.0


def _edge_field() -> np.ndarray:
    """(h, w) uint8 sRGB of EDGE_FIELD: the squares' area coverage (8 x 8 samples a pixel) mixed in linear light."""
    x0, y0, x1, y1 = EDGE_FIELD
    ss = 8
    ys, xs = np.mgrid[y0 * ss:y1 * ss, x0 * ss:x1 * ss].astype(np.float32)
    xs, ys = (xs + 0.5) / ss, (ys + 0.5) / ss
    inside = np.zeros(xs.shape, bool)
    for (cx, cy), ang in _SQUARES:
        t = np.deg2rad(ang)
        u = (xs - cx) * np.cos(t) + (ys - cy) * np.sin(t)
        v = -(xs - cx) * np.sin(t) + (ys - cy) * np.cos(t)
        inside |= (np.abs(u) <= _SIDE / 2) & (np.abs(v) <= _SIDE / 2)
    cover = cv2.resize(inside.astype(np.float32), (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
    lin = _srgb_to_lin(_LIGHT) + cover * (_srgb_to_lin(_DARK) - _srgb_to_lin(_LIGHT))
    return np.round(_lin_to_srgb(lin)).astype(np.uint8)


def _carriers(seed: int, side: int) -> np.ndarray:
    """(side, side) float RGB pattern around 0: unit Gaussian coefficients in PRINT_BANDS (times the square
    root of their energies), scaled to CARRIER_STD per pixel."""
    rng = np.random.default_rng(seed)
    coeffs = {b: np.zeros(v.shape) for b, v in bands.analyse(np.zeros((side, side, 3))).items()}
    for b, energy in PRINT_BANDS.items():
        coeffs[b] = rng.standard_normal(coeffs[b].shape) * np.sqrt(energy)
    pat = bands.synthesise(coeffs)
    return pat * (CARRIER_STD / float(pat.std()))


@lru_cache(maxsize=1)
def _chart() -> np.ndarray:
    img = np.full((N, N, 3), _GREY, np.uint8)
    x0, y0, x1, y1 = EDGE_FIELD
    img[y0:y1, x0:x1] = _edge_field()[..., None]
    for (bx0, by0, bx1, by1), level in zip(PATCH_BOXES, PATCH_LEVELS):
        img[by0:by1, bx0:bx1] = level
    rx0, ry0, rx1, ry1 = RAMP_BOX
    ramp = np.round((np.arange(rx0, rx1) - rx0 + 0.5) / (rx1 - rx0) * 255.0).astype(np.uint8)
    img[ry0:ry1, rx0:rx1] = ramp[None, :, None]
    for i, (bx0, by0, bx1, by1) in enumerate(CARRIER_BOXES):
        pat = _carriers(38_000 + i, bx1 - bx0)
        img[by0:by1, bx0:bx1] = np.clip(np.round(_GREY + 255.0 * pat), 0, 255).astype(np.uint8)
    img.setflags(write=False)
    return img


def chart_snapshot() -> np.ndarray:
    """The chart's snapshot square: (380, 380, 3) uint8 sRGB RGB, the same on every call (read-only)."""
    return _chart()


def chart_meta():
    """The chart's QR metadata (`scanner.qr.SheetMeta` with codec `formats.CALIB_CODEC`)."""
    from .qr import SheetMeta

    return SheetMeta(codec=formats.CALIB_CODEC)


def draw_caption(sheet: np.ndarray, k: int) -> np.ndarray:
    """Write the caption across CAPTION_BOX of a chart's sheet (H, W, 3) uint8 RGB drawn at k dots per snapshot
    pixel (`sheet.chart_sheet`), at printer resolution, in place; returns the sheet."""
    sx0, sy0 = formats.SHEET_BOX[:2]
    x0, y0, x1, y1 = CAPTION_BOX
    words = CAPTION.split(" ")
    cut = int(np.argmin([abs(len(" ".join(words[:i])) - len(CAPTION) / 2) for i in range(len(words))]))
    lines = [" ".join(words[:cut]), " ".join(words[cut:])]   # two lines of about equal length
    box_w, line_h = (x1 - x0) * k, (y1 - y0) * k / 2
    scale = 1.0
    (tw, th), _ = cv2.getTextSize(max(lines, key=len), cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    scale = min(0.96 * box_w / tw, 0.62 * line_h / th)
    thick = max(1, int(round(scale * 1.5)))
    for i, line in enumerate(lines):
        org = (int((x0 - sx0) * k + 0.02 * box_w), int((y0 - sy0) * k + (i + 0.8) * line_h))
        cv2.putText(sheet, line, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thick, cv2.LINE_AA)
    return sheet
