"""`snapshot3d decode PHOTO -o OUT`: views, turntable, contact sheet, report (and a mesh); no torch.

Everything is written into a hidden sibling folder first and moved into place at the end, so that an
interrupted or failed decode never leaves a half-written OUT."""
from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import numpy as np

from snapshot3d.errors import UserError
from snapshot3d.images import contact_sheet, write_gif, write_png, write_views

__all__ = ["decode_command", "write_outputs", "decoded_mesh"]


def decoded_mesh(baked, box):
    """Vertex-coloured trimesh of a baked field (marching cubes where one reference step is half
    opaque; colours read from the bake)."""
    from snapshot3d.meshing import density_to_mesh

    from .bake import sample_points
    from .march import Frame

    step = Frame.from_box(box).step
    return density_to_mesh(np.exp(baked.grid[..., 0]), float(np.log(2.0) / step), np.asarray(box),
                           lambda unit: sample_points(baked, unit)[1], cell_centred=True)


def write_outputs(folder: Path, views: np.ndarray, report: dict, mesh=None) -> None:
    write_views(folder / "views", views)
    write_gif(folder / "turntable.gif", views)
    write_png(folder / "contact.png", contact_sheet(views))
    if mesh is not None:
        from snapshot3d.meshing import write_mesh
        write_mesh(mesh, folder / "mesh.glb")
    (folder / "report.json").write_text(json.dumps(report, indent=2) + "\n")


def _publish(tmp: Path, out: Path) -> None:
    if out.exists():
        if not out.is_dir():
            raise UserError(f"{out} exists and is not a folder")
        old = out.with_name(f".{out.name}.old")
        shutil.rmtree(old, ignore_errors=True)
        out.rename(old)
        tmp.rename(out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        tmp.rename(out)


def decode_command(args) -> int:
    from .decode import decode_photo
    from .render import RenderConfig

    if not 1 <= args.views <= 360 or not 16 <= args.size <= 2048:
        raise UserError("--views must be in 1..360 and --size in 16..2048")
    if args.samples is not None and args.samples < 1:
        raise UserError("--samples must be >= 1")
    out = Path(args.output)
    dec = decode_photo(args.photo, args.views, args.size, RenderConfig(**({"samples": args.samples} if args.samples else {})))
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    try:
        mesh = decoded_mesh(dec.baked, dec.scene.box) if args.mesh else None
        write_outputs(tmp, dec.views, dec.report, mesh)
        from snapshot3d.scene import save_scene
        save_scene(dec.scene, tmp / "scene.s3d")
        _publish(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    r = dec.report
    print(f"decoded {args.photo}: {len(dec.views)} views of {args.size}x{args.size} in {r['decode_ms']:.0f} ms "
          f"(scan {r['timings_ms']['scan']:.0f}, restore {r['timings_ms']['restore']:.0f}, render "
          f"{r['timings_ms']['render']:.0f}); wrote {out}/")
    return 0
