"""The field baked into a grid once per decode (numpy + OpenCV + the ONNX project and field graphs), so that
rendering reads a table instead of running the network for every sample (the PlenOctrees / SNeRG
idea, here for a view-independent decoder, where baking loses only interpolation).

Grid: (B, B, B) cells over the unit box [-1, 1]^3, indexed [ix, iy, iz], values at cell centres:
density logit (interpolated, then exp: DVGO's post-activation, which keeps surfaces sharp) and rgb in
[0, 1] (interpolated after the sigmoid). Only cells near the surface run the network: a coarse pass
(B/4 per axis) finds the occupied cells and the opaque interior, and the fine pass evaluates the
occupied cells that are not interior; every other cell keeps its coarse value (nearest).

For trilinear reads with OpenCV, the grid is stored as an atlas: the grid padded by one cell on every
side (edge values, so reads within one cell outside the grid clamp to it), z-slice k a (B + 2, B + 2)
tile, rows iy and columns ix, the tiles side by side in one row. Slice k + 1 is then always B + 2
columns right of slice k, so the two reads of a trilinear sample share one map but for a constant;
`cv2.remap` interpolates inside the two slices and numpy blends them. OpenCV's maps hold coordinates
below 32768, hence at most `MAX_RES` cells per axis."""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.head import apply_head

from .march import Frame

__all__ = ["Baked", "cell_coords", "interp_matrix", "grid_field", "bake_field", "sample_baked", "sample_points",
           "dilate3", "erode3"]

COARSE = 4          # the coarse pass has B / COARSE cells per axis
DENSE_ALPHA = 0.5   # a coarse cell is opaque when one reference step through its centre is this opaque
MAX_RES = 176       # the largest multiple of 8 with (B + 2)^2 atlas columns below 32768


@dataclass(frozen=True)
class Baked:
    grid: np.ndarray    # (B, B, B, 4) float32 [ix, iy, iz]: density logit, r, g, b (`bake_field`'s: a view of atlas)
    sigma: np.ndarray   # (B/2, B/2, B/2) float32 density at the cell centres of the level below, for the probe
    evaluated: int      # network evaluations the bake took (coarse + fine)
    atlas: np.ndarray | None = field(default=None, repr=False)
    """(B + 2, (B + 2)^2, 4) float32, the padded grid (module doc); made from grid when not given"""

    def __post_init__(self):  # once per bake, not per read
        if self.atlas is None:
            object.__setattr__(self, "atlas", _atlas(self.grid))

    @property
    def res(self) -> int:
        return self.grid.shape[0]


def cell_coords(res: int) -> np.ndarray:
    """(res,) float32 unit coordinates of the cell centres along one axis."""
    return ((np.arange(res, dtype=np.float32) + 0.5) / res * 2 - 1).astype(np.float32)


def interp_matrix(coords: np.ndarray, r: int) -> np.ndarray:
    """(B, r) float32 bilinear weights of unit coordinates (B,) over r texels (align_corners, border
    clamp: as `train.field.sample_planes`)."""
    u = np.clip((coords.astype(np.float64) + 1) * 0.5 * (r - 1), 0, r - 1)
    u0 = np.minimum(np.floor(u), r - 2).astype(np.int64)
    m = np.zeros((len(u), r), np.float32)
    np.add.at(m, (np.arange(len(u)), u0), 1 - (u - u0))
    np.add.at(m, (np.arange(len(u)), u0 + 1), u - u0)
    return m


def grid_field(models, planes12: np.ndarray, res: int, cells: np.ndarray, chunk: int = 1 << 16):
    """The field at cell centres of a res^3 grid: cells (M, 3) int [ix, iy, iz] -> density logit (M,),
    rgb (M, 3). One `project` call reads the planes at every grid node; `field` then runs per cell."""
    if len(cells) == 0:
        return np.zeros(0, np.float32), np.zeros((0, 3), np.float32)
    interp = interp_matrix(cell_coords(res), planes12.shape[-1])
    tables = models.project.run(None, {"planes": planes12, "interp": interp})[0]
    rows = np.stack([cells[:, b] * res + cells[:, a] for a, b in formats.PLANE_AXES], 1).astype(np.int64)
    head = getattr(models, "head", None)
    names = ["density_logit", "rgb"] if head is None else ["hidden"]
    outs = [models.field.run(names, {"tables": tables, "rows": rows[i:i + chunk]}) for i in range(0, len(rows), chunk)]
    if head is not None:   # the scene's own last layer on the shared decoder's last hidden layer (snapshot3d.head)
        outs = [apply_head(o[0], head) for o in outs]
    return np.concatenate([o[0] for o in outs]), np.concatenate([o[1] for o in outs])


def _neighbourhood(mask: np.ndarray, op) -> np.ndarray:
    """3x3x3 max (dilate) or min (erode) of a bool grid, the outside counted as False."""
    p = np.pad(mask, 1)
    n = mask.shape[0]
    out = p[1:-1, 1:-1, 1:-1].copy()
    for dx in range(3):
        for dy in range(3):
            for dz in range(3):
                op(out, p[dx:dx + n, dy:dy + n, dz:dz + n], out=out)
    return out


def dilate3(mask: np.ndarray) -> np.ndarray:
    return _neighbourhood(mask, np.logical_or)


def erode3(mask: np.ndarray) -> np.ndarray:
    return _neighbourhood(mask, np.logical_and)


def _atlas(grid: np.ndarray) -> np.ndarray:
    """(B, B, B, K) [ix, iy, iz] -> (B + 2, (B + 2)^2, K): padded slices side by side (see the module doc)."""
    b, k = grid.shape[0] + 2, grid.shape[3]
    padded = np.pad(grid, ((1, 1), (1, 1), (1, 1), (0, 0)), mode="edge")
    return np.ascontiguousarray(padded.transpose(1, 2, 0, 3)).reshape(b, b * b, k)


def _upsample(a: np.ndarray, f: int) -> np.ndarray:
    """(n, n, n, ...) -> (f n, f n, f n, ...), each cell repeated (one copy)."""
    n = a.shape[0]
    b = np.broadcast_to(a[:, None, :, None, :, None], (n, f, n, f, n, f, *a.shape[3:]))
    return b.reshape(n * f, n * f, n * f, *a.shape[3:])


def _block_cells(blocks: np.ndarray, f: int) -> np.ndarray:
    """coarse cells (K, 3) [bx, by, bz] -> their (K f^3, 3) fine cells [ix, iy, iz], block by block and in each
    block y slowest, then z, then x (the atlas' order, `_blocks_view`)."""
    oy, oz, ox = np.unravel_index(np.arange(f ** 3), (f, f, f))
    return (blocks[:, None, :] * f + np.stack([ox, oy, oz], 1)[None]).reshape(-1, 3)


def _blocks_view(a: np.ndarray, f: int) -> np.ndarray:
    """a (n f, n f, n f, ...) [i, j, k] -> a view (n, f, n, f, n, f, ...) [bi, oi, bj, oj, bk, ok] (never a copy)."""
    n = a.shape[0] // f
    return a.reshape(n, f, n, f, n, f, *a.shape[3:], copy=False)


def _fine_atlas(coarse: np.ndarray, blocks: np.ndarray, fine: np.ndarray, f: int) -> np.ndarray:
    """The atlas (module doc) of the grid that is `coarse` (n, n, n, K) [bx, by, bz] repeated f times per axis,
    but for the coarse cells `blocks` (M, 3), whose f^3 fine cells hold `fine` (M, f, f, f, K) [oy, oz, ox],
    written straight into the atlas: no grid, transpose or padding copy in between."""
    n, k = coarse.shape[0], coarse.shape[3]
    b = n * f + 2
    padded = np.empty((b, b, b, k), np.float32)  # [iy + 1, iz + 1, ix + 1]
    inner = _blocks_view(padded[1:-1, 1:-1, 1:-1], f)  # [by, oy, bz, oz, bx, ox]
    inner[...] = coarse.transpose(1, 2, 0, 3)[:, None, :, None, :, None]
    inner[blocks[:, 1], :, blocks[:, 2], :, blocks[:, 0]] = fine
    for axis in range(3):  # edge padding, axis by axis over the whole extent of the others (as np.pad's "edge")
        edge = [slice(None)] * 3
        for dst, src in ((0, 1), (b - 1, b - 2)):
            edge[axis] = dst
            pad = tuple(edge)
            edge[axis] = src
            padded[pad] = padded[tuple(edge)]
    return padded.reshape(b, b * b, k)


def bake_field(models, planes12: np.ndarray, frame: Frame, res: int) -> Baked:
    """Bake the field of planes12 (3, C_MAX, R, R) at res^3 (res a multiple of 2 * COARSE) with the
    renderer's graphs (`runtime.FieldModels`)."""
    if res % (2 * COARSE) or not 2 * COARSE <= res <= MAX_RES:
        raise ValueError(f"bake resolution must be a multiple of {2 * COARSE} from {2 * COARSE} to {MAX_RES}, got {res}")
    nc = res // COARSE
    logit_c, rgb_c = grid_field(models, planes12, nc, np.argwhere(np.ones((nc, nc, nc), bool)))
    alpha = -np.expm1(-np.exp(logit_c) * frame.step).reshape(nc, nc, nc)
    shell = dilate3(alpha > formats.OCC_ALPHA_THRESHOLD) & ~erode3(alpha > DENSE_ALPHA)
    blocks = np.argwhere(shell)
    logit_f, rgb_f = grid_field(models, planes12, res, _block_cells(blocks, COARSE))
    f = (len(blocks), COARSE, COARSE, COARSE)  # [block, oy, oz, ox]
    atlas = _fine_atlas(np.concatenate([logit_c[:, None], rgb_c], 1).reshape(nc, nc, nc, 4), blocks,
                        np.concatenate([logit_f[:, None], rgb_f], 1).reshape(*f, 4), COARSE)
    sigma = _sigma(logit_c.reshape(nc, nc, nc), blocks, logit_f.reshape(f))
    grid = atlas.reshape(res + 2, res + 2, res + 2, 4)[1:-1, 1:-1, 1:-1].transpose(2, 0, 1, 3)
    return Baked(grid, sigma, int(nc ** 3 + len(logit_f)), atlas)


def _sigma(coarse: np.ndarray, blocks: np.ndarray, fine: np.ndarray) -> np.ndarray:
    """`Baked.sigma` of the grid whose density logit is `coarse` (n, n, n) repeated COARSE times per axis but
    for the coarse cells `blocks` (M, 3), which hold `fine` (M, COARSE, COARSE, COARSE) [oy, oz, ox]: the mean
    density over each 2^3 cells, from the logits laid out [ix, iy, iz] in C order (as it was always summed)."""
    logit = _upsample(coarse, COARSE)
    _blocks_view(logit, COARSE)[blocks[:, 0], :, blocks[:, 1], :, blocks[:, 2]] = fine.transpose(0, 3, 1, 2)
    h = logit.shape[0] // 2
    return np.exp(logit).reshape(h, 2, h, 2, h, 2).mean((1, 3, 5), dtype=np.float32)


def sample_baked(baked: Baked, gx: np.ndarray, gy: np.ndarray, gz: np.ndarray):
    """Trilinear read at cell coordinates gx, gy, gz (N, S) each (`march.ray_cells`; cell i's centre
    at i) -> density logit (N, S), rgb (N, S, 3). Coordinates within one cell outside the grid read as
    clamped to it (the renderer's stay inside the box); N < 32767, OpenCV's map limit."""
    b = np.float32(baked.res + 2)  # tile width: slice k + 1 starts this many columns right of slice k
    fz = np.clip(gz, -1.0, baked.res - 1e-3, dtype=np.float32)
    fz += 1.0                      # the padded slice coordinate
    mx = np.floor(fz)
    fz -= mx                       # the weight of the upper slice
    mx *= b
    mx += gx
    mx += 1.0                      # the lower slice's atlas column
    my = gy + np.float32(1.0)
    lo = cv2.remap(baked.atlas, mx, my, cv2.INTER_LINEAR)
    mx += b
    v = cv2.remap(baked.atlas, mx, my, cv2.INTER_LINEAR)
    v -= lo
    v *= fz[..., None]
    v += lo
    return v[..., 0], v[..., 1:]


def sample_points(baked: Baked, unit: np.ndarray, width: int = 1024):
    """sample_baked at any number of points (M, 3) in unit coordinates -> logit (M,), rgb (M, 3)."""
    m = len(unit)
    cells = np.clip((unit + 1.0) * (0.5 * baked.res) - 0.5, 0.0, baked.res - 1.0, dtype=np.float32)
    cells = np.pad(cells, ((0, (-m) % width), (0, 0)))
    logit, rgb = sample_baked(baked, *(cells[:, k].reshape(-1, width) for k in range(3)))
    return logit.reshape(-1)[:m], rgb.reshape(-1, 3)[:m]
