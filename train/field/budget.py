"""`fit --budget auto` (DESIGN section 4): fit a ladder of plane sizes, keep the smallest whose held-out
`field_psnr` is within `tolerance_db` of the best.

The largest rung is fitted from scratch; each smaller rung starts from the largest planes, area-
downsampled to its resolution with the leading channels kept (the decoder is trained with nested
channels, so leading channels carry the most), and is fine-tuned for a fraction of the steps.
"""
from __future__ import annotations

import time
from dataclasses import replace

import torch
import torch.nn.functional as F

from snapshot3d.posed import PosedImages
from snapshot3d.scene import dequantize_planes

from .config import LADDER, FitConfig
from .evaluate import evaluate_planes
from .fit import fit, hull_grid

__all__ = ["fit_ladder", "choose_rung"]


def choose_rung(rungs: list[dict], tolerance_db: float = 0.5) -> int:
    """Index of the smallest rung (by scene_kb) whose field_psnr is within `tolerance_db` of the best."""
    best = max(r["field_psnr"] for r in rungs)
    ok = [i for i, r in enumerate(rungs) if r["field_psnr"] >= best - tolerance_db]
    return min(ok, key=lambda i: rungs[i]["scene_kb"])


def fit_ladder(posed: PosedImages, decoder, cfg: FitConfig, ladder=LADDER, tolerance_db: float = 0.5,
               finetune_fraction: float = 0.4, log=print, progress_factory=None, device=None):
    """Returns (chosen rung index, rungs): each rung a dict with plane_res, plane_channels, scene_kb,
    field_psnr, field_ssim, fit_seconds and its `codes`."""
    from snapshot3d.scene import Orbit, Scene
    hull = hull_grid(posed)
    rungs, big = [], None
    for i, (res, ch) in enumerate(ladder):
        rcfg = replace(cfg, plane_res=res, plane_channels=ch)
        init = None
        if big is not None:
            rcfg = replace(rcfg, steps=max(100, int(cfg.steps * finetune_fraction)), lr=cfg.lr / 2, occ_warmup=0)
            init = F.interpolate(big[:, :ch], size=(res, res), mode="area")
        t0 = time.perf_counter()
        res_ = fit(posed, decoder, rcfg, init_planes=init, hull=hull, device=device,
                   progress=progress_factory(f"R={res} C={ch}", rcfg.steps) if progress_factory else None)
        seconds = time.perf_counter() - t0
        if big is None:
            big = torch.from_numpy(dequantize_planes(res_.codes))
        ev = evaluate_planes(dequantize_planes(res_.codes), decoder, posed)
        kb = Scene(codes=res_.codes, box=posed.box, orbit=Orbit(radius=1.0)).scene_kb
        rungs.append({"plane_res": res, "plane_channels": ch, "scene_kb": round(kb, 2),
                      "field_psnr": round(ev["field_psnr"], 3), "field_ssim": round(ev["field_ssim"], 4),
                      "fit_seconds": round(seconds, 1), "codes": res_.codes})
        log(f"ladder R={res} C={ch}: {kb:.1f} kB, field_psnr {ev['field_psnr']:.2f} dB, {seconds:.0f} s")
    return choose_rung(rungs, tolerance_db), rungs
