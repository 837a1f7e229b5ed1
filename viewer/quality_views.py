"""The print decode's scene-aware quality estimate (issue 38 item 4): what the planes' expected error does to
*this* scene's views, found by trying it.

The print codec's pilots give the channel's gain and noise; the MMSE restore then has an expected error per
DCT coefficient, scaled so that its mean is the reading's `plane_rmse` squared. It has two parts that act
differently on a view (measured on the bench's decodes, docs/decoder.md "The quality estimate's error model"):
- the channel noise the MMSE lets through, w^2 n / a^2 where a coefficient is carried (w = a^2 p / (a^2 p + n)):
  spread evenly over the planes;
- the signal the restore loses: the share (1 - w)^2 of the scene's power it shrinks away where a coefficient is
  carried, all of it where none is. The scene's power is read from the restored carried coefficients and
  extrapolated to the rest (`scene_power`) rather than taken from the codec's prior (which ran 2.1 dB high on a
  smooth scene's missing frequencies and 1.4 dB low on a detailed one's). Lost detail sits where the planes have
  detail (the real error is 2 to 2.5 times its mean at the 5% of texels with the steepest gradients, on planes of
  24 to 48), so this part is drawn in proportion to the restored planes' local gradient energy.
One draw of that error is added to the restored planes, and a few small orbit views of both are rendered: the
PSNR between them is the restore fidelity this scene, this payload size and this channel lead to. The views
take 16 samples per pixel and a bake of 48 cells: with 8 samples the renderer's own noise between two nearly
equal fields put the estimate up to 3 dB low on good captures and not on bad ones (a bias that ran with the
capture's severity).

numpy + the renderer's ONNX graphs (no torch). planes: (3, C, R, R) float32 in [-1, 1]; coefficient arrays are
flat (3 * C * R * R,), plane-major as `print_layout`'s `coef`."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapshot3d.cameras import orbit_cameras
from snapshot3d.codecs.print_carriers import print_layout
from snapshot3d.codecs.print_source import plane_dct, plane_idct, prior_spectrum
from snapshot3d.metrics import psnr
from snapshot3d.scene import dequantize_planes, quantize_planes

from .render import RenderConfig, render_views

__all__ = ["ViewsCheck", "ErrorSpectrum", "error_spectrum", "scene_power", "error_draw", "views_psnr_expected"]


@dataclass(frozen=True)
class ViewsCheck:
    """How the estimate renders (measured against `restore_psnr` by `snapshot3d bench quality`)."""

    views: int = 6
    """orbit views compared"""
    size: int = 48
    """their size in pixels"""
    bake: int = 48
    """cells per axis of the coarse bake (32 smoothed away the error of 24x24 to 48x48 planes: up to 1.5 dB high)"""
    samples: int = 16
    """samples per pixel (8 left render noise of its own: 3 dB low on good captures, a few tenths on bad ones)"""
    detail_floor: float = 0.1
    """the lost signal's spatial weight where the planes are flat, relative to its mean where they are not"""
    seed: int = 0
    """the error draw's seed (a decode is repeatable)"""


@dataclass(frozen=True)
class ErrorSpectrum:
    """The planes' expected squared error per DCT coefficient, in parts (each (3 * C * R * R,) float64)."""

    noise: np.ndarray
    """the channel noise left after the MMSE (0 where a coefficient is not carried)"""
    lost: np.ndarray
    """the signal the restore loses: the shrunk share where carried, the prior's power where not"""
    weight: np.ndarray
    """the MMSE weight w of each coefficient (0 where not carried)"""
    scale: float
    """what `noise` and `lost` were multiplied by so that their mean is the reading's rmse squared"""

    def total(self) -> np.ndarray:
        return self.noise + self.lost


def error_spectrum(codec: str, res: int, channels: int, gain: float, noise: float, rmse: float) -> ErrorSpectrum:
    """The expected error of each plane DCT coefficient after the MMSE restore at the pilots' `gain` and mean
    `noise` per carrier, scaled so that its mean is `rmse` squared (the reading's own figure, which weighs each
    carrier's noise)."""
    lay = print_layout(res, channels, codec)
    a2 = (lay.scale * gain) ** 2
    lost = np.tile(prior_spectrum(res).ravel(), 3 * channels)
    left, weight = np.zeros_like(lost), np.zeros_like(lost)
    w = a2 * lay.prior / (a2 * lay.prior + noise)
    weight[lay.coef] = w
    left[lay.coef] = w * w * noise / a2
    lost[lay.coef] = (1 - w) ** 2 * lay.prior
    scale = rmse * rmse / max(float((left + lost).mean()), 1e-30)
    return ErrorSpectrum(left * scale, lost * scale, weight, scale)


def _frequency(res: int, channels: int) -> np.ndarray:
    """(3 * C * R * R,) each coefficient's frequency in cycles per plane width (as `prior_spectrum`)."""
    u = np.arange(res)
    return np.tile((np.hypot(u[None, :], u[:, None]) / 2.0).ravel(), 3 * channels)


_BANDS = (2.0, 4.0, 6.0, 8.0, 16.0)   # cycles per plane width: the carried bands the scene's power is read in
_PRIOR_SD = (0.5, 0.3)                # the fit's prior: ln(power / prior) within ~ +-2 dB, its slope per octave


def scene_power(planes: np.ndarray, err: ErrorSpectrum) -> np.ndarray:
    """(3 * C * R * R,) the scene's power relative to the codec's prior, per coefficient: read in bands of the
    carried coefficients from 2 cycles per plane width up (where a restored coefficient r of weight w has
    E[r^2] = w^2 rho p + w (1 - w) p, so rho - 1 = sum(r^2 - w p) / sum(w^2 p)), and a line in ln(rho) against
    log2(frequency) through them, each band weighed by its estimate's precision and the line drawn towards
    rho = 1 (a noisy capture's carried coefficients say little), clipped to [0.1, 10]. Measured on the bench's
    planes of 24 to 48: the missing frequencies' power within 0.9 dB of the truth up to `moderate` (the prior was
    off by -2.1 to +1.4 dB), within 2.4 dB at `severe`."""
    res, channels = planes.shape[2], planes.shape[1]
    r2 = plane_dct(planes) ** 2
    w = err.weight
    p = np.tile(prior_spectrum(res).ravel(), 3 * channels)
    f = _frequency(res, channels)
    rows, ys = [[1.0 / _PRIOR_SD[0], 0.0], [0.0, 1.0 / _PRIOR_SD[1]]], [0.0, 0.0]
    for lo, hi in zip(_BANDS[:-1], _BANDS[1:]):
        m = (w > 0) & (f >= lo) & (f < hi)
        den = float(np.sum(w[m] ** 2 * p[m]))
        if den <= 0:
            continue
        rho = min(max(1.0 + float(np.sum(r2[m] - w[m] * p[m])) / den, 0.1), 10.0)
        var = 2.0 * float(np.sum((w[m] ** 2 * rho * p[m] + w[m] * (1 - w[m]) * p[m]) ** 2)) / den ** 2 / rho ** 2
        sw = 1.0 / np.sqrt(var)
        rows.append([sw, sw * (np.log2(np.sqrt(lo * hi)) - 3.0)])
        ys.append(sw * np.log(rho))
    c = np.linalg.lstsq(np.array(rows), np.array(ys), rcond=None)[0]
    return np.exp(np.clip(c[0] + c[1] * (np.log2(np.maximum(f, 1.0)) - 3.0), np.log(0.1), np.log(10.0)))


def _detail(planes: np.ndarray, floor: float) -> np.ndarray:
    """(3, C, R, R) each texel's share of the lost signal: its gradient energy over the plane channel's mean,
    plus `floor`, normalised to mean 1 per plane channel."""
    gy, gx = np.gradient(planes.astype(np.float64), axis=(-2, -1))
    g = gx * gx + gy * gy
    g = g / np.maximum(g.mean(axis=(-2, -1), keepdims=True), 1e-30) + floor
    return g / g.mean(axis=(-2, -1), keepdims=True)


def error_draw(planes: np.ndarray, err: ErrorSpectrum, cfg: ViewsCheck = ViewsCheck()) -> np.ndarray:
    """(3, C, R, R) float32: one draw of the restore's error for `planes` as restored: the noise spread evenly,
    the lost signal (the scene's own power where not carried, `scene_power`) where the planes have detail."""
    rng = np.random.default_rng(cfg.seed)
    lost = err.lost * scene_power(planes, err)
    noise = plane_idct(np.sqrt(err.noise) * rng.standard_normal(err.noise.size), planes.shape)
    loss = plane_idct(np.sqrt(lost) * rng.standard_normal(lost.size), planes.shape)
    return (noise + loss * np.sqrt(_detail(planes, cfg.detail_floor))).astype(np.float32)


def views_psnr_expected(models, planes: np.ndarray, box, orbit, err: ErrorSpectrum,
                        cfg: ViewsCheck = ViewsCheck()) -> float:
    """PSNR (dB) between small orbit views of `planes` and of `planes` plus one `error_draw` of `err`
    (`error_spectrum`), both 8-bit as a snapshot carries them. `models`: `runtime.FieldModels`."""
    if planes.ndim != 4 or planes.shape[0] != 3 or err.noise.size != planes.size:
        raise ValueError(f"planes {planes.shape} and an error spectrum of {err.noise.size} coefficients do not match")
    noisy = dequantize_planes(quantize_planes(np.clip(planes + error_draw(planes, err, cfg), -1.0, 1.0)))
    c2w, intr = orbit_cameras(orbit, cfg.views, cfg.size)
    rcfg = RenderConfig(bake=cfg.bake, samples=cfg.samples)
    ref, got = (render_views(models, p, box, c2w, intr, cfg.size, cfg.size, rcfg) for p in (planes, noisy))
    return float(psnr(got, ref))
