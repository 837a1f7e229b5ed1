"""A pilot signal the sheet already carries: its ArUco markers are known images, printed and
photographed through the same channel as the snapshot. After the scanner's rectification and colour
correction, how close they come back to their ideal black and white (`pilot_psnr`, dB) measures the
channel's blur, misregistration, noise, tone error and JPEG loss, with no ground truth of the scene.
`viewer.decode` maps it to an expected `restore_psnr` with a calibration measured by `bench decode`.
numpy and OpenCV only."""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from snapshot3d import formats

from . import layout
from .colour import apply_colour

__all__ = ["ideal_marker", "pilot_psnr"]


@lru_cache(maxsize=8)
def ideal_marker(marker_id: int) -> np.ndarray:
    """(MARKER_SIZE, MARKER_SIZE) float32 in {0, 1}: the marker as `sheet` prints it, one pixel per unit."""
    img = cv2.aruco.generateImageMarker(layout.aruco_dictionary(), marker_id, formats.MARKER_SIZE, borderBits=1)
    return img.astype(np.float32) / 255.0


def pilot_psnr(lin: np.ndarray, model: dict, marker_ids) -> float:
    """lin: the rectified sheet (h, w, 3) float32 linear RGB, one pixel per layout unit; model: the
    colour correction (`colour.fit_colour`); marker_ids: the markers found. PSNR (dB) of the corrected
    markers' grey level against their ideal images."""
    x0, y0 = formats.SHEET_BOX[:2]
    corners, n = layout.marker_corners(), formats.MARKER_SIZE
    err = []
    for mid in marker_ids:
        mx, my = int(corners[mid][0, 0]), int(corners[mid][0, 1])
        region = lin[my - y0:my - y0 + n, mx - x0:mx - x0 + n]
        grey = apply_colour(model, region, (mx, my, mx + n, my + n)).astype(np.float32).mean(-1) / 255.0
        err.append(np.mean((grey - ideal_marker(mid)) ** 2))
    return float(10 * np.log10(1.0 / max(float(np.mean(err)), 1e-10)))
