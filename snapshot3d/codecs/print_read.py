"""Reading the `print` medium's carriers back (numpy; torch-free): the designed receiver, the reference of
the restore graph (`export.print_graph`, `restore-print.onnx`).

Each carrier is read by its matched filter (shaped and weighted by the capture's brightness,
`print_carriers.filters`); the bands are combined as the pilots say this capture kept them
(`band_weights`); the pilots measure the channel's gain and noise, and the plane coefficients are a
linear estimate that shrinks less than the MMSE (`VIEW_PRIOR`; for `print-2`'s folded coefficients, the
posterior mean of `print_fold.unfold`).

Layouts: image (380, 380, 3) uint8 RGB or float in [0, 1]; readings and their relative noise powers (N,)
float in `print_carriers` order (pilots first); planes (3, C, R, R) float32, not clipped.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapshot3d import formats

from . import bands, print_fold
from .print_carriers import PILOTS, PrintLayout, filters, flat, noise_map, print_layout
from .print_source import plane_idct, prior_spectrum

__all__ = ["despread", "read_carriers", "band_response", "band_weights", "band_fit", "per_band", "Reading", "restore",
           "restore_layout", "VIEW_PRIOR", "linear_weight", "linear_error"]


def despread(image: np.ndarray, res: int, channels: int, capture: np.ndarray | None = None,
             weighted: bool = True, combine: bool = True, codec: str = formats.PRINT_CODEC) -> tuple[np.ndarray, np.ndarray]:
    """What each carrier of (3, channels, res, res) planes reads in an image: `read_carriers` of their
    layout under `codec`."""
    return read_carriers(image, print_layout(res, channels, codec), capture, weighted, combine)


def read_carriers(image: np.ndarray, lay: PrintLayout, capture: np.ndarray | None = None,
                  weighted: bool = True, combine: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """What each carrier reads in an image (380, 380, 3) (uint8, or float in [0, 1]): the readings (N,)
    and each reading's relative noise power (N,). The carriers' shapes follow the brightness of
    `capture` (default: the image itself; give the capture when `image` is the front-end's payload
    estimate). `weighted`: a matched filter that also listens less where the print is noisier (the
    darks), for a raw capture; else matched to the carriers only (the front-end has weighed the places).
    `combine` (weighted only): the bands are combined as the pilots say this capture kept them
    (`band_weights`), not as designed."""
    img = image.astype(np.float64) / 255.0 if image.dtype == np.uint8 else np.asarray(image, np.float64)
    cap = img if capture is None else (capture / 255.0 if capture.dtype == np.uint8 else capture)
    w, q = filters(lay, cap)
    noise = noise_map(cap, lay.bands)[lay.chips]
    chips = flat(bands.analyse(img), lay.bands)[lay.chips]
    if not weighted:
        q, noise = w, np.ones_like(noise)
    elif combine:
        q, noise = band_weights(lay, chips, w, q, noise)
    return np.einsum("nk,nk->n", chips, q), np.einsum("nk,nk->n", q * q, noise)


def _chip_bands(lay: PrintLayout) -> np.ndarray:
    """(N, K) int: the index in `lay.bands` of every chip's band."""
    n = formats.SNAPSHOT_SIZE
    edges = np.cumsum([int(np.prod(bands.band_shape(b, n))) for b in lay.bands])
    return np.searchsorted(edges, lay.chips, side="right")


def per_band(band: np.ndarray, x: np.ndarray, nb: int) -> np.ndarray:
    """x (N, K) at chips whose bands are `band` (N, K) -> (N, nb) the sums of x over each band's chips."""
    idx = (np.arange(len(x))[:, None] * nb + band).ravel()
    return np.bincount(idx, weights=x.ravel(), minlength=len(x) * nb).reshape(len(x), nb)


def band_fit(read: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per band, the least-squares gain (nb,) of partial readings (n, nb) on their reference (n, nb), and
    the residuals (n, nb)."""
    gain = np.einsum("nb,nb->b", read, ref) / np.maximum(np.einsum("nb,nb->b", ref, ref), 1e-30)
    return gain, read - gain * ref


def band_response(capture: np.ndarray, snapshot: np.ndarray, lay: PrintLayout) -> tuple[np.ndarray, np.ndarray]:
    """What a capture kept of each band of `lay` (bench): the gain (nb,) of every carrier's partial reading
    in that band against the digital snapshot's, and the noise power left (nb,) relative to the print noise
    model (`band_noise`). Both (380, 380, 3) uint8 RGB. gain^2 / noise is what a unit of payload energy in
    that band is worth to the combining receiver."""
    cap = capture / 255.0
    w, q = filters(lay, cap)
    band, nb = _chip_bands(lay), len(lay.bands)
    read = per_band(band, flat(bands.analyse(cap), lay.bands)[lay.chips] * q, nb)
    sent = per_band(band, flat(bands.analyse(snapshot / 255.0), lay.bands)[lay.chips] * q, nb)
    var = per_band(band, q * q * noise_map(cap, lay.bands)[lay.chips], nb)
    gain, resid = band_fit(read, sent)
    return gain, np.sum(resid ** 2, axis=0) / np.maximum(var.sum(0), 1e-30)


def band_weights(lay: PrintLayout, chips: np.ndarray, w: np.ndarray, q: np.ndarray,
                 noise: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Combining the bands as this capture kept them: a print keeps its bands unequally (blur takes the
    finest luma, a JPEG the chroma, the host's texture stays in the luma of 4-pixel cells), so each
    carrier's reading becomes a weighted sum of its per-band partial readings, with the weights that
    give the pilots' value the least noise: the pilots' per-band gains g and the covariance S of their
    per-band residuals give weights S^-1 g (the minimum-variance combiner; S is not diagonal, because
    the embedder cancelled the host's projection on the whole carrier, not on each band). chips (N, K):
    the image's coefficients under the carriers; w, q (N, K): the carriers and their matched filters;
    noise (N, K): the chips' modelled relative noise powers (returned as they are). Returns the filters
    (N, K), scaled so that each carrier's expected reading stays its value times the pilots' overall
    gain; the designed filters q when the pilots read no better through the combined ones."""
    band = _chip_bands(lay)
    nb, p = len(lay.bands), slice(0, PILOTS)

    def pilot_bands(x):   # (PILOTS, K) -> (PILOTS, nb) sums of x over each band's chips
        return per_band(band[p], x, nb)

    shape = pilot_bands(q[p] * w[p]) * (lay.pilot_amp * lay.pilot_signs)[:, None]   # a pilot's value per band
    read = pilot_bands(q[p] * chips[p])
    gain, resid = band_fit(read, shape)
    cov = resid.T @ resid / PILOTS
    cov += np.eye(nb) * 1e-3 * np.trace(cov) / nb          # a little shrinkage: 256 pilots, nb x nb
    beta = np.linalg.solve(cov, gain * np.abs(shape).mean(0))
    share = per_band(band, q * w, nb)   # each carrier's designed response per band
    resp = share @ (beta * gain)
    if 2 * np.count_nonzero(resp > 0) <= len(resp):   # most carriers would read with the wrong sign
        return q, noise
    # a carrier the combination hardly reads, or reads with the wrong sign, keeps its designed filter (scaled to
    # the rest, its noise would reach 1e54 and overflow the float32 graph: a `severe` photo in rocket, seed 1002)
    ok = resp > 1e-3 * float(np.mean(np.abs(resp)))
    keep = (share @ gain) / np.where(ok, resp, 1.0)
    combined = np.where(ok[:, None], q * beta[band] * keep[:, None], q)
    signs = lay.pilot_signs

    def pilot_snr(f):   # the pilots' SNR through filters f (scale-free: normalised first, as the float32 graph must)
        x = np.einsum("nk,nk->n", chips[p], f[p]) * signs
        x = x / max(float(np.abs(x).max()), 1e-30)
        return float(np.mean(x)) ** 2 / max(float(np.var(x)), 1e-30)

    return (combined, noise) if pilot_snr(combined) > pilot_snr(q) else (q, noise)


@dataclass(frozen=True)
class Reading:
    """What the pilots say about one capture: the channel's gain and its noise power per carrier, and the
    planes' expected RMS error that follows (no ground truth needed)."""

    gain: float
    noise: float
    plane_rmse: float


VIEW_PRIOR = 2.0
"""The linear carriers' estimate shrinks each reading as the MMSE would under a prior this many times the codec's:
it estimates the planes for the views, not for the planes' own error. The part of a coefficient that a shrink
takes away is the scene's own contrast, lost alike along every ray; the views pay several times more for it than
for noise of the same power (docs/decoder.md, "third pass"), so their error is least at less shrinkage than the
planes' own. Chosen on simulated photos of spot-print and lego-print-auto (coffee and chelsea, seeds 1000-1001) and
checked on others (two held-out hosts too, seeds 2000-2001): e2e_psnr +0.03 to +0.07 dB on spot, +0.40 to +0.42 on
lego at `moderate`, no severity worse (docs/print-codec.md, "Shrinking for the views"). 1 is the plain MMSE."""


def linear_weight(a2, prior, noise, view_prior: float = VIEW_PRIOR):
    """The weight w a linear carrier's reading gets (the estimate is w y / a for gain a, a2 = a^2): the MMSE's
    a2 p / (a2 p + n) with the prior p scaled by `view_prior` (1: the MMSE itself). Its error per coefficient is
    (1 - w)^2 p (the shrink) + w^2 n / a2 (the noise)."""
    return a2 * view_prior * prior / (a2 * view_prior * prior + noise)


def linear_error(w, prior):
    """The expected squared error of a coefficient read with weight w (`linear_weight`): the shrink (1 - w)^2 p
    plus the noise w^2 n / a2, which is VIEW_PRIOR w (1 - w) p at that weight (no n: finite when n is not)."""
    return (1 - w) * prior * (1 + (VIEW_PRIOR - 1) * w)


def restore(read: np.ndarray, factor: np.ndarray, res: int, channels: int,
            strength: float = 1.0, codec: str = formats.PRINT_CODEC) -> tuple[np.ndarray, Reading]:
    """Carrier readings (N,) and their relative noise powers (N,) (`despread` with the same `codec`) ->
    planes (3, C, R, R) float32 (the linear estimate of `linear_weight`, not clipped; the posterior mean for
    folded coefficients) and the pilots' `Reading` (gain; noise per carrier of average noise factor; the
    planes' expected rmse)."""
    return restore_layout(print_layout(res, channels, codec), read, factor, strength)


def restore_layout(lay: PrintLayout, read: np.ndarray, factor: np.ndarray,
                   strength: float = 1.0) -> tuple[np.ndarray, Reading]:
    """`restore` with any layout (`make_layout`)."""
    res, channels = lay.res, lay.channels
    pilots = read[:PILOTS] * lay.pilot_signs / strength
    gain = max(float(np.mean(pilots)) / lay.pilot_amp, 1e-3)
    unit = max(float(np.mean((pilots - gain * lay.pilot_amp) ** 2 / factor[:PILOTS])), 1e-14)
    noise = unit * factor[PILOTS:] / strength ** 2   # per carrier, in units of strength 1
    m, f = len(lay.coef), len(lay.folded)
    a, y, n = lay.scale * gain, read[PILOTS:] / strength, noise[:m]
    w = linear_weight(a * a, lay.prior, n)
    est = w / a * y[:m]
    err = linear_error(w, lay.prior)
    if f:   # the folded coefficients: the posterior mean from their linear and helix readings
        k, sd = lay.folded, np.sqrt(lay.prior[lay.folded])
        x, var = print_fold.unfold(y[k], a[k] * sd, n[k], y[m:m + f], y[m + f:], gain * lay.fold_amp,
                                   noise[m:m + f], noise[m + f:])
        est[k], err[k] = x * sd, var * lay.prior[k]
    coef = np.zeros(3 * channels * res * res)
    coef[lay.coef] = est
    missing = np.ones(coef.size, bool)
    missing[lay.coef] = False
    total_err = err.sum() + np.tile(prior_spectrum(res).ravel(), 3 * channels)[missing].sum()
    rmse = float(np.sqrt(total_err / coef.size))
    planes = plane_idct(coef, (3, channels, res, res)).astype(np.float32)
    return planes, Reading(gain, float(unit * np.mean(factor)), rmse)
