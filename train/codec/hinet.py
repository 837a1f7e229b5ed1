"""The codec in torch: weights in and out, and the two operations a user runs.

Weights live in the package as `assets/codec-<FILE_CODEC>.npz` (the state dict as numpy arrays
plus the config as JSON) beside a JSON summary of the run that made them.

`embed_planes`: host (380, 380, 3) float RGB in [0, 1] and planes (3, C, R, R) in [-1, 1] ->
snapshot (380, 380, 3) uint8 RGB. `restore_secret`: snapshot (380, 380, 3) uint8 RGB -> the secret
(24, 95, 95) float32 (24 = 3 planes x 8 channels on the 95x95 grid of two Haar levels), turned into planes by `snapshot3d.codecs.file_layout.secret_to_planes`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from snapshot3d import formats
from snapshot3d.codecs import file_layout
from snapshot3d.paths import asset

from ..weights import load_weights, save_weights
from .config import CodecConfig
from .net import CodecNet

__all__ = ["build_codec", "secret_grid", "codec_path", "save_codec", "load_codec", "embed_planes", "restore_secret"]


def build_codec(cfg: CodecConfig) -> CodecNet:
    return CodecNet(file_layout.SECRET_CHANNELS, cfg.blocks, cfg.width, cfg.layers, cfg.clamp, cfg.levels)


def secret_grid(net: CodecNet) -> int:
    """Side of the secret's grid for a 380x380 snapshot."""
    return formats.SNAPSHOT_SIZE >> net.levels


def codec_path(version: str = formats.FILE_CODEC) -> Path:
    return asset(f"codec-{version}.npz")


def save_codec(net: CodecNet, cfg: CodecConfig, path: Path) -> None:
    """Atomic write of the weights (float32) and the config they were built from."""
    save_weights(net, cfg, path)


def load_codec(path: Path | None = None) -> tuple[CodecNet, CodecConfig]:
    """The codec in eval mode with frozen weights (default: the package's)."""
    return load_weights(Path(path) if path else codec_path(), CodecConfig, build_codec, "codec",
                        "snapshot3d train codec")


def _check_host(host: np.ndarray) -> None:
    s = formats.SNAPSHOT_SIZE
    if host.shape != (s, s, 3):
        raise ValueError(f"host must be ({s}, {s}, 3) RGB, got {host.shape}")


@torch.no_grad()
def embed_planes(net: CodecNet, host: np.ndarray, planes: np.ndarray, strength: float = 1.0) -> np.ndarray:
    """host (380, 380, 3) float RGB in [0, 1], planes (3, C, R, R) in [-1, 1] -> snapshot uint8 RGB.
    `strength` scales the secret (1 = as trained): more is more robust and more visible."""
    _check_host(host)
    secret = torch.from_numpy(file_layout.planes_to_secret(planes, secret_grid(net)))[None] * strength
    h = torch.from_numpy(np.ascontiguousarray(host.transpose(2, 0, 1), np.float32))[None]
    snap, _ = net(h, secret)
    return (snap[0].clamp(0, 1).permute(1, 2, 0).numpy() * 255 + 0.5).astype(np.uint8)


@torch.no_grad()
def restore_secret(net: CodecNet, snapshot: np.ndarray, strength: float = 1.0) -> np.ndarray:
    """snapshot (380, 380, 3) uint8 RGB -> secret (24, G, G) float32 (divided by `strength`)."""
    _check_host(snapshot)
    x = torch.from_numpy(snapshot.transpose(2, 0, 1).astype(np.float32) / 255.0)[None]
    _, secret = net.reverse(x)
    return (secret[0] / strength).numpy()
