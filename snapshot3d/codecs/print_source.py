"""Source coding of the `print` medium (numpy; torch-free): a scene's planes as DCT coefficients and the
power each gets.

Each plane channel (R x R) is taken to the frequency domain by an orthonormal 2-D DCT. A scene's plane
values are smooth, so their energy sits in the low frequencies; a fixed prior spectrum `prior_spectrum(R)`
(fitted on the training scenes, in cycles per plane, so one prior serves every R) sets how much power each
coefficient gets: the linear minimum-MSE allocation for a Gaussian source over a noisy channel
(`allocate`), which gives nothing to coefficients the channel could not carry above its noise (they
restore as 0). The carriers that hold the coefficients are `print_carriers`'.

Layouts: planes (3, C, R, R) float in [-1, 1] (`formats.PLANE_NAMES` order); flat coefficients (3*C*R*R,)
float64, plane-major (plane, channel, row v, column u).
"""
from __future__ import annotations

import cv2
import numpy as np

from .media import PRINT

__all__ = ["check_print_planes", "prior_spectrum", "allocate", "random_planes", "plane_dct", "plane_idct",
           "DESIGN_NOISE", "PAYLOAD_RMS", "HOST_PSNR"]

DESIGN_NOISE = 0.03
"""noise power per unit-energy carrier, referred to the input, that the allocation is designed for: what
`moderate` photos leave once the host's interference is counted (chosen by measurement, docs/print-codec.md
"The design"; a lower value spreads the payload over more plane frequencies than the print carries)"""
PAYLOAD_RMS = 0.02
"""RMS of the payload per pixel value at strength 1 (before the host cancellation and clipping)"""
HOST_PSNR = 32.0
"""host fidelity of a print snapshot (dB): the payload's power is scaled to it"""


def check_print_planes(channels: int, res: int) -> None:
    """ValueError unless the print codec carries (3, channels, res, res) planes (`media.PRINT`'s limits)."""
    error = PRINT.plane_error(channels, res)
    if error:
        raise ValueError(error)


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
