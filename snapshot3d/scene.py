"""The scene file (`.s3d`): everything the snapshot must carry for one scene.

A scene is three planes of 8-bit codes plus a few numbers; the decoder is shared and versioned.
The file is an uncompressed numpy `.npz` with the arrays below and a JSON header.
"""
from __future__ import annotations

import json
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from . import formats
from .errors import UserError

__all__ = ["Scene", "Orbit", "save_scene", "load_scene_file", "quantize_planes", "dequantize_planes"]


@dataclass(frozen=True)
class Orbit:
    """The default viewing orbit of a scene: cameras at `radius` (world units) around `target`."""

    radius: float
    elevation_deg: float = formats.ORBIT_ELEVATION_DEG
    fov_deg: float = formats.ORBIT_FOV_DEG
    target: tuple = (0.0, 0.0, 0.0)


@dataclass
class Scene:
    """codes: (3, C, R, R) uint8 plane codes in `formats.PLANE_NAMES` order, rows index the second
    axis of the pair, columns the first (the `grid_sample` layout). box: (2, 3) float32 world box."""

    codes: np.ndarray
    box: np.ndarray
    orbit: Orbit
    decoder_version: str = formats.DECODER_VERSION
    name: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.codes.dtype != np.uint8 or self.codes.ndim != 4 or self.codes.shape[0] != 3:
            raise ValueError(f"codes must be (3, C, R, R) uint8, got {self.codes.shape} {self.codes.dtype}")
        if self.codes.shape[1] > formats.C_MAX or self.codes.shape[2] != self.codes.shape[3]:
            raise ValueError(f"planes must be square with at most {formats.C_MAX} channels: {self.codes.shape}")
        self.box = np.asarray(self.box, dtype=np.float32).reshape(2, 3)

    @property
    def channels(self) -> int:
        return self.codes.shape[1]

    @property
    def resolution(self) -> int:
        return self.codes.shape[2]

    def planes(self) -> np.ndarray:
        """(3, C, R, R) float32 plane values in [-1, 1]."""
        return dequantize_planes(self.codes)

    def carried_bytes(self) -> int:
        """Bytes the snapshot must carry: 8-bit codes, the box (6 float32), the orbit (3 float32)."""
        return int(self.codes.size) + 6 * 4 + 3 * 4

    @property
    def scene_kb(self) -> float:
        return self.carried_bytes() / formats.KB


def quantize_planes(planes: np.ndarray) -> np.ndarray:
    """float planes in [-1, 1] (values outside are clipped) -> uint8 codes of the same shape."""
    lo, hi = formats.PLANE_RANGE
    return np.round((np.clip(planes, lo, hi) - lo) / (hi - lo) * 255.0).astype(np.uint8)


def dequantize_planes(codes: np.ndarray) -> np.ndarray:
    lo, hi = formats.PLANE_RANGE
    return (codes.astype(np.float32) / 255.0 * (hi - lo) + lo).astype(np.float32)


def save_scene(scene: Scene, path) -> None:
    """Write atomically: a partial file never stands at `path`."""
    path = Path(path)
    header = {
        "format_version": formats.SCENE_FORMAT_VERSION, "decoder_version": scene.decoder_version,
        "name": scene.name, "orbit": asdict(scene.orbit), "meta": scene.meta,
    }
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "wb") as f:
        np.savez(f, codes=scene.codes, box=scene.box, header=np.frombuffer(json.dumps(header).encode(), np.uint8))
    tmp.replace(path)


def load_scene_file(path, expect_decoder: str | None = formats.DECODER_VERSION) -> Scene:
    """Read a `.s3d`; refuses a missing or corrupt file and a scene made for another decoder."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"scene file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            codes, box = z["codes"], z["box"]
            header = json.loads(z["header"].tobytes().decode())
    except (OSError, EOFError, ValueError, KeyError, zipfile.BadZipFile, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise UserError(f"{path} is not a snapshot3d scene file ({type(e).__name__})") from None
    if header.get("format_version") != formats.SCENE_FORMAT_VERSION:
        raise UserError(f"{path}: scene format {header.get('format_version')} is not supported "
                        f"(this build reads format {formats.SCENE_FORMAT_VERSION})")
    dec = header.get("decoder_version")
    if expect_decoder is not None and dec != expect_decoder:
        raise UserError(f"{path} was fitted for decoder {dec!r}, but this build has decoder {expect_decoder!r}; "
                        f"fit the scene again")
    try:
        return Scene(codes=codes, box=box, orbit=Orbit(**{k: (tuple(v) if isinstance(v, list) else v)
                                                          for k, v in header["orbit"].items()}),
                     decoder_version=dec, name=header.get("name", ""), meta=header.get("meta", {}))
    except (TypeError, ValueError, KeyError) as e:
        raise UserError(f"{path}: malformed scene ({e})") from None
