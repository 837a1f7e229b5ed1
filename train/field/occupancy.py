"""Occupancy grid for empty-space skipping, updated from the density being learned (NerfAcc's
OccGridEstimator idea): an exponential moving maximum of density per cell, thresholded on the alpha
of one marching step, and never outside the visual hull when one is known."""
from __future__ import annotations

import torch
from torch import Tensor, nn

from snapshot3d import formats

__all__ = ["OccupancyGrid"]


class OccupancyGrid(nn.Module):
    """Cells (G, G, G) indexed [ix, iy, iz] over plane coordinates [-1, 1]^3."""

    def __init__(self, res: int = formats.OCC_RES, hull: Tensor | None = None, decay: float = 0.95):
        super().__init__()
        hull = torch.ones(res, res, res, dtype=torch.bool) if hull is None else hull.bool()
        assert hull.shape == (res, res, res), hull.shape
        self.decay = decay
        self.register_buffer("hull", hull)
        # Every hull cell starts occupied: the field has not learned anything yet (callers warm up
        # before the first update so that density can grow where it belongs).
        self.register_buffer("density", torch.zeros(res, res, res))
        self.register_buffer("occ", hull.clone())
        self.outside_hull = not bool(hull.all())  # is there known-empty space?

    def cell_points(self, generator: torch.Generator | None = None) -> Tensor:
        """One random point per cell, (G^3, 3) in plane coordinates."""
        g = self.hull.shape[0]
        idx = torch.stack(torch.meshgrid(*[torch.arange(g)] * 3, indexing="ij"), -1).reshape(-1, 3)
        return ((idx + torch.rand(idx.shape, generator=generator)) / g * 2.0 - 1.0).to(self.hull.device)

    @torch.no_grad()
    def update(self, density_fn, step: float, generator: torch.Generator | None = None,
               chunk: int = 1 << 16) -> float:
        """Re-evaluate `density_fn(points (M, 3)) -> (M,)` in hull cells; returns the occupied fraction."""
        pts = self.cell_points(generator)
        inside = self.hull.reshape(-1)
        new = torch.zeros(inside.shape[0], device=inside.device)
        sel = torch.nonzero(inside).squeeze(1)
        for i in range(0, sel.shape[0], chunk):
            j = sel[i:i + chunk]
            new[j] = density_fn(pts[j])
        flat = self.density.view(-1)
        flat.copy_(torch.maximum(flat * self.decay, new))
        threshold = -torch.log1p(torch.tensor(-formats.OCC_ALPHA_THRESHOLD)) / step  # alpha > thr
        self.occ.copy_((self.density > threshold) & self.hull)
        return float(self.occ.float().mean())
