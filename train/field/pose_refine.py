"""Camera pose refinement during a fit (fit --refine-poses): a small correction per training view, learnt with the
planes, for captures whose poses are a little off (COLMAP, a capture app). nerfstudio's camera optimiser does the
same (a rotation and a translation per frame, from zero); this one acts on the q-space rays the bank holds.

A view's correction is a rotation about its camera centre (axis-angle r, radians, in the world's axes) and a shift
t (q-space units, box half-sizes): a ray o + s d becomes (o + t) + s R(r) d. Its origin is the camera centre, so
the rotation leaves it in place. The corrections' mean over the views is held at zero after each step: a shift or
turn of every camera at once is a move of the whole world, which the planes can follow instead (the gauge), and
left free it drifts the scene away from the frame the box and the orbit were found in.

Shapes: params (V, 6) float32 [r | t] per training view (the order of `posed.train`); rays (N, 3); view (N,)
int32 indices into the params' rows.
"""
from __future__ import annotations

import math

import torch
from torch import Tensor, nn

__all__ = ["PoseRefine", "axis_angle_matrix", "correct_rays", "pose_summary"]


def axis_angle_matrix(r: Tensor) -> Tensor:
    """(N, 3) axis-angle vectors (radians) -> (N, 3, 3) rotation matrices (Rodrigues; first order near zero)."""
    theta2 = (r * r).sum(-1, keepdim=True)
    theta = torch.sqrt(theta2.clamp(min=1e-12))
    small = theta2 < 1e-8
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)           # sin(t) / t
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / theta2.clamp(min=1e-12))   # (1 - cos t) / t^2
    zero = torch.zeros_like(r[:, 0])
    k = torch.stack([zero, -r[:, 2], r[:, 1], r[:, 2], zero, -r[:, 0], -r[:, 1], r[:, 0], zero], -1).view(-1, 3, 3)
    eye = torch.eye(3, dtype=r.dtype, device=r.device).expand_as(k)
    return eye + a[..., None] * k + b[..., None] * (k @ k)


def correct_rays(params: Tensor, view: Tensor, o: Tensor, d: Tensor) -> tuple[Tensor, Tensor]:
    """Rays (N, 3) of views `view` (N,) moved by their corrections `params` (V, 6) -> (o + t, R d)."""
    p = params[view]
    rot = axis_angle_matrix(p[:, :3])
    return o + p[:, 3:], (rot @ d[:, :, None])[:, :, 0]


class PoseRefine(nn.Module):
    """The corrections (V, 6) of V training views, from zero."""

    def __init__(self, views: int):
        super().__init__()
        self.params = nn.Parameter(torch.zeros(views, 6))

    def forward(self, view: Tensor, o: Tensor, d: Tensor) -> tuple[Tensor, Tensor]:
        return correct_rays(self.params, view, o, d)

    @torch.no_grad()
    def hold_gauge(self) -> None:
        """Remove the corrections' mean rotation and shift (a move of the whole world)."""
        self.params.sub_(self.params.mean(0, keepdim=True))


def pose_summary(params: Tensor, scale: float) -> dict:
    """What the refinement moved: rms and largest rotation (degrees) and shift (world units, q units times the
    box's `scale`) over the views."""
    p = params.detach().cpu().double()
    ang = torch.rad2deg(p[:, :3].norm(dim=1))
    shift = p[:, 3:].norm(dim=1) * scale
    rms = lambda x: float(math.sqrt(float((x * x).mean()))) if len(x) else 0.0  # noqa: E731
    return {"views": int(p.shape[0]), "rotation_rms_deg": round(rms(ang), 4),
            "rotation_max_deg": round(float(ang.max()) if len(ang) else 0.0, 4),
            "shift_rms": round(rms(shift), 5), "shift_max": round(float(shift.max()) if len(shift) else 0.0, 5)}
