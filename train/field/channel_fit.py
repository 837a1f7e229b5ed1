"""A differentiable stand-in for what the print codec does to a scene's planes, for the last phase of a fit
(`FitConfig.channel_fraction`; `fit --medium print`).

Per DCT coefficient k of a plane channel (the print codec's source coding: `print_source.plane_dct`), a
print and its capture restore `a_k * x_k + s_k * n` with n ~ N(0, 1): `a_k` the receiver's MMSE shrinkage,
`s_k` the rest of its error. Both are measured once per plane size (`channel_response`, numpy) by
regression over simulations of the channel's model (`print_channel.predicted_planes`, the model that
`fit --budget auto --medium print` predicts with) on planes drawn from the codec's prior spectrum, in
the bundled hosts `curves.PREDICT_HOSTS`. `through_channel` applies them in torch (the DCT as a matrix
product). The responses at the print ladder's sizes for the channel of budget-curves.json are shipped
(`snapshot3d/assets/channel-responses.npz`, `write_stored_responses`, rewritten by `bench print-predict` with the
channel): measuring them costs a fit about 2 s per size. A channel or size they were not stored for is measured.
The fit uses the noise alone unless `FitConfig.channel_gain`: with the gain, the fit boosts the shrunk
frequencies and lost 0.2 dB of e2e_psnr at `moderate` (spot 16x4, `bench fit-channel`).

Layouts: planes (3, C, R, R) float in [-1, 1]; responses (R, R) float32, index [v, u] as `plane_dct`.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

__all__ = ["channel_response", "dct_matrix", "through_channel", "response_tensors", "RESPONSES_FILE",
           "stored_responses", "write_stored_responses"]

RESPONSES_FILE = "channel-responses.npz"
DRAWS = 4   # plane sets per host in the shipped responses


def channel_response(res: int, channels: int, channel, hosts, draws: int = DRAWS, seed: int = 0):
    """(a, s), each (res, res) float32: per DCT coefficient, the least-squares gain of the restored
    coefficient on the sent one and the RMS of what is left, over `draws` random plane sets per host
    (host specs as `load_host` takes them), pooled over the 3 * channels plane channels."""
    from snapshot3d.codecs.print_channel import predicted_planes
    from snapshot3d.codecs.print_source import plane_dct, random_planes
    from snapshot3d.scanner.backgrounds import load_host

    rng = np.random.default_rng(seed)
    xs, ys = [], []
    for h in hosts:
        host = load_host(h)
        for _ in range(draws):
            x = random_planes(res, channels, rng)
            y = predicted_planes(host, x, channel, rng)
            xs.append(plane_dct(x).reshape(-1, res, res))
            ys.append(plane_dct(y).reshape(-1, res, res))
    x, y = np.concatenate(xs), np.concatenate(ys)                # (n, R, R)
    a = (x * y).sum(0) / np.maximum((x * x).sum(0), 1e-12)
    s = np.sqrt(np.mean((y - a * x) ** 2, axis=0))
    return a.astype(np.float32), s.astype(np.float32)


def _response_key(channel) -> str:
    """What the shipped responses were measured for: the print codec, the channel, the hosts and the draws."""
    from snapshot3d import formats

    from .curves import PREDICT_HOSTS
    return (f"{formats.PRINT_CODEC}|gain={float(channel.gain)!r}|unit={float(channel.unit)!r}|"
            f"hosts={','.join(PREDICT_HOSTS)}|draws={DRAWS}|seed=0")


@lru_cache(maxsize=1)
def _stored() -> dict:
    from snapshot3d.paths import asset

    path = asset(RESPONSES_FILE)
    if not path.is_file():
        return {}
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def stored_responses(res: int, channels: int, channel) -> tuple[np.ndarray, np.ndarray] | None:
    """The shipped (a, s) for planes of (res, channels) through `channel`, or None where they were stored for
    another channel (or codec, hosts, draws) or not at this size."""
    table = _stored()
    if "key" not in table or str(table["key"]) != _response_key(channel) or f"a_{res}x{channels}" not in table:
        return None
    return table[f"a_{res}x{channels}"], table[f"s_{res}x{channels}"]


def write_stored_responses(channel, sizes=None) -> Path:
    """Measure the responses at `sizes` (default the print ladder's) through `channel` and ship them."""
    from snapshot3d.paths import asset

    from .config import LADDER_PRINT
    from .curves import PREDICT_HOSTS

    arrays = {"key": np.array(_response_key(channel))}
    for res, channels in sizes or LADDER_PRINT:
        arrays[f"a_{res}x{channels}"], arrays[f"s_{res}x{channels}"] = channel_response(res, channels, channel,
                                                                                        PREDICT_HOSTS)
    path = asset(RESPONSES_FILE)
    np.savez_compressed(path, **arrays)
    _stored.cache_clear()
    return path


@lru_cache(maxsize=16)
def _cached_response(res: int, channels: int, channel) -> tuple[np.ndarray, np.ndarray]:
    from .curves import PREDICT_HOSTS
    return stored_responses(res, channels, channel) or channel_response(res, channels, channel, PREDICT_HOSTS)


def response_tensors(res: int, channels: int, device=None, channel=None, gain: bool = True,
                     scale: float = 1.0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
    """(D, a, s) on `device` for planes of (res, channels) through `channel` (a hashable `print_channel.
    ChannelModel`; None: the one measured in budget-curves.json, and None back without one): D the (R, R)
    orthonormal DCT matrix, a and s (R, R); a all ones unless `gain`, s times `scale`. The response is measured
    once per size and channel."""
    from .curves import print_channel

    channel = channel or print_channel()
    if channel is None:
        return None
    a, s = (torch.from_numpy(x) for x in _cached_response(res, channels, channel))
    a = a if gain else torch.ones_like(a)
    return tuple(t.to(device) for t in (dct_matrix(res), a, scale * s))


def dct_matrix(res: int) -> torch.Tensor:
    """(R, R) float32 orthonormal DCT-II matrix D: cv2.dct(X) == D @ X @ D.T."""
    k = np.arange(res)[:, None]
    n = np.arange(res)[None, :]
    d = np.sqrt(2.0 / res) * np.cos(np.pi * (2 * n + 1) * k / (2 * res))
    d[0] /= np.sqrt(2.0)
    return torch.from_numpy(d.astype(np.float32))


def through_channel(planes: torch.Tensor, d: torch.Tensor, a: torch.Tensor, s: torch.Tensor,
                    gen: torch.Generator | None = None) -> torch.Tensor:
    """planes (3, C, R, R) -> one draw of what the print restores of them (same shape; differentiable in
    `planes`): each channel's DCT coefficients scaled by `a` plus Gaussian noise of std `s` (the noise drawn
    on the CPU from `gen`)."""
    coef = d @ planes @ d.T
    noise = torch.randn(planes.shape, generator=gen).to(planes.device)
    return d.T @ (a * coef + s * noise) @ d
