"""Held-out measures of a fitted scene (DESIGN section 3): `field_psnr`, `field_ssim`."""
from __future__ import annotations

import numpy as np
import torch

from snapshot3d.metrics import psnr, ssim
from snapshot3d.posed import PosedImages

from .render import render_views

__all__ = ["evaluate_planes"]


def evaluate_planes(planes: np.ndarray, decoder, posed: PosedImages, views=None) -> dict:
    """Render the test views (default `posed.test`) from planes (3, C, R, R) float32; mean PSNR/SSIM."""
    views = posed.test if views is None else views
    device = next(decoder.parameters()).device
    pred = render_views(torch.from_numpy(planes).to(device), decoder, posed.box, posed.c2w[views], posed.intrinsics[views],
                        posed.width, posed.height)
    gt = posed.images[views]
    return {"field_psnr": float(np.mean([psnr(p, g) for p, g in zip(pred, gt)])),
            "field_ssim": float(np.mean([ssim(p, g) for p, g in zip(pred, gt)])), "renders": pred}
