"""Embed-time refinement: the encoder knows the host, the planes and the restore network, so it can
nudge the snapshot's pixels until the frozen restore network reads the planes back better, from the
snapshot itself and from JPEG copies of it, without moving further from the host.

Each step restores one copy of the current snapshot, in turn the 8-bit file itself and a JPEG copy
at a quality drawn in [65, 95] (expectation over the draws, as for robust adversarial examples; the
copy is `train.codec.jpeg`'s differentiable JPEG as OpenCV writes one, of the file as `embed` writes it:
`formats.FILE_SCALE` times the snapshot's size, read back by block means), and takes an Adam step on the
plane error. The host fidelity is a hard constraint: after every step the snapshot's difference from the host
is scaled back onto the unrefined snapshot's mean square, so the host PSNR never falls below the
unrefined snapshot's (projected gradient). The former schedule (`both-weighted`: both copies every step,
a Lagrange weight on the host term) took 2.9 times as long and let the host PSNR fall by up to 0.6 dB;
held at the same host it restored no better (`snapshot3d bench refine`, docs/file-codec.md "Embed-time
refinement"). The restore side is unchanged: any decoder of this codec
version reads a refined snapshot. Phone photos do not gain (0.2-0.6 dB lower in `bench codec`'s medians):
drawing the whole training channel did not help them either, their sub-pixel misregistration defeats
it (docs/file-codec.md "Embed-time refinement").

Layouts: host (380, 380, 3) float RGB in [0, 1]; planes (3, C, R, R) in [-1, 1];
snapshot (380, 380, 3) uint8 RGB.
"""
from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from snapshot3d import formats
from snapshot3d.codecs import file_layout
from snapshot3d.errors import UserError

from .channel import round_8bit
from .file_copies import copy_of
from .hinet import embed_planes, secret_grid
from .net import CodecNet
from .training import secret_to_planes_t

__all__ = ["refine_snapshot", "snapshot_of", "copies", "JPEG_QUALITY", "SCHEDULES", "Adam"]

JPEG_QUALITY = (65.0, 95.0)
"""the range the JPEG copies' quality is drawn from"""


SCHEDULES = {"turns": 1e-3, "both-weighted": 2e-3}
"""refinement schedules and their learning rates at strength 1: `turns` (shipped) restores one copy per step, the
file and a JPEG in turn, and holds the host by projection, with a learning rate proportional to the strength
(the hidden secret's amplitude in the pixels); `both-weighted` (the former one, kept for `bench refine`) restores
both copies every step and weighs the host term by a steered Lagrange multiplier. The `turns` rate was 3e-3
at every strength until a learning-rate sweep (docs/file-codec.md "The refinement's choices") found 1e-3 best at strength 1 and
0.5e-3 at `--host-psnr 38` (strengths 0.50-0.68)."""


class Adam:
    """Adam on one tensor, step for step what `torch.optim.Adam` (default settings) computes: bit-identical
    parameters after 25 steps (tests/test_codec_refine.py). Kept rather than `torch.optim.Adam` because torch's
    optimisers import `torch._dynamo` on their first step: 1.1-1.5 s for constructing it and its first step on
    a (1, 3, 380, 380) tensor against 9 ms here (later steps 3.2-5.1 ms against 4.4 ms), in an embed of
    6.3-6.6 s. Measured 2026-11-25 on 2 cores (AMD EPYC, torch 2.13): in a fresh process each, time
    `opt = torch.optim.Adam([p], lr=1e-3)` and 21 steps of `(p.sin() ** 2).sum()` against `Adam(p, 1e-3)`."""

    def __init__(self, param: torch.Tensor, lr: float, betas=(0.9, 0.999), eps: float = 1e-8):
        self.param, self.lr, self.betas, self.eps, self.t = param, lr, betas, eps, 0
        self.m, self.v = torch.zeros_like(param), torch.zeros_like(param)

    def zero_grad(self, set_to_none: bool = True) -> None:
        self.param.grad = None

    @torch.no_grad()
    def step(self) -> None:
        (b1, b2), g = self.betas, self.param.grad
        self.t += 1
        self.m.lerp_(g, 1 - b1)
        self.v.mul_(b2).addcmul_(g, g, value=1 - b2)
        denom = (self.v.sqrt() / math.sqrt(1 - b2 ** self.t)).add_(self.eps)
        self.param.addcdiv_(self.m, denom, value=-self.lr / (1 - b1 ** self.t))


def copies(x: Tensor, jpeg: tuple[bool, ...], gen: torch.Generator, scale: int = 1) -> Tensor:
    """What the restore network reads of snapshot x (1, 3, H, W) in [0, 1]: per entry of `jpeg`, the 8-bit
    file (False) or a JPEG copy of it at a quality drawn in JPEG_QUALITY (True), the file written at `scale`
    times the snapshot's size and read back by `scale` x `scale` means, in 8-bit steps as a reader gets them
    (`file_copies.copy_of`, the one path of the copies training and refinement make) -> (len(jpeg), 3, H, W)."""
    file, (lo, hi) = round_8bit(x), JPEG_QUALITY
    return torch.cat([copy_of(file, None, (lo + (hi - lo) * float(torch.rand(1, generator=gen)),), scale) if j
                      else file for j in jpeg])


def _psnr(mse: float) -> float:
    return 10 * math.log10(1.0 / max(mse, 1e-12))


def _project(x0: torch.Tensor, delta: torch.Tensor, host: torch.Tensor, budget: float) -> None:
    """Scale the snapshot's difference from the host (in place, through `delta`) back onto a mean square of
    `budget` when it is over."""
    diff = (x0 + delta).clamp(0, 1) - host
    mse = float(diff.pow(2).mean())
    if mse > budget:
        delta.copy_(host + diff * math.sqrt(budget / mse) - x0)


def refine_snapshot(net: CodecNet, host: np.ndarray, planes: np.ndarray, steps: int, strength: float = 1.0,
                    lr: float | None = None, seed: int = 0, on_step=None, schedule: str = "turns",
                    scale: int = formats.FILE_SCALE) -> tuple[np.ndarray, dict]:
    """-> (snapshot (380, 380, 3) uint8 RGB, {"host_psnr_unrefined", "plane_mse_first", "plane_mse_last"}).
    `schedule` one of SCHEDULES (lr None: its own, times `strength` for `turns`); `on_step(i)` is called after
    each step (progress); `scale`: the JPEG copies are of the file written at that many times the size."""
    if schedule not in SCHEDULES:
        raise ValueError(f"unknown refinement schedule {schedule!r}; choose from {', '.join(SCHEDULES)}")
    _, c, r, _ = planes.shape
    h = torch.from_numpy(np.ascontiguousarray(host.transpose(2, 0, 1), np.float32))[None]
    target_planes = torch.from_numpy(np.ascontiguousarray(planes, np.float32))
    secret = torch.from_numpy(file_layout.planes_to_secret(planes, secret_grid(net)))[None] * strength
    with torch.no_grad():
        x0 = net(h, secret)[0].clamp(0, 1)
    budget = F.mse_loss(x0, h).item()
    target_db = _psnr(budget)
    delta = torch.zeros_like(x0, requires_grad=True)
    opt = Adam(delta, lr=lr or SCHEDULES[schedule] * (strength if schedule == "turns" else 1.0))
    gen = torch.Generator().manual_seed(seed)
    weighted, log_w, losses = schedule == "both-weighted", math.log(10.0), []
    for i in range(steps):
        x = (x0 + delta).clamp(0, 1)
        rest = net.reverse_secret(copies(x, (False, True) if weighted else (bool(i % 2),), gen, scale)) / strength
        loss = sum(F.mse_loss(secret_to_planes_t(s, r, c), target_planes) for s in rest) / len(rest)
        opt.zero_grad(set_to_none=True)
        if weighted:
            l_host = F.mse_loss(x, h)
            (loss + math.exp(log_w) * l_host).backward()
            opt.step()
            log_w = float(np.clip(log_w + 0.1 * np.clip(target_db - _psnr(l_host.item()), -5, 5), -2.0, 10.0))
        else:
            loss.backward()
            opt.step()
            with torch.no_grad():
                _project(x0, delta, h, budget)
        losses.append(loss.item())
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
