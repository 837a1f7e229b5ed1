"""ArUco marker detection (OpenCV 5 `cv2.aruco.ArucoDetector`) and sub-pixel corner refinement.

Corners are (N, 4, 2) float32 pixel coordinates (pixel centres at integers), clockwise from each
marker's own top-left, as OpenCV returns them; ids are (N,) int32."""
from __future__ import annotations

import cv2
import numpy as np

from snapshot3d import formats

from .layout import aruco_dictionary

__all__ = ["make_detector", "detect_markers", "refine_corners", "to_gray"]


def to_gray(img: np.ndarray) -> np.ndarray:
    """(H, W) uint8 grey from (H, W) grey or (H, W, 3) uint8 **BGR**."""
    if img.dtype != np.uint8:
        raise ValueError(f"expected uint8, got {img.dtype}")
    return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


def make_detector(dictionary=formats.ARUCO_DICT, subpix: bool = False) -> cv2.aruco.ArucoDetector:
    """An ArucoDetector for a predefined dictionary name or a `cv2.aruco.Dictionary`.

    subpix: OpenCV's own sub-pixel corner refinement (for small images scanned at full resolution)."""
    d = aruco_dictionary(dictionary) if isinstance(dictionary, str) else dictionary
    p = cv2.aruco.DetectorParameters()
    if subpix:
        p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        p.cornerRefinementWinSize = 3
    return cv2.aruco.ArucoDetector(d, p)


def detect_markers(image: np.ndarray, dictionary=formats.ARUCO_DICT, subpix: bool = True,
                   detector: cv2.aruco.ArucoDetector | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Find markers of `dictionary` in an (H, W) grey or (H, W, 3) uint8 BGR image.

    Returns ids (N,) int32 and corners (N, 4, 2) float32 in pixels of `image`."""
    det = detector or make_detector(dictionary, subpix=subpix)
    corners, ids, _ = det.detectMarkers(to_gray(image))
    if ids is None or len(ids) == 0:
        return np.zeros((0,), np.int32), np.zeros((0, 4, 2), np.float32)
    return np.asarray(ids, np.int32).reshape(-1), np.asarray(corners, np.float32).reshape(-1, 4, 2)


def refine_corners(image_bgr: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Refine approximate marker corners (N, 4, 2) at the full resolution of `image_bgr` (H, W, 3) uint8
    BGR with `cv2.cornerSubPix`, one small grey window per corner (no full-frame conversion).

    The search half-window is 0.5 of the white gap between a marker and the snapshot (the nearest other
    ink; a marker's border cell, 13 units, is wider than that gap, 8 units)."""
    out = corners.astype(np.float32).copy()
    h, w = image_bgr.shape[:2]
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
    for m, quad in enumerate(corners):
        side = min(np.linalg.norm(quad[i] - quad[(i + 1) % 4]) for i in range(4))
        win = int(np.clip(0.5 * formats.MARKER_GAP * side / formats.MARKER_SIZE, 2, 20))
        for i, (x, y) in enumerate(quad):
            r = win + 3
            x0, y0 = int(round(x)) - r, int(round(y)) - r
            if x0 < 0 or y0 < 0 or x0 + 2 * r + 1 > w or y0 + 2 * r + 1 > h:
                continue  # too close to the frame's edge to refine
            patch = cv2.cvtColor(image_bgr[y0:y0 + 2 * r + 1, x0:x0 + 2 * r + 1], cv2.COLOR_BGR2GRAY)
            pt = np.array([[[x - x0, y - y0]]], np.float32)
            cv2.cornerSubPix(patch, pt, (win, win), (-1, -1), crit)
            if np.all(np.isfinite(pt)) and np.hypot(*(pt[0, 0] - (x - x0, y - y0))) < win:
                out[m, i] = pt[0, 0] + (x0, y0)
    return out
