"""Held-out measures of a fitted scene (DESIGN section 3): `field_psnr`, `field_ssim`.

A capture fitted with the background model (fit --background outer) has a room in its photos that the planes do
not hold. Its views are then rendered with that model behind the planes, and scored on the object's own pixels:
where the fitted planes' opacity is at least a half (`OBJECT_OPACITY`), the only object mask such a capture has.
The restored planes of a print (`budget.predicted_e2e`) are scored on the same pixels, given as `masks`."""
from __future__ import annotations

import numpy as np
import torch

from snapshot3d.metrics import psnr, ssim
from snapshot3d.posed import PosedImages

from .render import occupancy_from_planes, render_pixels, render_views
from .sampler import BoxFrame

__all__ = ["evaluate_planes", "render_with_model", "OBJECT_OPACITY"]

OBJECT_OPACITY = 0.5


@torch.no_grad()
def render_with_model(planes: torch.Tensor, decoder, background, samples: int, posed: PosedImages, views,
                      chunk: int = 8192) -> tuple[np.ndarray, np.ndarray]:
    """Views `views` of `posed` with the planes (3, C, R, R) in front of `background` (a `background.OuterField`)
    -> RGB (V, H, W, 3) float32 in [0, 1], the planes' opacity (V, H, W) float32."""
    from .background import render_with_background
    frame = BoxFrame.from_box(posed.box, planes.device)
    occ = occupancy_from_planes(planes, decoder, frame)
    views = np.asarray(views)
    return render_pixels(lambda o, d: render_with_background(planes, decoder, frame, occ, background, o, d, samples)[:2],
                         frame, posed.c2w[views], posed.intrinsics[views], posed.width, posed.height, chunk)


def evaluate_planes(planes: np.ndarray, decoder, posed: PosedImages, views=None, background=None, samples: int = 24,
                    masks: np.ndarray | None = None, with_ssim: bool = True) -> dict:
    """Render the test views (default `posed.test`) from planes (3, C, R, R) float32; mean PSNR/SSIM. With
    `background` (an OuterField and its `samples` per segment): rendered in front of it and scored on the pixels
    of `masks` (V, H, W) bool, by default where these planes' opacity >= OBJECT_OPACITY (returned as "masks");
    its field_ssim is then the whole view's, background included, and "opacity" (V, H, W) is the planes' own.
    `with_ssim` False: no field_ssim (a PSNR-only score, as the print budget's predictions need)."""
    views = posed.test if views is None else views
    device = next(decoder.parameters()).device
    p = torch.from_numpy(planes).to(device)
    gt = posed.images[views]
    if background is None:
        pred = render_views(p, decoder, posed.box, posed.c2w[views], posed.intrinsics[views], posed.width, posed.height)
        return {"field_psnr": float(np.mean([psnr(a, g) for a, g in zip(pred, gt)])), "renders": pred,
                **_ssim(pred, gt, with_ssim)}
    pred, acc = render_with_model(p, decoder, background, samples, posed, views)
    masks = acc >= OBJECT_OPACITY if masks is None else masks
    scores = [-10 * np.log10(max(float(((a - g) ** 2)[m].mean()), 1e-10)) if m.any() else 0.0
              for a, g, m in zip(pred, gt, masks)]
    return {"field_psnr": float(np.mean(scores)), "renders": pred, "masks": masks, "opacity": acc,
            **_ssim(pred, gt, with_ssim)}


def _ssim(pred: np.ndarray, gt: np.ndarray, wanted: bool) -> dict:
    return {"field_ssim": float(np.mean([ssim(a, g) for a, g in zip(pred, gt)]))} if wanted else {}
