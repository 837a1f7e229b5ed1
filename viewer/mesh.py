"""A decoded scene as a mesh (numpy, scikit-image, trimesh; no torch): what `decode --mesh` writes and
`serve` hands out (GLB)."""
from __future__ import annotations

import numpy as np

__all__ = ["decoded_mesh"]


def decoded_mesh(baked, box):
    """Vertex-coloured trimesh of a baked field (`viewer.bake`; marching cubes where one reference step is
    half opaque; colours read from the bake). box (2, 3) float: the scene's box corners."""
    from snapshot3d.meshing import density_to_mesh

    from .bake import sample_points
    from .march import Frame

    step = Frame.from_box(box).step
    return density_to_mesh(np.exp(baked.grid[..., 0]), float(np.log(2.0) / step), np.asarray(box),
                           lambda unit: sample_points(baked, unit)[1], cell_centred=True)
