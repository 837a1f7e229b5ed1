"""The rays that see the object, without masks (fit --object-rays): the object-box fit's cells
(`box_tighten.object_box`, the object's cells of a short fit without the penalty) projected into each training
view and grown by GROW_PX. A fit given masks draws `fg_fraction` of each batch from the rays its masks cover; with
this set a fit without masks can do the same, so the object's pixels, its outline among them, get as many rays as
in the masked fit instead of their share of the frame. Spaces: cells (G, G, G) [ix, iy, iz] over a world box;
cameras OpenGL c2w, intrinsics (fx, fy, cx, cy) of the undistorted frames."""
from __future__ import annotations

import cv2
import numpy as np

from snapshot3d.cameras import project
from snapshot3d.carve import grid_centres

__all__ = ["GROW_PX", "object_pixels", "object_ray_index"]

GROW_PX = 2   # the projected cells grown by this many pixels: the outline's own pixels and the holes between cells


def object_pixels(cells: np.ndarray, box: np.ndarray, c2w: np.ndarray, intrinsics: np.ndarray, height: int,
                  width: int, grow: int = GROW_PX) -> np.ndarray:
    """cells (G, G, G) bool over world `box` (2, 3); c2w (N, 4, 4), intrinsics (N, 4) -> (N, H, W) bool: the
    pixels onto which a set cell's centre projects (in front of the camera), grown by `grow` pixels."""
    centres = grid_centres(np.asarray(box, np.float64), cells.shape[0])[np.asarray(cells, bool)]
    out = np.zeros((len(c2w), height, width), bool)
    kernel = np.ones((2 * grow + 1,) * 2, np.uint8)
    for i, (pose, k) in enumerate(zip(c2w, intrinsics)):
        uv, depth = project(centres, np.asarray(pose, np.float64), *[float(v) for v in k])
        uv = np.floor(uv[depth > 0]).astype(np.int64)   # pixel centres at +0.5: the pixel a point falls in
        ok = (uv[:, 0] >= 0) & (uv[:, 0] < width) & (uv[:, 1] >= 0) & (uv[:, 1] < height)
        hit = np.zeros((height, width), np.uint8)
        hit[uv[ok, 1], uv[ok, 0]] = 1
        out[i] = cv2.dilate(hit, kernel) > 0 if grow > 0 else hit > 0
    return out


def object_ray_index(cells: np.ndarray, box: np.ndarray, c2w: np.ndarray, intrinsics: np.ndarray, height: int,
                     width: int, grow: int = GROW_PX) -> np.ndarray:
    """`object_pixels` of the training views in the ray bank's order -> (K,) int64 indices into the bank
    (`rays.make_rays`: view by view, row-major)."""
    return np.flatnonzero(object_pixels(cells, box, c2w, intrinsics, height, width, grow).reshape(-1))
