"""The rays of pixels that show the ground (fit --seen-ground-weight): where a matched feature of the training photos
lies on the ground (`snapshot3d.sparse_box.ground_pixels`), its pixel's ray crosses the box through empty space
down to it. The planes' opacity along that ray is penalised above `clear` over the ground plane; below it, the
feature may lie on the object's own base (a hoof within the ground's band), where the ray ends inside the box.

Spaces: the rays are the fit's (q space, `sampler.BoxFrame`); the ground plane z = a x + b y + c is in world units.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from .field import decode, sample_planes
from .sampler import BoxFrame, march

__all__ = ["GroundRays", "ground_rays", "clear_opacity"]


@dataclass(frozen=True)
class GroundRays:
    """index (K,) int64 into the fit's ray bank; the ground plane (a, b, c), world; clear: world units over it."""

    index: Tensor
    plane: tuple
    clear: float


def ground_rays(info: dict, height: int, width: int) -> GroundRays | None:
    """posed.info's "ground_pixels" (K, 3) (train frame, row, col), "ground_plane" and "ground_clear" (the sparse
    box's) -> their rays as indices into the fit's ray bank (`rays.make_rays` of the training views, row-major), or
    None when there are none."""
    seen = info.get("ground_pixels")
    if seen is None or not len(seen) or info.get("ground_plane") is None:
        return None
    frame, row, col = (torch.from_numpy(np.asarray(seen, np.int64)[:, k]) for k in range(3))
    return GroundRays((frame * height + row) * width + col, tuple(float(v) for v in info["ground_plane"]),
                      float(info["ground_clear"]))


def clear_opacity(planes: Tensor, decoder, frame: BoxFrame, occ: Tensor | None, o: Tensor, d: Tensor, plane,
                  clear: float, generator: torch.Generator | None = None) -> Tensor:
    """q-space rays (N, 3), unit dirs -> (N,) the planes' opacity along each ray counting only its samples (jittered)
    higher than `clear` (world units) over the ground plane (a, b, c). Differentiable in the planes (and the rays,
    when they are being refined)."""
    s = march(o, d, frame, occ, jitter=True, generator=generator)
    world = s.unit * frame.half_unit * frame.scale + frame.centre
    a, b, c = (float(v) for v in plane)
    keep = (world[:, 2] - a * world[:, 0] - b * world[:, 1] - c) > clear
    sigma = decode(sample_planes(planes, s.unit[keep]), decoder)[0]
    tau = torch.zeros(s.n_rays, device=o.device, dtype=sigma.dtype).index_add(0, s.ray[keep], sigma * frame.step)
    return 1 - torch.exp(-tau)
