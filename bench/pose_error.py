"""How far a fit's training poses lie from a synthetic capture's true poses (issue 40, `bench capture-background`):
the object's true box seen from each pose against the same box seen from the true pose, in pixels.

Shapes: c2w and true_c2w (V, 4, 4) OpenGL camera-to-world of the same V frames; intrinsics (V, 4) rows (fx, fy, cx,
cy) in pixels; box (2, 3) world corners [min, max]."""
from __future__ import annotations

import numpy as np

from snapshot3d.cameras import project

__all__ = ["pose_error"]


def _grid(box: np.ndarray, n: int = 5) -> np.ndarray:
    """(n**3, 3) points evenly over the box, its corners included."""
    axes = [np.linspace(box[0][k], box[1][k], n) for k in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def _turn_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle (degrees) of the rotation between two 3x3 rotations."""
    cos = (np.trace(a @ b.T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def pose_error(c2w: np.ndarray, true_c2w: np.ndarray, intrinsics: np.ndarray, box) -> dict:
    """Each frame's median over the box's 5x5x5 points of |projection at c2w - projection at true_c2w| (px); their
    median, mean and largest over the frames (px_median, px_mean, px_max) and the rms of the frames' turn from the
    true rotation (rot_deg_rms)."""
    points = _grid(np.asarray(box, np.float64))
    px, turns = [], []
    for pose, truth, (fx, fy, cx, cy) in zip(np.asarray(c2w, np.float64), np.asarray(true_c2w, np.float64),
                                             np.asarray(intrinsics, np.float64)):
        at, _ = project(points, pose, fx, fy, cx, cy)
        true, _ = project(points, truth, fx, fy, cx, cy)
        px.append(float(np.median(np.linalg.norm(at - true, axis=1))))
        turns.append(_turn_deg(pose[:3, :3], truth[:3, :3]))
    px, turns = np.array(px), np.array(turns)
    return {"px_median": round(float(np.median(px)), 3), "px_mean": round(float(px.mean()), 3),
            "px_max": round(float(px.max()), 3), "rot_deg_rms": round(float(np.sqrt((turns ** 2).mean())), 3)}
