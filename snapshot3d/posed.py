"""A posed image set: the common form every scene input (Blender, nerfstudio, builtin) is loaded into."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["PosedImages"]


@dataclass
class PosedImages:
    """Images with exact pinhole cameras.

    images: (N, H, W, 3) float32, RGB, linear-free sRGB values in [0, 1], composited on white.
    alpha: (N, H, W) float32 in [0, 1], or None when the input has no coverage mask.
    c2w: (N, 4, 4) float32, OpenGL axes (see `snapshot3d.cameras`).
    intrinsics: (N, 4) float32 rows of (fx, fy, cx, cy) in pixels.
    box: (2, 3) float32 world-space axis-aligned box (min row, max row) that holds the scene.
    train, test: index arrays into the N views.
    """

    images: np.ndarray
    alpha: np.ndarray | None
    c2w: np.ndarray
    intrinsics: np.ndarray
    box: np.ndarray
    train: np.ndarray
    test: np.ndarray
    name: str = ""
    skipped: int = 0  # frames listed by the input whose image was missing
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        n, h, w, c = self.images.shape
        assert c == 3 and self.images.dtype == np.float32, (self.images.shape, self.images.dtype)
        assert self.c2w.shape == (n, 4, 4) and self.intrinsics.shape == (n, 4)
        assert self.alpha is None or self.alpha.shape == (n, h, w)
        assert self.box.shape == (2, 3)

    @property
    def height(self) -> int:
        return self.images.shape[1]

    @property
    def width(self) -> int:
        return self.images.shape[2]
