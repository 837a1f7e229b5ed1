"""Geometry of the sheet layout (numpy only): where the snapshot, markers, patches and QR code lie.

Coordinates are layout units (= snapshot pixels, `formats` section "sheet and scan"), continuous,
with the snapshot's top-left pixel *corner* at (0, 0): snapshot pixel (i, j) covers
[j, j+1) x [i, i+1) and its centre is (j + 0.5, i + 0.5)."""
from __future__ import annotations

import cv2
import numpy as np

from snapshot3d import formats

__all__ = ["snapshot_corners", "marker_corners", "sheet_size", "patch_boxes", "aruco_dictionary",
           "layout_to_pixels"]


def snapshot_corners() -> np.ndarray:
    """(4, 2) float64 corners of the snapshot, clockwise from its top-left."""
    s = float(formats.SNAPSHOT_SIZE)
    return np.array([[0, 0], [s, 0], [s, s], [0, s]], np.float64)


def marker_corners(version: int = formats.SHEET_FORMAT_VERSION) -> dict[int, np.ndarray]:
    """{marker id: (4, 2) float64 corners} in ArUco's order (clockwise from the marker's top-left)."""
    m = float(formats.MARKER_SIZE)
    out = {}
    for mid, (x, y) in zip(formats.SHEET_MARKER_IDS[version], formats.MARKER_ORIGINS):
        out[mid] = np.array([[x, y], [x + m, y], [x + m, y + m], [x, y + m]], np.float64)
    return out


def sheet_size() -> tuple[int, int]:
    """(width, height) of the whole sheet in layout units."""
    x0, y0, x1, y1 = formats.SHEET_BOX
    return x1 - x0, y1 - y0


def patch_boxes() -> np.ndarray:
    """(P, 4) float64 boxes (x0, y0, x1, y1) of the colour patches, in `formats.PATCH_COLOURS` order."""
    x0, y0, x1, y1 = formats.PATCH_BOX
    w = (x1 - x0) / formats.PATCH_COLS
    h = (y1 - y0) / formats.PATCH_ROWS
    boxes = []
    for i in range(len(formats.PATCH_COLOURS)):
        r, c = divmod(i, formats.PATCH_COLS)
        boxes.append((x0 + c * w, y0 + r * h, x0 + (c + 1) * w, y0 + (r + 1) * h))
    return np.array(boxes, np.float64)


def aruco_dictionary(name: str = formats.ARUCO_DICT):
    """A `cv2.aruco.Dictionary` by predefined name (e.g. "DICT_4X4_50")."""
    if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
        raise ValueError(f"unknown ArUco dictionary {name!r}")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


def layout_to_pixels(scale: float) -> np.ndarray:
    """(3, 3) homography from layout units to pixel coordinates (pixel centres at integers) of a sheet
    image drawn at `scale` pixels per layout unit."""
    x0, y0 = formats.SHEET_BOX[:2]
    return np.array([[scale, 0, -x0 * scale - 0.5], [0, scale, -y0 * scale - 0.5], [0, 0, 1]], np.float64)
