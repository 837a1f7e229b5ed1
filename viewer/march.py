"""Where the renderer's samples go (numpy): rays of a camera in the scene box's frame, ray-box
clipping, and for each pixel the interval where its ray becomes opaque, found on a low-resolution
probe image marched through a density grid; a few samples spread over that interval are all the
renderer reads.

Frames: world -> q = (world - centre) / scale (scale = largest half-extent) -> unit = q / half_unit in
[-1, 1]^3, the planes' coordinates. Grids are (G, G, G) indexed [ix, iy, iz] over unit coordinates,
values at cell centres. `Frame.step` is the reference renderer's sample spacing: the box diagonal
(q space) over `formats.RENDER_STEPS_PER_BOX`."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from snapshot3d import formats
from snapshot3d.cameras import pixel_rays

__all__ = ["Frame", "ray_box", "view_rays", "ray_cells", "probe_window", "clip_window"]


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
    half = np.asarray(half, d.dtype)  # float32 rays stay float32 (half the memory traffic)
    with np.errstate(divide="ignore"):
        inv = 1 / np.where(np.abs(d) < 1e-9, d.dtype.type(1e-9), d)
    t0, t1 = (-half - o) * inv, (half - o) * inv
    lo, hi = np.minimum(t0, t1), np.maximum(t0, t1)  # per axis; then across the three columns (a reduction
    near = np.maximum(np.maximum(lo[:, 0], lo[:, 1]), np.maximum(lo[:, 2], 0.0))  # over axis 1 of
    return near, np.minimum(np.minimum(hi[:, 0], hi[:, 1]), hi[:, 2])             # width 3 is 20x slower)


@lru_cache(maxsize=8)
def _camera_dirs(fx: float, fy: float, cx: float, cy: float, width: int, height: int) -> np.ndarray:
    """unit ray directions (H*W, 3) in camera axes (`cameras.pixel_rays` with the identity pose)."""
    return pixel_rays(np.eye(4), fx, fy, cx, cy, width, height)[1]


_BLAS_ROWS = 16384
"""rows per product of ray directions and a rotation: 16384 x 3 x 3 is below OpenBLAS's threading threshold
(4 x 65536), so each part runs on the calling thread, with the same numbers as one product. One threaded
product of a whole 380x380 view takes 0.2 ms on an idle machine but waited up to 110-170 ms for its second
thread on the shared 2 cores (issue 39)"""


def view_rays(c2w: np.ndarray, intr: np.ndarray, width: int, height: int, frame: Frame):
    """q-space rays of one OpenGL camera: its centre (1, 3) (every ray's origin) and unit directions
    (H*W, 3) float32, row-major."""
    c2w = np.asarray(c2w, np.float64)
    dirs, rot = _camera_dirs(*[float(x) for x in intr], width, height), c2w[:3, :3].T.astype(np.float32)
    d = np.empty_like(dirs)
    for i in range(0, len(dirs), _BLAS_ROWS):
        np.matmul(dirs[i:i + _BLAS_ROWS], rot, out=d[i:i + _BLAS_ROWS])
    return ((c2w[:3, 3] - frame.centre) / frame.scale).astype(np.float32).reshape(1, 3), d


def ray_cells(o: np.ndarray, d: np.ndarray, frame: Frame, res: int):
    """q-space rays (origins (N or 1, 3), directions (N, 3)) -> a, b (same shapes) float32 such that
    a + t b are the cell coordinates of the ray's point at t in a res^3 grid over the unit box (cell
    i's centre at coordinate i)."""
    s = 0.5 * res / frame.half_unit
    return (o * s + (0.5 * res - 0.5)).astype(np.float32), (d * s).astype(np.float32)


def _nearest(grid: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """grid (G, G, G) read at the nearest cells of cell coordinates (..., 3)."""
    g = grid.shape[0]
    c = np.clip(np.rint(cells), 0, g - 1).astype(np.int32)
    return grid.reshape(-1)[(c[..., 0] * g + c[..., 1]) * g + c[..., 2]]


def _march_density(o, d, frame: Frame, sigma: np.ndarray, t_lo: float, t_hi: float, chunk: int = 1024):
    """Transmittance-based interval of each q-space ray through the density grid (nearest cell):
    t where the transmittance first falls below `t_lo`'s complement (entry) and below `t_hi` (exit);
    entry is inf where the ray never gets dense. o (1, 3) is the camera centre, d (N, 3). Only rays
    that meet the box march, `chunk` at a time (cache-sized arrays) in order of their length inside
    it, so that each chunk's steps fit its own rays rather than the longest of all."""
    near, far = ray_box(o, d, frame.half_unit)
    entry, exit_ = np.full(len(d), np.inf, np.float32), far.astype(np.float32)
    inside = np.flatnonzero(far > near)
    inside = inside[np.argsort(far[inside] - near[inside], kind="stable")]
    for i in range(0, len(inside), chunk):
        rays = inside[i:i + chunk]
        entry[rays], exit_[rays] = _march_chunk(o, d[rays], near[rays], far[rays], frame, sigma, t_lo, t_hi)
    return entry, exit_


def _march_chunk(o, d, near, far, frame: Frame, sigma: np.ndarray, t_lo: float, t_hi: float):
    """`_march_density` of rays (N, 3) that meet the box, between near and far (N,)."""
    step = 2.0 * frame.step  # about one grid cell: the grid is read by nearest cell anyway
    n = int(np.ceil(float((far - near).max()) / step)) + 1
    t = near[:, None] + (np.arange(n, dtype=np.float32)[None] + 0.5) * np.float32(step)
    a, b = ray_cells(o, d, frame, sigma.shape[0])
    tau = _nearest(sigma, a[:, None] + t[..., None] * b[:, None]) * np.float32(step)
    tau[t >= far[:, None]] = 0.0
    optical = np.cumsum(tau, axis=1)  # compared with -log of the transmittance thresholds
    dense, opaque = optical > -np.log1p(-t_lo), optical > -np.log(t_hi)
    rows = np.arange(len(d))
    entry = np.where(dense.any(1), t[rows, dense.argmax(1)] - step, np.inf)
    exit_ = np.where(opaque.any(1), t[rows, opaque.argmax(1)] + step, far)
    return entry, exit_


def probe_window(c2w, intr, width: int, height: int, frame: Frame, sigma: np.ndarray, div: int,
                 margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) interval [lo, hi] of each pixel's ray worth sampling, from a probe image `div` times
    smaller marched through the density grid: the union over the 2x2 probe pixels whose centres
    surround the pixel's centre, widened by `margin` (q units); lo is inf where nothing is dense nearby."""
    pw, ph = -(-width // div), -(-height // div)
    scale = np.array([pw / width, ph / height, pw / width, ph / height])
    o, d = view_rays(c2w, np.asarray(intr) * scale, pw, ph, frame)
    entry, exit_ = _march_density(o, d, frame, sigma, 0.002, 0.01)
    hit = np.isfinite(entry)
    lo = np.where(hit, entry, 1e9).reshape(ph, pw).astype(np.float32)
    hi = np.where(hit, exit_, -1e9).reshape(ph, pw).astype(np.float32)
    lo, hi = _pairs(np.pad(lo, 1, mode="edge"), np.minimum) - margin, _pairs(np.pad(hi, 1, mode="edge"), np.maximum) + margin
    iy, ix = (_surrounding(n, div) for n in (height, width))  # pixel -> its 2x2 block's (bottom, right) probe
    lo, hi = lo[iy[:, None], ix[None]], hi[iy[:, None], ix[None]]
    return np.where(lo >= 1e8, np.inf, lo), hi


def _pairs(a: np.ndarray, op) -> np.ndarray:
    """(h + 1, w + 1) over every 2x2 block of a (h + 2, w + 2) image: out[i, j] = op of a[i:i+2, j:j+2]."""
    return op(op(a[:-1, :-1], a[1:, :-1]), op(a[:-1, 1:], a[1:, 1:]))


def _surrounding(n: int, div: int) -> np.ndarray:
    """for each of n full-resolution pixels, the index into `_pairs` of the two probe pixels around it"""
    return ((np.arange(n) + 0.5) / div + 0.5).astype(np.int64)


def clip_window(o, d, lo, hi, frame: Frame):
    """[lo, hi] (N,) intersected with each ray's span inside the box."""
    near, far = ray_box(o, d, frame.half_unit)
    return np.maximum(lo, near), np.minimum(hi, far)
