"""Ray marching through the scene box with occupancy-based empty-space skipping (the NerfAcc idea),
in plain torch: uniform steps clipped to the box, only samples in occupied cells are kept.

Spaces: world rays are mapped to `q` space, q = (p - centre) / s with s the box's largest
half-extent (so distances are scale-free and the box fits in [-1, 1]^3); plane lookups use
u = q * s / half (each axis in [-1, 1]).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import Tensor

from snapshot3d import formats

__all__ = ["BoxFrame", "ray_box", "march", "Samples"]


@dataclass(frozen=True)
class BoxFrame:
    """The scene box as used for marching. box (2, 3) world min/max rows."""

    centre: Tensor  # (3,)
    scale: float    # largest half-extent, world units
    half_unit: Tensor  # (3,) half-extents in q space (<= 1)

    @classmethod
    def from_box(cls, box, device=None) -> "BoxFrame":
        box = torch.as_tensor(box, dtype=torch.float32)
        half = (box[1] - box[0]) / 2
        scale = float(half.max())
        return cls(centre=(box[0] + box[1]) / 2, scale=scale, half_unit=half / scale).to(device)

    def to(self, device) -> "BoxFrame":
        """The same frame with its tensors on `device` (None: unchanged)."""
        if device is None:
            return self
        return BoxFrame(centre=self.centre.to(device), scale=self.scale, half_unit=self.half_unit.to(device))

    def rays_to_q(self, origins: Tensor, dirs: Tensor) -> tuple[Tensor, Tensor]:
        """World rays (N, 3), unit dirs -> q-space rays (directions stay unit)."""
        return (origins - self.centre) / self.scale, dirs

    def q_to_unit(self, q: Tensor) -> Tensor:
        return q / self.half_unit

    @property
    def step(self) -> float:
        """Sample spacing in q space: the box diagonal over RENDER_STEPS_PER_BOX."""
        return 2.0 * float(self.half_unit.norm()) / formats.RENDER_STEPS_PER_BOX


def ray_box(o: Tensor, d: Tensor, half: Tensor) -> tuple[Tensor, Tensor]:
    """Slab test of rays (N, 3) against the box [-half, half] -> t_near, t_far (N,); miss when near >= far."""
    inv = 1.0 / torch.where(d.abs() < 1e-9, torch.full_like(d, 1e-9), d)
    t0, t1 = (-half - o) * inv, (half - o) * inv
    near = torch.minimum(t0, t1).amax(dim=1).clamp(min=0.0)
    far = torch.maximum(t0, t1).amin(dim=1)
    return near, far


@dataclass
class Samples:
    """Kept samples of a ray batch: `ray`, `step` (M,) indices into the dense (N, S) grid, positions (M, 3)
    in plane coordinates [-1, 1]; S the dense width; offset (N,) each ray's sample offset in steps (jitter)."""

    ray: Tensor
    idx: Tensor
    unit: Tensor
    n_rays: int
    width: int
    offset: Tensor | None = None


def march(o: Tensor, d: Tensor, frame: BoxFrame, occ: Tensor | None, jitter: bool,
          generator: torch.Generator | None = None) -> Samples:
    """Uniform samples along q-space rays inside the box, kept where `occ` (G, G, G) bool [ix, iy, iz]
    over plane coordinates is set (all kept when occ is None)."""
    if o.requires_grad or d.requires_grad:   # rays being refined (fit --refine-poses): grad on the kept samples only
        with torch.no_grad():
            s = march(o.detach(), d.detach(), frame, occ, jitter, generator)
        near = ray_box(o, d, frame.half_unit)[0]
        t = near[s.ray] + (s.idx.to(o.dtype) + s.offset[s.ray]) * frame.step
        unit = frame.q_to_unit(o[s.ray] + t[:, None] * d[s.ray]).clamp(-1.0, 1.0)
        return Samples(ray=s.ray, idx=s.idx, unit=unit, n_rays=s.n_rays, width=s.width, offset=s.offset)
    step = frame.step
    near, far = ray_box(o, d, frame.half_unit)
    width = max(1, int(math.ceil(float((far - near).detach().clamp(min=0).max()) / step)))
    k = torch.arange(width, dtype=o.dtype, device=o.device)
    off = torch.rand(o.shape[0], 1, generator=generator).to(o.device) if jitter else \
        torch.full((o.shape[0], 1), 0.5, device=o.device)
    t = near[:, None] + (k[None, :] + off) * step  # (N, S)
    valid = t < far[:, None]
    ray, idx = torch.nonzero(valid, as_tuple=True)
    q = o[ray] + t[ray, idx, None] * d[ray]
    unit = frame.q_to_unit(q).clamp(-1.0, 1.0)
    if occ is not None:
        g = occ.shape[0]
        cell = ((unit + 1.0) * 0.5 * g).long().clamp(0, g - 1)
        keep = occ[cell[:, 0], cell[:, 1], cell[:, 2]]
        ray, idx, unit = ray[keep], idx[keep], unit[keep]
    return Samples(ray=ray, idx=idx, unit=unit, n_rays=o.shape[0], width=width, offset=off[:, 0])
