"""Five ways to hold a scene's field in a given number of bytes, for `snapshot3d bench fit --representations`
(issue 37 item 2: why this project uses tri-planes, and at which sizes it should not). The product carries the
first; the others exist to be measured against it.

- `triplane-shared`: the product's tri-planes (3, C, R, R), decoded by the frozen shared decoder (`tri-dec-1`,
  shipped in the app, so it costs no payload);
- `triplane`: the same planes with their own small head, fitted per scene and carried;
- `grid`: a dense (C, G, G, G) grid, trilinear, with its own head (DVGO / Plenoxels without the view term);
- `hash`: a multiresolution hash grid (Instant-NGP: L levels of T entries of F features, trilinear, the
  coarse levels indexed densely where they fit), with its own head;
- `mlp`: a pure MLP on a positional encoding of the point (NeRF without the view term).

Every value a snapshot would have to carry counts one byte (8-bit codes, one range per tensor, trained through
the rounding in the last part of the fit as the product's planes are). Points are box-normalised (N, 3) in
[-1, 1]; every field returns density sigma (N,) >= 0 per unit of normalised length and rgb (N, 3) in [0, 1],
as `field.decode` does."""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from snapshot3d import formats

from .field import activate, decode, sample_planes
from .rep_sizes import (
    HASH_FEATURES,
    HASH_LEVELS,
    HASH_MAX_RES,
    HASH_MIN_RES,
    HEAD_HIDDEN,
    KINDS,
    MLP_HIDDEN_LAYERS,
    PE_FREQS,
    RepSize,
    size_for_budget,
)

__all__ = ["KINDS", "RepSize", "size_for_budget", "RepField", "build_field", "quantize_st", "carried_bytes"]


def quantize_st(t: Tensor) -> Tensor:
    """t rounded to 256 levels over its own range (what an 8-bit code per value with one range per tensor
    carries), with identity gradient."""
    lo, hi = t.detach().min(), t.detach().max()
    scale = torch.clamp(hi - lo, min=1e-8) / 255
    q = torch.round((t.detach() - lo) / scale) * scale + lo
    return t + (q - t.detach())


class _Head(nn.Module):
    """features (N, F) -> density logit and rgb logits (N, 4)."""

    def __init__(self, features: int, hidden: int = HEAD_HIDDEN, layers: int = 2):
        super().__init__()
        dims = [features] + [hidden] * layers + [4]
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(dims[:-1], dims[1:]))

    def forward(self, x: Tensor, quant: bool) -> Tensor:
        for i, lin in enumerate(self.layers):
            w, b = (quantize_st(lin.weight), quantize_st(lin.bias)) if quant else (lin.weight, lin.bias)
            x = F.linear(x, w, b)
            if i < len(self.layers) - 1:
                x = F.relu(x)
        return x


def _hash_index(corner: Tensor, res: int, table: int) -> Tensor:
    """integer corners (..., 3) of a level of `res` cells per axis -> entries (...,) of a table of `table`:
    dense where the level's (res + 1)^3 nodes fit, else Instant-NGP's spatial hash."""
    n = res + 1
    if n ** 3 <= table:
        return corner[..., 0] + n * (corner[..., 1] + n * corner[..., 2])
    h = corner[..., 0] ^ (corner[..., 1] * 2654435761) ^ (corner[..., 2] * 805459861)
    return h % table


_CORNERS = torch.tensor([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)])


class RepField(nn.Module):
    """One representation at one size (`size_for_budget`); `forward(points (N, 3), quant)` -> sigma (N,), rgb
    (N, 3). `decoder`: the frozen shared decoder, for `triplane-shared` only."""

    def __init__(self, size: RepSize, seed: int = 0, decoder=None):
        super().__init__()
        self.size, self.decoder = size, decoder
        g = torch.Generator().manual_seed(seed)
        kind, r, c = size.kind, size.res, size.channels
        if kind in ("triplane", "triplane-shared"):
            self.values = nn.Parameter(torch.randn(3, c, r, r, generator=g) * 0.1)
        elif kind == "grid":
            self.values = nn.Parameter(torch.randn(1, c, r, r, r, generator=g) * 0.1)
        elif kind == "hash":
            self.values = nn.Parameter((torch.rand(HASH_LEVELS, r, HASH_FEATURES, generator=g) * 2 - 1) * 1e-4)
            growth = (HASH_MAX_RES / HASH_MIN_RES) ** (1 / max(1, HASH_LEVELS - 1))
            self.level_res = [int(HASH_MIN_RES * growth ** i) for i in range(HASH_LEVELS)]
        if kind == "mlp":
            self.values = None
            self.head = _Head(c, r, MLP_HIDDEN_LAYERS)
        elif kind != "triplane-shared":
            self.head = _Head({"triplane": 3 * c, "grid": c, "hash": c}[kind])
        if kind == "triplane-shared" and decoder is None:
            raise ValueError("triplane-shared needs the shared decoder")

    def tv(self) -> Tensor | float:
        """Total variation of the planes or the grid (mean squared difference of neighbours, per axis), the
        regulariser `fit` puts on the product's planes; 0 for the hash grid and the MLP."""
        v = self.values
        if self.size.kind == "hash" or v is None:
            return 0.0
        dims = range(2, v.ndim)
        return sum(((v.narrow(a, 1, v.shape[a] - 1) - v.narrow(a, 0, v.shape[a] - 1)) ** 2).mean() for a in dims)

    @torch.no_grad()
    def clamp_(self) -> None:
        """Encodings' values kept in `formats.PLANE_RANGE`, as the product's planes (their 8-bit codes' range)."""
        if self.values is not None:
            self.values.clamp_(*formats.PLANE_RANGE)

    def encoding_parameters(self) -> list:
        return [] if self.values is None else [self.values]

    def head_parameters(self) -> list:
        return [] if self.size.kind == "triplane-shared" else list(self.head.parameters())

    def features(self, pts: Tensor, quant: bool) -> Tensor:
        kind = self.size.kind
        v = self.values if self.values is None or not quant else quantize_st(self.values)
        if kind == "triplane":
            return sample_planes(v, pts).reshape(len(pts), 3 * v.shape[1])
        if kind == "grid":
            out = F.grid_sample(v, pts.view(1, -1, 1, 1, 3), mode="bilinear", padding_mode="border", align_corners=True)
            return out.view(v.shape[1], -1).t()
        if kind == "hash":
            return self._hash_features(v, pts)
        freqs = (2.0 ** torch.arange(PE_FREQS, device=pts.device)) * math.pi
        ang = pts[:, :, None] * freqs   # (N, 3, K)
        return torch.cat([pts, torch.sin(ang).reshape(len(pts), 3 * PE_FREQS), torch.cos(ang).reshape(len(pts), 3 * PE_FREQS)], 1)

    def _hash_features(self, tables: Tensor, pts: Tensor) -> Tensor:
        """All levels at once: (N, L, 8) corner entries gathered from the tables laid end to end."""
        corners = _CORNERS.to(pts.device)
        res = torch.tensor(self.level_res, dtype=pts.dtype, device=pts.device)         # (L,)
        x = (pts[:, None, :] + 1) * 0.5 * res[None, :, None]                               # (N, L, 3)
        x0 = torch.minimum(torch.floor(x), (res - 1)[None, :, None])
        w = x - x0
        c = x0.long()[:, :, None, :] + corners[None, None]                                 # (N, L, 8, 3)
        idx = torch.stack([_hash_index(c[:, i], r, tables.shape[1]) for i, r in enumerate(self.level_res)], 1)
        idx = idx + (torch.arange(len(self.level_res), device=pts.device) * tables.shape[1])[None, :, None]
        wt = torch.where(corners.bool()[None, None], w[:, :, None, :], 1 - w[:, :, None, :]).prod(-1)  # (N, L, 8)
        feat = tables.reshape(-1, tables.shape[2])[idx]                                   # (N, L, 8, F)
        return (feat * wt[..., None]).sum(2).reshape(len(pts), tables.shape[0] * tables.shape[2])

    def forward(self, pts: Tensor, quant: bool = False) -> tuple[Tensor, Tensor]:
        if self.size.kind == "triplane-shared":
            v = self.values if not quant else quantize_st(self.values)
            return decode(sample_planes(v, pts), self.decoder)
        return activate(self.head(self.features(pts, quant), quant))


def build_field(kind: str, budget: int, seed: int = 0, decoder=None) -> RepField:
    return RepField(size_for_budget(kind, budget), seed, decoder)


def carried_bytes(field: RepField) -> int:
    """The parameters a snapshot of `field` carries, at one byte each (the shared decoder not counted)."""
    own = field.encoding_parameters() + field.head_parameters()
    return int(sum(p.numel() for p in own))
