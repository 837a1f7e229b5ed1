"""The options of `snapshot3d make-capture` as a typed dataclass (import-light: the CLI's parser reads it)."""
from __future__ import annotations

from dataclasses import dataclass

from .options import config_field

__all__ = ["SynthCaptureConfig"]


@dataclass(frozen=True)
class SynthCaptureConfig:
    """How a synthetic capture is made (`snapshot3d.make_capture`); one field per command-line option."""

    views: int = config_field(48, "frames, taken on a walk around the object (two turns, rising from low to high)")
    arc_deg: float = config_field(720.0, "degrees the walk turns round the object over its frames (720: two turns; "
                                         "120: a frontal arc, as of an object against a wall)")
    size: int = config_field(256, "image width in pixels; the height is 3/4 of it (a landscape phone frame)")
    seed: int = config_field(0, "seed of the photos picked, the walk, the lens centre and the jitters")
    backdrop: str = config_field("auto", "photo wrapped round the room behind the object: an image file, or auto (a "
                                         "photo of ../shared/data/hosts/train, else a bundled one)")
    ground: bool = config_field(True, "stand the object on a ground plane textured with a crop of another photo "
                                      "(--no-ground: it floats in front of the backdrop)")
    fov_deg: float = config_field(50.0, "horizontal field of view in degrees")
    exposure_jitter: float = config_field(0.2, "standard deviation of each frame's exposure in stops (white balance: "
                                               "a quarter of it per channel)")
    pose_noise_deg: float = config_field(0.0, "rms rotation error of the poses written to transforms.json (degrees); "
                                              "images are rendered at the true poses (gt/truth.json)")
    pose_noise_frac: float = config_field(0.0, "rms position error of the written poses, a fraction of the camera's "
                                               "distance to the object")
    lens: tuple = config_field((-0.08, 0.02, 0.0005, -0.0005), "OPENCV distortion k1 k2 p1 p2 applied to every "
                                                                 "frame (0 0 0 0: none)")
