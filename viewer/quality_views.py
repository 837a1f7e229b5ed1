"""The print decode's scene-aware quality estimate (issue 38 item 4): what the planes' expected error does to
*this* scene's views, found by trying it.

The print codec's pilots give the channel's gain and noise; the MMSE restore then has an expected error per
DCT coefficient (the posterior variance prior * n / (a^2 prior + n) where a coefficient is carried, its prior
where it is not), scaled so that its mean is the reading's `plane_rmse` squared. One draw of that error is
added to the restored planes, and a few small orbit views of both are rendered through a coarse bake: the
PSNR between them is the restore fidelity this scene, this payload size and this channel lead to. A flat,
smooth scene shrugs off plane noise that a detailed one cannot; a line in log10(plane_rmse) alone could not
tell them apart (it ran 2.2 dB high on lego).

numpy + the renderer's ONNX graphs (no torch). planes: (3, C, R, R) float32 in [-1, 1]."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapshot3d.cameras import orbit_cameras
from snapshot3d.codecs.print_carriers import print_layout
from snapshot3d.codecs.print_source import plane_idct, prior_spectrum
from snapshot3d.metrics import psnr
from snapshot3d.scene import dequantize_planes, quantize_planes

from .render import RenderConfig, render_views

__all__ = ["ViewsCheck", "error_spectrum", "views_psnr_expected"]


@dataclass(frozen=True)
class ViewsCheck:
    """How the estimate renders (measured against `restore_psnr` by `snapshot3d bench quality`)."""

    views: int = 4
    """orbit views compared"""
    size: int = 48
    """their size in pixels"""
    bake: int = 32
    """cells per axis of the coarse bake"""
    samples: int = 8
    """samples per pixel"""
    seed: int = 0
    """the error draw's seed (a decode is repeatable)"""


def error_spectrum(codec: str, res: int, channels: int, gain: float, noise: float, rmse: float) -> np.ndarray:
    """(3 * C * R * R,) expected squared error of each plane DCT coefficient (plane-major, as `print_layout`'s
    `coef`) after the MMSE restore at the pilots' `gain` and mean `noise` per carrier, scaled so that its mean
    is `rmse` squared (the reading's own figure, which weighs each carrier's noise)."""
    lay = print_layout(res, channels, codec)
    a = lay.scale * gain
    err = np.tile(prior_spectrum(res).ravel(), 3 * channels)
    err[lay.coef] = lay.prior * noise / (a * a * lay.prior + noise)
    return err * (rmse * rmse / max(float(err.mean()), 1e-30))


def views_psnr_expected(models, planes: np.ndarray, box, orbit, err: np.ndarray,
                        cfg: ViewsCheck = ViewsCheck()) -> float:
    """PSNR (dB) between small orbit views of `planes` and of `planes` plus one draw of the coefficient error
    `err` (`error_spectrum`), both 8-bit as a snapshot carries them. `models`: `runtime.FieldModels`."""
    rng = np.random.default_rng(cfg.seed)
    noise = plane_idct(np.sqrt(err) * rng.standard_normal(err.size), planes.shape).astype(np.float32)
    noisy = dequantize_planes(quantize_planes(np.clip(planes + noise, -1.0, 1.0)))
    c2w, intr = orbit_cameras(orbit, cfg.views, cfg.size)
    rcfg = RenderConfig(bake=cfg.bake, samples=cfg.samples)
    ref, got = (render_views(models, p, box, c2w, intr, cfg.size, cfg.size, rcfg) for p in (planes, noisy))
    return float(psnr(got, ref))
