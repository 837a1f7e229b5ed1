"""Held-out views aligned to a fit before they are scored (issue 40's pose-noise diagnostic): a fit of poses a
little off lives in a world a little off from the truth's, and the truth's held-out poses then see the object
shifted by a fraction of a pixel. Each view's pose gets a small correction (a turn about its camera and a shift,
`pose_refine`) fitted to its own photo of the object with the planes frozen: test-time pose optimisation, as BARF
(Lin et al. 2021) scores its pose-refined fits. What is left after it is what the planes lack, not where they lie.

Shapes: c2w (V, 4, 4) OpenGL camera-to-world, intrinsics (V, 4) (fx, fy, cx, cy) px, images (V, H, W, 3) float32 RGB
in [0, 1], the object on white; planes (3, C, R, R) torch over world box (2, 3)."""
from __future__ import annotations

import cv2
import numpy as np
import torch

from .object_carve import refined_c2w
from .pose_refine import PoseRefine
from .rays import view_rays
from .render import occupancy_from_planes, render_rays
from .sampler import BoxFrame

__all__ = ["align_views"]


def align_views(planes: torch.Tensor, decoder, box, c2w: np.ndarray, intrinsics: np.ndarray, images: np.ndarray,
                masks: np.ndarray, grow: int = 4, steps: int = 100, rays: int = 4096, lr: float = 5e-4,
                seed: int = 0) -> np.ndarray:
    """The views' poses (V, 4, 4) float32 moved to where the planes, rendered over white, best match `images`:
    mean squared error over `rays` random pixels a step of the object's `masks` (V, H, W) bool grown by `grow` px
    (white on white elsewhere says nothing), Adam at `lr` decayed tenfold over the `steps` steps."""
    planes = planes.detach()
    frame = BoxFrame.from_box(box, planes.device)
    occ = occupancy_from_planes(planes, decoder, frame)
    v, h, w = images.shape[:3]
    rays_q = [view_rays(c2w[i], intrinsics[i], w, h, frame) for i in range(v)]
    o_all, d_all = torch.cat([o for o, _ in rays_q]).float(), torch.cat([d for _, d in rays_q]).float()
    colour = torch.from_numpy(np.ascontiguousarray(images, np.float32).reshape(-1, 3))
    view = torch.arange(v, dtype=torch.int64).repeat_interleave(h * w)
    kernel = np.ones((2 * grow + 1, 2 * grow + 1), np.uint8)
    near = np.stack([cv2.dilate(np.asarray(m, np.uint8), kernel) > 0 for m in masks])
    where = torch.from_numpy(np.flatnonzero(near.reshape(-1)))
    poses = PoseRefine(v)
    opt = torch.optim.Adam(poses.parameters(), lr=lr)
    decay = torch.optim.lr_scheduler.ExponentialLR(opt, 0.1 ** (1 / max(steps, 1)))
    gen = torch.Generator().manual_seed(seed)
    for _ in range(steps):   # the decoder comes frozen (`decoder.load_decoder`)
        pick = where[torch.randint(0, len(where), (rays,), generator=gen)]
        o, d = poses(view[pick], o_all[pick], d_all[pick])
        rgb = render_rays(planes, decoder, frame, occ, o, d)[0]
        loss = ((rgb - colour[pick]) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        decay.step()
    return refined_c2w(c2w, poses.params.detach().cpu().numpy(), frame.scale)
