"""The `print` medium's carriers (numpy; torch-free): where and how a scene's planes sit in a snapshot
that is printed and photographed, and how they are read back.

Source side: each plane channel (R x R) is taken to the frequency domain by an orthonormal 2-D DCT. A
scene's plane values are smooth, so their energy sits in the low frequencies; a fixed prior spectrum
`prior_spectrum(R)` (fitted on the training scenes, in cycles per plane, so one prior serves every R)
sets how much power each coefficient gets: the linear minimum-MSE allocation for a Gaussian source over
a noisy channel (`allocate`), which gives nothing to coefficients the channel could not carry above its
noise (they restore as 0). Pilots, carriers of known value, come first: the decoder measures the gain
and the noise of this very capture from them.

Channel side: every carrier is a pseudo-random +-1 pattern over `chips` coefficients drawn from the
whole snapshot's detail bands (`snapshot3d.bands`: opponent colours x two Haar levels; the coarse band
is left to the host), so each plane coefficient is averaged over many places and a glare spot or a
shadow costs each a little. Carriers use disjoint coefficients, so they are orthonormal. The embedder
knows the host, so it cancels the host's own projection on each carrier (improved spread spectrum,
Malvar and Florencio 2003): the decoder sees the carrier's value plus channel noise, not the host.
Clipping to [0, 1] and 8-bit rounding are corrected by a few projection rounds (`embed`).

Codecs: `print-1` is that linear code; `print-2` (what `embed` writes) also winds the ~300 strongest
coefficients onto folded carriers (`snapshot3d.print_fold`), a non-linear code that gains where the
capture's noise is low. Both are read (the metadata names the codec).

Layouts: planes (3, C, R, R) float in [-1, 1] (`formats.PLANE_NAMES` order); images (380, 380, 3) RGB,
uint8 or float in [0, 1]; carrier values (N,) float: pilots, one per coefficient (`coef` order), then
the folded coefficients' cos carriers and their sin carriers.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from . import bands, formats, print_fold

__all__ = ["PrintLayout", "print_layout", "make_layout", "restore_layout", "prior_spectrum", "allocate", "embed", "embed_values", "despread",
           "read_carriers", "band_weights", "band_response", "carrier_chips", "plane_dct", "plane_idct", "restore",
           "Reading", "PRINT_BANDS", "DESIGN_NOISE", "PAYLOAD_RMS", "PILOTS", "HOST_PSNR", "READ_NOISE", "cancel_share",
           "check_print_planes", "random_planes", "noise_map", "band_noise", "PRINT_NOISE"]

# detail bands that carry the payload, with their relative energy per coefficient: the luma band of
# 4-pixel cells, the finest luma band (horizontal and vertical) and the red-green band of 4-pixel cells.
# Chosen by measurement (README "The print codec"): the finest chroma bands are blurred away by print
# and lens, the coarser (8-pixel) bands carry too much of the host's own texture, which the decoder must
# then treat as noise or the embedder must pay to cancel
PRINT_BANDS = {"Y2LH": 1.0, "Y2HL": 1.0, "Y2HH": 1.0, "Y1LH": 0.5, "Y1HL": 0.5, "RG2LH": 0.5, "RG2HL": 0.5}
READ_NOISE = 0.003
"""channel noise per carrier reading (at the payload's design scale) the host cancellation is weighed
against (`moderate` photos)"""
DESIGN_NOISE = 0.03
"""noise power per unit-energy carrier, referred to the input, that the allocation is designed for: what
`moderate` photos leave once the host's interference is counted (chosen by measurement, README "The print
codec"; a lower value spreads the payload over more plane frequencies than the print carries)"""
PAYLOAD_RMS = 0.02
"""RMS of the payload per pixel value at strength 1 (before the host cancellation and clipping)"""
HOST_PSNR = 32.0
"""host fidelity of a print snapshot (dB): the payload's power is scaled to it"""
PILOTS = 256
"""pilot carriers: known values from which the decoder measures gain and noise"""
_PILOT_SHARE = 0.02   # of the payload power
_SEED = 20261123


def check_print_planes(channels: int, res: int) -> None:
    """ValueError unless the print codec carries (3, channels, res, res) planes."""
    if not (1 <= channels <= formats.C_MAX and 4 <= res <= formats.CODEC_MAX_RES):
        raise ValueError(f"the print codec carries planes of 4x4 to {formats.CODEC_MAX_RES}x{formats.CODEC_MAX_RES} "
                         f"with 1 to {formats.C_MAX} channels; this scene has {channels} channels of {res}x{res}")


def prior_spectrum(res: int) -> np.ndarray:
    """(res, res) expected square of each DCT coefficient of a plane channel (index [v, u]): a scene's
    planes as measured on fitted scenes, 15 f^-2.1 at f cycles per plane width (f >= 0.5) and 40 for the
    DC at R = 32; the same continuous spectrum at every resolution, so the coefficients of the orthonormal
    DCT grow as R^2."""
    u = np.arange(res, dtype=np.float64)
    f = np.hypot(u[None, :], u[:, None]) / 2.0          # cycles per plane width
    s = 15.0 * np.maximum(f, 0.5) ** -2.1
    s[0, 0] = 40.0
    return s * (res / 32.0) ** 2


def allocate(lam: np.ndarray, total: float, noise: float) -> np.ndarray:
    """Power per coefficient p (same shape as lam) with sum(p) = total minimising sum(lam / (1 + p / noise))
    (linear MMSE over a channel of noise `noise`): p = max(0, sqrt(lam * noise / mu) - noise)."""
    lo, hi = 1e-16, 1e16
    for _ in range(200):
        mu = np.sqrt(lo * hi)
        p = np.maximum(0.0, np.sqrt(lam * noise / mu) - noise)
        lo, hi = (mu, hi) if p.sum() > total else (lo, mu)
    return p * (total / max(p.sum(), 1e-30))


@dataclass(frozen=True)
class PrintLayout:
    """The carriers of one plane size. chips (N, K) int: coefficient indices of each carrier in the flat
    pool of its bands; base (N, K) float: the carrier's entries before the host's brightness shapes
    them (a random sign times the square root of its band's weight); coef (M,) int: the flat DCT
    coefficient (of 3*C*R*R, plane-major) each non-pilot carrier holds; scale (M,): its amplitude per
    unit coefficient at strength 1; prior (M,): the coefficient's expected square."""

    res: int
    channels: int
    chips: np.ndarray
    base: np.ndarray
    coef: np.ndarray
    scale: np.ndarray
    prior: np.ndarray
    pilot_amp: float
    pilot_signs: np.ndarray
    bands: dict[str, float] = field(default_factory=lambda: dict(PRINT_BANDS))
    """its carrier bands and their relative energies per coefficient (the codec's: `PRINT_BANDS`)"""
    folded: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    """(F,) int: indices into `coef` of the coefficients also carried on a helix (`print_fold`; none in
    `print-1`); their `scale` is the linear carrier's share"""
    fold_amp: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(F,): the helix carriers' amplitude of each folded coefficient at strength 1"""

    @property
    def carriers(self) -> int:
        return len(self.chips)


def _pool_weights(pool: dict[str, float]) -> np.ndarray:
    n = formats.SNAPSHOT_SIZE
    return np.concatenate([np.full(int(np.prod(bands.band_shape(b, n))), w) for b, w in pool.items()])


def _flat(coeffs: dict, pool: dict[str, float]) -> np.ndarray:
    return np.concatenate([coeffs[b].ravel() for b in pool])


def _unflat(vec: np.ndarray, coeffs: dict, pool: dict[str, float]) -> dict:
    out, i = dict(coeffs), 0
    for b in pool:
        n = coeffs[b].size
        out[b] = vec[i:i + n].reshape(coeffs[b].shape)
        i += n
    return out


def _srgb_slope(s: np.ndarray) -> np.ndarray:
    """d(sRGB)/d(linear) at sRGB value s in [0, 1]: how much a print's linear-light noise (halftone,
    sensor) grows in sRGB, the space the snapshot is carried in (large in the darks)."""
    s = np.clip(s, 0.0, 1.0)
    dlin = np.where(s <= 0.04045, 1 / 12.92, 2.4 / 1.055 * ((s + 0.055) / 1.055) ** 1.4)
    return 1.0 / dlin


PRINT_NOISE = 3e-4
"""the print's own noise power per coefficient (halftone, paper, sensor) per unit of `_srgb_slope` squared"""


def band_noise(image: np.ndarray, pool: dict[str, float] = PRINT_BANDS) -> dict[str, np.ndarray]:
    """Noise power a carrier chip meets at every coefficient of each band of `pool` (band -> (h, w)),
    estimated from an image (380, 380, 3) float sRGB in [0, 1] alone, so that the embedder (from the
    snapshot) and the decoder (from the capture) agree: the print's noise (halftone, paper, sensor) is
    even in linear light, so in sRGB it grows with the slope of the sRGB curve at the blurred grey there,
    most in the darks (`PRINT_NOISE` times the slope squared, capped at 100 times). (Counting the host's
    own texture as noise too was measured and lost: README "The print codec".)"""
    grey = cv2.GaussianBlur(np.asarray(image, np.float32).mean(2), (0, 0), 2.0)
    n = formats.SNAPSHOT_SIZE
    e = n // 8 * 8   # level 3 covers the top-left e x e pixels
    maps = {1: cv2.resize(grey, (n // 2, n // 2), interpolation=cv2.INTER_AREA),
            2: cv2.resize(grey, (n // 4, n // 4), interpolation=cv2.INTER_AREA),
            3: cv2.resize(grey[:e, :e], (n // 8, n // 8), interpolation=cv2.INTER_AREA)}
    noise = {lvl: PRINT_NOISE * np.minimum(_srgb_slope(m.astype(np.float64)) ** 2, 100.0) for lvl, m in maps.items()}
    return {b: noise[int(b[-3])] for b in pool}


def noise_map(image: np.ndarray, pool: dict[str, float] = PRINT_BANDS) -> np.ndarray:
    """`band_noise` flattened in the order of the carriers' pool (M,)."""
    per = band_noise(image, pool)
    return np.concatenate([per[b].ravel() for b in pool])


def carrier_chips(count: int, rng: np.random.Generator,
                  pool: dict[str, float] = PRINT_BANDS) -> tuple[np.ndarray, np.ndarray]:
    """`count` disjoint carriers over the bands of `pool`, as many chips each as fit: chips (count, K)
    int indices into the pool and their entries (count, K) (a random sign times the square root of the
    band's weight)."""
    pool_w = _pool_weights(pool)
    k = len(pool_w) // count
    if k < 1:
        raise ValueError(f"{count} carriers do not fit the snapshot's {len(pool_w)} coefficients")
    chips = rng.permutation(len(pool_w))[:count * k].reshape(count, k)
    return chips, rng.choice([-1.0, 1.0], size=chips.shape) * np.sqrt(pool_w[chips])


@lru_cache(maxsize=16)
def print_layout(res: int, channels: int, codec: str = formats.PRINT_CODEC) -> PrintLayout:
    """The carriers of (3, channels, res, res) planes for a print codec id (deterministic: both sides
    build the same)."""
    if codec not in formats.PRINT_CODECS:
        raise ValueError(f"unknown print codec {codec!r}: this build reads {', '.join(formats.PRINT_CODECS)}")
    return make_layout(res, channels, PRINT_BANDS, fold=codec != "print-1")


def make_layout(res: int, channels: int, pool: dict[str, float], fold: bool = False) -> PrintLayout:
    """The carriers of (3, channels, res, res) planes over any bands `pool` (name -> relative energy per
    coefficient; the codec's are `PRINT_BANDS`, others are bench candidates: `bench.print_bands`);
    `fold`: the strongest coefficients also get helix carriers (`print-2`)."""
    check_print_planes(channels, res)
    n = formats.SNAPSHOT_SIZE
    lam = np.tile(prior_spectrum(res).ravel(), 3 * channels)
    total = PAYLOAD_RMS ** 2 * n * n * 3
    power = allocate(lam, total * (1 - _PILOT_SHARE), DESIGN_NOISE)
    active = np.flatnonzero(power > 1e-9 * total)
    folded = np.flatnonzero(power[active] >= DESIGN_NOISE * 10 ** (print_fold.FOLD_CSNR_DB / 10)) if fold \
        else np.zeros(0, np.int64)
    rng = np.random.default_rng(_SEED + 1000 * res + channels)
    chips, w = carrier_chips(PILOTS + len(active) + 2 * len(folded), rng, pool)
    pilot_amp = float(np.sqrt(total * _PILOT_SHARE / PILOTS))
    scale = np.sqrt(power[active] / lam[active])
    scale[folded] *= np.sqrt(print_fold.FOLD_LINEAR)
    fold_amp = np.sqrt((1 - print_fold.FOLD_LINEAR) * power[active][folded])
    return PrintLayout(res, channels, chips, w, active, scale, lam[active], pilot_amp,
                       rng.choice([-1.0, 1.0], size=PILOTS), dict(pool), folded, fold_amp)


def random_planes(res: int, channels: int, rng: np.random.Generator) -> np.ndarray:
    """(3, channels, res, res) float32 planes drawn from the prior spectrum (clipped to [-1, 1]): a
    stand-in scene for training the restore network."""
    lam = prior_spectrum(res)
    coef = rng.normal(size=(3 * channels, res, res)) * np.sqrt(lam)
    return np.clip(plane_idct(coef.ravel(), (3, channels, res, res)), -1, 1).astype(np.float32)


def plane_dct(planes: np.ndarray) -> np.ndarray:
    """planes (..., R, R) -> the orthonormal 2-D DCT of every channel, flattened (float64)."""
    return np.stack([cv2.dct(p.astype(np.float64)) for p in planes.reshape(-1, *planes.shape[-2:])]).ravel()


def plane_idct(coef: np.ndarray, shape) -> np.ndarray:
    """The inverse of `plane_dct`: flat coefficients -> planes of `shape` (..., R, R), float64."""
    c = coef.reshape(-1, shape[-2], shape[-1])
    return np.stack([cv2.idct(x) for x in c]).reshape(shape)


def carrier_values(lay: PrintLayout, planes: np.ndarray, strength: float = 1.0) -> np.ndarray:
    """planes (3, C, R, R) -> what each carrier must read (N,): pilots, scaled DCT coefficients, then the
    folded coefficients' helix carriers (cos, then sin)."""
    coef = plane_dct(planes)[lay.coef]
    cos, sin = print_fold.helix(coef[lay.folded] / np.sqrt(lay.prior[lay.folded]))
    return strength * np.concatenate([lay.pilot_amp * lay.pilot_signs, coef * lay.scale,
                                      lay.fold_amp * cos, lay.fold_amp * sin])


def cancel_share(host: np.ndarray, lay: PrintLayout, host_psnr: float) -> float:
    """How much of the host's own projection on the carriers to cancel, lambda in [0, 1]: cancelling costs
    host fidelity (lambda^2 times the projections' energy), leaving it costs the reader (1 - lambda)^2
    times it as interference; the share that gives the best reading SNR for this host at this fidelity,
    against READ_NOISE. A smooth host is cancelled wholly, a busy one in part."""
    w, q = _filters(lay, np.asarray(host, np.float64))
    own = np.einsum("nk,nk->n", _flat(bands.analyse(host), lay.bands)[lay.chips], q)
    inter = float(np.mean(own ** 2))                       # per carrier
    budget = 10 ** (-host_psnr / 10) * host.size / lay.carriers
    lam = np.linspace(0.0, 1.0, 41)
    payload = budget - lam ** 2 * inter
    snr = np.where(payload > 0, payload / (READ_NOISE + (1 - lam) ** 2 * inter), -1.0)
    return float(lam[int(np.argmax(snr))])


def embed(host: np.ndarray, planes: np.ndarray, host_psnr: float = HOST_PSNR, rounds: int = 4,
          cancel: float | None = None, with_payload: bool = False, codec: str = formats.PRINT_CODEC):
    """host (380, 380, 3) float RGB in [0, 1], planes (3, C, R, R) in [-1, 1] -> snapshot (380, 380, 3)
    uint8 RGB at `host_psnr` dB from the host (the payload's power is scaled to it; the pilots tell the
    decoder the scale) whose every carrier reads its value plus what is left of the host's own projection:
    `cancel` of it is cancelled (None: `cancel_share` decides for this host), and clipping and rounding
    are corrected by `rounds` projections. `with_payload`: also the payload pattern alone (380, 380, 3)
    float32, the carriers times their values with no host (what the restore front-end learns to find).
    `codec`: the print codec id whose carriers to write."""
    _, c, r, _ = planes.shape
    lay = print_layout(r, c, codec)
    unit = carrier_values(lay, planes)
    snap, scaled = embed_values(host, lay, unit, host_psnr, rounds, cancel)
    if not with_payload:
        return snap
    w, _ = _filters(lay, snap / 255.0)
    coeffs = {b: np.zeros_like(v) for b, v in bands.analyse(snap / 255.0).items()}
    vec = _flat(coeffs, lay.bands)
    vec[lay.chips] = w * scaled[:, None]
    return snap, bands.synthesise(_unflat(vec, coeffs, lay.bands)).astype(np.float32)


def embed_values(host: np.ndarray, lay: PrintLayout, unit: np.ndarray, host_psnr: float = HOST_PSNR,
                 rounds: int = 4, cancel: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Any carrier values (N,) (pilots first) written into host (380, 380, 3) float RGB in [0, 1] at
    `host_psnr` dB (see `embed`): the snapshot (380, 380, 3) uint8 RGB and the values as scaled (N,)."""
    n = formats.SNAPSHOT_SIZE
    if host.shape != (n, n, 3):
        raise ValueError(f"host must be ({n}, {n}, 3) RGB, got {host.shape}")
    host = np.asarray(host, np.float64)
    cancel = cancel_share(host, lay, host_psnr) if cancel is None else cancel
    host8 = np.round(np.clip(host, 0, 1) * 255.0) / 255.0
    want = 10 ** (-host_psnr / 10)
    base = 0.0   # without cancelling, an empty payload costs nothing but rounding
    if cancel > 0:
        base = float(np.mean((_embed_scaled(lay, host, 0.0 * unit, rounds, cancel) / 255.0 - host8) ** 2))
        if base >= want:
            raise ValueError(f"cancelling the host alone costs more than {host_psnr} dB of host fidelity")
    scale = np.sqrt(want / max(float(np.mean(unit ** 2)) * len(unit) / host8.size, 1e-12))   # energy is preserved
    for _ in range(2):   # the payload's scale that lands on the host fidelity asked for: mse = base + s^2 P
        snap = _embed_scaled(lay, host, unit * scale, rounds, cancel)
        mse = float(np.mean((snap / 255.0 - host8) ** 2))
        scale *= np.sqrt((want - base) / max(mse - base, 1e-12))
    return _embed_scaled(lay, host, unit * scale, rounds, cancel), unit * scale


def _embed_scaled(lay: PrintLayout, host: np.ndarray, target: np.ndarray, rounds: int, cancel: float) -> np.ndarray:
    img, own = host, None
    for _ in range(rounds + 1):
        w, q = _filters(lay, img)   # as the decoder will see them in this very image
        coeffs = bands.analyse(img)
        vec = _flat(coeffs, lay.bands)
        read = np.einsum("nk,nk->n", vec[lay.chips], q)
        own = read if own is None else own   # the host's own projection, measured once
        vec[lay.chips] += w * (target + (1.0 - cancel) * own - read)[:, None]
        img = np.round(np.clip(bands.synthesise(_unflat(vec, coeffs, lay.bands)), 0.0, 1.0) * 255.0) / 255.0
    return (img * 255.0 + 0.5).astype(np.uint8)


def _filters(lay: PrintLayout, img: np.ndarray):
    """The carriers w (N, K) shaped by the brightness of `img`, the matched filters q (N, K) that read
    them (weighted by 1 / noise, <q_i, w_i> = 1) and the chips' relative noise powers (N, K)."""
    noise = noise_map(img, lay.bands)[lay.chips]
    w = lay.base / np.sqrt(noise)
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    q = w / noise
    q /= np.einsum("nk,nk->n", q, w)[:, None]
    return w, q


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
    w, q = _filters(lay, cap)
    noise = noise_map(cap, lay.bands)[lay.chips]
    chips = _flat(bands.analyse(img), lay.bands)[lay.chips]
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


def _per_band(band: np.ndarray, x: np.ndarray, nb: int) -> np.ndarray:
    """x (N, K) at chips whose bands are `band` (N, K) -> (N, nb) the sums of x over each band's chips."""
    idx = (np.arange(len(x))[:, None] * nb + band).ravel()
    return np.bincount(idx, weights=x.ravel(), minlength=len(x) * nb).reshape(len(x), nb)


def _band_fit(read: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
    w, q = _filters(lay, cap)
    band, nb = _chip_bands(lay), len(lay.bands)
    read = _per_band(band, _flat(bands.analyse(cap), lay.bands)[lay.chips] * q, nb)
    sent = _per_band(band, _flat(bands.analyse(snapshot / 255.0), lay.bands)[lay.chips] * q, nb)
    var = _per_band(band, q * q * noise_map(cap, lay.bands)[lay.chips], nb)
    gain, resid = _band_fit(read, sent)
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

    def per_band(x):   # (PILOTS, K) -> (PILOTS, nb) sums of x over each band's chips
        return _per_band(band[p], x, nb)

    shape = per_band(q[p] * w[p]) * (lay.pilot_amp * lay.pilot_signs)[:, None]   # a pilot's value per band
    read = per_band(q[p] * chips[p])
    gain, resid = _band_fit(read, shape)
    cov = resid.T @ resid / PILOTS
    cov += np.eye(nb) * 1e-3 * np.trace(cov) / nb          # a little shrinkage: 256 pilots, nb x nb
    beta = np.linalg.solve(cov, gain * np.abs(shape).mean(0))
    share = _per_band(band, q * w, nb)   # each carrier's designed response per band
    resp = share @ (beta * gain)
    if 2 * np.count_nonzero(resp > 0) <= len(resp):   # most carriers would read with the wrong sign
        return q, noise
    keep = (share @ gain) / np.where(resp > 1e-30, resp, 1e-30)
    combined = q * beta[band] * keep[:, None]
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


def restore(read: np.ndarray, factor: np.ndarray, res: int, channels: int,
            strength: float = 1.0, codec: str = formats.PRINT_CODEC) -> tuple[np.ndarray, Reading]:
    """Carrier readings (N,) and their relative noise powers (N,) (`despread` with the same `codec`) ->
    planes (3, C, R, R) float32 (the MMSE estimate, not clipped; the posterior mean for folded
    coefficients) and the pilots' `Reading` (gain; noise per carrier of average noise factor)."""
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
    est = a * lay.prior / (a * a * lay.prior + n) * y[:m]
    err = lay.prior * n / (a * a * lay.prior + n)
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
