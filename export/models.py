"""The two exported graphs as thin torch modules over the functional core (`train.field`,
`train.codec_net`), so that export, parity tests and the torch reference share one set of maths.

- `RestoreGraph`: snapshot (1, 3, 380, 380) float32 RGB in [0, 1] -> secret (1, 24, 190, 190)
  (the codec's reverse pass with the learned z).
- `ShadeGraph` (the renderer's neural part): planes (3, C_MAX, R, R) float32 in [-1, 1], zero-padded
  to C_MAX channels; points (N, S, 3) box-normalised in [-1, 1]^3, S samples along each of N rays,
  front to back; delta (N, S) each sample's length (0 drops a sample: outside the box, in an empty
  cell, or padding) -> rgb (N, 3) composited over white, acc (N,) opacity. Where the samples go
  (ray-box clipping, occupancy skipping) is decided outside, in numpy (`viewer.march`).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from snapshot3d import formats
from snapshot3d.train.field import composite

__all__ = ["RestoreGraph", "ShadeGraph", "RESTORE_INPUTS", "RESTORE_OUTPUTS", "SHADE_INPUTS", "SHADE_OUTPUTS"]

RESTORE_INPUTS, RESTORE_OUTPUTS = ["snapshot"], ["secret"]
SHADE_INPUTS, SHADE_OUTPUTS = ["planes", "points", "delta"], ["rgb", "acc"]


class RestoreGraph(nn.Module):
    def __init__(self, codec):
        super().__init__()
        self.codec = codec

    def forward(self, snapshot: Tensor) -> Tensor:
        return self.codec.reverse(snapshot)[1]


def first_layer(planes: Tensor, points: Tensor, decoder) -> Tensor:
    """The decoder's first layer (before its ReLU) at points (M, 3), computed as `train.field` does
    (bilinear plane features, align_corners, border clamp, then the linear layer) but in the order that
    is fast in onnxruntime: the layer is linear, so each plane is first projected to the hidden width
    and the projected planes are read by four row gathers per plane (GridSample is slow there).
    planes (3, C_MAX, R, R) -> (M, hidden)."""
    _, c, r, _ = planes.shape
    w0 = decoder.l0.weight.view(-1, 3, c)                                   # (hidden, 3, C)
    proj = torch.einsum("kcyx,hkc->kyxh", planes, w0).reshape(3, r * r, -1)  # (3, R*R, hidden)
    out = decoder.l0.bias
    for k, (a, b) in enumerate(formats.PLANE_AXES):
        u = ((points[:, a] + 1) * 0.5 * (r - 1)).clamp(0, r - 1)
        v = ((points[:, b] + 1) * 0.5 * (r - 1)).clamp(0, r - 1)
        u0, v0 = u.floor().clamp(max=r - 2), v.floor().clamp(max=r - 2)
        fu, fv = (u - u0).unsqueeze(1), (v - v0).unsqueeze(1)
        i = (v0 * r + u0).long()
        g = proj[k]
        top = g[i] * (1 - fu) + g[i + 1] * fu
        bot = g[i + r] * (1 - fu) + g[i + r + 1] * fu
        out = out + top * (1 - fv) + bot * fv
    return out


class ShadeGraph(nn.Module):
    def __init__(self, decoder):
        super().__init__()
        self.decoder = decoder

    def forward(self, planes: Tensor, points: Tensor, delta: Tensor) -> tuple[Tensor, Tensor]:
        n, s, _ = points.shape
        h = F.relu(first_layer(planes, points.reshape(-1, 3), self.decoder))
        out = self.decoder.l2(F.relu(self.decoder.l1(h)))
        sigma = torch.exp(torch.clamp(out[:, 0], max=formats.DENSITY_CLAMP))
        rgb = torch.sigmoid(out[:, 1:4])
        color, acc, _ = composite(sigma.reshape(n, s), rgb.reshape(n, s, 3), delta, formats.BACKGROUND)
        return color, acc
