"""The print codec's restore network (torch): a front-end that undoes what the print did to a capture.

A printed and photographed snapshot comes back blurred, halftoned, tone-shifted and noisy. The front-end
maps the rectified capture to an estimate of the snapshot that was printed, in the bands that carry the
payload (`snapshot3d.codecs.print_carriers.PRINT_BANDS`); the fixed despreader then reads every carrier from it.
It is residual (the capture plus a learned correction that starts at zero), so at worst it is the linear
reader, and it learns what no fixed filter can: to sharpen where the noise allows and to smooth the
halftone and sensor noise away from the host's and the carriers' texture, with the context of about
100 pixels around each carrier cell. Fully convolutional: a pixel-unshuffle to cells of 4 x 4,
convolutions at 1/4 and 1/8 of the resolution, and a pixel-shuffle back.

Layouts: capture and snapshot (B, 3, H, W) float RGB in [0, 1], H and W multiples of 8. `pool_bands` /
`pool_loss`: the carriers' bands of such images, and the error the despreader sees.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from snapshot3d.codecs import bands as _bands
from snapshot3d.codecs.print_carriers import PRINT_BANDS

__all__ = ["FrontEnd", "pool_bands", "pool_loss"]

_OPP = torch.tensor(_bands.OPPONENT, dtype=torch.float32)   # RGB -> (Y, RG, YB), orthonormal rows


class FrontEnd(nn.Module):
    """capture (B, 3, H, W) -> restored snapshot (B, 3, H, W) = capture + a learned correction. `width`
    channels at 1/4 resolution, 2 * width at 1/8; `depth` 3x3 convolutions at each."""

    def __init__(self, width: int = 48, depth: int = 4):
        super().__init__()
        self.width, self.depth = width, depth
        self.inp = nn.Conv2d(48, width, 3, padding=1)
        self.fine = nn.ModuleList(nn.Conv2d(width, width, 3, padding=1) for _ in range(depth))
        self.down = nn.Conv2d(width, 2 * width, 3, stride=2, padding=1)
        self.coarse = nn.ModuleList(nn.Conv2d(2 * width, 2 * width, 3, padding=1) for _ in range(depth))
        self.up = nn.Conv2d(2 * width, 4 * width, 1)   # pixel-shuffled to 1/4 resolution
        self.mix = nn.Conv2d(2 * width, width, 3, padding=1)
        self.out = nn.Conv2d(width, 48, 3, padding=1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, x: Tensor) -> Tensor:
        h = F.leaky_relu(self.inp(F.pixel_unshuffle(x - 0.5, 4)), 0.1)
        for conv in self.fine:
            h = h + F.leaky_relu(conv(h), 0.1)
        c = F.leaky_relu(self.down(h), 0.1)
        for conv in self.coarse:
            c = c + F.leaky_relu(conv(c), 0.1)
        u = F.pixel_shuffle(self.up(c), 2)[..., :h.shape[-2], :h.shape[-1]]
        h = F.leaky_relu(self.mix(torch.cat([h, u], 1)), 0.1)
        return x + F.pixel_shuffle(self.out(h), 4) * 0.1


def haar(x: Tensor):
    a, b, c, d = x[..., 0::2, 0::2], x[..., 0::2, 1::2], x[..., 1::2, 0::2], x[..., 1::2, 1::2]
    return (a + b + c + d) / 2, {"LH": (a - b + c - d) / 2, "HL": (a + b - c - d) / 2, "HH": (a - b - c + d) / 2}


def pool_bands(img: Tensor) -> dict[str, Tensor]:
    """The carriers' bands of images (B, 3, H, W) (H, W multiples of 8, on the snapshot's 8-pixel grid):
    band name -> (B, h, w), as `snapshot3d.codecs.bands.analyse` names them."""
    opp = torch.einsum("bchw,kc->bkhw", img, _OPP.to(img.device))
    out = {}
    for k, colour in enumerate(_bands.COLOURS):
        ll = opp[:, k]
        for level in (1, 2, 3):
            if not any(b.startswith(f"{colour}{level}") for b in PRINT_BANDS):
                break
            ll, det = haar(ll)
            for o, v in det.items():
                if f"{colour}{level}{o}" in PRINT_BANDS:
                    out[f"{colour}{level}{o}"] = v
    return out


def pool_loss(estimate: Tensor, payload: Tensor, weights: dict[str, Tensor]) -> Tensor:
    """Weighted mean square error over the carriers' bands; `weights` band -> (B, h, w) (each band's
    energy weight over the channel's noise there: how much the despreader listens to each place)."""
    got, want = pool_bands(estimate), pool_bands(payload)
    num = sum((weights[b] * (got[b] - want[b]) ** 2).sum() for b in got)
    den = sum(weights[b].sum() * 1.0 for b in got)
    return num / den
