"""The fit's last phase chosen by what a print would give (`fit --budget auto --medium print`, `FitConfig.ending`).

A fit trains its last phase (`FitConfig.qat_fraction` of the steps) through the 8-bit rounding the snapshot
carries. Through a print, a scene can do better if that phase also sees the noise the print channel leaves
on the planes' DCT coefficients (`channel_fit.through_channel`, its noise alone): lego's 16x4 gained 0.8 dB
of e2e_psnr at `moderate` on every photo, spot's nothing (+0.2 and -0.04 dB on two seeds) and 0.1-0.4 dB less
at `mild` (`bench fit-channel`, docs/fitting.md). So the fit forks at that phase, runs both endings, and keeps
the channel ending only where the print channel's model (`budget.predicted_e2e`, the same paired noise draws for
both) expects it `MARGIN_DB` or more better: on the bench's fits the model said lego +0.86 / +0.98 dB (two
draws; measured +0.80) and spot +0.07 / +0.21 (measured -0.04).

Layouts: planes (3, C, R, R) float in [-1, 1]."""
from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

__all__ = ["MARGIN_DB", "Ending", "ending_noise", "ending_views", "fork"]

MARGIN_DB = 0.3
"""how much better the model must expect the channel ending before the fit keeps it"""


@dataclass(frozen=True)
class Ending:
    """What `fit` needs to choose its ending: the channel ending's stand-in and a scorer."""

    channel: tuple
    """(D, a, s) as `FitState.channel`: the DCT matrix, a gain of ones, the noise per coefficient"""
    score: Callable[[np.ndarray, object], float]
    """planes (3, C, R, R) float32 and the decoder they are read with (the scene's own head, when it has one) ->
    the e2e_psnr a print of them is expected to give (dB)"""


def ending_noise(res: int, channels: int, channel, device=None, scale: float = 1.0) -> tuple:
    """(D, ones, s) on `device`: the channel ending's stand-in for planes of (res, channels) through `channel`
    (`channel_fit.response_tensors` without the gain), its noise times `scale` (`FitConfig.channel_noise`)."""
    from .channel_fit import response_tensors
    return response_tensors(res, channels, device, channel=channel, gain=False, scale=scale)


def ending_views(posed, count: int = 5) -> np.ndarray:
    """About `count` of the held-out views, evenly spread: enough to compare two endings scored on the same noise
    draws (the ladder scores the kept ending on all of them)."""
    return posed.test[:: max(1, len(posed.test) // count)]


def fork(st, gen: torch.Generator):
    """A copy of a fit's state (`fit.FitState`, sharing its read-only ray bank) and of its generator."""
    twin = copy.deepcopy(st, memo={id(st.bank): st.bank})
    g = torch.Generator(device=gen.device)
    g.set_state(gen.get_state())
    return twin, g
