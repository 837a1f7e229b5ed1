"""Visual-hull carving from coverage masks (numpy): a tight scene box and a first occupancy grid.

A voxel is empty when some view sees it (its centre projects inside the image) on background. What
survives every view holds the object, so it is a safe start for empty-space skipping and gives the
planes a box no larger than the object needs.
"""
from __future__ import annotations

import cv2
import numpy as np

from .cameras import project

__all__ = ["carve", "grid_centres", "tight_box"]


def grid_centres(box: np.ndarray, res: int) -> np.ndarray:
    """World-space centres (res, res, res, 3) of a grid over `box` (2, 3), indexed [ix, iy, iz]."""
    t = (np.arange(res) + 0.5) / res
    axes = [box[0, a] + t * (box[1, a] - box[0, a]) for a in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def carve(alpha: np.ndarray, c2w: np.ndarray, intrinsics: np.ndarray, box: np.ndarray, res: int,
          threshold: float = 0.05, margin_px: int = 2, min_views: int = 2) -> np.ndarray:
    """Boolean occupancy (res, res, res) [ix, iy, iz] of voxels that no view sees on background and
    at least `min_views` views see at all (what no camera sees cannot be fitted, so it is dropped).

    alpha: (N, H, W) coverage in [0, 1]; c2w (N, 4, 4) OpenGL; intrinsics (N, 4) (fx, fy, cx, cy).
    Masks are dilated by `margin_px` so that thin parts and calibration error are not carved away.
    """
    n, h, w = alpha.shape
    pts = grid_centres(box, res).reshape(-1, 3)
    keep = np.ones(len(pts), dtype=bool)
    seen = np.zeros(len(pts), dtype=np.int32)
    kernel = np.ones((2 * margin_px + 1, 2 * margin_px + 1), np.uint8)
    for i in range(n):
        fg = cv2.dilate((alpha[i] > threshold).astype(np.uint8), kernel)
        uv, depth = project(pts, c2w[i], *intrinsics[i])
        u = np.floor(uv[:, 0]).astype(np.int64)
        v = np.floor(uv[:, 1]).astype(np.int64)
        inside = (depth > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        seen_bg = np.zeros_like(keep)
        seen_bg[inside] = fg[v[inside], u[inside]] == 0
        keep &= ~seen_bg
        seen += inside
    return (keep & (seen >= min_views)).reshape(res, res, res)


def tight_box(occ: np.ndarray, box: np.ndarray, pad_cells: float = 1.5) -> np.ndarray:
    """The (2, 3) box around the occupied cells of `occ` over `box`, padded by `pad_cells` cells."""
    if not occ.any():
        return box.astype(np.float32)
    res = occ.shape[0]
    idx = np.argwhere(occ)
    cell = (box[1] - box[0]) / res
    lo = box[0] + (idx.min(0) - pad_cells) * cell
    hi = box[0] + (idx.max(0) + 1 + pad_cells) * cell
    return np.stack([np.maximum(lo, box[0]), np.minimum(hi, box[1])]).astype(np.float32)
