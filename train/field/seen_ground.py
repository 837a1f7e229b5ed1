"""The rays of pixels that show the ground (fit --seen-ground-weight): where a matched feature of the training photos
lies on the ground (`snapshot3d.sparse_box.ground_pixels`), its pixel's ray crosses the box through empty space
down to it. The planes' opacity along that ray is penalised above `clear` over the ground plane; below it, the
feature may lie on the object's own base (a hoof within the ground's band), where the ray ends inside the box.
A ray whose pixel lies next to the object's outline passes within a texel of its edge, and the penalty wears the
edge away (spot's frontal arc: the held-out views' pixels along the outline lost 1.8 dB, docs/capture.md). With
`fit --seen-ground-spare` the samples in the object's cells as the object-box fit found them
(`box_tighten.object_box`) are spared: the object gains, the floaters that those cells hold stay.

Spaces: the rays are the fit's (q space, `sampler.BoxFrame`); the ground plane z = a x + b y + c is in world units.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from .field import decode, sample_planes
from .sampler import BoxFrame, march

__all__ = ["GroundRays", "Spared", "ground_rays", "clear_opacity"]


@dataclass(frozen=True)
class Spared:
    """cells (G, G, G) bool [ix, iy, iz] over world `box` (2, 3): where the penalty counts no sample. Both on the
    device of the points `holds` is asked about (`ground_rays` puts them there once)."""

    cells: Tensor
    box: Tensor

    def holds(self, world: Tensor) -> Tensor:
        """world points (M, 3) -> (M,) bool, those in a set cell (none outside the box)."""
        cells, box = self.cells, self.box
        g = torch.tensor(cells.shape, device=world.device)
        idx = torch.floor((world - box[0]) / (box[1] - box[0]) * g).long()
        inside = ((idx >= 0) & (idx < g)).all(dim=1)
        idx = torch.minimum(idx.clamp(min=0), g - 1)
        return inside & cells[idx[:, 0], idx[:, 1], idx[:, 2]]


@dataclass(frozen=True)
class GroundRays:
    """index (K,) int64 into the fit's ray bank; the ground plane (a, b, c), world; clear: world units over it;
    spared: the object's cells, or None."""

    index: Tensor
    plane: tuple
    clear: float
    spared: Spared | None = None


def ground_rays(info: dict, height: int, width: int, spare: bool = False, device=None) -> GroundRays | None:
    """posed.info's "ground_pixels" (K, 3) (train frame, row, col), "ground_plane" and "ground_clear" (the sparse
    box's) -> their rays as indices into the fit's ray bank (`rays.make_rays` of the training views, row-major), or
    None when there are none; with `spare`, and "object_cells" over "object_cells_box" in info (`object_box`'s),
    the cells the penalty spares, on `device` (None: the CPU), where the fit's samples are."""
    seen = info.get("ground_pixels")
    if seen is None or not len(seen) or info.get("ground_plane") is None:
        return None
    frame, row, col = (torch.from_numpy(np.asarray(seen, np.int64)[:, k]) for k in range(3))
    cells, spared = info.get("object_cells") if spare else None, None
    if cells is not None and np.any(cells):
        spared = Spared(torch.from_numpy(np.asarray(cells, bool)).to(device),
                        torch.from_numpy(np.asarray(info["object_cells_box"], np.float32)).to(device))
    return GroundRays((frame * height + row) * width + col, tuple(float(v) for v in info["ground_plane"]),
                      float(info["ground_clear"]), spared)


def clear_opacity(planes: Tensor, decoder, frame: BoxFrame, occ: Tensor | None, o: Tensor, d: Tensor, plane,
                  clear: float, generator: torch.Generator | None = None, spared: Spared | None = None) -> Tensor:
    """q-space rays (N, 3), unit dirs -> (N,) the planes' opacity along each ray counting only its samples (jittered)
    higher than `clear` (world units) over the ground plane (a, b, c), and outside the `spared` cells. Differentiable
    in the planes (and the rays, when they are being refined)."""
    s = march(o, d, frame, occ, jitter=True, generator=generator)
    world = s.unit * frame.half_unit * frame.scale + frame.centre
    a, b, c = (float(v) for v in plane)
    keep = (world[:, 2] - a * world[:, 0] - b * world[:, 1] - c) > clear
    if spared is not None:
        keep &= ~spared.holds(world)
    sigma = decode(sample_planes(planes, s.unit[keep]), decoder)[0]
    tau = torch.zeros(s.n_rays, device=o.device, dtype=sigma.dtype).index_add(0, s.ray[keep], sigma * frame.step)
    return 1 - torch.exp(-tau)
