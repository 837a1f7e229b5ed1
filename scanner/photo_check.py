"""What a scanned photo did to the print, measured from the photo itself (numpy and OpenCV): the sheet's tilt, the
blur and the glare, so that a poor decode can say what to change when the photo is taken again.

- **tilt**: the angle between the sheet's normal and the camera's axis, from the fitted homography and a phone's
  focal length (0.76 of the frame's longer side, a 26 mm-equivalent main camera);
- **blur**: how far the markers' outer edges, black ink on paper, are spread, in snapshot pixels: the 10-90% rise
  of each edge's profile (linear light, photo resampled at 8 samples per snapshot pixel) over 2.56, the sigma of
  a Gaussian blur of that rise;
- **glare**: the share of the snapshot's area brighter than the bare paper around it (the scanner's flat field):
  light that the print's inks and paper cannot reflect diffusely, a highlight or a veil over its light parts.
`snapshot3d bench print-ablation` says what each costs a `moderate` photo: glare 1.1-1.4 dB of restore_psnr, the
blur 0.6-1.2, a tilt under 30 degrees 0.3-0.5 (docs/print-codec.md); and how well the check reads them
(docs/scanner.md)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from snapshot3d import formats

from . import layout
from .colour import srgb_decode
from .fit import Fit
from .rectify import rectify_box

__all__ = ["PhotoCheck", "tilt_deg", "edge_blur", "glare_share", "check_photo", "TILT_MAX_DEG", "BLUR_MAX",
           "GLARE_MAX"]

TILT_MAX_DEG = 30.0
"""tilts above this are named when a decode is poor (moderate photos are drawn up to 45 degrees)"""
BLUR_MAX = 0.5
"""blur (sigma, snapshot pixels) above this is named when a decode is poor"""
GLARE_MAX = 0.002
"""a share of the snapshot brighter than the paper above this is named when a decode is poor"""
GLARE_LEVEL = 1.1
"""brighter than the bare paper by this factor (linear light): more than the print can reflect"""
_FOCAL_FRAC = 0.76
_SCALE = 8
_EDGE_HALF = 5            # units either side of an edge
_RISE_TO_SIGMA = 2.563    # 10-90% rise of a Gaussian-blurred step, in sigmas


@dataclass(frozen=True)
class PhotoCheck:
    """What a photo did to the print (`check_photo`); `asdict` is the scan report's `photo`."""

    tilt_deg: float
    """the sheet's normal against the camera's axis, degrees"""
    blur_px: float | None
    """the markers' edge spread (a Gaussian's sigma, snapshot pixels); None where no edge was read"""
    glare_share: float
    """the share of the snapshot brighter than its paper (GLARE_LEVEL)"""

    def causes(self) -> list[str]:
        """What to change, one short clause per measure over its limit, worst first in the order glare, tilt, blur."""
        out = []
        if self.glare_share > GLARE_MAX:
            out.append(f"glare on the print ({100 * self.glare_share:.1f}% of it brighter than its paper: move the "
                       f"light or the phone so that no reflection falls on it)")
        if self.tilt_deg > TILT_MAX_DEG:
            out.append(f"the sheet was tilted {self.tilt_deg:.0f} degrees (hold the phone square over it)")
        if self.blur_px is not None and self.blur_px > BLUR_MAX:
            out.append(f"the photo is blurred ({self.blur_px:.1f} snapshot pixels: hold still and tap to focus)")
        return out


def tilt_deg(fit: Fit) -> float:
    """The angle (degrees) between the sheet's normal and the camera's axis, from the layout -> photo homography
    and a phone's focal length (principal point at the frame's centre)."""
    cam = fit.camera
    f = _FOCAL_FRAC * max(cam.width, cam.height)
    K = np.array([[f, 0, (cam.width - 1) / 2], [0, f, (cam.height - 1) / 2], [0, 0, 1]], np.float64)
    B = np.linalg.solve(K, fit.H)
    n = np.cross(B[:, 0], B[:, 1])
    return float(np.degrees(np.arccos(min(1.0, abs(n[2]) / max(np.linalg.norm(n), 1e-30)))))


def _rise(profile: np.ndarray) -> float | None:
    """10-90% rise distance (samples) of a monotone-ish step profile (n,), dark to bright; None if flat."""
    lo, hi = np.median(profile[:_SCALE * 2]), np.median(profile[-_SCALE * 2:])
    if hi - lo < 0.05:
        return None
    p = (profile - lo) / (hi - lo)
    x = np.arange(len(p), dtype=np.float64)

    def cross(level):   # the last crossing from below of `level`, interpolated
        above = np.flatnonzero((p[:-1] < level) & (p[1:] >= level))
        if not len(above):
            return None
        i = above[-1]
        return x[i] + (level - p[i]) / max(p[i + 1] - p[i], 1e-9)
    a, b = cross(0.1), cross(0.9)
    return None if a is None or b is None or b < a else float(b - a)


def edge_blur(image_bgr: np.ndarray, fit: Fit, marker_ids) -> float | None:
    """The markers' outer edges' blur in snapshot pixels (a Gaussian's sigma; the print's and the resampling's own
    spread included, about 0.2), the median over the four sides of each marker found; None if no edge read."""
    m, h, e = float(formats.MARKER_SIZE), _EDGE_HALF, formats.MARKER_SIZE / 6
    rises = []
    corners = layout.marker_corners()
    for mid in marker_ids:
        x, y = corners[mid][0]
        sides = {   # box straddling the edge (layout units), and how to turn its profile dark -> bright
            "left": ((x - h, y + e, x + h, y + m - e), lambda g: g.mean(0)[::-1]),
            "right": ((x + m - h, y + e, x + m + h, y + m - e), lambda g: g.mean(0)),
            "top": ((x + e, y - h, x + m - e, y + h), lambda g: g.mean(1)[::-1]),
            "bottom": ((x + e, y + m - h, x + m - e, y + m + h), lambda g: g.mean(1)),
        }
        for box, profile in sides.values():
            grey = rectify_box(image_bgr, fit, tuple(int(round(v)) for v in box), _SCALE)
            r = _rise(profile(srgb_decode(grey.astype(np.float32) / 255.0)))
            if r is not None:
                rises.append(r / _SCALE)
    return float(np.median(rises)) / _RISE_TO_SIGMA if rises else None


def glare_share(snapshot_flat: np.ndarray) -> float:
    """The share of the snapshot brighter than the bare paper by GLARE_LEVEL or more: light the print cannot
    reflect diffusely (a glossy highlight, a veil of glare). snapshot_flat: (380, 380, 3) float32 RGB linear,
    over the paper's fitted level (`colour.flat_field`)."""
    return float(np.mean(snapshot_flat.max(-1) >= GLARE_LEVEL))


def check_photo(image_bgr: np.ndarray, fit: Fit, marker_ids, snapshot_flat: np.ndarray) -> PhotoCheck:
    """The photo's tilt, blur and glare (`PhotoCheck`) from the photo (H, W, 3) uint8 BGR, the scan's geometry,
    the markers it found and the rectified snapshot over the paper's level (`glare_share`)."""
    blur = edge_blur(image_bgr, fit, marker_ids)
    return PhotoCheck(tilt_deg=round(tilt_deg(fit), 1), blur_px=None if blur is None else round(blur, 3),
                      glare_share=round(glare_share(snapshot_flat), 5))
