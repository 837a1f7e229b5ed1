"""The background of a capture without masks (fit --background outer): a coarse field outside the box and a
colour per direction beyond it, fitted with the planes and never carried in the snapshot.

Spaces: rays are in the sampler's q space (box centre at 0, the box [-half_unit, half_unit]); the outer field is
read at u = q / half_unit (the box is [-1, 1]^3) contracted as in mip-NeRF 360 with the max norm,
contract(u) = u inside the box, (2 - 1/|u|) u/|u| outside (|u| the max norm), so the world outside the box fills
the shell between the cubes of half-size 1 and 2. Its density is zero inside the box, where the planes alone
explain what is seen. A ray is composited in order: the segment before the box (evenly spaced), the box's
samples (`render.render_rays`), the segment after it (evenly spaced in inverse distance, out to `T_MAX`), then the
per-direction colour. A ray that misses the box has its two segments meet at its closest approach to the centre.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from .field import composite
from .render import render_rays
from .sampler import BoxFrame, ray_box

__all__ = ["contract", "OuterField", "outer_query", "env_colour", "segment_samples", "render_with_background"]

T_MAX = 200.0     # q-space distance (box half-sizes) where the after-segment ends and the colour per direction starts
ENV_SIZE = (8, 16)  # the colour per direction: latitude x longitude cells


def contract(u: Tensor) -> Tensor:
    """(M, 3) box coordinates (the box is [-1, 1]^3) -> (M, 3) in [-2, 2]^3, the identity inside the box."""
    n = u.abs().amax(dim=-1, keepdim=True).clamp(min=1e-9)
    return torch.where(n <= 1, u, (2 - 1 / n) * u / n)


class OuterField(nn.Module):
    """Holds the outer grid (1, 4, G, G, G): density logit and RGB logits over contracted [-2, 2]^3 (the grid's
    last axis follows x, as `grid_sample` reads it), and the colour per direction (1, 3, *ENV_SIZE) logits."""

    def __init__(self, res: int = 48, init_density: float = -4.0):
        super().__init__()
        grid = torch.zeros(1, 4, res, res, res)
        grid[:, 0] = init_density
        self.grid = nn.Parameter(grid)
        self.env = nn.Parameter(torch.zeros(1, 3, *ENV_SIZE))


def outer_query(grid: Tensor, u: Tensor) -> tuple[Tensor, Tensor]:
    """grid (1, 4, G, G, G), u (M, 3) box coordinates -> density (M,) >= 0 per q-space unit (zero inside the
    box), rgb (M, 3) in [0, 1]; trilinear in contracted space."""
    c = contract(u) / 2
    raw = F.grid_sample(grid, c.view(1, 1, 1, -1, 3), mode="bilinear", padding_mode="border",
                        align_corners=True)[0, :, 0, 0]   # (4, M)
    outside = (u.abs().amax(dim=-1) >= 1).to(raw.dtype)
    return F.softplus(raw[0]) * outside, torch.sigmoid(raw[1:].t())


def env_colour(env: Tensor, d: Tensor) -> Tensor:
    """env (1, 3, He, We) logits, unit directions d (N, 3) -> RGB (N, 3) in [0, 1] (longitude x, latitude y)."""
    lon = torch.atan2(d[:, 1], d[:, 0]) / math.pi
    lat = torch.asin(d[:, 2].clamp(-1, 1)) / (math.pi / 2)
    g = torch.stack([lon, lat], -1).view(1, 1, -1, 2)
    return torch.sigmoid(F.grid_sample(env, g, mode="bilinear", padding_mode="border", align_corners=False)[0, :, 0].t())


def segment_samples(t0: Tensor, t1: Tensor, n: int, disparity: bool, jitter: bool,
                    generator: torch.Generator | None = None) -> tuple[Tensor, Tensor]:
    """n samples per ray in [t0, t1] (N,) each, one per bin, bins even in t (or in 1/t with `disparity`) ->
    t (N, n), bin lengths (N, n)."""
    k = torch.arange(n + 1, dtype=t0.dtype, device=t0.device) / n
    if disparity:
        edges = 1 / ((1 - k) / t0[:, None].clamp(min=1e-3) + k / t1[:, None])
    else:
        edges = t0[:, None] + k * (t1 - t0)[:, None]
    off = torch.rand(t0.shape[0], n, generator=generator).to(t0.device) if jitter else torch.full((t0.shape[0], n), 0.5,
                                                                                                  device=t0.device)
    return edges[:, :-1] + off * (edges[:, 1:] - edges[:, :-1]), edges[:, 1:] - edges[:, :-1]


def render_with_background(planes: Tensor, decoder, frame: BoxFrame, occ: Tensor | None, bg: OuterField,
                           o: Tensor, d: Tensor, samples: int, jitter: bool = False, generator=None,
                           min_transmittance: float = 0.0):
    """q-space rays (N, 3), unit dirs -> colour (N, 3) of the planes in front of the background, the planes'
    opacity (N,), number of box samples evaluated. Differentiable in the planes and `bg`."""
    near, far = ray_box(o, d, frame.half_unit)
    closest = (-(o * d).sum(-1)).clamp(min=0)
    hit = near < far
    t_in, t_out = torch.where(hit, near, closest), torch.where(hit, far, closest)
    tb, db = segment_samples(torch.zeros_like(t_in), t_in, samples, False, jitter, generator)
    ta, da = segment_samples(t_out, torch.full_like(t_out, T_MAX), samples, True, jitter, generator)
    t = torch.cat([tb, ta], 1)
    pts = o[:, None] + t[..., None] * d[:, None]
    sigma, rgb = outer_query(bg.grid, frame.q_to_unit(pts.reshape(-1, 3)))
    sigma, rgb = sigma.view(t.shape), rgb.view(*t.shape, 3)
    after, _, _ = composite(sigma[:, samples:], rgb[:, samples:], da, env_colour(bg.env, d))
    box, acc, n_box = render_rays(planes, decoder, frame, occ, o, d, jitter=jitter, generator=generator,
                                  min_transmittance=min_transmittance, background=after)
    colour, _, _ = composite(sigma[:, :samples], rgb[:, :samples], db, box)
    return colour, acc, n_box
