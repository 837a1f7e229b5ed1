"""The print decode's scene-aware quality estimate (issue 38 item 4): what the planes' expected error does to
*this* scene's views, found by trying it.

The print codec's pilots give the channel's gain and noise; the restore (`print_read.linear_weight`) then has an
expected error per DCT coefficient, scaled so that its mean is the reading's `plane_rmse` squared (the folded
coefficients' share from their unfold, `fold_error`). It has parts that act differently on a view (measured on
the bench's decodes, docs/decoder.md "The quality estimate's error model" and its third pass):
- the channel noise the restore lets through, and the carriers' gain spread (an error in proportion to each
  coefficient, `GAIN_SPREAD`): random, spread evenly over the planes;
- the signal the restore loses: drawn from the scene's own restored planes (`lost_signal`), since that error is
  the scene's own contrast and edges, which add up along a view's rays where a random error of the same
  spectrum averages out (2 to 5 dB less harm). Where a coefficient is carried, the restored coefficient shrunk
  once more by the share the restore took ((1 - w) |x|); where none is, the dropped band of a steepened copy of the
  planes, at the scene's own power there (read from the restored carried coefficients and extrapolated,
  `scene_power`, rather than the codec's prior, which ran 2.1 dB high on a smooth scene's missing frequencies
  and 1.4 dB low on a detailed one's).
Two draws of the random part are added to the restored planes, each rendered on half of a few small orbit
views, against the same views of the planes as restored: the PSNR between them is the restore fidelity this
scene, this payload size and this channel lead to. The views take 16 samples per pixel and a bake of 48 cells:
with 8 samples the renderer's own noise between two nearly equal fields put the estimate up to 3 dB low on good
captures and not on bad ones (a bias that ran with the capture's severity).

numpy + the renderer's ONNX graphs (no torch). planes: (3, C, R, R) float32 in [-1, 1]; coefficient arrays are
flat (3 * C * R * R,), plane-major as `print_layout`'s `coef`."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from snapshot3d.cameras import orbit_cameras
from snapshot3d.codecs import print_fold
from snapshot3d.codecs.print_carriers import print_layout
from snapshot3d.codecs.print_read import VIEW_PRIOR, linear_weight
from snapshot3d.codecs.print_source import plane_dct, plane_idct, prior_spectrum
from snapshot3d.metrics import psnr
from snapshot3d.scene import dequantize_planes, quantize_planes

from .render import RenderConfig, render_views

__all__ = ["ViewsCheck", "ErrorSpectrum", "GAIN_SPREAD", "error_spectrum", "fold_error", "scene_power", "lost_signal",
           "error_draw", "views_psnr_expected"]


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
    """the lost signal's spatial weight where the planes are flat, relative to its mean where they are not (the
    random draw of the lost signal, `coherent` False)"""
    coherent: bool = True
    """draw the lost signal from the scene's own planes (`lost_signal`) rather than at random: the restore shrinks
    the scene's own coefficients and drops its own edges' fine detail, and that error adds up along a view's rays
    where a random one of the same spectrum averages out (on the bench's decodes a random draw of the true error's
    own spectrum put the views 2 to 3 dB above what the true error gives)"""
    edge_steepness: float = 3.0
    """how much the steepened copy of the planes that stands for their dropped detail sharpens it (tanh gain)"""
    draws: int = 2
    """independent draws of the error, each rendered on its share of the views (view i takes draw i mod draws): the
    random part's luck shrinks at the cost of a bake per draw"""
    seed: int = 0
    """the first error draw's seed (draw d takes seed + d; a decode is repeatable)"""


@dataclass(frozen=True)
class ErrorSpectrum:
    """The planes' expected squared error per DCT coefficient, in parts (each (3 * C * R * R,) float64)."""

    noise: np.ndarray
    """the channel noise left after the restore (0 where a coefficient is not carried)"""
    lost: np.ndarray
    """the signal the restore loses: the shrunk share where carried, the prior's power where not"""
    weight: np.ndarray
    """the restore's weight w of each coefficient (`print_read.linear_weight`; the MMSE's on folded ones; 0 where
    not carried)"""
    scale: float
    """what `noise` and `lost` were multiplied by so that their mean is the reading's rmse squared"""
    spread: np.ndarray | None = None
    """the error the carriers' gain spread lets through per unit of the scene's squared coefficient,
    w^2 GAIN_SPREAD / gain^2 where a linear carrier holds the coefficient (0 on folded and dropped ones; None: none)"""
    heard: np.ndarray | None = None
    """the noise in a restored coefficient (before the scale) in units of w (1 - w) p: `VIEW_PRIOR` where a
    linear carrier holds it (w^2 n / a^2 = VIEW_PRIOR w (1 - w) p), 1 on folded ones (None: 1 everywhere, the
    MMSE's identity)"""

    def total(self) -> np.ndarray:
        return self.noise + self.lost


GAIN_SPREAD = 1e-3
"""variance of each carrier's gain about the pilots' mean (in units of the designed gain): an error in proportion to
the coefficient it carries, which the pilots, all of one small amplitude, cannot tell from noise. On the fit
scenes' decodes (spot 16x4, lego 48x4) the carriers of the largest coefficients read 0.001 to 0.01 more noise per
unit of their squared value than the pilots say; the low end is used (that excess is partly the restore's shrinking
of large coefficients, which `lost_signal` draws), and 0.001 and 0.002 scored alike on held-out photos"""


def error_spectrum(codec: str, res: int, channels: int, gain: float, noise: float, rmse: float,
                   gain_spread: float = GAIN_SPREAD) -> ErrorSpectrum:
    """The expected error of each plane DCT coefficient after the restore (`print_read.linear_weight`; the
    folded coefficients' unfold) at the pilots' `gain` and mean
    `noise` per carrier, scaled so that its mean is `rmse` squared (the reading's own figure, which weighs each
    carrier's noise); the folded coefficients' share from their unfold (`fold_error`), not from their linear
    carrier alone; and the gain spread's error per unit of squared coefficient (`ErrorSpectrum.spread`)."""
    lay = print_layout(res, channels, codec)
    a2 = (lay.scale * gain) ** 2
    lost = np.tile(prior_spectrum(res).ravel(), 3 * channels)
    left, weight = np.zeros_like(lost), np.zeros_like(lost)
    w = linear_weight(a2, lay.prior, noise)
    heard_c = np.full_like(w, VIEW_PRIOR)   # the noise in a linear reading, w^2 n / a2, in units of w (1 - w) p
    left_c, lost_c = heard_c * w * (1 - w) * lay.prior, (1 - w) ** 2 * lay.prior
    if len(lay.folded):   # the folded coefficients: the MMSE weight, and their unfold's posterior variance
        k = lay.folded
        w[k] = linear_weight(a2[k], lay.prior[k], noise, view_prior=1.0)
        v = (1.0 - w[k]) * fold_error(lay, gain, noise)
        left_c[k], lost_c[k], heard_c[k] = (1 - v) * v * lay.prior[k], v * v * lay.prior[k], 1.0
    weight[lay.coef] = w
    left[lay.coef] = left_c
    lost[lay.coef] = lost_c
    heard_all = np.zeros_like(lost)
    heard_all[lay.coef] = heard_c
    scale = rmse * rmse / max(float((left + lost).mean()), 1e-30)
    spread = np.zeros_like(lost)
    spread[lay.coef] = w * w * gain_spread / max(gain, 1e-3) ** 2
    spread[lay.coef[lay.folded]] = 0.0   # the helix reads a phase, which a gain does not move
    return ErrorSpectrum(left * scale, lost * scale, weight, scale, spread, heard_all)


def fold_error(lay, gain: float, noise: float, sample: int = 64, seed: int = 0) -> float:
    """How much the helix lowers the folded coefficients' error: the mean posterior variance of `sample` of them
    (x ~ N(0, 1), one simulated reading of each, unfolded as the reader does: `print_fold.unfold`) over the mean
    of what their linear carriers alone leave (1 - w), at the pilots' `gain` and mean `noise` per carrier. Near
    0 where the helix reads clean, near 1 where its turns are confused."""
    rng = np.random.default_rng(seed)
    j = rng.choice(len(lay.folded), min(sample, len(lay.folded)), replace=False)
    k = lay.folded[j]
    x = rng.standard_normal(len(k))
    a = lay.scale[k] * gain * np.sqrt(lay.prior[k])
    amp = gain * lay.fold_amp[j]
    n = np.full(len(k), float(noise))
    c, s = print_fold.helix(x)
    sd = np.sqrt(n)
    y = a * x + sd * rng.standard_normal(len(k))
    yc, ys = amp * c + sd * rng.standard_normal(len(k)), amp * s + sd * rng.standard_normal(len(k))
    var = print_fold.unfold(y, a, n, yc, ys, amp, n, n)[1]
    return float(np.clip(np.mean(var) / max(float(np.mean(n / (a * a + n))), 1e-30), 0.0, 1.0))


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
    h = np.ones_like(w) if err.heard is None else err.heard
    p = np.tile(prior_spectrum(res).ravel(), 3 * channels)
    f = _frequency(res, channels)
    rows, ys = [[1.0 / _PRIOR_SD[0], 0.0], [0.0, 1.0 / _PRIOR_SD[1]]], [0.0, 0.0]
    for lo, hi in zip(_BANDS[:-1], _BANDS[1:]):
        m = (w > 0) & (f >= lo) & (f < hi)
        den = float(np.sum(w[m] ** 2 * p[m]))
        if den <= 0:
            continue
        heard = w[m] * (1 - w[m]) * p[m] * h[m]   # the noise's power in r
        rho = min(max(float(np.sum(r2[m] - heard)) / den, 0.1), 10.0)
        var = 2.0 * float(np.sum((w[m] ** 2 * rho * p[m] + heard) ** 2)) / den ** 2 / rho ** 2
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


def _scene_squares(planes: np.ndarray, err: ErrorSpectrum) -> tuple[np.ndarray, np.ndarray]:
    """The restored DCT coefficients r (3 * C * R * R,) of `planes` and the scene's squared coefficients read back
    from them where carried: x^2 = (r^2 - w (1 - w) p) / w^2 (E[r^2] = w^2 x^2 + w (1 - w) p for a linear
    carrier of weight w), 0 where the noise explains r and where nothing is carried."""
    r = plane_dct(planes.astype(np.float64))
    w = err.weight
    h = np.ones_like(w) if err.heard is None else err.heard
    res, channels = planes.shape[2], planes.shape[1]
    prior = np.tile(prior_spectrum(res).ravel(), 3 * channels)
    wk = np.where(w > 0, np.maximum(w, 1e-3), 1.0)
    return r, np.where(w > 0, np.maximum(r * r - h * w * (1 - w) * prior, 0.0) / (wk * wk), 0.0)


def lost_signal(planes: np.ndarray, err: ErrorSpectrum, rho: np.ndarray, steepness: float) -> np.ndarray:
    """(3 * C * R * R,) float64 DCT coefficients of the signal the restore lost, drawn from the scene's own
    restored planes (3, C, R, R) rather than at random. Where a coefficient is carried: the scene's coefficient
    x shrunk by the linear carrier's weight w, (1 - w) x, with |x| read back from the restored r
    (`_scene_squares`), signed to shrink the planes further (the restore shrank the scene: the estimate shrinks
    the restored planes by as much again). Where none is: the dropped band of a steepened copy of the planes
    (tanh(s p) / tanh(s): the harmonics of their own edges), scaled to the lost power `err.lost * rho` of the
    dropped coefficients (`scene_power`'s rho)."""
    r, x2 = _scene_squares(planes, err)
    w = err.weight
    carried = w > 0
    out = np.where(carried, -np.sign(r) * (1.0 - w) * np.sqrt(x2 * err.scale), 0.0)
    if not carried.all():
        steep = np.tanh(steepness * planes.astype(np.float64)) / np.tanh(steepness)
        edge = np.where(carried, 0.0, plane_dct(steep))
        want = float(np.sum(np.where(carried, 0.0, err.lost * rho)))
        out += edge * np.sqrt(want / max(float(np.sum(edge * edge)), 1e-30))
    return out


def error_draw(planes: np.ndarray, err: ErrorSpectrum, cfg: ViewsCheck = ViewsCheck()) -> np.ndarray:
    """(3, C, R, R) float32: one draw of the restore's error for `planes` as restored: the channel noise and the
    gain spread's error (`err.spread` times the scene's squared coefficients) at random, spread evenly; the lost
    signal (the scene's own power where not carried, `scene_power`) from the scene's own planes (`lost_signal`,
    `cfg.coherent`), or at random where the planes have detail."""
    rng = np.random.default_rng(cfg.seed)
    rho = scene_power(planes, err)
    var = err.noise if err.spread is None else err.noise + err.spread * _scene_squares(planes, err)[1]
    noise = plane_idct(np.sqrt(var) * rng.standard_normal(var.size), planes.shape)
    if cfg.coherent:
        return (noise + plane_idct(lost_signal(planes, err, rho, cfg.edge_steepness), planes.shape)).astype(np.float32)
    lost = err.lost * rho
    loss = plane_idct(np.sqrt(lost) * rng.standard_normal(lost.size), planes.shape)
    return (noise + loss * np.sqrt(_detail(planes, cfg.detail_floor))).astype(np.float32)


def views_psnr_expected(models, planes: np.ndarray, box, orbit, err: ErrorSpectrum,
                        cfg: ViewsCheck = ViewsCheck()) -> float:
    """PSNR (dB) between small orbit views of `planes` and of `planes` plus one `error_draw` of `err`
    (`error_spectrum`), both 8-bit as a snapshot carries them. `models`: `runtime.FieldModels`."""
    if planes.ndim != 4 or planes.shape[0] != 3 or err.noise.size != planes.size:
        raise ValueError(f"planes {planes.shape} and an error spectrum of {err.noise.size} coefficients do not match")
    c2w, intr = orbit_cameras(orbit, cfg.views, cfg.size)
    rcfg = RenderConfig(bake=cfg.bake, samples=cfg.samples)
    ref = render_views(models, planes, box, c2w, intr, cfg.size, cfg.size, rcfg)
    got = np.empty_like(ref)
    for d in range(max(1, min(cfg.draws, cfg.views))):
        idx = np.arange(d, cfg.views, max(1, min(cfg.draws, cfg.views)))
        draw = error_draw(planes, err, replace(cfg, seed=cfg.seed + d))
        noisy = dequantize_planes(quantize_planes(np.clip(planes + draw, -1.0, 1.0)))
        got[idx] = render_views(models, noisy, box, c2w[idx], intr[idx], cfg.size, cfg.size, rcfg)
    return float(psnr(got, ref))
