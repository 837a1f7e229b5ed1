"""The tri-plane field in torch: a functional core (plane sampling, decoding, compositing) and two thin
modules that hold parameters (`TriPlanes`, `Decoder`).

Coordinates: points are given box-normalised, `xyz` in [-1, 1]^3 per axis (see `sampler.to_unit`).
Plane k of `formats.PLANE_AXES` is indexed by the axis pair (a, b): its column follows axis a, its
row axis b (the `grid_sample` convention, align_corners=True, border padding).
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from snapshot3d import formats

__all__ = ["sample_planes", "decode", "activate", "composite", "TriPlanes", "Decoder", "frozen", "straight_through_8bit"]

_AXES = torch.tensor(formats.PLANE_AXES)


def sample_planes(planes: Tensor, xyz: Tensor) -> Tensor:
    """planes (3, C, R, R), xyz (N, 3) in [-1, 1] -> features (N, 3, C), bilinear."""
    assert planes.ndim == 4 and planes.shape[0] == 3 and xyz.ndim == 2 and xyz.shape[1] == 3
    grid = xyz[:, _AXES].permute(1, 0, 2).unsqueeze(1)  # (3, 1, N, 2): (x=axis a, y=axis b)
    feat = F.grid_sample(planes, grid, mode="bilinear", padding_mode="border", align_corners=True)
    return feat[:, :, 0, :].permute(2, 0, 1)  # (N, 3, C)


def decode(features: Tensor, decoder: "Decoder") -> tuple[Tensor, Tensor]:
    """features (N, 3, C) -> density sigma (N,) >= 0 per unit of normalised length, rgb (N, 3) in [0, 1]."""
    n, _, c = features.shape
    w0 = decoder.l0.weight.view(-1, 3, formats.C_MAX)[:, :, :c].reshape(-1, 3 * c)  # unused channels read 0
    h = F.relu(F.linear(features.reshape(n, 3 * c), w0, decoder.l0.bias))
    return activate(decoder.tail(h))


def activate(out: Tensor) -> tuple[Tensor, Tensor]:
    """(N, 4) density logit and rgb logits -> density sigma (N,) >= 0 (exp, clamped), rgb (N, 3) in [0, 1]."""
    return torch.exp(torch.clamp(out[:, 0], max=formats.DENSITY_CLAMP)), torch.sigmoid(out[:, 1:4])


def composite(sigma: Tensor, rgb: Tensor, delta: float | Tensor, background: float = formats.BACKGROUND):
    """Volume rendering of (N, S) densities and (N, S, 3) colours with step length `delta`.

    alpha_i = 1 - exp(-sigma_i delta_i); T_i = exp(-sum_{j<i} sigma_j delta_j), written as an exclusive
    cumulative sum (it exports to ONNX). Returns colour (N, 3) over `background`, opacity (N,), weights (N, S).
    """
    tau = sigma * delta
    trans = torch.exp(-(torch.cumsum(tau, dim=1) - tau))
    weights = trans * (1.0 - torch.exp(-tau))
    acc = weights.sum(dim=1)
    color = (weights.unsqueeze(-1) * rgb).sum(dim=1) + (1.0 - acc).unsqueeze(-1) * background
    return color, acc, weights


def straight_through_8bit(planes: Tensor) -> Tensor:
    """Round to the 8-bit codes the snapshot carries, with identity gradient."""
    lo, hi = formats.PLANE_RANGE
    q = torch.round((planes.clamp(lo, hi) - lo) / (hi - lo) * 255.0) / 255.0 * (hi - lo) + lo
    return planes + (q - planes).detach()


class TriPlanes(nn.Module):
    """Holds the (3, C, R, R) plane parameters, values kept in `formats.PLANE_RANGE`."""

    def __init__(self, resolution: int, channels: int, init_std: float = 0.1, seed: int = 0):
        super().__init__()
        g = torch.Generator().manual_seed(seed)
        self.planes = nn.Parameter(torch.randn(3, channels, resolution, resolution, generator=g) * init_std)

    @torch.no_grad()
    def clamp_(self):
        self.planes.clamp_(*formats.PLANE_RANGE)


class Decoder(nn.Module):
    """The shared MLP 3*C_MAX -> hidden (`layers` hidden layers, ReLU) -> (density logit, r, g, b): linear
    layers l0 .. l<layers>, l0 the first (linear in the plane features, which the bake exploits) and
    l<layers> the head. `tri-dec-1` is hidden 32, layers 2. Weights are stored as numpy arrays
    (`state_arrays`) so that the torch-free runtime can read them too."""

    def __init__(self, hidden: int = 32, layers: int = 2):
        super().__init__()
        assert layers >= 1
        self.hidden, self.layers = hidden, layers
        self.l0 = nn.Linear(3 * formats.C_MAX, hidden)
        for i in range(1, layers):
            setattr(self, f"l{i}", nn.Linear(hidden, hidden))
        setattr(self, f"l{layers}", nn.Linear(hidden, 4))

    def tail(self, h: Tensor) -> Tensor:
        """The layers after l0's ReLU: (N, hidden) -> (N, 4) density logit and rgb logits."""
        return self.head_out(self.hidden_out(h))

    def hidden_out(self, h: Tensor) -> Tensor:
        """l0's ReLU output (N, hidden) -> the last hidden layer's activations (N, hidden), what the head reads."""
        for i in range(1, self.layers):
            h = F.relu(getattr(self, f"l{i}")(h))
        return h

    def head_out(self, h: Tensor) -> Tensor:
        """The head, the last layer: (N, hidden) -> (N, 4) density logit and rgb logits."""
        return getattr(self, f"l{self.layers}")(h)

    def state_arrays(self) -> dict[str, np.ndarray]:
        return {k: v.detach().cpu().numpy().astype(np.float32) for k, v in self.state_dict().items()}

    @classmethod
    def from_arrays(cls, arrays: dict) -> "Decoder":
        layers = sum(1 for k in arrays if k.startswith("l") and k.endswith(".weight")) - 1
        dec = cls(hidden=int(arrays["l0.weight"].shape[0]), layers=layers)
        dec.load_state_dict({k: torch.from_numpy(np.asarray(arrays[k])) for k in dec.state_dict()})
        return dec


def frozen(dec: Decoder) -> Decoder:
    """`dec` in eval mode with no parameter requiring a gradient (in place)."""
    dec.eval()
    for p in dec.parameters():
        p.requires_grad_(False)
    return dec
