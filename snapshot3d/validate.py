"""Checks of numbers that come from outside (files, metadata text, the command line), shared by every reader.

Each check returns the value as the program uses it and raises `UserError` with one line naming the field
and the allowed range. The limits of the formats' numbers are here too (README "Errors and limits"
section states them):

- scene box: six finite numbers within +-WORLD_LIMIT, each side longer than BOX_MIN_SIDE of the longest;
- orbit: radius in RADIUS_RANGE, elevation in ELEVATION_RANGE, field of view in FOV_RANGE (degrees),
  target within +-WORLD_LIMIT;
- embedding strength in STRENGTH_RANGE;
- images: at most MAX_PIXELS pixels and MAX_BYTES bytes; scene files: planes of at most SCENE_MAX_RES and
  `formats.C_MAX` channels, at most SCENE_MAX_BYTES bytes;
- the renderers' options: VIEWS, VIEW_SIZE, SAMPLES, MESH_RES (inclusive ranges), and VIEW_PIXELS
  (views x size x size)."""
from __future__ import annotations

import math
from numbers import Real

import numpy as np

from . import formats
from .errors import UserError

__all__ = ["WORLD_LIMIT", "BOX_MIN_SIDE", "RADIUS_RANGE", "ELEVATION_RANGE", "FOV_RANGE", "STRENGTH_RANGE",
           "MAX_PIXELS", "MAX_BYTES", "SCENE_MAX_RES", "SCENE_MAX_BYTES", "VIEWS", "VIEW_SIZE", "VIEW_PIXELS", "SAMPLES",
           "MESH_RES", "number", "integer", "numbers", "finite_array", "finite_tree", "check_box", "check_orbit", "check_views", "check_image_size",
           "show"]

WORLD_LIMIT = 1e5            # world units: box corners and the orbit's target
BOX_MIN_SIDE = 1e-3          # each side of the box at least this fraction of its longest side
RADIUS_RANGE = (1e-4, 1e6)   # orbit radius (and a view's distance), world units
ELEVATION_RANGE = (-90.0, 90.0)
FOV_RANGE = (1.0, 170.0)     # degrees, horizontal
STRENGTH_RANGE = (0.01, 100.0)   # embedding strength a snapshot's metadata may name (embed writes 0.05 to 10)
MAX_PIXELS = 120_000_000     # an image file: larger than any phone's full-resolution photo (108 MP)
MAX_BYTES = 300_000_000      # an image file's size
SCENE_MAX_RES = 512          # plane resolution of a scene file (the codecs carry at most formats.CODEC_MAX_RES)
SCENE_MAX_BYTES = 3 * formats.C_MAX * SCENE_MAX_RES ** 2 + (1 << 20)   # the largest planes and 1 MiB besides
VIEWS = (1, 360)             # views of an orbit (render, decode)
VIEW_SIZE = (8, 2048)        # view side in pixels
VIEW_PIXELS = 1 << 26        # views x size x size of one render or decode (held in memory as float32 RGB)
SAMPLES = (1, 256)           # samples per pixel (decode)
MESH_RES = (8, 256)          # marching-cubes grid per axis (mesh)


def show(value, limit: int = 40) -> str:
    """A value as a short one-line text for an error message."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _range(lo, hi) -> str:
    return f"[{lo:g}, {hi:g}]"


def number(value, field: str, lo: float = -math.inf, hi: float = math.inf) -> float:
    """`value` as a finite float in [lo, hi] (not a bool, not text)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (Real, np.integer, np.floating)):
        raise UserError(f"{field} must be a number in {_range(lo, hi)}, got {show(value)}")
    try:
        x = float(value)
    except (OverflowError, ValueError):
        raise UserError(f"{field} must be a finite number in {_range(lo, hi)}, got {show(value)}") from None
    if not (math.isfinite(x) and lo <= x <= hi):
        raise UserError(f"{field} must be a finite number in {_range(lo, hi)}, got {show(value)}")
    return x


def integer(value, field: str, lo: int, hi: int) -> int:
    """`value` as an int in [lo, hi]: an integer, or a float with an integer value."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (Real, np.integer, np.floating)):
        raise UserError(f"{field} must be an integer in {lo}..{hi}, got {show(value)}")
    if isinstance(value, (float, np.floating)) and not (math.isfinite(value) and float(value).is_integer()):
        raise UserError(f"{field} must be an integer in {lo}..{hi}, got {show(value)}")
    if not lo <= value <= hi:
        raise UserError(f"{field} must be an integer in {lo}..{hi}, got {show(value)}")
    return int(value)


def numbers(values, field: str, n: int, lo: float = -math.inf, hi: float = math.inf) -> tuple[float, ...]:
    """A sequence of exactly `n` finite numbers in [lo, hi] -> tuple of floats."""
    if isinstance(values, (str, bytes, dict)) or not hasattr(values, "__len__") or len(values) != n:
        raise UserError(f"{field} must be {n} numbers, got {show(values)}")
    return tuple(number(v, f"{field}[{i}]", lo, hi) for i, v in enumerate(values))


def finite_array(a: np.ndarray, field: str) -> np.ndarray:
    """UserError unless every element of the float array `a` is finite; returns `a`."""
    if not np.all(np.isfinite(a)):
        raise UserError(f"{field} holds non-finite numbers (NaN or infinity)")
    return a


def finite_tree(obj, field: str):
    """UserError naming the first non-finite float in a report (nested dicts, lists and tuples); returns `obj`."""
    stack = [(field, obj)]
    while stack:
        name, x = stack.pop()
        if isinstance(x, dict):
            stack.extend((f"{name}.{k}", v) for k, v in x.items())
        elif isinstance(x, (list, tuple)):
            stack.extend((f"{name}[{i}]", v) for i, v in enumerate(x))
        elif isinstance(x, (float, np.floating)) and not math.isfinite(x):
            raise UserError(f"{name} came out as {x}: the input does not hold what it names, or is damaged past "
                            f"reading")
    return obj


def check_box(box, field: str = "box") -> np.ndarray:
    """A scene box as six numbers (x0, y0, z0, x1, y1, z1) or (2, 3) -> (2, 3) float32, finite, within
    +-WORLD_LIMIT, x1 > x0 (and y, z) with each side at least BOX_MIN_SIDE of the longest."""
    flat = box
    if isinstance(box, np.ndarray):
        flat = box.reshape(-1).tolist() if box.size == 6 else box
    elif isinstance(box, (list, tuple)) and len(box) == 2 and all(isinstance(r, (list, tuple)) and len(r) == 3
                                                                   for r in box):
        flat = [*box[0], *box[1]]
    vals = np.array(numbers(flat, field, 6, -WORLD_LIMIT, WORLD_LIMIT), np.float64).reshape(2, 3)
    side = vals[1] - vals[0]
    if not np.all(side > 0) or side.min() < BOX_MIN_SIDE * side.max():
        raise UserError(f"{field} must have x1 > x0, y1 > y0, z1 > z0, each side at least {BOX_MIN_SIDE:g} of the "
                        f"longest; got sides {', '.join(f'{s:.4g}' for s in side)}")
    return vals.astype(np.float32)


def check_orbit(radius, elevation_deg, fov_deg, target=None, field: str = "orbit") -> tuple:
    """(radius, elevation_deg, fov_deg, target (3,) or None) checked against RADIUS_RANGE, ELEVATION_RANGE,
    FOV_RANGE and WORLD_LIMIT -> the same as floats (target a tuple)."""
    r = number(radius, f"{field} radius", *RADIUS_RANGE)
    el = number(elevation_deg, f"{field} elevation_deg", *ELEVATION_RANGE)
    fov = number(fov_deg, f"{field} fov_deg", *FOV_RANGE)
    t = None if target is None else numbers(target, f"{field} target", 3, -WORLD_LIMIT, WORLD_LIMIT)
    return r, el, fov, t


def check_views(views, size, size_range: tuple = VIEW_SIZE) -> tuple[int, int]:
    """--views and --size of a render: each in its range, and views * size^2 at most VIEW_PIXELS."""
    views, size = integer(views, "--views", *VIEWS), integer(size, "--size", *size_range)
    if views * size * size > VIEW_PIXELS:
        raise UserError(f"--views {views} of --size {size} is {views * size * size / 1e6:.0f} M pixels, over the "
                        f"{VIEW_PIXELS / 1e6:.0f} M a render holds in memory: ask for fewer or smaller views")
    return views, size


def check_image_size(width: int, height: int, name: str) -> None:
    """UserError when an image's header declares more than MAX_PIXELS pixels or an empty side."""
    if width < 1 or height < 1:
        raise UserError(f"{name} declares an empty image ({width}x{height} pixels)")
    if width * height > MAX_PIXELS:
        raise UserError(f"{name} claims {width}x{height} pixels ({width * height / 1e6:.0f} MP), over the "
                        f"{MAX_PIXELS / 1e6:.0f} MP limit: refused as a possible decompression bomb")
