"""The fast renderer (numpy + OpenCV + the ONNX field graphs): the field baked into a grid once per
decode (`viewer.bake`), then for each view a low-resolution probe for where density starts and a
window of samples per pixel from there, read from the baked grid by trilinear interpolation and
composited in numpy in cache-sized chunks. The network never runs per sample.

planes: (3, C, R, R) float32 in [-1, 1]; cameras: c2w (N, 4, 4) OpenGL, intrinsics (N, 4) fx fy cx cy;
views: (N, H, W, 3) float32 RGB in [0, 1] over white."""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from snapshot3d import formats

from .bake import Baked, bake_field, sample_baked
from .march import Frame, clip_window, probe_window, ray_cells, view_rays

__all__ = ["RenderConfig", "pad_planes", "composite", "render_views"]


@dataclass(frozen=True)
class RenderConfig:
    """Speed/accuracy settings of the fast renderer (charted by `snapshot3d bench decode`)."""

    samples: int = 16
    """samples per pixel, spread over the interval where its ray turns opaque"""
    bake: int = 96
    """cells per axis of the baked field (a multiple of 8)"""
    probe_div: int = 4
    """the first-hit probe image is this many times smaller than the view"""
    chunk: int = 2048
    """rays per batch (bounds memory; batches that stay in cache run fastest)"""
    workers: int = 0
    """views rendered at once, one thread each (0: one per core); OpenCV and most numpy work release
    the GIL"""

    def n_workers(self) -> int:
        return self.workers or os.cpu_count() or 1


def pad_planes(planes: np.ndarray) -> np.ndarray:
    """(3, C, R, R) -> (3, C_MAX, R, R) float32, zero channels appended (the decoder ignores them)."""
    out = np.zeros((3, formats.C_MAX, *planes.shape[2:]), np.float32)
    out[:, :planes.shape[1]] = planes
    return out


def composite(logit: np.ndarray, rgb: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Volume rendering (DESIGN 1.1) of (N, S) density logits and (N, S, 3) colours with lengths delta
    (N, S) or (N, 1) -> (N, 3) over the white background. Weight i is T_i - T_{i+1} (transmittance
    before and after sample i), which is T_i (1 - exp(-tau_i))."""
    after = np.minimum(logit, formats.DENSITY_CLAMP)  # then, in place (one buffer): tau, optical depth,
    np.exp(after, out=after)                          # transmittance after each sample
    after *= delta
    np.cumsum(after, axis=1, out=after)
    np.exp(np.negative(after, out=after), out=after)
    w = np.empty_like(after)
    np.subtract(1.0, after[:, 0], out=w[:, 0])
    np.subtract(after[:, :-1], after[:, 1:], out=w[:, 1:])
    out = np.matmul(w[:, None, :], rgb)[:, 0]
    out += after[:, -1:] * np.float32(formats.BACKGROUND)
    return out


def _baked_colour(baked: Baked, o, d, lo, hi, frame: Frame, samples: int) -> np.ndarray:
    """(N, 3) colours of rays from o (1, 3) along d (N, 3), from `samples` reads spread over their
    windows [lo, hi] (N,), already clipped to the box (`clip_window`)."""
    width = np.maximum(hi - lo, 0.0) / samples
    t = lo[:, None] + (np.arange(samples, dtype=np.float32)[None] + 0.5) * width[:, None]
    a, b = ray_cells(o, d, frame, baked.res)
    logit, rgb = sample_baked(baked, *(a[:, k:k + 1] + t * b[:, k:k + 1] for k in range(3)))
    return composite(logit, rgb, width[:, None])


def render_views(models, planes: np.ndarray, box, c2w: np.ndarray, intr: np.ndarray, width: int, height: int,
                 cfg: RenderConfig = RenderConfig(), baked: Baked | None = None, on_view=None) -> np.ndarray:
    """`models`: `runtime.FieldModels`; `baked` from `bake_field`, computed here when not given (once
    per decode). The first view is split over the workers; the rest go `workers` at a time."""
    frame = Frame.from_box(box)
    baked = baked if baked is not None else bake_field(models, pad_planes(planes), frame, cfg.bake)
    margin = 2.0 * float(frame.half_unit.mean()) / baked.sigma.shape[0]
    out = np.full((len(c2w), height * width, 3), formats.BACKGROUND, np.float32)

    def shade(i, o, d, lo, hi, idx):
        out[i, idx] = _baked_colour(baked, o, d[idx], lo[idx], hi[idx], frame, cfg.samples)

    def view(i, pool=None):
        o, d = view_rays(c2w[i], intr[i], width, height, frame)
        lo, hi = probe_window(c2w[i], intr[i], width, height, frame, baked.sigma, cfg.probe_div, margin)
        lo, hi = lo.reshape(-1), hi.reshape(-1)
        hit = np.flatnonzero(np.isfinite(lo))
        lo[hit], hi[hit] = clip_window(o, d[hit], lo[hit], hi[hit], frame)  # once per view, not per chunk
        chunks = [hit[j:j + cfg.chunk] for j in range(0, len(hit), cfg.chunk)]
        list((pool.map if pool is not None else map)(lambda idx: shade(i, o, d, lo, hi, idx), chunks))
        if on_view is not None:
            on_view(i)

    if cfg.n_workers() > 1 and len(c2w) > 0:
        with ThreadPoolExecutor(cfg.n_workers()) as pool:
            view(0, pool)  # the first view's chunks on all workers: it shows as early as possible
            list(pool.map(view, range(1, len(c2w))))
    else:
        for i in range(len(c2w)):
            view(i)
    return np.clip(out.reshape(len(c2w), height, width, 3), 0, 1)
