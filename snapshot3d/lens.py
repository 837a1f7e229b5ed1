"""Lens distortion of a capture undone on load (OpenCV), keeping a pinhole camera with the same focal length
and principal point, so that the loaders hand out exact pinhole cameras.

Camera models are named as COLMAP and nerfstudio name them. Principal points follow the project's convention
(pixel centres at +0.5, as COLMAP and nerfstudio); OpenCV puts pixel centres at integers, so they are shifted by
half a pixel on the way in.
"""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from .errors import UserError

__all__ = ["MODELS", "check_model", "lens_coeffs", "undistort"]

# model -> the distortion coefficients it reads (in that order); all are pinhole once undone
MODELS = {"PINHOLE": (), "SIMPLE_PINHOLE": (), "SIMPLE_RADIAL": ("k1",), "RADIAL": ("k1", "k2"),
          "OPENCV": ("k1", "k2", "p1", "p2", "k3"), "OPENCV_FISHEYE": ("k1", "k2", "k3", "k4")}


def check_model(name, where: str) -> str:
    """The model's name in capitals, or a UserError naming the ones that are read."""
    if not isinstance(name, str) or name.upper() not in MODELS:
        raise UserError(f"{where}: camera model {str(name)[:40]!r} is not supported (one of {', '.join(MODELS)})")
    return name.upper()


def lens_coeffs(model: str, values: dict) -> np.ndarray:
    """OpenCV's coefficient vector of `model` from named values (missing ones are 0): (k1, k2, p1, p2, k3)
    for the perspective models, (k1, k2, k3, k4) for OPENCV_FISHEYE; all zeros when there is no distortion."""
    if model == "OPENCV_FISHEYE":
        return np.array([values.get(k, 0.0) for k in ("k1", "k2", "k3", "k4")], np.float64)
    return np.array([values.get(k, 0.0) if k in MODELS[model] else 0.0 for k in ("k1", "k2", "p1", "p2", "k3")],
                    np.float64)


def undistort(image: np.ndarray, fx: float, fy: float, cx: float, cy: float, model: str,
              coeffs: np.ndarray) -> np.ndarray:
    """`image` (H, W) or (H, W, C) float32 seen through the lens -> the same size as a pinhole camera with the
    same (fx, fy, cx, cy). Corners the lens did not see repeat the nearest edge pixel."""
    if not np.any(coeffs):
        return image
    h, w = image.shape[:2]
    m1, m2 = _maps(w, h, float(fx), float(fy), float(cx), float(cy), model, tuple(float(c) for c in coeffs))
    return cv2.remap(np.ascontiguousarray(image), m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


@lru_cache(maxsize=2)
def _maps(w: int, h: int, fx: float, fy: float, cx: float, cy: float, model: str, coeffs: tuple):
    """OpenCV's (H, W) float32 undistortion maps of one camera, made once for every frame (and mask) it shares."""
    k = np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1]], np.float64)
    c = np.array(coeffs, np.float64)
    if model == "OPENCV_FISHEYE":
        m1, m2 = cv2.fisheye.initUndistortRectifyMap(k, c.reshape(4, 1), np.eye(3), k, (w, h), cv2.CV_32FC1)
    else:
        m1, m2 = cv2.initUndistortRectifyMap(k, c, None, k, (w, h), cv2.CV_32FC1)
    if not (np.isfinite(m1).all() and np.isfinite(m2).all()):
        raise UserError(f"the {model} coefficients {np.round(c, 4).tolist()} do not map the image (the lens "
                        "model folds over): check them")
    return m1, m2
