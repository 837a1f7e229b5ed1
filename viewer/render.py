"""The fast renderer (numpy + the ONNX shading graph): an occupancy grid computed once from the
planes, then for each view a low-resolution probe for where density starts, a short window of
samples per pixel from there, shaded and composited by onnxruntime in bounded chunks.

planes: (3, C, R, R) float32 in [-1, 1]; cameras: c2w (N, 4, 4) OpenGL, intrinsics (N, 4) fx fy cx cy;
views: (N, H, W, 3) float32 RGB in [0, 1] over white."""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from snapshot3d import formats

from .march import Frame, probe_window, view_rays, window_samples

__all__ = ["RenderConfig", "pad_planes", "point_alpha", "density_grid", "render_views"]


@dataclass(frozen=True)
class RenderConfig:
    """Speed/accuracy settings of the fast renderer (charted by `snapshot3d bench decode`)."""

    samples: int = 12
    """samples per pixel, spread over the interval where its ray turns opaque"""
    occ_res: int = formats.OCC_RES
    """occupancy grid cells per axis"""
    probe_div: int = 4
    """the first-hit probe image is this many times smaller than the view"""
    chunk: int = 2048
    """rays per onnxruntime call (bounds memory; small chunks stay in cache and run faster)"""
    workers: int = 0
    """views rendered at once, each by a one-thread session (0: one per core); onnxruntime and most
    numpy work release the GIL, and this beats one view at a time on a multi-threaded session"""

    def n_workers(self) -> int:
        return self.workers or os.cpu_count() or 1


def pad_planes(planes: np.ndarray) -> np.ndarray:
    """(3, C, R, R) -> (3, C_MAX, R, R) float32, zero channels appended (the decoder ignores them)."""
    out = np.zeros((3, formats.C_MAX, *planes.shape[2:]), np.float32)
    out[:, :planes.shape[1]] = planes
    return out


def _shade(sess, planes12, pts, delta):
    rgb, acc = sess.run(None, {"planes": planes12, "points": pts, "delta": delta})
    return rgb, acc


def point_alpha(sess, planes12: np.ndarray, points: np.ndarray, step: float, chunk: int = 1 << 16):
    """alpha (M,) of one step of length `step` at points (M, 3) in unit coordinates, and the density
    (M,) it implies (sigma = -log(1 - alpha) / step)."""
    pts = points.reshape(-1, 1, 3).astype(np.float32)
    alpha = np.concatenate([_shade(sess, planes12, p, np.full((len(p), 1), step, np.float32))[1]
                            for p in np.array_split(pts, max(1, len(pts) // chunk))])
    return alpha, (-np.log1p(-np.minimum(alpha, 1 - 1e-6)) / step).astype(np.float32)


def density_grid(sess, planes12: np.ndarray, frame: Frame, res: int):
    """Density at the cell centres (res, res, res) float32 and the occupancy (bool, cells whose
    one-step alpha exceeds the threshold, dilated by one cell)."""
    c = (np.arange(res, dtype=np.float32) + 0.5) / res * 2 - 1
    alpha, sigma = point_alpha(sess, planes12, np.stack(np.meshgrid(c, c, c, indexing="ij"), -1), frame.step)
    sigma = sigma.reshape(res, res, res)
    occ = (alpha > formats.OCC_ALPHA_THRESHOLD).reshape(res, res, res)
    for ax in range(3):  # separable max filter = 3x3x3 dilation
        occ = occ | np.roll(occ, 1, ax) & _edge(res, ax, 1) | np.roll(occ, -1, ax) & _edge(res, ax, -1)
    return sigma, occ


def _edge(res: int, ax: int, shift: int) -> np.ndarray:
    m = np.ones(res, bool)
    m[0 if shift > 0 else -1] = False  # no wrap-around
    shape = [1, 1, 1]
    shape[ax] = res
    return m.reshape(shape)


def render_views(sess, planes: np.ndarray, box, c2w: np.ndarray, intr: np.ndarray, width: int, height: int,
                 cfg: RenderConfig = RenderConfig(), grids=None, on_view=None) -> np.ndarray:
    """`grids`: (sigma, occ) from `density_grid`, computed here when not given (once per decode)."""
    planes12 = pad_planes(planes)
    frame = Frame.from_box(box)
    sigma, occ = grids if grids is not None else density_grid(sess, planes12, frame, cfg.occ_res)
    margin = 2.0 * float(frame.half_unit.mean()) / cfg.occ_res
    out = np.full((len(c2w), height * width, 3), formats.BACKGROUND, np.float32)

    def one(i):
        o, d = view_rays(c2w[i], intr[i], width, height, frame)
        lo, hi = probe_window(c2w[i], intr[i], width, height, frame, sigma, cfg.probe_div, margin)
        lo, hi = lo.reshape(-1), hi.reshape(-1)
        hit = np.flatnonzero(np.isfinite(lo))
        for j in range(0, len(hit), cfg.chunk):
            idx = hit[j:j + cfg.chunk]
            pts, delta = window_samples(o[idx], d[idx], lo[idx], hi[idx], frame, occ, cfg.samples)
            out[i, idx] = _shade(sess, planes12, pts, delta)[0]
        if on_view is not None:
            on_view(i)

    if cfg.n_workers() > 1 and len(c2w) > 1:
        with ThreadPoolExecutor(cfg.n_workers()) as pool:
            list(pool.map(one, range(len(c2w))))
    else:
        for i in range(len(c2w)):
            one(i)
    return np.clip(out.reshape(len(c2w), height, width, 3), 0, 1)
