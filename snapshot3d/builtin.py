"""Built-in scenes: a mesh rendered from an orbit of cameras into `PosedImages`.

`procedural` is built in code and ships with the package; the other meshes are read from the
project's `../shared/data/meshes` (see SOURCES.md there) and are never copied into the package.
Rendering is OpenCV 5's `cv2.triangleRasterize` (see `snapshot3d._raster` for the measured choice).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from . import _raster
from .cameras import focal_from_fov, look_at
from .errors import UserError
from .posed import PosedImages

__all__ = ["BUILTIN_NAMES", "shared_data_dir", "load_mesh", "render_mesh", "builtin_scene"]

BUILTIN_NAMES = ("procedural", "spot", "duck", "teapot", "bunny", "suzanne")

# name: (mesh path under shared/data, texture path or None, crease angle in degrees below which normals
#        are smoothed, RGB albedo for untextured meshes). All five files are y-up; after turning them
#        z-up the cow faces +y, the duck +x, suzanne -y, the bunny -x and the teapot's spout points +x.
_FILES = {
    "spot": ("meshes/spot/spot_triangulated.obj", "meshes/spot/spot_texture.png", 50.0, None),
    "duck": ("meshes/duck.glb", None, 50.0, None),
    "teapot": ("meshes/teapot.obj", None, 50.0, (0.82, 0.80, 0.74)),
    "bunny": ("meshes/stanford-bunny.obj", None, 50.0, (0.80, 0.66, 0.50)),
    "suzanne": ("meshes/suzanne.obj", None, 100.0, (0.90, 0.55, 0.25)),  # low-poly: smooth it as Blender does
}
FOV_X_DEG = 40.0  # horizontal field of view of every built-in camera
FILL = 0.85  # the largest half-extent over all views reaches this fraction of the half-frame
ELEVATIONS_DEG = (-15.0, 65.0)  # the orbit spiral's elevation range
RENDERER = "opencv-triangleRasterize, 2x supersampled"


def shared_data_dir() -> Path | None:
    """`$SNAPSHOT3D_SHARED_DATA` if set, else `<repo>/../shared/data` of the checkout that holds this
    file (the repo root is the folder with pyproject.toml); None when the folder does not exist."""
    env = os.environ.get("SNAPSHOT3D_SHARED_DATA")
    if env:
        return Path(env) if Path(env).is_dir() else None
    for parent in Path(__file__).resolve().parents:
        if (parent / "pyproject.toml").is_file():
            candidate = parent.parent / "shared" / "data"
            return candidate if candidate.is_dir() else None
    return None


def _paint(mesh: trimesh.Trimesh, rgb: np.ndarray) -> None:
    """Give every vertex of `mesh` the colour `rgb` (3,) in [0, 1]."""
    rgba = np.append(np.round(255 * np.asarray(rgb)), 255).astype(np.uint8)
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=np.tile(rgba, (len(mesh.vertices), 1)))


def _procedural() -> trimesh.Trimesh:
    """Grey slab with a red box, green sphere, blue cylinder, yellow cone and orange torus (z up)."""
    c = trimesh.creation
    box = c.box(extents=(0.55, 0.55, 0.55))
    box.apply_transform(trimesh.transformations.rotation_matrix(np.deg2rad(25.0), (0, 0, 1)))
    parts = [
        (c.box(extents=(2.2, 2.2, 0.12)), (0.0, 0.0, -0.06), (150, 150, 150)),
        (box, (-0.55, -0.55, 0.275), (210, 50, 45)),
        (c.icosphere(subdivisions=3, radius=0.33), (0.55, -0.55, 0.33), (60, 170, 75)),
        (c.cylinder(radius=0.22, height=0.8, sections=48), (0.55, 0.55, 0.4), (50, 90, 205)),
        (c.cone(radius=0.3, height=0.75, sections=48), (-0.55, 0.55, 0.0), (235, 200, 40)),
        (c.torus(major_radius=0.24, minor_radius=0.08), (0.0, 0.0, 0.08), (235, 125, 35)),
    ]
    for mesh, offset, rgb in parts:
        mesh.apply_translation(offset)
        _paint(mesh, np.array(rgb) / 255.0)
    return trimesh.util.concatenate([m for m, _, _ in parts])


def _from_file(name: str) -> trimesh.Trimesh:
    rel, tex_rel, crease, rgb = _FILES[name]
    data = shared_data_dir()
    missing = [r for r in (rel, tex_rel) if r and (data is None or not (data / r).exists())]
    if missing:
        raise UserError(f"builtin:{name} needs ../shared/data/{missing[0]} (not found); "
                        "builtin:procedural ships with the package")
    mesh = trimesh.load(data / rel, force="mesh")
    if tex_rel:  # the OBJ names no material: attach the texture; uv keep OBJ's bottom-up v
        mesh.visual = trimesh.visual.TextureVisuals(uv=mesh.visual.uv, image=Image.open(data / tex_rel))
    if rgb is not None:
        _paint(mesh, np.array(rgb))
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))  # y up -> z up
    mesh.metadata["crease_deg"] = crease
    return mesh


def load_mesh(name: str) -> trimesh.Trimesh:
    """The named built-in mesh, z up, centred on its bounding box and scaled so that its largest
    half-extent is 1, outward-facing winding. Textured meshes keep trimesh TextureVisuals, the others
    carry vertex colours. Raises UserError for an unknown name or a missing ../shared/data mesh."""
    if name == "procedural":
        mesh = _procedural()
    elif name in _FILES:
        mesh = _from_file(name)
    else:
        raise UserError(f"unknown builtin scene {name!r}; choose one of {', '.join(BUILTIN_NAMES)}")
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    mesh.apply_scale(2.0 / mesh.extents.max())
    if mesh.is_winding_consistent and mesh.volume < 0:
        mesh.invert()
    return mesh


def render_mesh(mesh: trimesh.Trimesh, c2w: np.ndarray, intrinsics: np.ndarray, width: int, height: int,
                supersample: int = 2):
    """Rasterise `mesh` for each camera with view-independent shading (albedo from the texture, sampled
    per pixel, or vertex colours, times ambient + two fixed world-space Lambertian lights).

    c2w: (N, 4, 4) OpenGL camera-to-world; intrinsics: (N, 4) rows (fx, fy, cx, cy) in pixels.
    Returns images (N, H, W, 3) float32 RGB in [0, 1] composited on white and alpha (N, H, W) float32
    coverage in [0, 1], both anti-aliased by rendering `supersample`x larger and averaging."""
    c2w = np.asarray(c2w, dtype=np.float64)
    intrinsics = np.asarray(intrinsics, dtype=np.float64)
    assert c2w.ndim == 3 and c2w.shape[1:] == (4, 4), c2w.shape
    assert intrinsics.shape == (len(c2w), 4), intrinsics.shape
    assert int(width) > 0 and int(height) > 0 and int(supersample) >= 1
    surface = _raster.prepare_surface(mesh, max_texture_side=max(256, supersample * max(width, height)))
    images = np.empty((len(c2w), height, width, 3), np.float32)
    alpha = np.empty((len(c2w), height, width), np.float32)
    for i in range(len(c2w)):
        images[i], alpha[i] = _raster.render_view(surface, c2w[i], intrinsics[i], width, height, supersample)
    return images, alpha


def _orbit_directions(n: int, seed: int) -> np.ndarray:
    """(n, 3) unit directions on a golden-angle spiral, uniform in area between the elevation limits,
    ordered by elevation, with a seed-dependent azimuth offset."""
    lo, hi = np.sin(np.deg2rad(ELEVATIONS_DEG))
    el = np.arcsin(lo + (hi - lo) * (np.arange(n) + 0.5) / n)
    az = np.random.default_rng(seed).uniform(0, 2 * np.pi) + np.arange(n) * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def _fit_radius(vertices: np.ndarray, rotations: np.ndarray, f_over_c: float):
    """Smallest orbit radius at which every vertex stays within FILL of the half-frame in every view
    (cameras at radius * their back axis, looking at the origin). Returns (radius, per-view fill (N,))."""
    q = np.stack([vertices @ r for r in rotations])  # camera-frame coordinates before the radius shift
    lateral = np.maximum(np.abs(q[..., 0]), np.abs(q[..., 1])) * f_over_c
    radius = float(np.max(q[..., 2] + lateral / FILL))
    return radius, (lateral / (radius - q[..., 2])).max(axis=1)


def builtin_scene(name: str, n_train: int = 80, n_test: int = 20, size: int = 200, seed: int = 0) -> PosedImages:
    """Render built-in `name` from n_train + n_test cameras on one orbit sphere (test views interleaved
    on the same spiral, so no test pose is a train pose), size x size pixels, FOV_X_DEG horizontal fov."""
    if n_train < 1 or n_test < 0 or size < 8:
        raise UserError(f"builtin:{name} needs n_train >= 1, n_test >= 0 and size >= 8")
    mesh = load_mesh(name)
    n = n_train + n_test
    dirs = _orbit_directions(n, seed)
    c2w = np.stack([look_at(d, np.zeros(3)) for d in dirs])
    fx = focal_from_fov(np.deg2rad(FOV_X_DEG), size)
    radius, fill = _fit_radius(np.asarray(mesh.vertices), c2w[:, :3, :3], fx / (0.5 * size))
    c2w[:, :3, 3] = radius * dirs
    intrinsics = np.tile([fx, fx, 0.5 * size, 0.5 * size], (n, 1))
    images, alpha = render_mesh(mesh, c2w, intrinsics, size, size)
    is_test = (np.arange(1, n + 1) * n_test) // n > (np.arange(n) * n_test) // n
    lo, hi = mesh.bounds
    box = np.stack([lo - 0.03 * (hi - lo), hi + 0.03 * (hi - lo)]).astype(np.float32)
    info = {"radius": radius, "fov_x_deg": FOV_X_DEG, "renderer": RENDERER, "seed": seed,
            "fill_min": float(fill.min()), "fill_max": float(fill.max())}
    return PosedImages(images=images, alpha=alpha, c2w=c2w.astype(np.float32),
                       intrinsics=intrinsics.astype(np.float32), box=box, train=np.flatnonzero(~is_test),
                       test=np.flatnonzero(is_test), name=f"builtin:{name}", info=info)
