"""An orthonormal split of an image into spatial-frequency bands (numpy; torch-free): an opponent colour
basis (luma, red-green, yellow-blue) and a three-level Haar transform. The print codec's carriers live in
its detail bands (`codecs.print_carriers`); `bench.capacity_model` measures the channel per band with
the same opponent basis.

Image: (H, W, 3) float RGB, H and W multiples of 4. Coefficients: a dict band name -> float64 array,
names "<colour><level><orientation>" with colour in (Y, RG, YB), level 1 (finest, H/2 x W/2), 2 (H/4 x
W/4) or 3, orientation LH, HL, HH; level 3 splits the even top-left part of level 2's coarse band
(2 * floor(H/8) square), so that a 380 x 380 snapshot, whose level-2 band is 95 x 95, has 47 x 47 level-3
bands. "<colour>LL3" is the coarse remainder and "<colour>LL2e" (1-D) what level 3 leaves of level 2's
coarse band (its last row and column when they are odd). Orthonormal: the squares of all coefficients sum
to the image's (so an MSE budget in pixels is the same budget in coefficients).
"""
from __future__ import annotations

import numpy as np

__all__ = ["OPPONENT", "COLOURS", "DETAIL_BANDS", "ALL_BANDS", "analyse", "synthesise", "band_shape", "haar"]

# orthonormal RGB -> (luma, red-green, yellow-blue)
OPPONENT = np.array([[1, 1, 1], [1, -1, 0], [1, 1, -2]], np.float64) / np.sqrt([[3.0], [2.0], [6.0]])
COLOURS = ("Y", "RG", "YB")
_ORIENT = ("LH", "HL", "HH")
DETAIL_BANDS = tuple(f"{c}{lvl}{o}" for c in COLOURS for lvl in (1, 2, 3) for o in _ORIENT)
ALL_BANDS = DETAIL_BANDS + tuple(f"{c}{b}" for c in COLOURS for b in ("LL3", "LL2e"))


def haar(x: np.ndarray):
    a, b, c, d = x[..., 0::2, 0::2], x[..., 0::2, 1::2], x[..., 1::2, 0::2], x[..., 1::2, 1::2]
    return (a + b + c + d) / 2, ((a - b + c - d) / 2, (a + b - c - d) / 2, (a - b - c + d) / 2)


def _ihaar(ll: np.ndarray, det) -> np.ndarray:
    lh, hl, hh = det
    h, w = ll.shape[-2:]
    out = np.empty(ll.shape[:-2] + (2 * h, 2 * w))
    out[..., 0::2, 0::2] = (ll + lh + hl + hh) / 2
    out[..., 0::2, 1::2] = (ll - lh + hl - hh) / 2
    out[..., 1::2, 0::2] = (ll + lh - hl - hh) / 2
    out[..., 1::2, 1::2] = (ll - lh - hl + hh) / 2
    return out


def band_shape(name: str, size: int) -> tuple[int, int]:
    """(h, w) of detail band `name` (level 1, 2 or 3) for a size x size image."""
    level = int(name[-3])
    s = size // 2 if level == 1 else size // 4 if level == 2 else size // 8
    return s, s


def analyse(img: np.ndarray) -> dict[str, np.ndarray]:
    """(H, W, 3) RGB -> every band (see the module doc)."""
    h, w, _ = img.shape
    if h % 4 or w % 4:
        raise ValueError(f"image sides must be multiples of 4, got {img.shape}")
    opp = (np.asarray(img, np.float64) @ OPPONENT.T).transpose(2, 0, 1)   # (3, H, W)
    ll1, d1 = haar(opp)
    ll2, d2 = haar(ll1)
    e = ll2.shape[-1] // 2 * 2
    ll3, d3 = haar(ll2[..., :e, :e])
    edge = np.concatenate([ll2[..., e:, :].reshape(3, -1), ll2[..., :e, e:].reshape(3, -1)], axis=1)
    out = {}
    for k, c in enumerate(COLOURS):
        for o, b1, b2, b3 in zip(_ORIENT, d1, d2, d3):
            out[f"{c}1{o}"], out[f"{c}2{o}"], out[f"{c}3{o}"] = b1[k], b2[k], b3[k]
        out[f"{c}LL3"], out[f"{c}LL2e"] = ll3[k], edge[k]
    return out


def synthesise(bands: dict[str, np.ndarray]) -> np.ndarray:
    """Inverse of `analyse`: every band -> (H, W, 3) float64 RGB (not clipped)."""
    ll3 = np.stack([bands[f"{c}LL3"] for c in COLOURS])
    d3 = tuple(np.stack([bands[f"{c}3{o}"] for c in COLOURS]) for o in _ORIENT)
    d2 = tuple(np.stack([bands[f"{c}2{o}"] for c in COLOURS]) for o in _ORIENT)
    n2, e = d2[0].shape[-1], 2 * ll3.shape[-1]
    ll2 = np.empty((3, n2, n2))
    ll2[..., :e, :e] = _ihaar(ll3, d3)
    edge = np.stack([bands[f"{c}LL2e"] for c in COLOURS])
    ll2[..., e:, :] = edge[:, :(n2 - e) * n2].reshape(3, n2 - e, n2)
    ll2[..., :e, e:] = edge[:, (n2 - e) * n2:].reshape(3, e, n2 - e)
    d1 = tuple(np.stack([bands[f"{c}1{o}"] for c in COLOURS]) for o in _ORIENT)
    opp = _ihaar(_ihaar(ll2, d2), d1)
    return opp.transpose(1, 2, 0) @ OPPONENT   # OPPONENT is orthogonal: its inverse is its transpose
