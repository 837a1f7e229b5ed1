"""Training rays: every pixel of the training views as a q-space ray with its target colour."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from snapshot3d.cameras import pixel_rays
from snapshot3d.posed import PosedImages

from .sampler import BoxFrame

__all__ = ["RayBank", "make_rays", "view_rays", "recomposite"]


@dataclass
class RayBank:
    """origins, dirs, rgb: (M, 3) float32 (q space, unit dirs, RGB in [0, 1] over white); view: (M,) int32, each
    ray's view as an index into the bank's views (0 .. V-1, in the order `make_rays` was given them); fg: indices
    of rays that see the object (from the coverage mask), or None; alpha: (M,) float32 coverage in [0, 1], or
    None when the images carry none."""

    origins: Tensor
    dirs: Tensor
    rgb: Tensor
    view: Tensor
    fg: Tensor | None
    alpha: Tensor | None = None

    def __len__(self) -> int:
        return self.rgb.shape[0]

    def batch(self, n: int, fg_fraction: float, generator: torch.Generator) -> tuple:
        """n rays (origins, dirs, rgb, view, alpha or None), `fg_fraction` of them drawn from the foreground rays
        when those are known."""
        n_fg = int(n * fg_fraction) if self.fg is not None and len(self.fg) else 0
        idx = torch.randint(len(self), (n - n_fg,), generator=generator)
        if n_fg:
            idx = torch.cat([idx, self.fg[torch.randint(len(self.fg), (n_fg,), generator=generator)]])
        idx = idx.to(self.rgb.device)
        return self.origins[idx], self.dirs[idx], self.rgb[idx], self.view[idx], \
            None if self.alpha is None else self.alpha[idx]

    def to(self, device) -> "RayBank":
        """The rays on `device` (the foreground index stays on the CPU, where the generator draws)."""
        return RayBank(self.origins.to(device), self.dirs.to(device), self.rgb.to(device), self.view.to(device), self.fg,
                       None if self.alpha is None else self.alpha.to(device))


def recomposite(rgb: Tensor, cover: Tensor, behind: Tensor, was: float = 1.0) -> Tensor:
    """rgb (N, 3) composited over `was` (white) with coverage cover (N,) in [0, 1] -> the same pixels over behind
    (N, 3): c a + (1 - a) was becomes c a + (1 - a) behind."""
    return rgb + (1 - cover)[:, None] * (behind - was)


def view_rays(c2w: np.ndarray, intr: np.ndarray, width: int, height: int, frame: BoxFrame):
    """q-space rays (H*W, 3) of one view, row-major, on the frame's device."""
    o, d = pixel_rays(np.asarray(c2w, np.float64), *[float(x) for x in intr], width, height)
    dev = frame.centre.device
    return frame.rays_to_q(torch.from_numpy(o).to(dev), torch.from_numpy(d).to(dev))


def make_rays(posed: PosedImages, views: np.ndarray, frame: BoxFrame, keep_alpha: bool = False) -> RayBank:
    """The bank of `views`' pixels; their coverage kept per ray only with `keep_alpha` (a fit over random
    colours needs it; others only need the foreground's indices)."""
    os_, ds, cs, vs, als = [], [], [], [], []
    for j, i in enumerate(views):
        o, d = view_rays(posed.c2w[i], posed.intrinsics[i], posed.width, posed.height, frame)
        os_.append(o), ds.append(d), cs.append(torch.from_numpy(posed.images[i].reshape(-1, 3)))
        vs.append(torch.full((o.shape[0],), j, dtype=torch.int32))
        if posed.alpha is not None:
            als.append(torch.from_numpy(np.asarray(posed.alpha[i], np.float32).reshape(-1)))
    alpha = torch.cat(als) if als else None
    fg = torch.nonzero(alpha > 0.01).squeeze(1) if alpha is not None else None
    return RayBank(torch.cat(os_), torch.cat(ds), torch.cat(cs), torch.cat(vs), fg, alpha if keep_alpha else None)
