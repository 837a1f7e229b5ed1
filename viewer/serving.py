"""The work behind `snapshot3d serve`, without the web framework: decode an upload into a scene folder,
render one view on demand, make the mesh; baked grids kept in memory (least recently used) for
/render. Views are (size, size, 3) RGB, written as PNG."""
from __future__ import annotations

import gzip
import json
import threading
from collections import OrderedDict
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats, validate
from snapshot3d.cameras import orbit_cameras, view_camera
from snapshot3d.errors import UserError
from snapshot3d.scanner.imageio_safe import write_atomic
from snapshot3d.scene import load_scene_file, save_scene

from .bake import Baked, bake_field
from .decode import DecodedScene, decode_scene
from .gridfile import encode_grid
from .march import Frame
from .render import RenderConfig, pad_planes, render_views
from .runtime import scene_models

__all__ = ["BakedCache", "write_scene", "png_bytes", "render_png", "orbit_view_png", "mesh_file"]


class BakedCache:
    """scene id -> (scene, baked), at most `keep` of them in memory; a miss bakes the scene file again."""

    def __init__(self, keep: int):
        self.keep = max(int(keep), 1)
        self._items: OrderedDict[str, tuple] = OrderedDict()
        self._lock = threading.Lock()

    def put(self, sid: str, scene, baked: Baked) -> None:
        with self._lock:
            self._items[sid] = (scene, baked)
            self._items.move_to_end(sid)
            while len(self._items) > self.keep:
                self._items.popitem(last=False)

    def get(self, sid: str, folder: Path, cfg: RenderConfig = RenderConfig()):
        with self._lock:
            if sid in self._items:
                self._items.move_to_end(sid)
                return self._items[sid]
        scene = load_scene_file(folder / "scene.s3d")
        baked = bake_field(scene_models(scene), pad_planes(scene.planes()),
                           Frame.from_box(scene.box), cfg.bake)
        self.put(sid, scene, baked)
        return scene, baked


def write_scene(folder: Path, path, cfg: RenderConfig = RenderConfig()) -> DecodedScene:
    """Decode the photo or snapshot file at `path` (or several photos of one sheet, a list) into `folder`:
    scene.s3d, report.json, grid.bin.gz and capture.png (the rectified, colour-corrected capture the restore read,
    (380, 380, 3) RGB; for several photos, their combination). A non-finite
    scene or report is refused (UserError) before anything is written."""
    ds = decode_scene(path, cfg)
    report = dict(ds.report, views=formats.ORBIT_VIEWS, size=formats.ORBIT_SIZE)
    validate.finite_tree(report, "report")   # save_scene checks the box and orbit
    snap = np.asarray(ds.snapshot, np.uint8)
    save_scene(ds.scene, folder / "scene.s3d")
    grid = encode_grid(ds.baked.grid, ds.scene.box, ds.scene.orbit, Frame.from_box(ds.scene.box).step)
    (folder / "grid.bin.gz").write_bytes(gzip.compress(grid, compresslevel=6))
    (folder / "report.json").write_text(json.dumps(report, indent=2, allow_nan=False) + "\n")
    ok, buf = cv2.imencode(".png", cv2.cvtColor(snap, cv2.COLOR_RGB2BGR))
    if not ok:
        raise OSError("cannot encode the capture as PNG")
    (folder / "capture.png").write_bytes(buf.tobytes())
    return ds


def png_bytes(rgb01: np.ndarray) -> bytes:
    """(H, W, 3) float RGB in [0, 1] -> PNG bytes."""
    u8 = np.clip(np.rint(rgb01 * 255), 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(".png", cv2.cvtColor(u8, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise OSError("cannot encode a PNG")
    return buf.tobytes()


def _render(scene, baked: Baked, c2w, intr, size: int, cfg: RenderConfig) -> np.ndarray:
    return render_views(scene_models(scene), None, scene.box, c2w, intr, size, size, cfg, baked=baked)[0]


def render_png(scene, baked: Baked, azimuth: float, elevation: float, distance: float | None, size: int,
               cfg: RenderConfig = RenderConfig()) -> bytes:
    """One view from anywhere on the scene's orbit sphere (`cameras.view_camera`) as PNG bytes."""
    c2w, intr = view_camera(scene.orbit, azimuth, elevation, distance, size)
    if not (np.isfinite(c2w).all() and np.isfinite(intr).all() and intr[0, 0] > 0):
        raise UserError(f"no camera at azimuth {azimuth:g}, elevation {elevation:g}, distance {distance}: "
                        "it is degenerate for this scene")
    return png_bytes(_render(scene, baked, c2w, intr, size, cfg))


def orbit_view_png(folder: Path, scene, baked: Baked, i: int, cfg: RenderConfig = RenderConfig()) -> Path:
    """views/NNN.png of the scene's orbit (as `decode` writes them), rendered once and kept."""
    path = folder / "views" / f"{i:03d}.png"
    if not path.is_file():
        c2w, intr = orbit_cameras(scene.orbit, formats.ORBIT_VIEWS, formats.ORBIT_SIZE)
        write_atomic(path, png_bytes(_render(scene, baked, c2w[i:i + 1], intr[i:i + 1], formats.ORBIT_SIZE, cfg)))
    return path


def mesh_file(folder: Path, scene, baked: Baked) -> Path:
    """mesh.glb of the scene (marching cubes on the bake, vertex colours), made once and kept."""
    from .mesh import decoded_mesh

    path = folder / "mesh.glb"
    if not path.is_file():
        write_atomic(path, decoded_mesh(baked, scene.box).export(file_type="glb"))
    return path
