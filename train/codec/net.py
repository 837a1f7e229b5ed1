"""The invertible hiding network (HiNet-style): a Haar-wavelet split of the host, affine coupling
blocks between a host branch and a secret branch, and a learned constant standing in for the lost
part z on the way back.

Layouts: host and snapshot (B, 3, H, W) RGB in [0, 1], H and W divisible by 2^levels; secret
(B, Cs, H/2^levels, W/2^levels) on the host's wavelet grid (see `snapshot3d.codecs.file_layout`). Forward: (host, secret) -> (snapshot, z);
reverse: snapshot -> (host estimate, secret estimate). Everything is plain convolution, slicing and
reshapes, so the reverse pass exports to ONNX.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

__all__ = ["haar", "ihaar", "DenseSubnet", "Coupling", "CodecNet"]


def haar(x: Tensor) -> Tensor:
    """Orthonormal Haar split: (B, C, H, W) -> (B, 4C, H/2, W/2), bands [LL, LH, HL, HH] of C channels each."""
    b, c, h, w = x.shape
    x = x.reshape(b, c, h // 2, 2, w // 2, 2)
    p, q, r, s = x[:, :, :, 0, :, 0], x[:, :, :, 0, :, 1], x[:, :, :, 1, :, 0], x[:, :, :, 1, :, 1]
    return 0.5 * torch.cat([p + q + r + s, p - q + r - s, p + q - r - s, p - q - r + s], dim=1)


def ihaar(y: Tensor) -> Tensor:
    """Inverse of `haar`: (B, 4C, h, w) -> (B, C, 2h, 2w)."""
    b, c4, h, w = y.shape
    ll, lh, hl, hh = y.reshape(b, 4, c4 // 4, h, w).unbind(1)
    p = ll + lh + hl + hh
    q = ll - lh + hl - hh
    r = ll + lh - hl - hh
    s = ll - lh - hl + hh
    top = torch.stack([p, q], dim=-1)      # (b, c, h, w, 2)
    bot = torch.stack([r, s], dim=-1)
    return 0.5 * torch.stack([top, bot], dim=3).reshape(b, c4 // 4, 2 * h, 2 * w)


class DenseSubnet(nn.Module):
    """Densely connected 3x3 convolutions (each layer sees the input and every earlier layer);
    the last layer starts at zero so each coupling block starts as the identity."""

    def __init__(self, cin: int, cout: int, width: int, layers: int):
        super().__init__()
        self.hidden = nn.ModuleList(nn.Conv2d(cin + i * width, width, 3, padding=1) for i in range(layers - 1))
        self.out = nn.Conv2d(cin + (layers - 1) * width, cout, 3, padding=1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, x: Tensor) -> Tensor:
        feats = [x]
        for conv in self.hidden:
            feats.append(F.leaky_relu(conv(torch.cat(feats, 1)), 0.2))
        return self.out(torch.cat(feats, 1))


class Coupling(nn.Module):
    """y1 = x1 + phi(x2); y2 = x2 * exp(s(y1)) + eta(y1), with s = clamp * tanh(rho(y1)) bounded."""

    def __init__(self, c1: int, c2: int, width: int, layers: int, clamp: float):
        super().__init__()
        self.phi = DenseSubnet(c2, c1, width, layers)
        self.rho = DenseSubnet(c1, c2, width, layers)
        self.eta = DenseSubnet(c1, c2, width, layers)
        self.clamp = clamp

    def _scale(self, y1: Tensor) -> Tensor:
        return self.clamp * torch.tanh(self.rho(y1))

    def forward(self, x1: Tensor, x2: Tensor) -> tuple[Tensor, Tensor]:
        y1 = x1 + self.phi(x2)
        return y1, x2 * torch.exp(self._scale(y1)) + self.eta(y1)

    def reverse(self, y1: Tensor, y2: Tensor) -> tuple[Tensor, Tensor]:
        x2 = self.reverse_secret(y1, y2)
        return y1 - self.phi(x2), x2

    def reverse_secret(self, y1: Tensor, y2: Tensor) -> Tensor:
        """The secret half of `reverse` alone."""
        return (y2 - self.eta(y1)) * torch.exp(-self._scale(y1))


class CodecNet(nn.Module):
    """Host branch: the host's Haar bands after `levels` full splits (3 * 4^levels channels on a grid
    2^levels times smaller); secret branch: `secret_channels` channels on that grid."""

    def __init__(self, secret_channels: int, blocks: int, width: int, layers: int, clamp: float, levels: int = 1):
        super().__init__()
        self.levels = levels
        host = 3 * 4 ** levels
        self.blocks = nn.ModuleList(Coupling(host, secret_channels, width, layers, clamp) for _ in range(blocks))
        self.z = nn.Parameter(torch.zeros(1, secret_channels, 1, 1))
        """the learned constant that replaces z in the reverse pass"""

    def forward(self, host: Tensor, secret: Tensor) -> tuple[Tensor, Tensor]:
        """host (B, 3, H, W), secret (B, Cs, H/2^L, W/2^L) -> snapshot (B, 3, H, W) (not clipped), z."""
        x1, x2 = host, secret
        for _ in range(self.levels):
            x1 = haar(x1)
        for blk in self.blocks:
            x1, x2 = blk(x1, x2)
        for _ in range(self.levels):
            x1 = ihaar(x1)
        return x1, x2

    def reverse(self, snapshot: Tensor, z: Tensor | None = None) -> tuple[Tensor, Tensor]:
        """snapshot (B, 3, H, W) -> host estimate (B, 3, H, W), secret estimate (B, Cs, H/2, W/2).
        `z` defaults to the learned constant (a true z gives an exact inverse, for tests)."""
        y1, y2 = self._reverse_to_first(snapshot, z)
        y1, y2 = self.blocks[0].reverse(y1, y2)
        for _ in range(self.levels):
            y1 = ihaar(y1)
        return y1, y2

    def reverse_secret(self, snapshot: Tensor) -> Tensor:
        """The secret estimate of `reverse` alone: the first block's host half is skipped (one subnet in
        3 x blocks), for the embed-time refinement."""
        return self.blocks[0].reverse_secret(*self._reverse_to_first(snapshot, None))

    def _reverse_to_first(self, snapshot: Tensor, z: Tensor | None) -> tuple[Tensor, Tensor]:
        """`reverse` up to the input of the first block (in the forward order)."""
        y1 = snapshot
        for _ in range(self.levels):
            y1 = haar(y1)
        y2 = self.z.expand(y1.shape[0], -1, y1.shape[2], y1.shape[3]) if z is None else z
        for blk in reversed(self.blocks[1:]):
            y1, y2 = blk.reverse(y1, y2)
        return y1, y2
