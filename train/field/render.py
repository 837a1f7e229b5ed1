"""Reference torch renderer: views of planes + decoder along camera rays, chunked, with empty-space
skipping from an occupancy grid computed once from the planes."""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from snapshot3d import formats

from .field import composite, decode, sample_planes
from .rays import view_rays
from .sampler import BoxFrame, march

__all__ = ["render_rays", "composite_samples", "render_views", "occupancy_from_planes", "density_fn", "cell_alpha",
           "render_pixels"]


def density_fn(planes: Tensor, decoder):
    """points (M, 3) in plane coordinates -> density (M,)."""
    return lambda pts: decode(sample_planes(planes, pts), decoder)[0]


@torch.no_grad()
def occupancy_from_planes(planes: Tensor, decoder, frame: BoxFrame, res: int = formats.OCC_RES) -> Tensor:
    """(res, res, res) bool: cell centres whose one-step alpha exceeds the threshold, dilated by one cell."""
    t = (torch.arange(res, dtype=torch.float32, device=planes.device) + 0.5) / res * 2 - 1
    pts = torch.stack(torch.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    sigma = torch.cat([density_fn(planes, decoder)(p) for p in pts.split(1 << 16)])
    alpha = 1 - torch.exp(-sigma * frame.step)
    occ = (alpha > formats.OCC_ALPHA_THRESHOLD).float().view(1, 1, res, res, res)
    return F.max_pool3d(occ, 3, stride=1, padding=1)[0, 0] > 0


@torch.no_grad()
def cell_alpha(planes: torch.Tensor, decoder, box: np.ndarray, g: int = formats.OCC_RES, with_rgb: bool = False):
    """(g, g, g) [ix, iy, iz] opacity of one cell of the planes over `box` at the cells' centres; with `with_rgb`, also
    their colour (g, g, g, 3) RGB in [0, 1]."""
    frame = BoxFrame.from_box(box, planes.device)
    t = (np.arange(g) + 0.5) / g * 2 - 1
    unit = torch.from_numpy(np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3).astype(np.float32))
    out = [decode(sample_planes(planes, u.to(planes.device)), decoder) for u in unit.split(1 << 16)]
    sigma = torch.cat([o[0] for o in out])
    cell_q = float((2 * frame.half_unit / g).mean())
    alpha = (1 - torch.exp(-sigma * cell_q)).cpu().numpy().reshape(g, g, g)
    return (alpha, torch.cat([o[1] for o in out]).cpu().numpy().reshape(g, g, g, 3)) if with_rgb else alpha


def render_rays(planes: Tensor, decoder, frame: BoxFrame, occ: Tensor | None, o: Tensor, d: Tensor,
                jitter: bool = False, generator=None, min_transmittance: float = 0.0,
                background: float | Tensor = formats.BACKGROUND, with_weights: bool = False):
    """q-space rays (N, 3) -> colour (N, 3) over `background` (white, or a colour (N, 3) per ray: what lies
    behind the box, `background.render_with_background`), opacity (N,), number of samples evaluated with
    gradient; `with_weights`: also the samples' compositing weights (N, S), evenly spaced by frame.step along
    each ray (zero where a sample was skipped). Differentiable in planes/decoder. With `min_transmittance` > 0, a first pass without
    gradient finds where each ray is already opaque and the samples behind are dropped (early ray
    termination, as in NerfAcc)."""
    s = march(o, d, frame, occ, jitter=jitter, generator=generator)
    ray, idx, unit = s.ray, s.idx, s.unit
    if min_transmittance > 0 and torch.is_grad_enabled():
        with torch.no_grad():
            sig = decode(sample_planes(planes, unit), decoder)[0]
            tau = torch.zeros(s.n_rays, s.width, device=o.device).index_put((ray, idx), sig * frame.step)
            trans = torch.exp(-(torch.cumsum(tau, dim=1) - tau))
            keep = trans[ray, idx] > min_transmittance
        ray, idx, unit = ray[keep], idx[keep], unit[keep]
    color, acc, weights = composite_samples(s, ray, idx, *decode(sample_planes(planes, unit), decoder), frame.step,
                                            background)
    return (color, acc, int(ray.shape[0])) + ((weights,) if with_weights else ())


def composite_samples(s, ray: Tensor, idx: Tensor, sigma_s: Tensor, rgb_s: Tensor, step: float,
                      background: float | Tensor = formats.BACKGROUND):
    """Kept samples' density (M,) and rgb (M, 3) at `ray`, `idx` (M,) of a march `s` (`sampler.Samples`), laid
    into its dense (N, S) grid and composited: colour (N, 3) over `background`, opacity (N,), weights (N, S)."""
    dev = sigma_s.device
    sigma = torch.zeros(s.n_rays, s.width, device=dev).index_put((ray, idx), sigma_s)
    rgb = torch.zeros(s.n_rays, s.width, 3, device=dev).index_put((ray, idx), rgb_s)
    return composite(sigma, rgb, step, background)


@torch.no_grad()
def render_pixels(ray_fn, frame: BoxFrame, c2w: np.ndarray, intrinsics: np.ndarray, width: int, height: int,
                  chunk: int = 8192, progress=None) -> tuple[np.ndarray, np.ndarray]:
    """Views through `ray_fn(o, d) -> (colour (N, 3), opacity (N,))` of q-space rays in `frame`, chunked, for
    cameras c2w (V, 4, 4) OpenGL, intrinsics (V, 4) -> RGB (V, H, W, 3) float32 clamped to [0, 1], opacity (V, H, W)
    float32. `progress(i)` after each view."""
    rgb = np.empty((len(c2w), height, width, 3), np.float32)
    acc = np.empty((len(c2w), height, width), np.float32)
    for i in range(len(c2w)):
        o, d = view_rays(c2w[i], intrinsics[i], width, height, frame)
        out = [ray_fn(oc, dc) for oc, dc in zip(o.split(chunk), d.split(chunk))]
        rgb[i] = torch.cat([c for c, _ in out]).clamp(0, 1).reshape(height, width, 3).cpu().numpy()
        acc[i] = torch.cat([a for _, a in out]).reshape(height, width).cpu().numpy()
        if progress is not None:
            progress(i)
    return rgb, acc


@torch.no_grad()
def render_views(planes: Tensor, decoder, box, c2w: np.ndarray, intrinsics: np.ndarray, width: int,
                 height: int, occ: Tensor | None = None, chunk: int = 8192, progress=None, with_opacity: bool = False):
    """Views (N, H, W, 3) float32 RGB in [0, 1] for cameras c2w (N, 4, 4) OpenGL, intrinsics (N, 4); with
    `with_opacity`, also their opacity (N, H, W) float32."""
    frame = BoxFrame.from_box(box, planes.device)
    if occ is None:
        occ = occupancy_from_planes(planes, decoder, frame)
    rgb, acc = render_pixels(lambda o, d: render_rays(planes, decoder, frame, occ, o, d)[:2], frame, c2w, intrinsics,
                             width, height, chunk, progress)
    return (rgb, acc) if with_opacity else rgb
