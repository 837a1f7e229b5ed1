"""The pixels that show the ground, found densely (fit --ground-sweep): the sparse points mark the ground where a
feature was matched (`sparse_box.ground_pixels`, about 1% of the pixels); the ground plane they found lets every
training view be compared with its nearest views warped onto it through that plane (the homography a plane
induces between two cameras). Where a patch of the ground is textured, it agrees with its warped neighbours at the
ground's height and not at heights a little over it (a plane sweep round the ground, as multi-view stereo tests
depths); a patch of the object, or of the room behind, agrees at no such height, and a patch without texture
is not counted. Agreement is normalised cross-correlation over a small window, so each frame's exposure does not
count.

Spaces: c2w (N, 4, 4) OpenGL camera-to-world; intrinsics (N, 4) (fx, fy, cx, cy) with pixel centres at +0.5; the
ground plane z = a x + b y + c in world units; images (N, H, W, 3) float32 RGB in [0, 1], undistorted.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["SweepConfig", "plane_homography", "window_stats", "window_ncc", "ground_sweep"]


@dataclass(frozen=True)
class SweepConfig:
    """How the ground is swept. neighbours: how many training cameras each view is compared with, those whose angle
    about the look-at point lies nearest angle_deg (near cameras see too little parallax between the ground and the
    raised planes, far ones too different a view); best: how many of them must agree (the object hides the ground
    from some); window: the correlation's window, pixels; agree: the correlation the best neighbours reach at the
    ground; margin: by how much more than at the raised planes; lift: the raised planes' heights over the ground,
    as shares of the cameras' median distance to the look-at point; texture: the least standard deviation of a
    window's grey levels; border: pixels taken off the found set's edge (a ray next to the object's outline grazes
    its edge; at 1 px the teapot's dark lower rim, which meets the ground, stayed in the set on its frontal arc)."""

    neighbours: int = 4
    angle_deg: float = 20.0
    best: int = 2
    window: int = 7
    agree: float = 0.7
    margin: float = 0.2
    lift: tuple = (0.03, 0.06)
    texture: float = 0.02
    border: int = 3


def plane_homography(c2w_dst, intr_dst, c2w_src, intr_src, plane) -> np.ndarray:
    """The two cameras (OpenGL c2w (4, 4), intrinsics (fx, fy, cx, cy)) and the plane z = a x + b y + c -> (3, 3) H
    that maps a pixel of dst (OpenCV's integer centres) to the pixel of src that sees the same point of the plane:
    each camera's projection (`bundle.projection`) of the plane's points (x, y, 1), the one through the other's
    inverse."""
    from .bundle import projection

    a, b, c = (float(v) for v in plane)
    on_plane = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [a, b, c], [0.0, 0.0, 1.0]])   # (x, y, 1) -> world
    half = np.array([[1.0, 0.0, -0.5], [0.0, 1.0, -0.5], [0.0, 0.0, 1.0]])   # centres at +0.5 -> OpenCV's
    h = half @ projection(c2w_src, intr_src) @ on_plane @ np.linalg.inv(
        half @ projection(c2w_dst, intr_dst) @ on_plane)
    return h / h[2, 2]


def window_stats(x: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """x (H, W) float32 grey image -> (the mean of each pixel's window, its variance), both (H, W)."""
    box = (window, window)
    m = cv2.blur(x, box)
    return m, np.maximum(cv2.blur(x * x, box) - m * m, 0.0)


def window_ncc(x: np.ndarray, y: np.ndarray, window: int,
               x_stats: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """x, y (H, W) float32 grey images -> (normalised cross-correlation of each pixel's window (H, W) in [-1, 1],
    the standard deviation of x's window (H, W)); x_stats: `window_stats(x, window)` when the caller has it
    already (one view against many warps)."""
    box = (window, window)
    mx, vx = window_stats(x, window) if x_stats is None else x_stats
    my, vy = window_stats(y, window)
    cov = cv2.blur(x * y, box) - mx * my
    return cov / np.sqrt(vx * vy + 1e-8), np.sqrt(vx)


def _neighbours(rays: np.ndarray, d: int, cfg: SweepConfig) -> np.ndarray:
    """rays (N, 3) unit directions from the look-at point to the cameras -> the indices of view d's neighbours."""
    angle = np.degrees(np.arccos(np.clip(rays @ rays[d], -1.0, 1.0)))
    angle[d] = np.inf
    return np.argsort(np.abs(angle - cfg.angle_deg))[:cfg.neighbours]


def ground_sweep(images: np.ndarray, c2w: np.ndarray, intrinsics: np.ndarray, plane, centre,
                 cfg: SweepConfig = SweepConfig()) -> np.ndarray:
    """Training frames (module docstring's spaces), the ground plane (a, b, c) and the look-at point centre (3,) ->
    (K, 3) int64 (frame, row, col), the pixels whose window agrees with its neighbours' through the ground plane
    and not through the raised planes (SweepConfig)."""
    c2w = np.asarray(c2w, np.float64)
    n, h, w = images.shape[:3]
    grey = np.stack([cv2.cvtColor(np.ascontiguousarray(im, np.float32), cv2.COLOR_RGB2GRAY) for im in images])
    centres = c2w[:, :3, 3]
    rays = centres - np.asarray(centre, np.float64)
    dist = float(np.median(np.linalg.norm(rays, axis=1)))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    a, b, c = (float(v) for v in plane)
    heights = [0.0] + [s * dist for s in cfg.lift]
    out = []
    for d in range(n):
        near = _neighbours(rays, d, cfg)
        scores = np.full((len(heights), len(near), h, w), -1.0, np.float32)
        stats = window_stats(grey[d], cfg.window)   # the view's own windows, once for all its warps
        texture = np.sqrt(stats[1])
        for j, s in enumerate(near):
            for i, dz in enumerate(heights):
                hm = plane_homography(c2w[d], intrinsics[d], c2w[s], intrinsics[s], (a, b, c + dz))
                warped = cv2.warpPerspective(grey[s], hm, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                             borderValue=-1.0)
                ncc = window_ncc(grey[d], warped, cfg.window, stats)[0]
                inside = cv2.erode((warped >= 0).astype(np.uint8), np.ones((cfg.window,) * 2, np.uint8)) > 0
                scores[i, j] = np.where(inside, ncc, -1.0)
        # the mean of the `best` neighbours at each height (the object hides the ground from some of them)
        top = np.sort(scores, axis=1)[:, -cfg.best:].mean(axis=1)
        found = (top[0] >= cfg.agree) & (top[0] - top[1:].max(axis=0) >= cfg.margin) & (texture >= cfg.texture)
        if cfg.border > 0:
            found = cv2.erode(found.astype(np.uint8), np.ones((2 * cfg.border + 1,) * 2, np.uint8),
                              borderValue=1) > 0
        rows, cols = np.nonzero(found)
        out.append(np.column_stack([np.full(len(rows), d), rows, cols]))
    return np.concatenate(out).astype(np.int64) if out else np.zeros((0, 3), np.int64)
