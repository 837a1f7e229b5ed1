"""The baked grid as a compact binary for client-side rendering (`GET /v1/scenes/{id}/grid`; the page's
WebGL2 ray marcher reads it). Little-endian, in this order:

- 8 bytes magic `S3DGRID1`;
- uint32 n, then n bytes of UTF-8 JSON: `res` (B), `box` [[x0, y0, z0], [x1, y1, z1]] (world),
  `orbit` {radius, elevation_deg, fov_deg, target}, `logit_range` [lo, hi], `step` (the reference
  sample spacing in the box's normalised frame), `density_clamp`, `background` (1.0: white),
  `world_up`, `layout` ("uint8 rgba, z slowest, then y, then x");
- B * B * B * 4 bytes: per cell (x fastest, then y, then z, as a WebGL 3D texture) r, g, b in
  [0, 255] (value / 255, sRGB as rendered) and a = the density logit quantised linearly over
  `logit_range` (logit = lo + a / 255 * (hi - lo)).

Cell (ix, iy, iz) has its centre at unit coordinates ((i + 0.5) / B * 2 - 1) along each axis; unit
coordinates map to the world through the box (`march.Frame`: centre, scale = the largest half-extent,
half_unit = half-extents / scale). Density at a point is exp(min(logit, density_clamp)) with the logit
interpolated trilinearly; volume rendering as DESIGN 1.1 with distances in the normalised frame
(world / scale)."""
from __future__ import annotations

import json
import struct

import numpy as np

from snapshot3d import formats

__all__ = ["MAGIC", "LOGIT_FLOOR", "encode_grid", "decode_grid"]

MAGIC = b"S3DGRID1"
LOGIT_FLOOR = -10.0
"""logits below this are stored as the floor: exp(-10) is far below any density that shows"""


def encode_grid(grid: np.ndarray, box, orbit, step: float) -> bytes:
    """grid (B, B, B, 4) float32 [ix, iy, iz] (density logit, r, g, b) -> the bytes above."""
    b = grid.shape[0]
    logit = np.clip(grid[..., 0], LOGIT_FLOOR, formats.DENSITY_CLAMP)
    lo, hi = LOGIT_FLOOR, max(float(logit.max()), LOGIT_FLOOR + 1.0)
    a = np.rint((logit - lo) / (hi - lo) * 255)
    rgb = np.rint(np.clip(grid[..., 1:], 0, 1) * 255)
    cells = np.concatenate([rgb, a[..., None]], -1).astype(np.uint8).transpose(2, 1, 0, 3)  # [z, y, x, rgba]
    header = {"res": b, "box": np.asarray(box, float).reshape(2, 3).tolist(),
              "orbit": {"radius": orbit.radius, "elevation_deg": orbit.elevation_deg, "fov_deg": orbit.fov_deg,
                        "target": [float(v) for v in orbit.target]},
              "logit_range": [lo, hi], "step": float(step), "density_clamp": formats.DENSITY_CLAMP,
              "background": formats.BACKGROUND, "world_up": list(formats.WORLD_UP),
              "layout": "uint8 rgba, z slowest, then y, then x"}
    text = json.dumps(header).encode()
    return MAGIC + struct.pack("<I", len(text)) + text + np.ascontiguousarray(cells).tobytes()


def decode_grid(data: bytes) -> tuple[dict, np.ndarray]:
    """The bytes above -> (header, grid (B, B, B, 4) float32 [ix, iy, iz] (logit, r, g, b)); ValueError
    when they are not a grid."""
    if data[:8] != MAGIC or len(data) < 12:
        raise ValueError("not a snapshot3d grid (bad magic)")
    n = struct.unpack("<I", data[8:12])[0]
    try:
        header = json.loads(data[12:12 + n])
        b = int(header["res"])
        lo, hi = (float(v) for v in header["logit_range"])
    except (ValueError, KeyError, TypeError, RecursionError, OverflowError) as e:
        raise ValueError(f"not a snapshot3d grid (header: {type(e).__name__})") from None
    if 12 + n > len(data) or not 1 <= b <= 1024 or not (np.isfinite(lo) and np.isfinite(hi)):
        raise ValueError("not a snapshot3d grid (header out of range)")
    cells = np.frombuffer(data, np.uint8, offset=12 + n)
    if cells.size != b ** 3 * 4:
        raise ValueError(f"grid payload is {cells.size} bytes, expected {b ** 3 * 4}")
    cells = cells.reshape(b, b, b, 4).transpose(2, 1, 0, 3).astype(np.float32)
    return header, np.concatenate([lo + cells[..., 3:] / 255 * (hi - lo), cells[..., :3] / 255], -1)
