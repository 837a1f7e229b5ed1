"""The room behind a synthetic capture (`snapshot3d make-capture`): a ground plane textured with a photo crop,
carrying the object's soft shadow, inside a cylinder wall wrapped with a backdrop photo. Ray-cast per pixel in
numpy (exact, so the object, rasterised separately, is composited over it: the cameras are above the ground and
the wall is behind everything). World z up, the ground at z = ground_z.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from . import _raster
from .cameras import pixel_rays
from .errors import UserError

__all__ = ["Room", "photo_pool", "read_photo", "make_room", "render_room"]

WALL_RADIUS = 9.0     # world units; built-in meshes have a largest half-extent of 1
WALL_COPIES = 6       # the backdrop photo repeats (mirrored) this many times round the wall
GROUND_TILE = 1.6     # world units a copy of the ground crop covers (mirrored tiles)
SHADOW_HALF = 3.0     # the shadow map covers [-SHADOW_HALF, SHADOW_HALF]^2 of the ground
BUNDLED = ("astronaut", "coffee", "chelsea", "rocket")   # skimage photos when ../shared/data is absent


@dataclass
class Room:
    """wall, ground: mip pyramids of (h, w, 3) float32 RGB in [0, 1] (level 0 first); ground None: no ground
    plane (the wall goes on below). shadow: (S, S) float32 light factor over the ground's shadow map."""

    wall: list
    wall_height: float
    wall_phase: float
    ground: list | None
    ground_z: float
    shadow: np.ndarray


def photo_pool(shared: Path | None) -> list[str]:
    """Photo specs for `auto`: files of `shared/hosts/train/*.jpg` when present, else 'builtin:NAME' (skimage)."""
    files = sorted(str(p) for p in (shared / "hosts" / "train").glob("*.jpg")) if shared else []
    return files or [f"builtin:{n}" for n in BUNDLED]


def read_photo(spec: str, max_side: int = 1024) -> np.ndarray:
    """An image file or 'builtin:NAME' (a skimage photo) -> (h, w, 3) float32 RGB in [0, 1], longer side at most
    `max_side`. UserError (one line) for a missing or unreadable file."""
    if spec.startswith("builtin:"):
        import skimage.data

        if spec[8:] not in BUNDLED:
            raise UserError(f"unknown bundled photo {spec!r}; give an image file or one of "
                            + ", ".join(f"builtin:{n}" for n in BUNDLED))
        img = np.asarray(getattr(skimage.data, spec[8:])())
        img = np.repeat(img[..., None], 3, axis=2) if img.ndim == 2 else img[..., :3]
    else:
        if not Path(spec).is_file():
            raise UserError(f"backdrop photo not found: {spec}")
        from .image_decode import decode_image
        try:
            bgr = decode_image(Path(spec).read_bytes())
        except (OSError, ValueError):
            bgr = None
        if bgr is None or min(bgr.shape[:2]) < 8:
            raise UserError(f"{spec}: cannot read the backdrop photo (not an image, or smaller than 8 px)")
        img = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    img = img.astype(np.float32) / 255.0
    f = max_side / max(img.shape[:2])
    return cv2.resize(img, None, fx=f, fy=f, interpolation=cv2.INTER_AREA) if f < 1 else img


def _pyramid(img: np.ndarray, levels: int = 7) -> list:
    out = [np.ascontiguousarray(img, np.float32)]
    while len(out) < levels and min(out[-1].shape[:2]) >= 4:
        out.append(cv2.pyrDown(out[-1]))
    return out


def _mirror(t: np.ndarray) -> np.ndarray:
    """Mirrored repeat of [0, 1]: 0..1 then 1..0, period 2 (seamless tiles)."""
    m = np.mod(t, 2.0)
    return np.where(m > 1.0, 2.0 - m, m)


def _sample(pyr: list, s: np.ndarray, t: np.ndarray, lod: np.ndarray, shape: tuple) -> np.ndarray:
    """Trilinear lookup: s, t (K,) in [0, 1] (t = 0 the bottom row), lod (K,) log2 of level-0 texels per pixel;
    K = H * W of `shape` (OpenCV's remap takes image-shaped maps). Returns (K, 3) float32."""
    s, t = s.reshape(shape), t.reshape(shape)
    lod = np.clip(lod, 0.0, len(pyr) - 1.0).reshape(shape)
    out = np.zeros(shape + (3,), np.float32)
    for level, img in enumerate(pyr):
        w = np.clip(1.0 - np.abs(lod - level), 0.0, 1.0).astype(np.float32)
        if not w.any():
            continue
        h_, w_ = img.shape[:2]
        x = (s * w_ - 0.5).astype(np.float32)
        y = ((1.0 - t) * h_ - 0.5).astype(np.float32)
        out += w[..., None] * cv2.remap(img, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1, 3)


def _shadow_map(mesh, ground_z: float, size: int = 256) -> np.ndarray:
    """(size, size) light factor on the ground: the key light's shadow (soft) times a contact darkening under
    the parts that touch the ground. Row 0 at y = +SHADOW_HALF, column 0 at x = -SHADOW_HALF."""
    tri = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)]
    light = _raster.LIGHTS[0]
    px = size / (2 * SHADOW_HALF)

    def footprint(points, sigma):
        img = np.zeros((size, size), np.uint8)
        pix = np.stack([(points[..., 0] + SHADOW_HALF) * px, (SHADOW_HALF - points[..., 1]) * px], -1)
        cv2.fillPoly(img, list(np.round(pix * 16).astype(np.int32)), 255, cv2.LINE_AA, shift=4)
        return cv2.GaussianBlur(img.astype(np.float32) / 255.0, (0, 0), sigma * px)

    cast = tri - ((tri[..., 2:] - ground_z) / light[2]) * light
    low = tri[tri[..., 2].min(axis=1) < ground_z + 0.15]
    contact = footprint(low, 0.12) if len(low) else 0.0
    return np.clip(1.0 - 0.55 * footprint(cast, 0.05) - 0.3 * contact, 0.25, 1.0).astype(np.float32)


def make_room(mesh, backdrop: np.ndarray, ground: np.ndarray | None, rng: np.random.Generator) -> Room:
    """A room for `mesh` (standing on its lowest point): backdrop and ground photos (h, w, 3) float32 RGB, the
    ground photo cropped at random and its contrast lowered (a table cloth, not a second picture)."""
    h, w = backdrop.shape[:2]
    wall_height = (2 * np.pi * WALL_RADIUS / WALL_COPIES) * h / w
    ground_z = float(mesh.bounds[0][2])
    pyr = None
    if ground is not None:
        gh, gw = ground.shape[:2]
        c = max(8, min(gh, gw) // 2)
        y0, x0 = rng.integers(0, gh - c + 1), rng.integers(0, gw - c + 1)
        crop = cv2.resize(ground[y0:y0 + c, x0:x0 + c], (256, 256), interpolation=cv2.INTER_AREA)
        mean = crop.reshape(-1, 3).mean(0)
        pyr = _pyramid(mean + 0.6 * (crop - mean))
    return Room(wall=_pyramid(backdrop), wall_height=float(wall_height), wall_phase=float(rng.uniform(0, 2 * np.pi)),
                ground=pyr, ground_z=ground_z, shadow=_shadow_map(mesh, ground_z) if pyr else np.ones((1, 1)))


def render_room(room: Room, c2w: np.ndarray, intr, width: int, height: int, supersample: int = 2) -> np.ndarray:
    """The room seen by one pinhole camera: c2w (4, 4) OpenGL, intr (fx, fy, cx, cy) pixels (centres at +0.5).
    Returns (height, width, 3) float32 RGB in [0, 1], `supersample`x anti-aliased. The camera must be inside the
    wall and above the ground."""
    s = supersample
    fx, fy, cx, cy = (float(v) * s for v in intr)
    rays = pixel_rays(np.asarray(c2w, np.float64), fx, fy, cx, cy, width * s, height * s)
    o, d = (a.astype(np.float64) for a in rays)
    f, shape = 0.5 * (fx + fy), (height * s, width * s)
    a = d[:, 0] ** 2 + d[:, 1] ** 2
    b = o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]
    c = o[:, 0] ** 2 + o[:, 1] ** 2 - WALL_RADIUS ** 2
    t_wall = (-b + np.sqrt(np.maximum(b * b - a * c, 0.0))) / np.maximum(a, 1e-12)
    p = o + t_wall[:, None] * d
    theta = np.arctan2(p[:, 1], p[:, 0]) + room.wall_phase
    wall_w = room.wall[0].shape[1]
    texels = wall_w * WALL_COPIES / (2 * np.pi * WALL_RADIUS)   # level-0 texels per world unit
    rgb = _sample(room.wall, _mirror(theta / (2 * np.pi) * WALL_COPIES), _mirror((p[:, 2] - room.ground_z) /
                  room.wall_height), np.log2(np.maximum(t_wall / f * texels, 1e-6)), shape)
    if room.ground is not None:
        down = d[:, 2] < -1e-9
        t_g = np.where(down, (room.ground_z - o[:, 2]) / np.where(down, d[:, 2], -1.0), 0.0)
        q = o + t_g[:, None] * d
        hit = down & (q[:, 0] ** 2 + q[:, 1] ** 2 < WALL_RADIUS ** 2)
        gw = room.ground[0].shape[1]
        lod = np.log2(np.maximum(t_g / (f * np.maximum(-d[:, 2], 0.05)) * gw / GROUND_TILE, 1e-6))
        col = _sample(room.ground, _mirror(q[:, 0] / GROUND_TILE), _mirror(q[:, 1] / GROUND_TILE), lod, shape)
        n = room.shadow.shape[0]
        sx = ((q[:, 0] + SHADOW_HALF) * n / (2 * SHADOW_HALF) - 0.5).astype(np.float32).reshape(shape)
        sy = ((SHADOW_HALF - q[:, 1]) * n / (2 * SHADOW_HALF) - 0.5).astype(np.float32).reshape(shape)
        shade = cv2.remap(room.shadow, sx, sy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0)
        light = float(_raster.lambert(np.array([0.0, 0.0, 1.0]), False))
        rgb = np.where(hit[:, None], col * (light * shade.reshape(-1))[:, None], rgb)
    rgb = np.clip(rgb, 0.0, 1.0).reshape(height, s, width, s, 3).mean(axis=(1, 3))
    return rgb.astype(np.float32)
