"""Constants of the snapshot3d formats, in one place (STYLE: one module for format constants).

Everything a scene file, the renderers and (later) the sheet and codec must agree on lives here.
"""
from __future__ import annotations

__all__ = [
    "SCENE_FORMAT_VERSION", "DECODER_VERSION", "C_MAX", "PLANE_AXES", "PLANE_NAMES", "PLANE_RANGE",
    "ORBIT_VIEWS", "ORBIT_SIZE", "ORBIT_ELEVATION_DEG", "ORBIT_FOV_DEG", "WORLD_UP", "BACKGROUND",
    "DENSITY_CLAMP", "RENDER_STEPS_PER_BOX", "OCC_RES", "OCC_ALPHA_THRESHOLD", "KB",
]

SCENE_FORMAT_VERSION = 1
# The shared decoder MLP (features -> density, colour). A scene names the version it was fitted for
# and refuses any other. Bump when the decoder's weights or definition change.
DECODER_VERSION = "tri-dec-1"
# Planes carry C <= C_MAX channels; the decoder reads 3*C_MAX features, unused channels are zero.
C_MAX = 12
# Axis pairs of the three planes (XY, XZ, YZ), in box-normalised coordinates.
PLANE_AXES = ((0, 1), (0, 2), (1, 2))
PLANE_NAMES = ("xy", "xz", "yz")
# Plane values are kept in [-1, 1] and carried as 8-bit codes: v = code / 255 * 2 - 1.
PLANE_RANGE = (-1.0, 1.0)

# The decode orbit (the paper's mobile setting): 20 views of 380x380 around the scene.
ORBIT_VIEWS = 20
ORBIT_SIZE = 380
ORBIT_ELEVATION_DEG = 20.0
ORBIT_FOV_DEG = 40.0
WORLD_UP = (0.0, 0.0, 1.0)
BACKGROUND = 1.0  # white

# Rendering: exp() of the density head is clamped here; sample spacing is box_diagonal / steps.
DENSITY_CLAMP = 15.0
RENDER_STEPS_PER_BOX = 192  # samples along the longest ray through the (normalised) box
OCC_RES = 64                # occupancy grid cells per axis
OCC_ALPHA_THRESHOLD = 0.01  # a cell is occupied when one step through it has alpha above this
KB = 1000                   # scene_kb is in kilobytes of 1000 bytes
