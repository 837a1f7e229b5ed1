"""Embed-time refinement: the encoder knows the host, the planes and the restore network, so it can
nudge the snapshot's pixels until the frozen restore network reads the planes back better, from the
snapshot itself and from JPEG copies of it, without moving further from the host.

Each step restores two copies of the current snapshot through the differentiable channel
(`train.channel`, JPEG only): the 8-bit file itself, and a JPEG at a quality drawn in [65, 95]
(expectation over the draws, as for robust adversarial examples). The loss is the plane error of both
plus a host-fidelity term whose weight is steered (a Lagrange multiplier) so that the host PSNR does
not fall below the unrefined snapshot's. The restore side is unchanged: any decoder of this codec
version reads a refined snapshot. Phone photos do not gain (0.2-0.6 dB lower in `bench codec`'s medians):
drawing the whole training channel did not help them either, their sub-pixel misregistration defeats
it (README "Embed-time refinement").

Layouts: host (380, 380, 3) float RGB in [0, 1]; planes (3, C, R, R) in [-1, 1];
snapshot (380, 380, 3) uint8 RGB.
"""
from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F

from snapshot3d import codec_layout
from snapshot3d.errors import UserError

from .channel import ChannelRanges, apply_channel
from .hinet import embed_planes, secret_grid
from .net import CodecNet
from .training import secret_to_planes_t

__all__ = ["refine_snapshot", "snapshot_of", "REFINE_CHANNEL"]

# JPEG only, quality in [65, 95] at level 1 (level 0: the 8-bit file alone)
REFINE_CHANNEL = ChannelRanges(shift_px=0.0, blur_px=0.0, gain=0.0, offset=0.0, gamma=0.0, saturation=0.0,
                               shading=0.0, texture=0.0, noise=0.0, jpeg_min=65.0, jpeg_prob=1.0)


def _psnr(mse: float) -> float:
    return 10 * math.log10(1.0 / max(mse, 1e-12))


def refine_snapshot(net: CodecNet, host: np.ndarray, planes: np.ndarray, steps: int, strength: float = 1.0,
                    lr: float = 2e-3, seed: int = 0, on_step=None) -> tuple[np.ndarray, dict]:
    """-> (snapshot (380, 380, 3) uint8 RGB, {"host_psnr_unrefined", "plane_mse_first", "plane_mse_last"}).
    `on_step(i)` is called after each step (progress)."""
    _, c, r, _ = planes.shape
    h = torch.from_numpy(np.ascontiguousarray(host.transpose(2, 0, 1), np.float32))[None]
    target_planes = torch.from_numpy(np.ascontiguousarray(planes, np.float32))
    secret = torch.from_numpy(codec_layout.planes_to_secret(planes, secret_grid(net)))[None] * strength
    with torch.no_grad():
        x0 = net(h, secret)[0].clamp(0, 1)
    target_db = _psnr(F.mse_loss(x0, h).item())
    delta = torch.zeros_like(x0, requires_grad=True)
    opt = torch.optim.Adam([delta], lr=lr)
    gen = torch.Generator().manual_seed(seed)
    log_w, levels, losses = math.log(10.0), torch.tensor([0.0, 1.0]), []
    for _ in range(steps):
        x = (x0 + delta).clamp(0, 1)
        seen = apply_channel(x.expand(len(levels), -1, -1, -1), levels, REFINE_CHANNEL, gen)
        rest = net.reverse(seen)[1] / strength
        l_plane = sum(F.mse_loss(secret_to_planes_t(s, r, c), target_planes) for s in rest) / len(levels)
        l_host = F.mse_loss(x, h)
        loss = l_plane + math.exp(log_w) * l_host
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        log_w = float(np.clip(log_w + 0.1 * np.clip(target_db - _psnr(l_host.item()), -5, 5), -2.0, 10.0))
        losses.append(l_plane.item())
        if on_step is not None:
            on_step(len(losses))
    with torch.no_grad():
        snap = (x0 + delta).clamp(0, 1)[0].permute(1, 2, 0).numpy()
    info = {"host_psnr_unrefined": target_db,
            "plane_mse_first": float(np.mean(losses[:10])) if losses else None,
            "plane_mse_last": float(np.mean(losses[-10:])) if losses else None}
    return (snap * 255 + 0.5).astype(np.uint8), info


def snapshot_of(net: CodecNet, host: np.ndarray, planes: np.ndarray, refine: int = 0, strength: float = 1.0,
                show_progress: bool = False) -> np.ndarray:
    """The snapshot `snapshot3d embed --refine REFINE` writes: refined when `refine` > 0, else the network's own."""
    if refine < 0:
        raise UserError(f"--refine must be >= 0 steps, got {refine}")
    if not refine:
        return embed_planes(net, host, planes, strength)
    if not show_progress:
        return refine_snapshot(net, host, planes, refine, strength)[0]
    from snapshot3d.progress import progress
    with progress(refine, "refine") as bar:
        return refine_snapshot(net, host, planes, refine, strength, on_step=lambda i: bar.update(1))[0]
