"""The box of a capture without masks, found from its cameras (`--box auto`, the default of fit --background
outer): a cube round the point nearest all optical axes (`box_from_cameras`' centre), as large as the
sphere that most views hold whole in their frame. A walk round an object keeps it in the frame of every view, so
this is the largest object the capture can have filmed whole; the floor under it is cut away later from the
fitted density (`train/field/box_tighten.py`). numpy, no torch."""
from __future__ import annotations

import numpy as np

__all__ = ["box_from_cameras", "overlap_box", "frustum_margins", "OVERLAP_SHARE"]

OVERLAP_SHARE = 0.9   # the sphere lies inside the frame of this share of the views


def box_from_cameras(c2w: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Cube around the point closest to all optical axes, `scale` times half the median camera distance wide."""
    o, d = c2w[:, :3, 3].astype(np.float64), -c2w[:, :3, 2].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    proj = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    centre = np.linalg.lstsq(proj.sum(0), np.einsum("nij,nj->i", proj, o), rcond=None)[0]
    half = 0.5 * scale * np.median(np.linalg.norm(o - centre, axis=1))
    return np.stack([centre - half, centre + half]).astype(np.float32)


def frustum_margins(point: np.ndarray, c2w: np.ndarray, intrinsics: np.ndarray, width: int, height: int) -> np.ndarray:
    """World distance (N,) from `point` (3,) to the nearest side plane of each camera's frustum: positive inside,
    negative outside or behind. c2w (N, 4, 4) OpenGL camera-to-world; intrinsics (N, 4) (fx, fy, cx, cy) in pixels
    with `width` x `height` images."""
    c2w = np.asarray(c2w, np.float64)
    p = np.einsum("nji,nj->ni", c2w[:, :3, :3], np.asarray(point, np.float64)[None] - c2w[:, :3, 3])
    x, y, depth = p[:, 0], p[:, 1], -p[:, 2]          # OpenGL: the camera looks down -z, y up
    fx, fy, cx, cy = (np.asarray(intrinsics, np.float64)[:, k] for k in range(4))
    sides = []
    for a, coord, f in ((cx / fx, x, 1), ((width - cx) / fx, x, -1), ((height - cy) / fy, y, 1), (cy / fy, y, -1)):
        sides.append((a * depth + f * coord) / np.sqrt(1 + a * a))   # x >= -a z', x <= a z', likewise y
    return np.where(depth > 0, np.min(sides, axis=0), -np.inf)


def overlap_box(c2w: np.ndarray, intrinsics: np.ndarray, width: int, height: int,
                share: float = OVERLAP_SHARE) -> np.ndarray:
    """(2, 3) float32 world box: a cube round the cameras' look-at point whose half-size is the radius of the
    sphere inside the frame of `share` of the views. UserError-free: a look-at point that few views hold falls
    back to `box_from_cameras`."""
    cube = box_from_cameras(c2w)
    centre = cube.mean(0).astype(np.float64)
    margins = frustum_margins(centre, c2w, intrinsics, width, height)
    radius = float(np.quantile(margins, 1 - share))
    if not np.isfinite(radius) or radius <= 0:
        return cube
    return np.stack([centre - radius, centre + radius]).astype(np.float32)
