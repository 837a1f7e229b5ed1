"""The background of a capture without masks (fit --background outer): a coarse field outside the box and a
colour per direction beyond it, fitted with the planes and never carried in the snapshot.

Spaces: rays are in the sampler's q space (box centre at 0, the box [-half_unit, half_unit]); the outer field is
read at u = q / half_unit (the box is [-1, 1]^3) contracted as in mip-NeRF 360 with the max norm,
contract(u) = u inside the box, (2 - 1/|u|) u/|u| outside (|u| the max norm), so the world outside the box fills
the shell between the cubes of half-size 1 and 2. Its density is zero inside the box, where the planes alone
explain what is seen. A ray is composited in order: the segment before the box (evenly spaced), the box's
samples (`render.render_rays`), the segment after it (evenly spaced in inverse distance, out to `T_MAX`), then the
per-direction colour. A ray that misses the box has its two segments meet at its closest approach to the centre.
The regularisers tried against floaters in the box (distortion, opacity, walls, floor; all off by default, as
measured in docs/capture.md) are plain functions here, summed by `render_and_regularise` for `fit.train_step`.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from .field import composite, decode, sample_planes
from .render import render_rays
from .sampler import BoxFrame, ray_box

__all__ = ["contract", "OuterField", "floor_colour", "outer_query", "env_colour", "segment_samples", "render_with_background",
           "distortion_loss", "opacity_entropy", "explained_by_background", "wall_points", "floor_points",
           "render_and_regularise"]

T_MAX = 200.0     # q-space distance (box half-sizes) where the after-segment ends and the colour per direction starts
ENV_SIZE = (8, 16)  # the colour per direction: latitude x longitude cells


def contract(u: Tensor) -> Tensor:
    """(M, 3) box coordinates (the box is [-1, 1]^3) -> (M, 3) in [-2, 2]^3, the identity inside the box."""
    n = u.abs().amax(dim=-1, keepdim=True).clamp(min=1e-9)
    return torch.where(n <= 1, u, (2 - 1 / n) * u / n)


class OuterField(nn.Module):
    """Holds the outer grid (1, 4, G, G, G): density logit and RGB logits over contracted [-2, 2]^3 (the grid's
    last axis follows x, as `grid_sample` reads it), the colour per direction (1, 3, *ENV_SIZE) logits, and with
    `floor` > 0 the ground's colour (1, 3, floor, floor) logits over the box's floor x (last axis), y, on a plane
    `floor_depth` q units below it, spanning `floor_reach` times the floor about its centre."""

    def __init__(self, res: int = 48, init_density: float = -4.0, floor: int = 0, floor_depth: float = 0.0,
                 floor_reach: float = 1.0):
        super().__init__()
        grid = torch.zeros(1, 4, res, res, res)
        grid[:, 0] = init_density
        self.grid = nn.Parameter(grid)
        self.env = nn.Parameter(torch.zeros(1, 3, *ENV_SIZE))
        self.floor = nn.Parameter(torch.zeros(1, 3, floor, floor)) if floor else None
        self.floor_depth = floor_depth
        self.floor_reach = floor_reach


def floor_colour(floor: Tensor, frame: BoxFrame, o: Tensor, d: Tensor, t_out: Tensor,
                 hit: Tensor, depth: float = 0.0, reach: float = 1.0) -> tuple[Tensor, Tensor]:
    """Where q-space rays (N, 3) leave the box (at t_out (N,), `hit` (N,) bool) through its floor, the ground's
    colour on the plane `depth` (q units) below that floor, where they meet it: -> (N,) bool, RGB (N, 3) in
    [0, 1] from `floor` (1, 3, F, F) logits (bilinear, over the floor's x, y). With `reach` > 1 the texture spans
    `reach` times the floor about its centre, and every ray that meets the plane within it past the box (t_out,
    the closest approach for rays that miss the box) ends there, through the box's sides too."""
    if reach > 1:
        z = -frame.half_unit[2] - depth   # the plane, q space
        t = (z - o[:, 2]) / d[:, 2].clamp(max=-1e-6)
        u = frame.q_to_unit(o + t[:, None] * d)[:, :2] / reach
        down = (d[:, 2] < -1e-6) & (t >= t_out - 1e-6) & (u.abs().amax(dim=-1) <= 1)
        g = u.clamp(-1, 1).view(1, 1, -1, 2)
        return down, torch.sigmoid(F.grid_sample(floor, g, mode="bilinear", padding_mode="border",
                                                 align_corners=False)[0, :, 0].t())
    exit_ = o + t_out[:, None] * d
    down = hit & (d[:, 2] < 0) & (frame.q_to_unit(exit_)[:, 2] <= -1 + 1e-3)
    u = frame.q_to_unit(exit_ + d * (depth / (-d[:, 2]).clamp(min=1e-3))[:, None])
    g = u[:, :2].clamp(-1, 1).view(1, 1, -1, 2)
    return down, torch.sigmoid(F.grid_sample(floor, g, mode="bilinear", padding_mode="border",
                                             align_corners=False)[0, :, 0].t())


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
                           min_transmittance: float = 0.0, extras: bool = False):
    """q-space rays (N, 3), unit dirs -> colour (N, 3) of the planes in front of the background, the planes'
    opacity (N,), number of box samples evaluated; with `extras`, also {"weights": the box samples' weights
    (N, S), evenly spaced by frame.step; "background_alone": the colour (N, 3) the ray would have with the box
    empty}. Differentiable in the planes and `bg`."""
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
    if bg.floor is not None:   # the box's floor is the ground: a ray that leaves through it ends there
        down, ground = floor_colour(bg.floor, frame, o, d, t_out, hit, bg.floor_depth, bg.floor_reach)
        after = torch.where(down[:, None], ground, after)
    box, acc, n_box, *weights = render_rays(planes, decoder, frame, occ, o, d, jitter=jitter, generator=generator,
                                            min_transmittance=min_transmittance, background=after, with_weights=extras)
    colour, _, _ = composite(sigma[:, :samples], rgb[:, :samples], db, box)
    if not extras:
        return colour, acc, n_box
    alone, _, _ = composite(sigma[:, :samples], rgb[:, :samples], db, after)
    return colour, acc, n_box, {"weights": weights[0], "background_alone": alone}


def distortion_loss(weights: Tensor, step: float) -> Tensor:
    """mip-NeRF 360's distortion loss of weights (N, S) at samples evenly spaced by `step` along each ray ->
    (N,): sum_ij w_i w_j |t_i - t_j| + step / 3 sum_i w_i^2, small when each ray's weight is one compact lump
    (a surface), large when it is spread along the ray (semi-transparent floaters). Pairs in O(S) by prefix sums."""
    t = torch.arange(weights.shape[1], dtype=weights.dtype, device=weights.device) * step
    wt = weights * t
    w_before, wt_before = torch.cumsum(weights, 1) - weights, torch.cumsum(wt, 1) - wt
    return 2 * (weights * (t * w_before - wt_before)).sum(1) + step / 3 * (weights ** 2).sum(1)


def opacity_entropy(acc: Tensor, eps: float = 1e-4) -> Tensor:
    """Binary entropy (nats) of the planes' opacity (N,) per ray -> (N,): zero for a ray that ends on the object
    (1) or passes through to the background (0), largest for a half-transparent one."""
    a = acc.clamp(eps, 1 - eps)
    return -(a * torch.log(a) + (1 - a) * torch.log(1 - a))


def floor_points(n: int, band: float, generator: torch.Generator | None = None) -> tuple[Tensor, Tensor]:
    """n random points (n, 3) in plane coordinates in the box's floor band (z within `band` of -1), and for each
    3 points (n, 3, 3) of its column above the band (z at -1 + 2 band, 3 band, 4 band): where nothing stands on
    the floor, the floor band should be empty (the ground belongs to the background model)."""
    u = torch.rand(n, 3, generator=generator) * 2 - 1
    u[:, 2] = -1 + band * torch.rand(n, generator=generator)
    above = u[:, None].repeat(1, 3, 1)
    above[:, :, 2] = -1 + band * torch.tensor([2.0, 3.0, 4.0])
    return u, above


def explained_by_background(background_alone: Tensor, target: Tensor, tol: float = 0.05) -> Tensor:
    """Colour (N, 3) of each ray with the box empty and the pixels' target (N, 3) -> (N,) in [0, 1], no gradient:
    1 where the background model alone already gives the pixel (rms error well under `tol`), falling to 0 past
    it; the rays that should pass through the box to the background."""
    err = ((background_alone.detach() - target) ** 2).mean(-1).sqrt()
    return torch.exp(-(err / tol) ** 2)


def wall_points(n: int, margin: float, generator: torch.Generator | None = None) -> Tensor:
    """n random points (n, 3) in plane coordinates ([-1, 1]^3) within `margin` of one of the box's side walls
    (x, y = +-1) or its top (z = 1), never its floor, where the object stands on the ground cut."""
    u = torch.rand(n, 3, generator=generator) * 2 - 1
    face = torch.randint(0, 5, (n,), generator=generator)   # -x, +x, -y, +y, +z
    axis, sign = torch.tensor([0, 0, 1, 1, 2])[face], torch.tensor([-1.0, 1.0, -1.0, 1.0, 1.0])[face]
    depth = torch.rand(n, generator=generator) * margin
    u[torch.arange(n), axis] = sign * (1 - depth)
    return u


def render_and_regularise(planes: Tensor, decoder, frame: BoxFrame, occ: Tensor | None, bg: OuterField, cfg, o: Tensor,
                          d: Tensor, target: Tensor, gen: torch.Generator):
    """One training batch with the background model: q-space rays (N, 3), unit dirs, target RGB (N, 3) in [0, 1]
    -> colour (N, 3) (jittered samples), samples evaluated, and the sum of the regularisers on the planes that
    `cfg` (a FitConfig) turns on (distortion, opacity, walls, floor; None when all weights are 0)."""
    extras = cfg.distortion_weight > 0 or cfg.opacity_weight > 0
    out = render_with_background(planes, decoder, frame, occ, bg, o, d, cfg.background_samples, jitter=True,
                                 generator=gen, min_transmittance=cfg.min_transmittance, extras=extras)
    color, acc, n_samples = out[:3]
    terms = []
    if cfg.distortion_weight > 0:
        terms.append(cfg.distortion_weight * distortion_loss(out[3]["weights"], frame.step).mean())
    if cfg.opacity_weight > 0:   # the entropy of each ray's opacity, or its opacity where the background explains it
        terms.append(cfg.opacity_weight * opacity_entropy(acc).mean() if cfg.opacity_entropy else
                     cfg.opacity_weight * (explained_by_background(out[3]["background_alone"], target) * acc).mean())
    if cfg.wall_weight > 0:
        pts = wall_points(cfg.batch_rays // 4, cfg.wall_margin, gen).to(o.device)
        terms.append(cfg.wall_weight * torch.mean(1 - torch.exp(-decode(sample_planes(planes, pts), decoder)[0]
                                                                * frame.step)))
    if cfg.floor_weight > 0:   # the floor band, weighted by how empty its column is just above
        pts, above = floor_points(cfg.batch_rays // 4, cfg.wall_margin, gen)
        sigma = decode(sample_planes(planes, torch.cat([pts, above.reshape(-1, 3)]).to(o.device)), decoder)[0]
        alpha = 1 - torch.exp(-sigma * frame.step)
        empty_above = 1 - alpha[pts.shape[0]:].detach().view(-1, 3).amax(1)
        terms.append(cfg.floor_weight * torch.mean(empty_above * alpha[:pts.shape[0]]))
    return color, n_samples, (sum(terms) if terms else None)
