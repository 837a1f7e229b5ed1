"""Where the planes sit in the codec's secret (numpy only: the torch trainer and the torch-free
decoder both use it).

Each plane channel (R x R) is spread over the whole wavelet grid G x G (G = `formats.CODEC_GRID`)
by separable linear interpolation, `S = U X U^T` with U (G, R); restoring is the least-squares
inverse `X = P S P^T`, P = pinv(U) (R, G), so every texel is an average over about (G / R)^2 grid
cells. The residual of S outside the span of U carries no signal; its energy measures the part of the
channel's noise that is white (`noise_estimate`); structured errors inside the span go unseen.

Layouts: planes (3, C, R, R) float in [-1, 1] (`formats.PLANE_NAMES` order); secret
(3 * CODEC_CHANNELS, G, G) float, plane-major (plane k, channel c at index k * CODEC_CHANNELS + c).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from snapshot3d import formats

from .media import FILE

__all__ = ["spread_matrix", "unspread_matrix", "planes_to_secret", "secret_to_planes", "noise_estimate",
           "SECRET_CHANNELS", "check_plane_shape"]

SECRET_CHANNELS = 3 * formats.CODEC_CHANNELS


@lru_cache(maxsize=16)
def spread_matrix(res: int, grid: int = formats.CODEC_GRID) -> np.ndarray:
    """U (grid, res) float64: linear interpolation of `res` texel centres onto `grid` cell centres
    (both spanning [0, 1], so the first and last texel sit at the grid's borders)."""
    pos = np.linspace(0.0, res - 1.0, grid)
    i0 = np.minimum(np.floor(pos).astype(int), res - 2)
    w = pos - i0
    u = np.zeros((grid, res))
    u[np.arange(grid), i0] = 1.0 - w
    u[np.arange(grid), i0 + 1] = w
    u.flags.writeable = False
    return u


@lru_cache(maxsize=16)
def unspread_matrix(res: int, grid: int = formats.CODEC_GRID) -> np.ndarray:
    """P (res, grid) float64 = pinv(U): the least-squares inverse of `spread_matrix`."""
    p = np.linalg.pinv(spread_matrix(res, grid))
    p.flags.writeable = False
    return p


def check_plane_shape(channels: int, res: int) -> None:
    """ValueError unless the codec has room for (3, channels, res, res) planes (`media.FILE`'s limits)."""
    error = FILE.plane_error(channels, res)
    if error:
        raise ValueError(error)


def planes_to_secret(planes: np.ndarray, grid: int = formats.CODEC_GRID) -> np.ndarray:
    """planes (3, C, R, R) -> secret (SECRET_CHANNELS, grid, grid) float32; missing channels are 0."""
    _, c, r, _ = planes.shape
    check_plane_shape(c, r)
    u = spread_matrix(r, grid)
    full = np.zeros((3, formats.CODEC_CHANNELS, r, r))
    full[:, :c] = planes
    return (u @ full @ u.T).reshape(SECRET_CHANNELS, grid, grid).astype(np.float32)


def secret_to_planes(secret: np.ndarray, res: int, channels: int) -> np.ndarray:
    """secret (SECRET_CHANNELS, G, G) -> planes (3, channels, res, res) float32 (not clipped)."""
    check_plane_shape(channels, res)
    p = unspread_matrix(res, secret.shape[-1])
    s = secret.reshape(3, formats.CODEC_CHANNELS, secret.shape[-2], secret.shape[-1])[:, :channels]
    return (p @ s.astype(np.float64) @ p.T).astype(np.float32)


def noise_estimate(secret: np.ndarray, res: int, channels: int) -> float:
    """RMS error of the restored plane values predicted from the secret alone (no ground truth).

    The part of each used secret channel outside the span of U is pure channel noise; assuming the
    noise is spread evenly, the part inside the span (what reaches the planes) has the same RMS per
    grid cell, and the unspread averages it over the texel's cells."""
    g = secret.shape[-1]
    u, p = spread_matrix(res, g), unspread_matrix(res, g)
    s = secret.reshape(3, formats.CODEC_CHANNELS, g, g)[:, :channels].astype(np.float64)
    planes = p @ s @ p.T
    resid = s - u @ planes @ u.T
    cell_var = float(np.mean(resid ** 2)) * g * g / max(g * g - res * res, 1)
    # variance gain of X = P S P^T for white noise in S: sum of squares of P's rows (per axis), mean
    gain = float(np.mean(np.sum(p ** 2, axis=1))) ** 2
    return float(np.sqrt(cell_var * gain))
