"""Sampling where the sheet lies in a photo: camera intrinsics, tilt, in-plane rotation, size and position."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapshot3d import formats

from . import layout
from .camera import Camera, apply_h, distort, quad_area, rotation, sheet_homography
from .presets import Preset

__all__ = ["Pose", "sample_pose"]


@dataclass(frozen=True)
class Pose:
    """A sampled capture geometry. H maps layout units to ideal (undistorted) photo pixels."""

    camera: Camera
    H: np.ndarray
    tilt_deg: float
    inplane_deg: float
    coverage: float
    """snapshot area in the photo / frame area (as rendered)"""

    def to_photo(self, pts: np.ndarray) -> np.ndarray:
        """Layout points (..., 2) -> photo pixels (lens distortion included)."""
        return distort(apply_h(self.H, pts), self.camera)

    def as_dict(self) -> dict:
        return {"camera": self.camera.as_dict(), "H_layout_to_ideal_px": self.H.tolist(), "tilt_deg": self.tilt_deg,
                "inplane_deg": self.inplane_deg, "coverage": self.coverage}


def _sheet_corners() -> np.ndarray:
    x0, y0, x1, y1 = formats.SHEET_BOX
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64)


def sample_pose(preset: Preset, rng: np.random.Generator, margin_frac: float = 0.01) -> Pose:
    """Draw a pose with the whole sheet inside the frame (at least `margin_frac` of the width from its
    edges). The coverage drawn from the preset shrinks by 15% after every 10 placements that do not fit."""
    W, Hh = preset.frame
    cam = Camera(W, Hh, f=float(rng.uniform(*preset.focal_frac)) * W, cx=(W - 1) / 2 + rng.normal(0, 0.004 * W),
                 cy=(Hh - 1) / 2 + rng.normal(0, 0.004 * W), k1=float(rng.uniform(*preset.k1)))
    tilt = float(rng.uniform(*preset.tilt_deg))
    tilt_dir = rng.uniform(0, 2 * np.pi)
    inplane = float(rng.uniform(0, 360))
    R = rotation([np.cos(tilt_dir), np.sin(tilt_dir), 0], np.deg2rad(tilt)) @ rotation([0, 0, 1], np.deg2rad(inplane))
    centre = np.array([formats.SNAPSHOT_SIZE / 2] * 2)
    snap, sheet = layout.snapshot_corners(), _sheet_corners()
    Kinv = np.linalg.inv(cam.K())
    cov = float(rng.uniform(*preset.coverage))
    margin = margin_frac * W
    for attempt in range(600):
        if attempt and attempt % 10 == 0:
            cov *= 0.85
        c = np.array([rng.uniform(margin, W - margin), rng.uniform(margin, Hh - margin)])
        ray = Kinv @ np.array([c[0], c[1], 1.0])
        H0 = sheet_homography(cam, R, ray * 1000.0, centre)
        area0 = quad_area(apply_h(H0, snap))
        z = 1000.0 * np.sqrt(area0 / (cov * W * Hh))
        H = sheet_homography(cam, R, ray * z, centre)
        corners3d_z = (R[:, :2] @ (sheet - centre).T)[2] + ray[2] * z
        if np.any(corners3d_z <= 0.05 * z):
            continue
        q = distort(apply_h(H, sheet), cam)
        if q[:, 0].min() >= margin and q[:, 1].min() >= margin and q[:, 0].max() <= W - 1 - margin \
                and q[:, 1].max() <= Hh - 1 - margin:
            actual = quad_area(distort(apply_h(H, snap), cam)) / (W * Hh)
            return Pose(cam, H, tilt, inplane, float(actual))
    raise RuntimeError("could not place the sheet inside the frame")
