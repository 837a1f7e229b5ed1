"""How well a fit of a capture holds the object alone (issue 40's measures), against the capture's ground truth:
the object's true masks (undistorted as the loader reads them) and its true box."""
from __future__ import annotations

import cv2
import numpy as np
import torch

from snapshot3d.carve import grid_centres
from snapshot3d.posed import PosedImages

from .field import decode, sample_planes
from .render import occupancy_from_planes, render_pixels, render_rays
from .sampler import BoxFrame

__all__ = ["score_object", "density_share_outside_box"]


@torch.no_grad()
def density_share_outside_box(planes: torch.Tensor, decoder, box, true_box, res: int = 64) -> float:
    """Share of the planes' one-step opacity, summed over a res^3 grid of the fitted `box` (2, 3) world, that lies
    outside `true_box` (2, 3) world."""
    box, true_box = np.asarray(box, np.float64), np.asarray(true_box, np.float64)
    frame = BoxFrame.from_box(box, planes.device)
    pts = grid_centres(box, res).reshape(-1, 3)
    unit = torch.from_numpy(((pts - box.mean(0)) / ((box[1] - box[0]) / 2)).astype(np.float32)).to(planes.device)
    sigma = torch.cat([decode(sample_planes(planes, u), decoder)[0] for u in unit.split(1 << 16)])
    alpha = (1 - torch.exp(-sigma * frame.step)).cpu().numpy()
    outside = ~np.all((pts >= true_box[0]) & (pts <= true_box[1]), axis=1)
    return float(alpha[outside].sum() / max(alpha.sum(), 1e-12))


@torch.no_grad()
def score_object(planes: torch.Tensor, decoder, box, truth: PosedImages, true_box, views=None,
                 chunk: int = 8192) -> dict:
    """planes (3, C, R, R) over world `box` (2, 3), rendered over white at `views` (default truth.test) of `truth`
    (the capture read with its true masks: alpha (N, H, W) coverage, images white outside the object) ->
    object_psnr: dB inside the true mask (alpha >= 0.5), mean over views;
    white_psnr: dB of the whole view against the object on white (floaters count);
    opacity_outside: share of the planes' opacity summed over the views' pixels that falls outside the mask;
    opacity_outside_2px: the same outside the mask grown by 2 pixels (edges and the mask's own rounding forgiven);
    density_outside_box: `density_share_outside_box` against `true_box`."""
    if truth.alpha is None:
        raise ValueError("score_object needs the capture read with its true masks")
    views = truth.test if views is None else views
    frame = BoxFrame.from_box(box, planes.device)
    occ = occupancy_from_planes(planes, decoder, frame)
    views = np.asarray(views)
    rgbs, accs = render_pixels(lambda o, d: render_rays(planes, decoder, frame, occ, o, d)[:2], frame, truth.c2w[views],
                               truth.intrinsics[views], truth.width, truth.height, chunk)
    obj, white, acc_in, acc_near, acc_all = [], [], 0.0, 0.0, 0.0
    for i, rgb, acc in zip(views, rgbs, accs):
        mask, gt = truth.alpha[i] >= 0.5, truth.images[i]
        err = (rgb - gt) ** 2
        obj.append(-10 * np.log10(max(float(err[mask].mean()), 1e-10)))
        white.append(-10 * np.log10(max(float(err.mean()), 1e-10)))
        near = cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        acc_in, acc_near, acc_all = acc_in + float(acc[mask].sum()), acc_near + float(acc[near].sum()), \
            acc_all + float(acc.sum())
    return {"object_psnr": float(np.mean(obj)), "white_psnr": float(np.mean(white)),
            "opacity_outside": float(1 - acc_in / max(acc_all, 1e-12)),
            "opacity_outside_2px": float(1 - acc_near / max(acc_all, 1e-12)),
            "density_outside_box": density_share_outside_box(planes, decoder, box, true_box)}
