"""`fit --budget auto --medium M` (DESIGN section 4): fit a ladder of plane sizes and keep the one that gives
the best `e2e_psnr` expected through medium M: the field's own error (held-out `field_psnr`) plus what the
medium's codec loses at that payload (its `restore_psnr`, read from the codec bench's curve of payload
size against restore fidelity, `snapshot3d/assets/budget-curves.json`), added as mean square errors;
the smallest rung within `tolerance_db` of the best wins.

The largest rung is fitted from scratch; each smaller rung starts from the largest planes, area-
downsampled to its resolution with the leading channels kept (the decoder is trained with nested
channels, so leading channels carry the most), and is fine-tuned for a fraction of the steps.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import torch
import torch.nn.functional as F

from snapshot3d.posed import PosedImages
from snapshot3d.scene import dequantize_planes

from .config import LADDER, LADDER_PRINT, FitConfig
from .evaluate import evaluate_planes
from .fit import fit, hull_grid

__all__ = ["fit_ladder", "choose_rung", "codec_psnr", "expected_e2e", "ladder_for", "CURVES_FILE"]

CURVES_FILE = "budget-curves.json"


def ladder_for(medium: str | None):
    """The plane sizes a medium's ladder tries (None: the fixed-budget ladder of the field alone)."""
    return LADDER_PRINT if medium == "print" else LADDER


def codec_psnr(medium: str, values: int) -> float:
    """The restore_psnr the medium's codec gives a payload of `values` plane values, interpolated in
    log(values) on the codec bench's curve (clamped to its ends)."""
    import json

    from snapshot3d.errors import UserError
    from snapshot3d.paths import asset

    path = asset(CURVES_FILE)
    curves = json.loads(path.read_text()) if path.is_file() else {}
    if medium not in curves:
        raise UserError(f"no codec curve for medium {medium!r} in {path}; run 'snapshot3d bench codec --medium {medium}'")
    pts = sorted(curves[medium]["points"])
    return float(np.interp(np.log(values), np.log([p[0] for p in pts]), [p[1] for p in pts]))


def expected_e2e(field_psnr: float, codec_db: float) -> float:
    """The e2e_psnr of a field of `field_psnr` carried with a codec of `codec_db`: their errors add."""
    return float(-10 * np.log10(10 ** (-field_psnr / 10) + 10 ** (-codec_db / 10)))


def choose_rung(rungs: list[dict], tolerance_db: float = 0.5, key: str = "field_psnr") -> int:
    """Index of the smallest rung (by scene_kb) whose `key` (field_psnr, or e2e_expected) is within
    `tolerance_db` of the best."""
    best = max(r[key] for r in rungs)
    ok = [i for i, r in enumerate(rungs) if r[key] >= best - tolerance_db]
    return min(ok, key=lambda i: rungs[i]["scene_kb"])


def fit_ladder(posed: PosedImages, decoder, cfg: FitConfig, ladder=None, tolerance_db: float = 0.5,
               finetune_fraction: float = 0.4, log=print, progress_factory=None, device=None, medium: str | None = None):
    """Returns (chosen rung index, rungs): each rung a dict with plane_res, plane_channels, scene_kb,
    field_psnr, field_ssim, fit_seconds and its `codes`; with a `medium`, also codec_psnr (what its codec
    gives that payload) and e2e_expected, by which the rung is chosen."""
    ladder = ladder or ladder_for(medium)
    from snapshot3d.scene import Orbit, Scene
    hull = hull_grid(posed)
    rungs, big = [], None
    for i, (res, ch) in enumerate(ladder):
        rcfg = replace(cfg, plane_res=res, plane_channels=ch)
        init = None
        if big is not None:
            rcfg = replace(rcfg, steps=max(min(100, cfg.steps), int(cfg.steps * finetune_fraction)), lr=cfg.lr / 2,
                           occ_warmup=0)
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
        if medium is not None:
            c = codec_psnr(medium, int(res_.codes.size))
            rungs[-1].update(codec_psnr=round(c, 3), e2e_expected=round(expected_e2e(ev["field_psnr"], c), 3))
        log(f"ladder R={res} C={ch}: {kb:.1f} kB, field_psnr {ev['field_psnr']:.2f} dB"
            + (f", codec ({medium}) {rungs[-1]['codec_psnr']:.2f} dB, e2e expected {rungs[-1]['e2e_expected']:.2f} dB"
               if medium else "") + f", {seconds:.0f} s")
    return choose_rung(rungs, tolerance_db, "e2e_expected" if medium else "field_psnr"), rungs
