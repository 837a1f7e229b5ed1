"""A pinhole camera with one radial distortion term, and the sheet's pose in front of it (numpy only).

Pixel coordinates have pixel centres at integers (OpenCV's convention); the camera looks along +z
with y down. The sheet is the plane z = 0 of its layout frame (layout units, `scanner.layout`)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["Camera", "distort", "undistort", "apply_h", "rotation", "sheet_homography", "quad_area"]


@dataclass(frozen=True)
class Camera:
    """Intrinsics of a photo: size, focal length f (pixels), principal point, distortion k1."""

    width: int
    height: int
    f: float
    cx: float
    cy: float
    k1: float = 0.0

    def K(self) -> np.ndarray:
        return np.array([[self.f, 0, self.cx], [0, self.f, self.cy], [0, 0, 1]], np.float64)

    def as_dict(self) -> dict:
        return {k: float(v) for k, v in asdict(self).items()}


def apply_h(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Apply a (3, 3) homography to (..., 2) points."""
    p = np.asarray(pts, np.float64)
    q = p @ H[:, :2].T + H[:, 2]
    return q[..., :2] / q[..., 2:3]


def distort(pts: np.ndarray, cam: Camera) -> np.ndarray:
    """Ideal (undistorted) pixel positions (..., 2) -> where the lens puts them."""
    c = np.array([cam.cx, cam.cy])
    n = (np.asarray(pts, np.float64) - c) / cam.f
    r2 = (n ** 2).sum(-1, keepdims=True)
    return n * (1.0 + cam.k1 * r2) * cam.f + c


def undistort(pts: np.ndarray, cam: Camera, iters: int = 12) -> np.ndarray:
    """Inverse of `distort` by fixed-point iteration (|k1| r^2 well below 1)."""
    c = np.array([cam.cx, cam.cy])
    d = (np.asarray(pts, np.float64) - c) / cam.f
    n = d.copy()
    for _ in range(iters):
        n = d / (1.0 + cam.k1 * (n ** 2).sum(-1, keepdims=True))
    return n * cam.f + c


def rotation(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rodrigues: (3, 3) rotation by `angle_rad` about the unit vector `axis`."""
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * k + (1 - np.cos(angle_rad)) * (k @ k)


def sheet_homography(cam: Camera, R: np.ndarray, t: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(3, 3) homography from layout (u, v) to ideal pixels, for the sheet point `centre` (layout) placed
    at camera-frame position t and the sheet's axes rotated by R: X = R [u - cu, v - cv, 0] + t."""
    M = np.column_stack([R[:, 0], R[:, 1], t - R[:, :2] @ np.asarray(centre, np.float64)])
    return cam.K() @ M


def quad_area(q: np.ndarray) -> float:
    """Area of a polygon (N, 2) by the shoelace formula."""
    x, y = q[:, 0], q[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
