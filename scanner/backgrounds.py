"""Bundled photographs used as backgrounds (and as no-sheet photos): scikit-image's sample photos and,
when matplotlib is installed, its `grace_hopper.jpg` (found by path; matplotlib is not imported)."""
from __future__ import annotations

import importlib.util
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

__all__ = ["BACKGROUND_NAMES", "background_names", "load_background"]

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
