"""The exported graphs as thin torch modules over the functional core (`train.field`,
`train.codec_net`), so that export, parity tests and the torch reference share one set of maths.

- `RestoreGraph` (the file medium): snapshot (1, 3, 380, 380) float32 RGB in [0, 1] -> secret
  (1, 24, 95, 95) (the invertible codec's reverse pass with the learned z).
- The renderer's neural part, for the field on a regular grid (the viewer bakes the field once per
  decode, `viewer.bake`; where samples go and the compositing are numpy and OpenCV):
  - `ProjectGraph`: planes (3, C_MAX, R, R) float32 in [-1, 1] (zero-padded to C_MAX channels),
    interp (B, R) float32 (the bilinear weights of the grid's B coordinates per axis over the R
    texels, `viewer.bake.interp_matrix`) -> tables (3, B*B, H): the decoder's first layer (before its
    bias) read from each plane at every grid node. The first layer is linear, so each plane is
    projected to the hidden width first and then resampled: two small matrix products.
  - `FieldGraph`: tables (3, T, H), rows (M, 3) int64 (the row of each plane's table for each point)
    -> density_logit (M,) (clamped at `formats.DENSITY_CLAMP`; density = exp(logit)) and rgb (M, 3)
    in [0, 1]: the rest of the decoder, a gather and two small layers per point; and hidden (M, H), the
    last hidden layer's activations, for a scene with a head of its own (`snapshot3d.head.apply_head`).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from snapshot3d import formats

__all__ = ["RestoreGraph", "ProjectGraph", "FieldGraph", "RESTORE_INPUTS", "RESTORE_OUTPUTS", "PROJECT_INPUTS",
           "PROJECT_OUTPUTS", "FIELD_INPUTS", "FIELD_OUTPUTS"]

RESTORE_INPUTS, RESTORE_OUTPUTS = ["snapshot"], ["secret"]
PROJECT_INPUTS, PROJECT_OUTPUTS = ["planes", "interp"], ["tables"]
FIELD_INPUTS, FIELD_OUTPUTS = ["tables", "rows"], ["density_logit", "rgb", "hidden"]


class RestoreGraph(nn.Module):
    def __init__(self, codec):
        super().__init__()
        self.codec = codec

    def forward(self, snapshot: Tensor) -> Tensor:
        return self.codec.reverse(snapshot)[1]


class ProjectGraph(nn.Module):
    def __init__(self, decoder):
        super().__init__()
        self.decoder = decoder

    def forward(self, planes: Tensor, interp: Tensor) -> Tensor:
        k, c, r, _ = planes.shape
        w0 = self.decoder.l0.weight.view(-1, 3, c)                          # (H, 3, C)
        proj = torch.einsum("kcyx,hkc->khyx", planes, w0)                    # (3, H, R, R)
        tables = torch.matmul(torch.matmul(interp, proj), interp.t())        # (3, H, B, B): [.., row b, col a]
        return tables.flatten(2).transpose(1, 2)                             # (3, B*B, H)


class FieldGraph(nn.Module):
    def __init__(self, decoder):
        super().__init__()
        self.decoder = decoder

    def forward(self, tables: Tensor, rows: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        h = self.decoder.l0.bias + tables[0][rows[:, 0]] + tables[1][rows[:, 1]] + tables[2][rows[:, 2]]
        hidden = self.decoder.hidden_out(F.relu(h))
        out = self.decoder.head_out(hidden)
        return torch.clamp(out[:, 0], max=formats.DENSITY_CLAMP), torch.sigmoid(out[:, 1:4]), hidden
