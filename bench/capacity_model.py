"""How much a capture channel can carry (numpy only): a yardstick for the codecs under Gaussian
assumptions, measured from real snapshots and the captures `scan` makes of them (`bench capacity`,
`bench codec --medium print`, `bench print-digital`).

The channel is taken as linear per subband: a snapshot is split into an orthonormal opponent colour
basis and a 3-level orthonormal Haar transform (`subbands`); in each subband b the capture is
`y_b = g_b * x_b + n_b` with a gain g_b and a noise variance N_b per coefficient fitted by least
squares (`fit_channel`). The host is known to the embedder, so it costs no capacity (dirty-paper
coding); the embedding may add a perturbation whose mean square per pixel value is at most
D = 10^(-host_psnr / 10) (the host-fidelity target). Water-filling that power over the subbands
(`waterfill`) gives the Gaussian capacity C in bits (`capacity_bits`). By the separation theorem the
smallest mean-square error any codec can restore N plane values of variance v with is
v * 2^(-2C / N) (`best_plane_rmse`); a scene's curve of `restore_psnr` against i.i.d. plane noise
(`noise_curve`) turns that error into the best `restore_psnr` (`psnr_at`).

Approximations, so it is a yardstick, not a proof: noise that is not Gaussian carries a little more,
and a plane source that is not Gaussian compresses better than v * 2^(-2R / N); subbands coarser than
the real spectrum carry a little less than finer ones would.

Images: (H, W, 3) float RGB in [0, 1], H and W multiples of 8.
"""
from __future__ import annotations

import numpy as np

from snapshot3d.metrics import psnr
from snapshot3d.scene import dequantize_planes, quantize_planes

from .common import ViewJudge

__all__ = ["OPPONENT", "QUANT_NOISE", "subbands", "fit_channel", "waterfill", "capacity_bits", "best_plane_rmse", "LEVELS",
           "NOISE_SIGMAS", "noise_curve", "psnr_at"]

LEVELS = 3
QUANT_NOISE = 1.0 / (12 * 255.0 ** 2)
"""noise floor per coefficient: the embedding itself must be rounded to 8 bits (uniform, 1/255 steps)"""
NOISE_SIGMAS = (0.004, 0.01, 0.02, 0.04, 0.07, 0.1, 0.15, 0.2, 0.3, 0.45)
"""the i.i.d. plane noise levels of `noise_curve`"""
# orthonormal RGB -> (luma, red-green, yellow-blue): mean squares are kept, JPEG's chroma shows apart
OPPONENT = np.array([[1, 1, 1], [1, -1, 0], [1, 1, -2]], np.float64) / np.sqrt([[3.0], [2.0], [6.0]])


def haar(x: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """(h, w) -> LL (h/2, w/2) and the three detail bands, orthonormal."""
    a, b, c, d = x[0::2, 0::2], x[0::2, 1::2], x[1::2, 0::2], x[1::2, 1::2]
    return (a + b + c + d) / 2, [(a - b + c - d) / 2, (a + b - c - d) / 2, (a - b - c + d) / 2]


def subbands(img: np.ndarray, levels: int = LEVELS) -> list[np.ndarray]:
    """(H, W, 3) -> 3 * (3 * levels + 1) flat coefficient arrays: per opponent channel, the detail bands
    of levels 1..L (finest first) then LL_L. Orthonormal: their squares sum to the image's."""
    h, w, _ = img.shape
    if h % (1 << levels) or w % (1 << levels):
        raise ValueError(f"image sides must be multiples of {1 << levels}, got {img.shape}")
    opp = np.asarray(img, np.float64) @ OPPONENT.T
    out = []
    for c in range(3):
        cur, bands = opp[..., c], []
        for _ in range(levels):
            cur, det = haar(cur)
            bands += [d.ravel() for d in det]
        out += bands + [cur.ravel()]
    return out


def fit_channel(sent: np.ndarray, seen: np.ndarray, levels: int = LEVELS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per subband: gain g (K,), noise variance per coefficient N (K,), coefficient count n (K,) of
    `seen = g * sent + noise`, from a sent snapshot and its capture (both (H, W, 3) in [0, 1]).
    N is at least `QUANT_NOISE` (a lossless capture still leaves the embedding's 8-bit rounding)."""
    g, n_var, count = [], [], []
    for x, y in zip(subbands(sent, levels), subbands(seen, levels)):
        gain = float(x @ y / max(x @ x, 1e-12))
        g.append(gain)
        n_var.append(max(float(np.mean((y - gain * x) ** 2)), QUANT_NOISE))
        count.append(x.size)
    return np.array(g), np.array(n_var), np.array(count)


def waterfill(noise: np.ndarray, count: np.ndarray, budget: float) -> np.ndarray:
    """Signal power per coefficient S (K,) with sum(count * S) = budget, S = max(0, mu - noise)."""
    order = np.argsort(noise)
    nz, cz = noise[order], count[order].astype(np.float64)
    mu = nz[0]
    for k in range(1, len(nz) + 1):
        mu = (budget + np.sum(cz[:k] * nz[:k])) / np.sum(cz[:k])
        if k == len(nz) or mu <= nz[k]:
            break
    s = np.maximum(0.0, mu - noise)
    return s * budget / max(float(np.sum(count * s)), 1e-300)


def capacity_bits(gain: np.ndarray, noise: np.ndarray, count: np.ndarray, host_psnr: float) -> float:
    """Gaussian capacity (bits) of one snapshot at a host-fidelity target (dB): the perturbation's mean
    square per pixel value is at most 10^(-host_psnr/10), water-filled over the subbands."""
    budget = 10 ** (-host_psnr / 10) * float(np.sum(count))
    eff = noise / np.maximum(gain ** 2, 1e-12)  # noise referred to the input
    s = waterfill(eff, count, budget)
    return float(np.sum(count * 0.5 * np.log2(1 + s / eff)))


def best_plane_rmse(bits: float, n_values: int, variance: float) -> float:
    """Smallest RMS error N Gaussian values of `variance` can be restored with through `bits` (separation)."""
    return float(np.sqrt(variance * 2.0 ** (-2.0 * bits / n_values)))


def noise_curve(judge: ViewJudge, seed: int = 0) -> list[tuple[float, float]]:
    """(plane RMS error, restore_psnr) of the scene's planes plus i.i.d. Gaussian noise, as carried (8-bit)."""
    rng = np.random.default_rng(seed)
    planes = judge.scene.planes()
    out = []
    for sigma in NOISE_SIGMAS:
        noisy = dequantize_planes(quantize_planes(planes + rng.normal(0, sigma, planes.shape).astype(np.float32)))
        rmse = float(np.sqrt(np.mean((noisy - planes) ** 2)))
        out.append((rmse, psnr(judge.views(noisy), judge.ref)))
    return out


def psnr_at(curve: list[tuple[float, float]], rmse: float) -> float:
    """restore_psnr at a plane RMS error, interpolated on log(rmse); clamped to the measured range."""
    x = np.log([c[0] for c in curve])
    y = np.array([c[1] for c in curve])
    return float(np.interp(np.log(max(rmse, 1e-9)), x, y))
