"""Marching cubes on a density grid into a vertex-coloured trimesh (numpy, scikit-image, trimesh).

Shared by `snapshot3d mesh` (torch field) and the torch-free decode path."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from skimage.measure import marching_cubes

from .errors import UserError

__all__ = ["density_to_mesh", "write_mesh", "unit_grid"]


def unit_grid(res: int) -> np.ndarray:
    """(res^3, 3) float32 points of a res^3 lattice over [-1, 1]^3 (corners included), [ix, iy, iz] order."""
    t = np.linspace(-1.0, 1.0, res, dtype=np.float32)
    return np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)


def density_to_mesh(density: np.ndarray, level: float, box: np.ndarray, colour_fn,
                    cell_centred: bool = False) -> trimesh.Trimesh:
    """density (G, G, G) on `unit_grid(G)` (or, `cell_centred`, at the centres of G^3 cells over the
    box); level: the iso-density; box (2, 3) world box; colour_fn(points (M, 3) in [-1, 1]) -> RGB
    (M, 3) in [0, 1]. Returns a world-space mesh."""
    g = density.shape[0]
    if not (density.max() > level > density.min()):
        raise UserError("the field has no surface at the mesh level (is the scene empty?)")
    padded = np.pad(density, 1, constant_values=0.0)  # closes surfaces that touch the box
    verts, faces, _, _ = marching_cubes(padded, level=level)
    unit = (verts - 0.5) / g if cell_centred else (verts - 1.0) / (g - 1)
    unit = np.clip(unit * 2.0 - 1.0, -1, 1).astype(np.float32)
    rgb = np.clip(colour_fn(unit), 0, 1)
    world = box[0] + (unit + 1.0) * 0.5 * (box[1] - box[0])
    colours = np.concatenate([(rgb * 255).round(), np.full((len(rgb), 1), 255)], 1).astype(np.uint8)
    # marching_cubes returns faces wound for increasing values; flip so normals point out of the solid.
    return trimesh.Trimesh(vertices=world, faces=faces[:, ::-1], vertex_colors=colours, process=False)


def write_mesh(mesh: trimesh.Trimesh, path) -> None:
    path = Path(path)
    if path.suffix.lower() not in (".glb", ".ply"):
        raise UserError(f"{path}: mesh output must end in .glb or .ply")
    data = mesh.export(file_type=path.suffix.lower()[1:])
    tmp = path.with_name(path.name + ".partial")
    tmp.write_bytes(data)
    tmp.replace(path)
