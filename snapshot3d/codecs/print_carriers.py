"""The `print` medium's carriers (numpy; torch-free): where a scene's plane coefficients sit in a snapshot,
and how a picture's brightness shapes them. Both sides build the same layout (`print_layout`).

Every carrier is a pseudo-random +-1 pattern over `chips` coefficients drawn from the whole snapshot's
detail bands (`codecs.bands`: opponent colours x two Haar levels; the coarse band is left to the host), so
each plane coefficient is averaged over many places and a glare spot or a shadow costs each a little.
Carriers use disjoint coefficients, so they are orthonormal. Pilots, carriers of known value, come first:
the decoder measures the gain and the noise of this very capture from them. The print's noise grows in the
darks, so both sides shape the carriers and their matched filters by the picture's brightness (`filters`).

Codecs: `print-1` is the linear code (one carrier per coefficient); `print-2` (what `embed` writes) also
winds the ~300 strongest coefficients onto folded carriers (`codecs.print_fold`).

Layouts: carrier values (N,) float: pilots, one per coefficient (`coef` order), then the folded
coefficients' cos carriers and their sin carriers; images (380, 380, 3) RGB float in [0, 1].
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from snapshot3d import formats

from . import bands, print_fold
from .media import PRINT
from .print_source import DESIGN_NOISE, PAYLOAD_RMS, allocate, check_print_planes, prior_spectrum

__all__ = ["PrintLayout", "print_layout", "make_layout", "carrier_chips", "band_noise", "noise_map", "filters",
           "flat", "unflat", "srgb_slope", "PRINT_BANDS", "PILOTS", "PRINT_NOISE"]

# detail bands that carry the payload, with their relative energy per coefficient: the luma band of
# 4-pixel cells, the finest luma band (horizontal and vertical) and the red-green band of 4-pixel cells.
# Chosen by measurement (docs/print-codec.md, "Dropped designs"): the finest chroma bands are blurred away by print
# and lens, the coarser (8-pixel) bands carry too much of the host's own texture, which the decoder must
# then treat as noise or the embedder must pay to cancel
PRINT_BANDS = {"Y2LH": 1.0, "Y2HL": 1.0, "Y2HH": 1.0, "Y1LH": 0.5, "Y1HL": 0.5, "RG2LH": 0.5, "RG2HL": 0.5}
PILOTS = 256
"""pilot carriers: known values from which the decoder measures gain and noise"""
_PILOT_SHARE = 0.02   # of the payload power
_SEED = 20261123


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


def flat(coeffs: dict, pool: dict[str, float]) -> np.ndarray:
    """The coefficients (band -> array, `bands.analyse`) of the bands of `pool`, as one flat pool."""
    return np.concatenate([coeffs[b].ravel() for b in pool])


def unflat(vec: np.ndarray, coeffs: dict, pool: dict[str, float]) -> dict:
    """The inverse of `flat`: `coeffs` with the bands of `pool` replaced by the flat pool `vec`."""
    out, i = dict(coeffs), 0
    for b in pool:
        n = coeffs[b].size
        out[b] = vec[i:i + n].reshape(coeffs[b].shape)
        i += n
    return out


def srgb_slope(s: np.ndarray) -> np.ndarray:
    """d(sRGB)/d(linear) at sRGB value s in [0, 1]: how much a print's linear-light noise (halftone,
    sensor) grows in sRGB, the space the snapshot is carried in (large in the darks)."""
    s = np.clip(s, 0.0, 1.0)
    dlin = np.where(s <= 0.04045, 1 / 12.92, 2.4 / 1.055 * ((s + 0.055) / 1.055) ** 1.4)
    return 1.0 / dlin


PRINT_NOISE = 3e-4
"""the print's own noise power per coefficient (halftone, paper, sensor) per unit of `srgb_slope` squared"""


def band_noise(image: np.ndarray, pool: dict[str, float] = PRINT_BANDS) -> dict[str, np.ndarray]:
    """Noise power a carrier chip meets at every coefficient of each band of `pool` (band -> (h, w)),
    estimated from an image (380, 380, 3) float sRGB in [0, 1] alone, so that the embedder (from the
    snapshot) and the decoder (from the capture) agree: the print's noise (halftone, paper, sensor) is
    even in linear light, so in sRGB it grows with the slope of the sRGB curve at the blurred grey there,
    most in the darks (`PRINT_NOISE` times the slope squared, capped at 100 times). (Counting the host's
    own texture as noise too was measured and lost: docs/print-codec.md, "Dropped designs".)"""
    grey = cv2.GaussianBlur(np.asarray(image, np.float32).mean(2), (0, 0), 2.0)
    n = formats.SNAPSHOT_SIZE
    e = n // 8 * 8   # level 3 covers the top-left e x e pixels
    maps = {1: cv2.resize(grey, (n // 2, n // 2), interpolation=cv2.INTER_AREA),
            2: cv2.resize(grey, (n // 4, n // 4), interpolation=cv2.INTER_AREA),
            3: cv2.resize(grey[:e, :e], (n // 8, n // 8), interpolation=cv2.INTER_AREA)}
    noise = {lvl: PRINT_NOISE * np.minimum(srgb_slope(m.astype(np.float64)) ** 2, 100.0) for lvl, m in maps.items()}
    return {b: noise[int(b[-3])] for b in pool}


def noise_map(image: np.ndarray, pool: dict[str, float] = PRINT_BANDS) -> np.ndarray:
    """`band_noise` flattened in the order of the carriers' pool (M,)."""
    per = band_noise(image, pool)
    return np.concatenate([per[b].ravel() for b in pool])


def filters(lay: PrintLayout, img: np.ndarray):
    """The carriers w (N, K) shaped by the brightness of `img`, the matched filters q (N, K) that read
    them (weighted by 1 / noise, <q_i, w_i> = 1) and the chips' relative noise powers (N, K)."""
    noise = noise_map(img, lay.bands)[lay.chips]
    w = lay.base / np.sqrt(noise)
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    q = w / noise
    q /= np.einsum("nk,nk->n", q, w)[:, None]
    return w, q


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
    if codec not in PRINT.codecs:
        raise ValueError(f"unknown print codec {codec!r}: this build reads {', '.join(PRINT.codecs)}")
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
