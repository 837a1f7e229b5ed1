"""Photometric correction from the sheet itself (numpy and OpenCV).

1. Flat field: the bare paper around the snapshot gives the illumination; a quadratic surface per
   channel is fitted to it (robustly: glare and shadows edges are trimmed) and divided out.
2. Tone: per channel, a monotone piecewise-linear curve through the six grey patches maps the
   flat-fielded value to the patch's true linear value.
3. Colour: a 3x3 matrix, fitted by ridge-regularised least squares on all patches, undoes the
   printer's gamut compression and the camera's colour mixing.
All work is in linear light: the photo is taken as sRGB-encoded, the output is sRGB."""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from snapshot3d import formats

from . import layout

__all__ = ["srgb_decode", "srgb_encode", "paper_mask", "fit_colour", "flat_field", "apply_colour", "colour_flat",
           "marker_contrast", "linear_lut", "linear_to_srgb_u8"]

_GREYS = (0, 1, 2, 3, 4, 5)  # indices of white, black and greys in formats.PATCH_COLOURS


def srgb_decode(x: np.ndarray) -> np.ndarray:
    """sRGB-encoded float in [0, 1] -> linear."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear float -> sRGB-encoded float in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055).astype(np.float32)


@lru_cache(maxsize=1)
def paper_mask(erode: int = 3) -> np.ndarray:
    """(h, w) bool at one pixel per layout unit: bare paper at least `erode` units from any ink."""
    w, h = layout.sheet_size()
    x0, y0 = formats.SHEET_BOX[:2]
    ink = np.zeros((h, w), np.uint8)
    boxes = [(0, 0, formats.SNAPSHOT_SIZE, formats.SNAPSHOT_SIZE), formats.PATCH_BOX, formats.QR_BOX]
    boxes += [(q[0, 0], q[0, 1], q[2, 0], q[2, 1]) for q in layout.marker_corners().values()]
    for bx0, by0, bx1, by1 in boxes:
        ink[int(by0 - y0):int(np.ceil(by1 - y0)), int(bx0 - x0):int(np.ceil(bx1 - x0))] = 1
    ink = cv2.dilate(ink, np.ones((2 * erode + 1, 2 * erode + 1), np.uint8))
    ink[:erode] = ink[-erode:] = 1
    ink[:, :erode] = ink[:, -erode:] = 1
    return ink == 0


def _design(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], -1)


@lru_cache(maxsize=1)
def _paper_samples():
    h, w = paper_mask().shape
    ys, xs = np.nonzero(paper_mask())
    step = max(1, len(xs) // 4000)  # a few thousand samples are plenty for six coefficients
    ys, xs = ys[::step], xs[::step]
    return ys, xs, _design((xs + 0.5) / w - 0.5, (ys + 0.5) / h - 0.5)


def _illumination_at(coef: np.ndarray, box: tuple) -> np.ndarray:
    """The fitted paper brightness (h, w, 3) over a layout box (x0, y0, x1, y1)."""
    sx0, sy0 = formats.SHEET_BOX[:2]
    w, h = layout.sheet_size()
    bx0, by0, bx1, by1 = (int(v) for v in box)
    gy, gx = np.mgrid[by0 - sy0:by1 - sy0, bx0 - sx0:bx1 - sx0].astype(np.float32) + 0.5
    return (_design(gx / w - 0.5, gy / h - 0.5) @ coef.astype(np.float32)).astype(np.float32)


def _illumination(lin: np.ndarray) -> np.ndarray:
    """Fit the paper's brightness over the layout from the paper mask: (6, 3) quadratic coefficients."""
    ys, xs, A = _paper_samples()
    vals = lin[ys, xs]
    keep = np.ones(len(xs), bool)
    coef = np.zeros((6, 3))
    for _ in range(3):
        Ak = A[keep]
        coef = np.linalg.solve(Ak.T @ Ak + 1e-9 * np.eye(6), Ak.T @ vals[keep])  # normal equations: 6 unknowns
        res = np.abs(vals - A @ coef).max(1)
        keep = res <= np.quantile(res, 0.8) + 1e-6
    return coef


def _patch_means(lin: np.ndarray, coef: np.ndarray) -> np.ndarray:
    x0, y0 = formats.SHEET_BOX[:2]
    out = []
    for bx0, by0, bx1, by1 in layout.patch_boxes():
        mx, my = 0.25 * (bx1 - bx0), 0.25 * (by1 - by0)
        box = (int(bx0 + mx), int(by0 + my), int(bx1 - mx), int(by1 - my))
        win = lin[box[1] - y0:box[3] - y0, box[0] - x0:box[2] - x0] / np.maximum(_illumination_at(coef, box), 1e-3)
        out.append(np.median(win.reshape(-1, 3), 0))
    return np.array(out, np.float64)


def marker_contrast(lin: np.ndarray) -> float:
    """(paper - ink) / paper over the markers' black border, from the linear layout image (h, w, 3)."""
    x0, y0 = formats.SHEET_BOX[:2]
    cell = formats.MARKER_SIZE / 6
    ink = []
    for q in layout.marker_corners().values():
        mx, my = int(q[0, 0] - x0), int(q[0, 1] - y0)
        ink.append(np.median(lin[my + 2:my + int(cell) - 2, mx + 2:mx + formats.MARKER_SIZE - 2]))
    paper = float(np.median(lin[paper_mask()]))
    return (paper - float(np.median(ink))) / max(paper, 1e-6)


def fit_colour(lin: np.ndarray) -> dict:
    """Fit the correction on the rectified sheet (h, w, 3) float32 **RGB**, linear light, one pixel per
    layout unit. Returns the model: illumination coefficients, tone curves, matrix."""
    coef = _illumination(lin)
    obs = _patch_means(lin, coef)
    target = srgb_decode(np.array(formats.PATCH_COLOURS, np.float32)).astype(np.float64)
    curves = []
    for c in range(3):
        xg, yg = obs[list(_GREYS), c], target[list(_GREYS), c]
        order = np.argsort(xg)
        xg, yg = np.maximum.accumulate(xg[order]), yg[order]
        curves.append((xg, yg))
    toned = np.stack([np.interp(obs[:, c], *curves[c]) for c in range(3)], -1)
    lam = 0.05
    A = toned.T @ toned + lam * np.eye(3)
    Mt = np.linalg.solve(A, toned.T @ target + lam * np.eye(3))  # (3, 3): target ~ toned @ Mt
    return {"illumination": coef, "curves": curves, "matrix": Mt}


def flat_field(model: dict, region_lin: np.ndarray, box: tuple) -> np.ndarray:
    """A region of the rectified sheet (h, w, 3) float32 RGB linear at one pixel per layout unit, covering layout
    box (x0, y0, x1, y1), over the paper's fitted brightness there: 1 is the bare paper's own level."""
    return region_lin / np.maximum(_illumination_at(model["illumination"], box), 1e-3)


def apply_colour(model: dict, region_lin: np.ndarray, box: tuple) -> np.ndarray:
    """Correct a region of the rectified sheet: region_lin (h, w, 3) float32 RGB linear at one pixel per
    layout unit, covering layout box (x0, y0, x1, y1). Returns (h, w, 3) uint8 sRGB RGB."""
    return colour_flat(model, flat_field(model, region_lin, box))


def colour_flat(model: dict, flat: np.ndarray) -> np.ndarray:
    """`apply_colour` of a region already over the paper's level (`flat_field`): tone and colour, (h, w, 3) uint8
    sRGB RGB."""
    toned = np.stack([np.interp(flat[..., c], *model["curves"][c]) for c in range(3)], -1).astype(np.float32)
    return linear_to_srgb_u8(toned @ model["matrix"].astype(np.float32))


def linear_lut() -> np.ndarray:
    """(256,) float32: uint8 sRGB code -> linear value (for cv2.LUT)."""
    return srgb_decode(np.arange(256, dtype=np.float32) / 255.0)


def linear_to_srgb_u8(lin: np.ndarray) -> np.ndarray:
    """Linear float (clipped to [0, 1]) -> uint8 sRGB, through a 4096-entry table."""
    x = np.arange(4096, dtype=np.float32) / 4095.0
    table = (srgb_encode(x) * 255.0 + 0.5).astype(np.uint8)
    return table[(np.clip(lin, 0.0, 1.0) * 4095.0 + 0.5).astype(np.int32)]
