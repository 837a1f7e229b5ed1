"""The print-and-capture channel as the print codec's carriers see it, to predict what a scene's own planes
keep through a print without printing them (numpy; `fit --budget auto --medium print` uses it).

Model: a capture's carrier readings are `gain` times what the digital snapshot's read (`print_read.
despread`), plus Gaussian noise of power `unit` times each reading's relative noise power (the factor
`despread` gives). The pilots measure both on a real capture (`measure`); `bench print-predict` takes
their medians over `moderate` captures and checks the predictions against measured restores. The model
is of the designed filters (`despread(..., combine=False)`), both on the digital copy (a clean copy has no
channel to adapt to) and on the capture: `decode` combines the bands as the pilots measure them and reads
up to 1 dB better than the model says. (A model measured through the combining receiver was tried: it
over-predicted spot's 16x4 by 2.0 dB, against 0-1.0 dB under for this one; docs/fitting.md "The print channel's model").

Why not a curve of payload size against restore_psnr: the loss depends on the scene's own plane spectrum
(lego's 48x4 restored at 19.8 dB where spot's curve said 23.9); the linear receiver's error for given
planes follows from their coefficients, the carriers and this channel."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .print_embed import embed
from .print_read import despread, restore
from .print_source import HOST_PSNR

__all__ = ["ChannelModel", "measure", "predicted_planes"]


@dataclass(frozen=True)
class ChannelModel:
    gain: float
    """capture reading / digital reading (the pilots' ratio)"""
    unit: float
    """noise power per carrier of unit relative noise power, in reading units"""


def _reading(image: np.ndarray, res: int, channels: int):
    read, factor = despread(image, res, channels, combine=False)   # the designed filters: see the module doc
    return read, factor, restore(read, factor, res, channels)[1]


def measure(snapshot: np.ndarray, capture: np.ndarray, res: int, channels: int) -> ChannelModel:
    """The channel between a digital snapshot and the rectified capture of its print ((380, 380, 3) uint8
    RGB both), from the pilots of each."""
    _, _, digital = _reading(snapshot, res, channels)
    _, factor, captured = _reading(capture, res, channels)
    return ChannelModel(captured.gain / max(digital.gain, 1e-9), captured.noise / float(np.mean(factor)))


def predicted_planes(host: np.ndarray, planes: np.ndarray, channel: ChannelModel, rng: np.random.Generator,
                     host_psnr: float = HOST_PSNR) -> np.ndarray:
    """planes (3, C, R, R) in [-1, 1] embedded in host (380, 380, 3) float RGB in [0, 1] -> the planes a
    capture through `channel` restores (float32, one draw of its noise, before 8-bit rounding)."""
    _, c, r, _ = planes.shape
    read, factor, _ = _reading(embed(host, planes, host_psnr), r, c)
    sim = channel.gain * read + np.sqrt(channel.unit * factor) * rng.standard_normal(len(read))
    return restore(sim, factor, r, c)[0]
