"""The scene file (`.s3d`): everything the snapshot must carry for one scene.

A scene is three planes of 8-bit codes plus a few numbers; the decoder is shared and versioned.
The file is an uncompressed numpy `.npz` with the arrays below and a JSON header.
"""
from __future__ import annotations

import contextlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from . import formats, scene_io, validate
from .errors import UserError
from .head import head_bytes, parse_head

__all__ = ["Scene", "Orbit", "save_scene", "load_scene_file", "check_orbit", "check_scene", "quantize_planes",
           "dequantize_planes"]


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
    head: str | None = None
    """the scene's own head (`snapshot3d.head`, the h= text `step,codes`), or None: the shared decoder's"""

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
        """Bytes the snapshot must carry: 8-bit codes, the box (6 float32), the orbit (3 float32), and the
        scene's own head when it has one (`head.head_bytes`)."""
        own = 0 if self.head is None else head_bytes(parse_head(self.head)[1].shape[1] - 1)
        return int(self.codes.size) + 6 * 4 + 3 * 4 + own

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
    """Write atomically (its folder made when missing): a partial file never stands at `path`; UserError when
    the scene is out of `check_scene`'s bounds or the file cannot be written."""
    path = Path(path)
    check_scene(scene, path.name)
    header = {
        "format_version": formats.SCENE_FORMAT_VERSION, "decoder_version": scene.decoder_version,
        "name": scene.name, "orbit": asdict(scene.orbit), "meta": scene.meta,
        **({"head": scene.head} if scene.head is not None else {}),
    }
    tmp = path.with_name(path.name + ".partial")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as f:
            np.savez(f, codes=scene.codes, box=scene.box, header=np.frombuffer(json.dumps(header).encode(), np.uint8))
        tmp.replace(path)
    except OSError as e:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise UserError(f"cannot write {path} ({e.strerror or type(e).__name__})") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def load_scene_file(path, expect_decoder: tuple | None = formats.DECODERS) -> Scene:
    """Read a `.s3d`; refuses (one-line UserError naming the field and its allowed range) a missing,
    corrupt or oversized file, one whose arrays or header are malformed or out of range, and a scene made
    for a decoder not in `expect_decoder` (default: every version this build decodes). Sizes are checked from the zip directory and the `.npy` headers before anything
    is allocated (`validate.SCENE_MAX_BYTES`, `validate.SCENE_MAX_RES`, `formats.C_MAX`)."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path} is not a regular file; give the scene file itself" if path.exists()
                        else f"scene file not found: {path}")
    size = path.stat().st_size
    if size > validate.SCENE_MAX_BYTES:
        raise UserError(f"{path}: {size / 1e6:.1f} MB is larger than any scene file (limit "
                        f"{validate.SCENE_MAX_BYTES / 1e6:.1f} MB)")
    arrays = scene_io.read_arrays(path, _ARRAYS)
    header = scene_io.parse_header(path, arrays["header"])
    if header.get("format_version") != formats.SCENE_FORMAT_VERSION:
        raise UserError(f"{path}: scene format {validate.show(header.get('format_version'))} is not supported "
                        f"(this build reads format {formats.SCENE_FORMAT_VERSION})")
    dec = header.get("decoder_version")
    if not isinstance(dec, str) or len(dec) > 64:
        raise UserError(f"{path}: header decoder_version must be a short text, got {validate.show(dec)}")
    if expect_decoder is not None and dec not in expect_decoder:
        raise UserError(f"{path} was fitted for decoder {dec!r}, but this build has decoder "
                        f"{', '.join(map(repr, expect_decoder))}; fit the scene again")
    name, meta = header.get("name", ""), header.get("meta", {})
    if not isinstance(name, str) or not isinstance(meta, dict):
        raise UserError(f"{path}: header name must be a text and meta an object")
    head = header.get("head")
    if head is not None:
        try:
            parse_head(head)
        except ValueError as e:
            raise UserError(f"{path}: header {e}") from None
    return Scene(codes=arrays["codes"], box=validate.check_box(arrays["box"], f"{path}: box"),
                 orbit=check_orbit(header.get("orbit"), f"{path}: orbit"), decoder_version=dec, name=name, meta=meta,
                 head=head)


_ARRAYS = {
    "codes": scene_io.ArraySpec(dtypes=("u1",), ndim=4, check=lambda shape: (
        shape[0] == 3 and 1 <= shape[1] <= formats.C_MAX and shape[2] == shape[3]
        and 2 <= shape[2] <= validate.SCENE_MAX_RES),
        allowed=f"(3, C, R, R) uint8 with C in 1..{formats.C_MAX}, R in 2..{validate.SCENE_MAX_RES}"),
    "box": scene_io.ArraySpec(dtypes=("f4", "f8"), ndim=None, check=lambda shape: shape in ((2, 3), (6,)),
                              allowed="(2, 3) float32"),
    "header": scene_io.ArraySpec(dtypes=("u1",), ndim=1, check=lambda shape: shape[0] <= scene_io.MAX_HEADER_BYTES,
                                 allowed=f"(N,) uint8 JSON text, N <= {scene_io.MAX_HEADER_BYTES}"),
}


def check_orbit(orbit, field: str = "orbit") -> Orbit:
    """A scene header's orbit object {radius, elevation_deg, fov_deg, target} -> `Orbit`, each number within
    `validate`'s bounds (elevation, fov and target may be left out: the defaults)."""
    if not isinstance(orbit, dict):
        raise UserError(f"{field} must be an object with radius, elevation_deg, fov_deg, target; got "
                        f"{validate.show(orbit)}")
    unknown = sorted(set(orbit) - {"radius", "elevation_deg", "fov_deg", "target"})
    if unknown or "radius" not in orbit:
        raise UserError(f"{field} needs radius (and may have elevation_deg, fov_deg, target); got keys "
                        f"{validate.show(sorted(map(str, orbit)))}")
    r, el, fov, target = validate.check_orbit(orbit["radius"], orbit.get("elevation_deg", formats.ORBIT_ELEVATION_DEG),
                                              orbit.get("fov_deg", formats.ORBIT_FOV_DEG),
                                              orbit.get("target", (0.0, 0.0, 0.0)), field)
    return Orbit(r, el, fov, target)


def check_scene(scene: Scene, where: str = "scene") -> Scene:
    """UserError unless the scene's box and orbit are within `validate`'s bounds (what `load_scene_file`
    accepts); returns `scene`."""
    validate.check_box(scene.box, f"{where}: box")
    o = scene.orbit
    validate.check_orbit(o.radius, o.elevation_deg, o.fov_deg, o.target, f"{where}: orbit")
    if scene.resolution > validate.SCENE_MAX_RES:
        raise UserError(f"{where}: planes of {scene.resolution}x{scene.resolution} are over the scene file's limit "
                        f"of {validate.SCENE_MAX_RES}")
    return scene
