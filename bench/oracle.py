"""What a perfect scanner could add (numpy and OpenCV): a capture re-registered and re-toned against the
snapshot that was really sent. Used by `bench capacity` to tell the scanner's residual errors (which an
oracle removes) from the print-and-photo noise (which nothing removes).

Images: (H, W, 3) uint8 RGB, the same size.
"""
from __future__ import annotations

import cv2
import numpy as np

__all__ = ["oracle_register", "oracle_tone", "oracle_correct"]


def oracle_register(seen: np.ndarray, sent: np.ndarray) -> np.ndarray:
    """`seen` warped onto `sent` by the homography ECC finds between their greys (float32 RGB, 0..255);
    `seen` unchanged when ECC does not converge."""
    a = cv2.cvtColor(sent, cv2.COLOR_RGB2GRAY).astype(np.float32) / 255.0
    b = cv2.cvtColor(seen, cv2.COLOR_RGB2GRAY).astype(np.float32) / 255.0
    warp = np.eye(3, dtype=np.float32)
    try:
        _, warp = cv2.findTransformECC(a, b, warp, cv2.MOTION_HOMOGRAPHY,
                                       (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-6), None, 1)
    except cv2.error:
        return seen.astype(np.float32)
    h, w = seen.shape[:2]
    return cv2.warpPerspective(seen.astype(np.float32), warp, (w, h), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_REFLECT)


def oracle_tone(seen: np.ndarray, sent: np.ndarray) -> np.ndarray:
    """Per channel, the least-squares fit of `sent` by a quadratic in the seen value whose gain and offset vary
    smoothly over the image (a tone curve plus shading): (H, W, 3) float, 0..255."""
    h, w, _ = seen.shape
    yy, xx = (np.mgrid[0:h, 0:w].astype(np.float64) / max(h, w) - 0.5).reshape(2, -1)
    out = np.empty((h, w, 3))
    for c in range(3):
        v = seen[..., c].reshape(-1).astype(np.float64) / 255.0
        design = np.stack([v, v * xx, v * yy, v * v, np.ones_like(v), xx, yy, xx * xx, yy * yy, xx * yy], 1)
        coef = np.linalg.lstsq(design, sent[..., c].reshape(-1) / 255.0, rcond=None)[0]
        out[..., c] = (design @ coef).reshape(h, w) * 255.0
    return out


def oracle_correct(seen: np.ndarray, sent: np.ndarray) -> np.ndarray:
    """Registration then tone against the sent snapshot -> (H, W, 3) uint8 RGB."""
    return np.clip(oracle_tone(oracle_register(seen, sent), sent) + 0.5, 0, 255).astype(np.uint8)
