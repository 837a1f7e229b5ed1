"""Camera and ray maths in numpy (no torch), shared by fitting, rendering and decoding.

Conventions (as in Blender, NeRF-Synthetic and nerfstudio):
- `c2w` is a camera-to-world matrix, float, shape (4, 4) or (N, 4, 4), OpenGL axes:
  camera x right, y up, and the camera looks down its -z axis.
- Intrinsics are pinhole `fx, fy, cx, cy` in pixels; pixel (u, v) has its centre at (u + 0.5, v + 0.5),
  u to the right, v down, the image origin at the top-left corner.
"""
from __future__ import annotations

import numpy as np

__all__ = ["orbit_cameras", "view_camera", "pixel_rays", "look_at", "orbit_poses", "focal_from_fov", "project",
           "azimuth_span_deg"]


def focal_from_fov(fov_x_rad: float, width: int) -> float:
    """Focal length in pixels for a horizontal field of view `fov_x_rad` (radians) over `width` pixels."""
    return 0.5 * width / np.tan(0.5 * fov_x_rad)


def pixel_rays(c2w: np.ndarray, fx: float, fy: float, cx: float, cy: float, width: int, height: int):
    """Rays through every pixel centre of one camera.

    c2w: (4, 4) OpenGL camera-to-world. Returns `origins` and unit `dirs`, both (H*W, 3) float32,
    row-major over (v, u).
    """
    assert c2w.shape == (4, 4), c2w.shape
    u, v = np.meshgrid(np.arange(width, dtype=np.float64) + 0.5, np.arange(height, dtype=np.float64) + 0.5)
    d_cam = np.stack([(u - cx) / fx, -(v - cy) / fy, -np.ones_like(u)], axis=-1).reshape(-1, 3)
    dirs = d_cam @ c2w[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    origins = np.broadcast_to(c2w[:3, 3], dirs.shape)
    return origins.astype(np.float32), dirs.astype(np.float32)


def project(points: np.ndarray, c2w: np.ndarray, fx: float, fy: float, cx: float, cy: float):
    """Project world points (N, 3) into a camera. Returns pixel coordinates (N, 2) as (u, v) in the
    convention above (pixel centres at +0.5) and depth (N,) along the viewing axis (positive in front)."""
    w2c = np.linalg.inv(c2w)
    p = points @ w2c[:3, :3].T + w2c[:3, 3]
    depth = -p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = fx * p[:, 0] / depth + cx
        v = -fy * p[:, 1] / depth + cy
    return np.stack([u, v], axis=-1), depth


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """OpenGL camera-to-world (4, 4) for a camera at `eye` looking at `target`, with world `up`."""
    eye, target, up = (np.asarray(a, dtype=np.float64) for a in (eye, target, up))
    back = eye - target
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    if np.linalg.norm(right) < 1e-8:  # looking straight along `up`: pick any right vector
        right = np.cross([0.0, 1.0, 0.0], back)
    right /= np.linalg.norm(right)
    true_up = np.cross(back, right)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, true_up, back, eye
    return c2w


def orbit_poses(n: int, radius: float, elevation_deg, target=(0.0, 0.0, 0.0), azimuth0_deg: float = 0.0,
                up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """`n` cameras evenly spaced in azimuth around `target` (world z up), (n, 4, 4) float64.

    `elevation_deg` is a scalar or a sequence of `n` elevations (degrees above the xy plane)."""
    az = np.deg2rad(azimuth0_deg + 360.0 * np.arange(n) / n)
    el = np.deg2rad(np.broadcast_to(np.asarray(elevation_deg, dtype=np.float64), (n,)))
    target = np.asarray(target, dtype=np.float64)
    eyes = target + radius * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    return np.stack([look_at(e, target, up) for e in eyes])


def orbit_cameras(orbit, views: int, size: int):
    """c2w (views, 4, 4) float32 OpenGL and intrinsics (views, 4) (fx, fy, cx, cy) of a scene's orbit
    (`scene.Orbit`) rendered at size x size pixels."""
    from . import formats

    c2w = orbit_poses(views, orbit.radius, orbit.elevation_deg, orbit.target, up=formats.WORLD_UP).astype(np.float32)
    f = focal_from_fov(np.deg2rad(orbit.fov_deg), size)
    return c2w, np.tile(np.array([f, f, size / 2, size / 2], np.float32), (views, 1))


def view_camera(orbit, azimuth_deg: float, elevation_deg: float, distance: float | None, size: int):
    """One camera of a scene's orbit moved anywhere on its sphere: c2w (1, 4, 4) float32 OpenGL and
    intrinsics (1, 4), looking at the orbit's target from `distance` world units (None: the orbit's
    radius) at `azimuth_deg` (0: the +x side, as view 0 of `orbit_cameras`; counter-clockwise seen from
    above) and `elevation_deg` above the xy plane, with the orbit's field of view over size x size. UserError
    (one line) when a number is out of `snapshot3d.validate`'s ranges (a request's parameters come here)."""
    from . import formats, validate
    from .errors import UserError

    radius = orbit.radius if distance is None else validate.number(distance, "distance", 0.0, 1e8)
    validate.number(azimuth_deg, "azimuth_deg", -1e6, 1e6)
    validate.number(elevation_deg, "elevation_deg", *validate.ELEVATION_RANGE)
    with np.errstate(invalid="ignore", divide="ignore"):
        c2w = orbit_poses(1, radius, elevation_deg, orbit.target, azimuth0_deg=azimuth_deg,
                          up=formats.WORLD_UP).astype(np.float32)
    if not np.isfinite(c2w).all() or np.all(c2w[0, :3, 3] == np.float32(orbit.target)):
        raise UserError(f"distance {radius:g} is too close to the orbit's target for a camera")
    f = focal_from_fov(np.deg2rad(orbit.fov_deg), size)
    return c2w, np.array([[f, f, size / 2, size / 2]], np.float32)


def azimuth_span_deg(c2w: np.ndarray, centre) -> float:
    """Cameras c2w (N, 4, 4) round `centre` (3,), z up -> the degrees of azimuth their positions span round it: 360
    less the widest gap between neighbours on the circle (0 for fewer than two cameras)."""
    rel = np.asarray(c2w, np.float64)[:, :2, 3] - np.asarray(centre, np.float64)[:2]
    if len(rel) < 2:
        return 0.0
    az = np.sort(np.degrees(np.arctan2(rel[:, 1], rel[:, 0])))
    return float(360.0 - np.diff(np.r_[az, az[0] + 360.0]).max())
