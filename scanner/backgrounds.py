"""Bundled photographs used as backgrounds (and as no-sheet photos): scikit-image's sample photos and,
when matplotlib is installed, its `grace_hopper.jpg` (found by path; matplotlib is not imported)."""
from __future__ import annotations

import importlib.util
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

__all__ = ["BACKGROUND_NAMES", "MIN_HOST_SIDE", "background_names", "load_background", "load_host"]

MIN_HOST_SIDE = 190
"""the shortest host photo side `load_host` takes: the 380x380 snapshot enlarges it at most twice (a smaller one
would be a blur of a few pixels, with no detail to hide the payload in)"""

BACKGROUND_NAMES = ("astronaut", "coffee", "chelsea", "rocket", "camera", "brick", "grass", "gravel", "coins",
                    "moon", "hubble_deep_field", "immunohistochemistry")


def _grace_hopper_path() -> Path | None:
    spec = importlib.util.find_spec("matplotlib")
    if spec is None or not spec.submodule_search_locations:
        return None
    p = Path(list(spec.submodule_search_locations)[0]) / "mpl-data" / "sample_data" / "grace_hopper.jpg"
    return p if p.is_file() else None


def background_names() -> tuple[str, ...]:
    """Names usable with `load_background` on this install."""
    return BACKGROUND_NAMES + (("grace_hopper",) if _grace_hopper_path() else ())


@lru_cache(maxsize=16)
def load_background(name: str) -> np.ndarray:
    """(H, W, 3) uint8 RGB bundled photo (grey ones repeated to three channels); read-only, cached."""
    if name == "grace_hopper":
        img = cv2.cvtColor(cv2.imread(str(_grace_hopper_path()), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    else:
        import skimage.data

        img = np.asarray(getattr(skimage.data, name)())
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    img = np.ascontiguousarray(img[..., :3])
    img.setflags(write=False)
    return img


def load_host(spec: str) -> np.ndarray:
    """A host photo for `embed`: `builtin:NAME` (a bundled photo) or an image file -> (380, 380, 3) float32
    RGB in [0, 1], the centred square crop resized. A UserError for a file whose shorter side is under
    MIN_HOST_SIDE."""
    from snapshot3d import formats
    from snapshot3d.errors import UserError
    from snapshot3d.images import fit_square

    from .imageio_safe import read_image_bgr

    if spec.startswith("builtin:"):
        name = spec.split(":", 1)[1]
        if name not in background_names():
            raise UserError(f"unknown bundled host {name!r}; choose from {', '.join(background_names())}")
        rgb = load_background(name)
    else:
        rgb = cv2.cvtColor(read_image_bgr(spec, "host photo"), cv2.COLOR_BGR2RGB)
        h, w = rgb.shape[:2]
        if min(h, w) < MIN_HOST_SIDE:
            n = formats.SNAPSHOT_SIZE
            raise UserError(f"host photo {Path(spec).name} is {w}x{h}: too small to hide a {n}x{n} snapshot in (its "
                            f"shorter side needs {MIN_HOST_SIDE} px or more; it would be enlarged "
                            f"{n / min(h, w):.0f} times)")
    return fit_square(rgb, formats.SNAPSHOT_SIZE).astype(np.float32) / 255.0
