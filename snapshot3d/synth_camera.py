"""Cameras of a synthetic capture (`snapshot3d make-capture`): a hand-held walk round the object, OPENCV lens
distortion applied to pinhole renders, exposure jitter and pose noise. numpy + OpenCV.

Pixel convention as in `snapshot3d.cameras` (centres at +0.5); OpenCV's integer centres only inside `distort_maps`.
"""
from __future__ import annotations

import cv2
import numpy as np

from .cameras import look_at
from .errors import UserError

__all__ = ["ELEVATIONS_DEG", "walk_poses", "distort_points", "distort_maps", "expose", "perturb_poses"]

ELEVATIONS_DEG = (8.0, 50.0)  # the walk rises from the first to the second over its two turns
FILL = 0.7                    # the object's bounding sphere spans this fraction of the half-height


def walk_poses(n: int, centre: np.ndarray, radius: float, fy_over_half_h: float, rng: np.random.Generator,
               arc: float = 4 * np.pi):
    """(n, 4, 4) float64 OpenGL c2w: a walk turning `arc` radians round `centre` (two turns by default) from a
    random start, rising through ELEVATIONS_DEG, at a distance that fits a sphere of `radius` in FILL of the
    half-height (fy / (H / 2) given), with hand-held wobble: the distance varies by +-6%, the aim by 3% of the
    radius, the roll by about 1.5 degrees."""
    t = (np.arange(n) + 0.5) / n
    az = rng.uniform(0, 2 * np.pi) + arc * t
    el = np.deg2rad(ELEVATIONS_DEG[0] + (ELEVATIONS_DEG[1] - ELEVATIONS_DEG[0]) * t)
    dist = radius / np.sin(np.arctan(FILL / fy_over_half_h)) * (1 + 0.06 * np.sin(6 * np.pi * t + rng.uniform(0, 6)))
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    out = []
    for i in range(n):
        aim = centre + 0.03 * radius * rng.standard_normal(3)
        c2w = look_at(centre + dist[i] * dirs[i], aim)
        roll = np.deg2rad(1.5 * rng.standard_normal())
        rz = np.array([[np.cos(roll), -np.sin(roll), 0], [np.sin(roll), np.cos(roll), 0], [0, 0, 1]])
        c2w[:3, :3] = c2w[:3, :3] @ rz
        out.append(c2w)
    return np.stack(out)


def distort_points(xy: np.ndarray, coeffs) -> np.ndarray:
    """OpenCV's forward lens model on normalised image points (..., 2) (x right, y down): k1, k2, p1, p2."""
    k1, k2, p1, p2 = (float(c) for c in coeffs)
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    return np.stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                     y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y], -1)


def distort_maps(width: int, height: int, intr, coeffs):
    """Where each pixel of the distorted (written) image looks in a pinhole render with the same (fx, fy, cx, cy):
    returns (map_x, map_y) (H, W) float32 for `cv2.remap` into a render padded by (pad_x, pad_y) pixels on every
    side, and (pad_x, pad_y). The lens is inverted by fixed-point iteration; UserError when it does not converge
    (coefficients that fold the image over)."""
    fx, fy, cx, cy = (float(v) for v in intr)
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    xd = np.stack([(u - cx) / fx, (v - cy) / fy], -1)
    xu = xd.copy()
    with np.errstate(all="ignore"):   # a lens that folds over diverges: refused below
        for _ in range(100):
            xu = xu + (xd - distort_points(xu, coeffs))
        err = np.abs(distort_points(xu, coeffs) - xd).max() * max(fx, fy)
    if not np.isfinite(err) or err > 1e-3:
        raise UserError(f"lens {list(coeffs)}: the distortion cannot be inverted over the frame (it folds over); "
                        "give smaller coefficients")
    px, py = xu[..., 0] * fx + cx, xu[..., 1] * fy + cy   # project convention: centres at +0.5
    pad_x = int(np.ceil(max(0.0, -px.min(), px.max() - width))) + 2
    pad_y = int(np.ceil(max(0.0, -py.min(), py.max() - height))) + 2
    return (px - 0.5 + pad_x).astype(np.float32), (py - 0.5 + pad_y).astype(np.float32), (pad_x, pad_y)


def expose(rgb: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """rgb (..., H, W, 3) float32 sRGB-like in [0, 1] with per-channel `gain` (3,) applied in linear light
    (gamma 2.2), clipped as a sensor clips."""
    lin = np.power(np.clip(rgb, 0.0, 1.0), 2.2) * np.asarray(gain, np.float32)
    return np.power(np.clip(lin, 0.0, 1.0), 1 / 2.2).astype(np.float32)


def perturb_poses(c2w: np.ndarray, centre: np.ndarray, deg: float, frac: float, rng: np.random.Generator):
    """c2w (N, 4, 4) with a random rotation of rms angle `deg` (about the camera centre) and a random shift of
    rms length `frac` times the camera's distance to `centre`. Returns a new float64 array."""
    out = np.array(c2w, np.float64)
    for m in out:
        rv = np.deg2rad(deg) / np.sqrt(3) * rng.standard_normal(3)
        m[:3, :3] = cv2.Rodrigues(rv)[0] @ m[:3, :3]
        m[:3, 3] += frac * np.linalg.norm(m[:3, 3] - centre) / np.sqrt(3) * rng.standard_normal(3)
    return out
