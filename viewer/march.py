"""Where the renderer's samples go (numpy): rays of a camera in the scene box's frame, ray-box
clipping, and for each pixel the interval where its ray becomes opaque, found on a low-resolution
probe image marched through a density grid (no network call); a few samples spread over that
interval are all the network shades.

Frames: world -> q = (world - centre) / scale (scale = largest half-extent) -> unit = q / half_unit in
[-1, 1]^3, the planes' coordinates. Occupancy grids are (G, G, G) bool indexed [ix, iy, iz] over unit
coordinates (as in `train.occupancy`). The sample spacing is the reference renderer's: the box
diagonal (q space) over `formats.RENDER_STEPS_PER_BOX`."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.cameras import pixel_rays

__all__ = ["Frame", "ray_box", "view_rays", "probe_window", "window_samples"]


@dataclass(frozen=True)
class Frame:
    centre: np.ndarray     # (3,)
    scale: float
    half_unit: np.ndarray  # (3,)

    @classmethod
    def from_box(cls, box) -> "Frame":
        box = np.asarray(box, np.float64).reshape(2, 3)
        half = (box[1] - box[0]) / 2
        return cls(centre=(box[0] + box[1]) / 2, scale=float(half.max()), half_unit=half / half.max())

    @property
    def step(self) -> float:
        return 2.0 * float(np.linalg.norm(self.half_unit)) / formats.RENDER_STEPS_PER_BOX


def ray_box(o: np.ndarray, d: np.ndarray, half: np.ndarray):
    """Slab test of q-space rays (N, 3) against [-half, half] -> near, far (N,); a miss has near >= far."""
    with np.errstate(divide="ignore"):
        inv = 1.0 / np.where(np.abs(d) < 1e-9, 1e-9, d)
    t0, t1 = (-half - o) * inv, (half - o) * inv
    return np.maximum(np.minimum(t0, t1).max(1), 0.0), np.maximum(t0, t1).min(1)


def view_rays(c2w: np.ndarray, intr: np.ndarray, width: int, height: int, frame: Frame):
    """q-space rays (H*W, 3) float32 of one OpenGL camera, row-major."""
    o, d = pixel_rays(np.asarray(c2w, np.float64), *[float(x) for x in intr], width, height)
    return ((o - frame.centre) / frame.scale).astype(np.float32), d


def _lookup(occ: np.ndarray, unit: np.ndarray) -> np.ndarray:
    g = occ.shape[0]
    cell = np.clip(((unit + 1.0) * 0.5 * g).astype(np.int32), 0, g - 1)
    return occ[cell[..., 0], cell[..., 1], cell[..., 2]]


def _march_density(o, d, frame: Frame, sigma: np.ndarray, t_lo: float, t_hi: float):
    """Transmittance-based interval of each q-space ray through the density grid (nearest cell):
    t where the transmittance first falls below `t_lo`'s complement (entry) and below `t_hi` (exit);
    entry is inf where the ray never gets dense."""
    near, far = ray_box(o, d, frame.half_unit)
    step = 2.0 * frame.step  # about one grid cell: the grid is read by nearest cell anyway
    n = int(np.ceil(max(float((far - near).max(initial=0.0)), 0.0) / step)) + 1
    t = near[:, None] + (np.arange(n, dtype=np.float32)[None] + 0.5) * step
    tau = _lookup(sigma, (o[:, None] + t[..., None] * d[:, None]) / frame.half_unit) * step
    tau = np.where(t < far[:, None], tau, 0.0)
    trans = np.exp(-np.cumsum(tau, axis=1))
    dense = trans < 1.0 - t_lo
    entry = np.where(dense.any(1), t[np.arange(len(t)), dense.argmax(1)] - step, np.inf)
    opaque = trans < t_hi
    exit_ = np.where(opaque.any(1), t[np.arange(len(t)), opaque.argmax(1)] + step, far)
    return entry, exit_


def probe_window(c2w, intr, width: int, height: int, frame: Frame, sigma: np.ndarray, div: int,
                 margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) interval [lo, hi] of each pixel's ray worth sampling, from a probe image `div` times
    smaller marched through the density grid: the union over a 3x3 neighbourhood of probe pixels,
    widened by `margin` (q units); lo is inf where nothing is dense nearby."""
    pw, ph = -(-width // div), -(-height // div)
    scale = np.array([pw / width, ph / height, pw / width, ph / height])
    o, d = view_rays(c2w, np.asarray(intr) * scale, pw, ph, frame)
    entry, exit_ = _march_density(o, d, frame, sigma, 0.002, 0.01)
    hit = np.isfinite(entry)
    lo = np.where(hit, entry, 1e9).reshape(ph, pw).astype(np.float32)
    hi = np.where(hit, exit_, -1e9).reshape(ph, pw).astype(np.float32)
    k = np.ones((3, 3), np.uint8)
    lo, hi = cv2.erode(lo, k) - margin, cv2.dilate(hi, k) + margin
    lo = np.repeat(np.repeat(lo, div, 0), div, 1)[:height, :width]
    hi = np.repeat(np.repeat(hi, div, 0), div, 1)[:height, :width]
    return np.where(lo >= 1e8, np.inf, lo), hi


def window_samples(o, d, lo, hi, frame: Frame, occ: np.ndarray, samples: int):
    """points (N, S, 3) in unit coordinates and lengths delta (N, S): S midpoint samples spread over
    [lo, hi] (clipped to the box), dropped (delta 0) in empty cells."""
    near, far = ray_box(o, d, frame.half_unit)
    lo, hi = np.maximum(lo, near), np.minimum(hi, far)
    width = np.maximum(hi - lo, 0.0) / samples
    t = lo[:, None] + (np.arange(samples, dtype=np.float32)[None] + 0.5) * width[:, None]
    unit = (o[:, None] + t[..., None] * d[:, None]) / frame.half_unit
    keep = _lookup(occ, unit)
    return np.clip(unit, -1, 1).astype(np.float32), np.where(keep, width[:, None], 0.0).astype(np.float32)
