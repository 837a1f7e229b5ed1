"""Geometry of a scan: a robust homography from layout to photo (USAC MAGSAC) and, where the marker
corners allow it, one radial distortion term k1 (numpy and OpenCV).

k1 here is relative to the frame's half-diagonal r0 with the principal point at the frame's centre:
x_d = c + (x_u - c) (1 + k1 |x_u - c|^2 / r0^2)."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .camera import Camera, apply_h, distort, undistort

__all__ = ["Fit", "fit_geometry"]

MIN_POINTS_FOR_K1 = 12   # three markers
K1_RANGE = (-0.4, 0.4)   # searched range of k1 (half-diagonal units)


@dataclass(frozen=True)
class Fit:
    """H: (3, 3) layout -> ideal photo pixels; camera: frame size, centre and k1 (f = half-diagonal)."""

    H: np.ndarray
    camera: Camera
    rms_px: float
    """RMS reprojection error of the marker corners (photo pixels)"""
    inliers: int

    def to_photo(self, pts: np.ndarray) -> np.ndarray:
        return distort(apply_h(self.H, pts), self.camera)


def _camera(w: int, h: int, k1: float) -> Camera:
    return Camera(w, h, f=0.5 * float(np.hypot(w, h)), cx=(w - 1) / 2, cy=(h - 1) / 2, k1=k1)


def _homography_rms(src: np.ndarray, dst_ideal: np.ndarray) -> tuple[np.ndarray, float]:
    H, _ = cv2.findHomography(src, dst_ideal, 0)
    if H is None:
        return None, np.inf
    return H, float(np.sqrt(np.mean(np.sum((apply_h(H, src) - dst_ideal) ** 2, -1))))


def fit_geometry(layout_pts: np.ndarray, photo_pts: np.ndarray, frame: tuple[int, int],
                 with_k1: bool = True, outlier_px: float = 3.0) -> Fit | None:
    """layout_pts, photo_pts: (N, 2) matching points. frame: (width, height) of the photo.

    MAGSAC rejects corners off the homography by more than about `outlier_px` (set it above the bending
    a lens can cause across the sheet); k1 is searched (golden section) when >= MIN_POINTS_FOR_K1 inliers
    remain and kept only when it lowers the RMS error by a quarter and by at least 0.1 px."""
    src = np.asarray(layout_pts, np.float64)
    dst = np.asarray(photo_pts, np.float64)
    if len(src) < 4:
        return None
    H, mask = cv2.findHomography(src, dst, cv2.USAC_MAGSAC, outlier_px, maxIters=2000, confidence=0.999)
    if H is None:
        return None
    inl = mask.ravel().astype(bool)
    src, dst = src[inl], dst[inl]
    w, h = frame
    H0, rms0 = _homography_rms(src, dst)
    best = (0.0, H0, rms0)
    if with_k1 and len(src) >= MIN_POINTS_FOR_K1:
        def cost(k1):
            return _homography_rms(src, undistort(dst, _camera(w, h, k1)))[1]

        a, b = K1_RANGE
        g = (np.sqrt(5) - 1) / 2
        c, d = b - g * (b - a), a + g * (b - a)
        fc, fd = cost(c), cost(d)
        for _ in range(40):
            if fc < fd:
                b, d, fd = d, c, fc
                c = b - g * (b - a)
                fc = cost(c)
            else:
                a, c, fc = c, d, fd
                d = a + g * (b - a)
                fd = cost(d)
        k1 = (a + b) / 2
        Hk, rmsk = _homography_rms(src, undistort(dst, _camera(w, h, k1)))
        if Hk is not None and rmsk < 0.75 * rms0 and rms0 - rmsk > 0.1:
            best = (k1, Hk, rmsk)
    k1, H, _ = best
    cam = _camera(w, h, k1)
    rms = float(np.sqrt(np.mean(np.sum((distort(apply_h(H, src), cam) - dst) ** 2, -1))))
    return Fit(H=H, camera=cam, rms_px=rms, inliers=int(inl.sum()))
