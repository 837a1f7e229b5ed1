"""Fitting and scoring one representation (`representations.RepField`) on a posed image set, the way `fit.py`
fits the product's planes: rays drawn from the training views (3/4 from the object's pixels when masks exist),
uniform steps through the box skipped by an occupancy grid learned from the field (NerfAcc's idea), the
learning rates decayed 10x, the last `qat_fraction` of the steps through the 8-bit rounding the snapshot would
carry. Scored as `evaluate_planes` scores planes: mean PSNR over held-out views, over white."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from snapshot3d.metrics import psnr
from snapshot3d.posed import PosedImages

from .fit import empty_alpha, hull_grid
from .occupancy import OccupancyGrid
from .rays import make_rays
from .render import composite_samples, render_pixels
from .representations import RepField, build_field, carried_bytes
from .sampler import BoxFrame, march

__all__ = ["RepFitConfig", "fit_representation", "evaluate_representation"]


@dataclass(frozen=True)
class RepFitConfig:
    steps: int = 1500
    batch_rays: int = 4096
    lr: float = 0.04           # the encodings' values (planes, grid, hash tables), as fit's planes
    head_lr: float = 3e-3      # the heads and the pure MLP
    qat_fraction: float = 0.15
    occ_warmup: int = 128
    occ_every: int = 16
    fg_fraction: float = 0.75
    tv_weight: float = 1e-4    # on the planes and the grid, as fit's
    empty_weight: float = 1.0  # the density penalty at random points outside the visual hull, as fit's
    seed: int = 0


def render_field(field: RepField, frame: BoxFrame, occ, o, d, quant: bool, jitter: bool = False, gen=None):
    """q-space rays (N, 3) -> colour (N, 3) over white, opacity (N,)."""
    s = march(o, d, frame, occ, jitter=jitter, generator=gen)
    return composite_samples(s, s.ray, s.idx, *field(s.unit, quant), frame.step)[:2]


def fit_representation(posed: PosedImages, kind: str, budget: int, cfg: RepFitConfig, decoder=None, device=None,
                       progress=None) -> tuple[RepField, dict]:
    """Fit `kind` at `budget` bytes to the training views -> (field, info: carried bytes, seconds, rays/s, the
    training rays' PSNR over the first and the last 10 steps)."""
    device = torch.device(device or "cpu")
    gen = torch.Generator().manual_seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    field = build_field(kind, budget, cfg.seed, decoder).to(device)
    frame = BoxFrame.from_box(posed.box, device)
    bank = make_rays(posed, posed.train, frame).to(device)
    occ = OccupancyGrid(hull=hull_grid(posed)).to(device)
    groups = [{"params": p, "lr": lr, "base": lr} for p, lr in
              ((field.encoding_parameters(), cfg.lr), (field.head_parameters(), cfg.head_lr)) if p]
    opt = torch.optim.Adam(groups)
    t0, losses = time.perf_counter(), []
    for step in range(cfg.steps):
        for g in opt.param_groups:
            g["lr"] = g["base"] * 0.1 ** (step / cfg.steps)
        quant = step >= cfg.steps * (1 - cfg.qat_fraction)
        o, d, target, _, _ = bank.batch(cfg.batch_rays, cfg.fg_fraction, gen)
        color, _ = render_field(field, frame, occ.occ, o, d, quant, jitter=True, gen=gen)
        mse = F.mse_loss(color, target)
        losses.append(float(mse.detach()))
        loss = mse + cfg.tv_weight * field.tv()
        if cfg.empty_weight and occ.outside_hull:
            loss = loss + cfg.empty_weight * empty_alpha(lambda p: field(p, quant)[0], occ.hull, frame,
                                                         cfg.batch_rays // 2, gen)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        field.clamp_()
        if step + 1 >= cfg.occ_warmup and (step + 1) % cfg.occ_every == 0:
            occ.update(lambda p: field(p, quant)[0], frame.step, gen)
        if progress is not None:
            progress(step)
    seconds = time.perf_counter() - t0
    first, last = (float(np.mean(losses[sl])) for sl in (slice(0, 10), slice(-10, None)))
    return field, {"carried_bytes": carried_bytes(field), "fit_seconds": round(seconds, 1),
                   "train_psnr_first": round(float(-10 * np.log10(first)), 2),
                   "train_psnr_last": round(float(-10 * np.log10(last)), 2),
                   "rays_per_s": round(cfg.steps * cfg.batch_rays / max(seconds, 1e-9))}


@torch.no_grad()
def evaluate_representation(field: RepField, posed: PosedImages, views=None) -> dict:
    """field_psnr (mean over `views`, default the held-out ones) of the field as carried (8-bit), and the
    median milliseconds a view took to render."""
    views = posed.test if views is None else np.asarray(views)
    device = next(field.parameters()).device
    frame = BoxFrame.from_box(posed.box, device)
    occ = OccupancyGrid().to(device)   # from the field alone, as a decode finds it (no masks there)
    occ.update(lambda p: field(p, True)[0], frame.step, torch.Generator().manual_seed(0))
    cells = F.max_pool3d(occ.occ.float()[None, None], 3, stride=1, padding=1)[0, 0] > 0
    times = []

    def tick(_):
        times.append(time.perf_counter())
    times.append(time.perf_counter())
    pred, _ = render_pixels(lambda o, d: render_field(field, frame, cells, o, d, True), frame, posed.c2w[views],
                            posed.intrinsics[views], posed.width, posed.height, progress=tick)
    gt = posed.images[views]
    return {"field_psnr": float(np.mean([psnr(a, g) for a, g in zip(pred, gt)])),
            "render_ms_per_view": round(1000 * float(np.median(np.diff(times))), 1), "renders": pred}
