"""Training data of the codec: host photos and scene planes, with augmentation.

Hosts are the photos bundled with scikit-image and matplotlib (`scanner.backgrounds`) and, when
`../shared/data` is present, the photos of its `hosts/train/` (never `hosts/heldout/`), each reduced to a
shorter side of at most `_HOST_SIDE` pixels; planes come from fitted scene files. Augmentation: hosts are
rescaled, cropped, flipped and colour-jittered; planes are flipped, rotated, their channels and planes
permuted, cropped and resized to another resolution, and sometimes cut to fewer channels, so that one codec
serves any scene.

Arrays: hosts (H, W, 3) float32 RGB in [0, 1]; planes (3, C, R, R) float32 in [-1, 1].
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch

from snapshot3d import formats
from snapshot3d.codecs import file_layout
from snapshot3d.images import fit_square
from snapshot3d.scene import Scene, load_scene_file

__all__ = ["CodecData", "load_codec_data", "crop_batch", "full_sample", "augment_planes"]

_RESOLUTIONS = (32, 48, 64)
_HOST_SIDE = 640


@dataclass
class CodecData:
    hosts: list            # (H, W, 3) float32 RGB in [0, 1]
    host_names: list
    scenes: list           # Scene


def _load_train_host(spec: str) -> np.ndarray:
    """A `print_data.host_sources` entry -> (H, W, 3) float32 RGB in [0, 1], shorter side <= _HOST_SIDE."""
    from .print_data import read_host

    img = read_host(spec)
    scale = _HOST_SIDE / min(img.shape[:2])
    if scale < 1:
        img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return img.astype(np.float32) / 255.0


def load_codec_data(scene_dir: Path, holdout_scenes: set, holdout_hosts: set) -> CodecData:
    from .print_data import host_name, host_sources

    scenes = [load_scene_file(p) for p in sorted(Path(scene_dir).glob("*.s3d")) if p.stem not in holdout_scenes]
    specs = [s for s in host_sources() if host_name(s) not in holdout_hosts]
    names = [host_name(s) for s in specs]
    hosts = [_load_train_host(s) for s in specs]
    if not scenes or not hosts:
        raise ValueError(f"no training scenes in {scene_dir} or no host photos")
    return CodecData(hosts, names, scenes)


def augment_planes(planes: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(3, C, R, R) -> (3, C', R', R') with R' in {32, 48, 64}, C' in {4, C}: a plausible other scene."""
    p = planes[rng.permutation(3)]
    p = p[:, rng.permutation(p.shape[1])]
    if rng.random() < 0.5:
        p = p[..., ::-1]
    if rng.random() < 0.5:
        p = p[..., ::-1, :]
    p = np.rot90(p, int(rng.integers(4)), axes=(2, 3))
    r = p.shape[-1]
    side = int(rng.integers(int(0.6 * r), r + 1))
    y0, x0 = rng.integers(0, r - side + 1, 2)
    crop = np.ascontiguousarray(p[:, :, y0:y0 + side, x0:x0 + side]).reshape(-1, side, side)
    out = int(rng.choice(_RESOLUTIONS))
    res = np.stack([cv2.resize(c, (out, out), interpolation=cv2.INTER_LINEAR) for c in crop])
    res = res.reshape(3, -1, out, out)
    if rng.random() < 0.25:
        res = res[:, :4]
    return np.clip(res, -1, 1).astype(np.float32)


def _jitter(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    grey = img.mean(2, keepdims=True)
    img = grey + (img - grey) * rng.uniform(0.6, 1.3)
    img = (img - 0.5) * rng.uniform(0.8, 1.2) + 0.5 + rng.uniform(-0.1, 0.1)
    return np.clip(img, 0, 1)


def _host_crop(img: np.ndarray, crop: int, rng: np.random.Generator) -> np.ndarray:
    h, w, _ = img.shape
    side = min(h, w) * rng.uniform(0.35, 1.0) * crop / formats.SNAPSHOT_SIZE
    side = int(np.clip(side, 16, min(h, w)))
    y0, x0 = rng.integers(0, h - side + 1), rng.integers(0, w - side + 1)
    c = cv2.resize(img[y0:y0 + side, x0:x0 + side], (crop, crop), interpolation=cv2.INTER_AREA)
    if rng.random() < 0.5:
        c = c[:, ::-1]
    return _jitter(c, rng)


def crop_batch(data: CodecData, batch: int, crop: int, rng: np.random.Generator,
               levels: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    """host crops (B, 3, crop, crop) and secret crops (B, 24, crop/2^L, crop/2^L) of augmented planes."""
    hosts, secrets = [], []
    g, grid = crop >> levels, formats.SNAPSHOT_SIZE >> levels
    for _ in range(batch):
        hosts.append(_host_crop(data.hosts[rng.integers(len(data.hosts))], crop, rng).transpose(2, 0, 1))
        planes = augment_planes(data.scenes[rng.integers(len(data.scenes))].planes(), rng)
        sec = file_layout.planes_to_secret(planes, grid)
        y0, x0 = rng.integers(0, grid - g + 1, 2)
        secrets.append(sec[:, y0:y0 + g, x0:x0 + g])
    return torch.from_numpy(np.stack(hosts).astype(np.float32)), torch.from_numpy(np.stack(secrets))


def full_sample(data: CodecData, rng: np.random.Generator) -> tuple[torch.Tensor, Scene]:
    """One whole host (1, 3, 380, 380), centre-fitted with a random zoom, and an unaugmented scene."""
    img = data.hosts[rng.integers(len(data.hosts))]
    h, w, _ = img.shape
    side = int(min(h, w) * rng.uniform(0.6, 1.0))
    y0, x0 = rng.integers(0, h - side + 1), rng.integers(0, w - side + 1)
    host = _jitter(fit_square(img[y0:y0 + side, x0:x0 + side], formats.SNAPSHOT_SIZE), rng)
    scene = data.scenes[rng.integers(len(data.scenes))]
    return torch.from_numpy(host.transpose(2, 0, 1)[None].astype(np.float32)), scene
