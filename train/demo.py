"""`snapshot3d demo`: the built-in default in about a minute: fit `builtin:procedural` (it ships with
the package), then render its 20-view orbit. (Later issues turn this into a photo decode.)"""
from __future__ import annotations

from pathlib import Path

from snapshot3d import formats
from snapshot3d.images import contact_sheet, write_gif, write_png, write_views
from snapshot3d.scene import save_scene

from .commands import fit_scene, render_scene, write_report
from .config import FitConfig

__all__ = ["demo_command", "DEMO_CONFIG"]

DEMO_CONFIG = FitConfig(plane_res=48, plane_channels=8, steps=500)


def demo_command(args) -> int:
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    print("fitting builtin:procedural (R=48, C=8, 500 steps) ...", flush=True)
    scene, report, _ = fit_scene("builtin:procedural", DEMO_CONFIG, size=160)
    report.pop("_throughput", None)
    save_scene(scene, out / "scene.s3d")
    write_report(out / "fit.json", report)
    views = render_scene(scene, formats.ORBIT_VIEWS, formats.ORBIT_SIZE)
    write_views(out / "views", views)
    write_gif(out / "turntable.gif", views)
    write_png(out / "contact.png", contact_sheet(views))
    print(f"field_psnr {report['field_psnr']:.2f} dB on held-out views, {report['scene_kb']:.1f} kB, "
          f"fit {report['fit_seconds']:.0f} s")
    print(f"wrote {out}/scene.s3d, {out}/views/000-{formats.ORBIT_VIEWS - 1:03d}.png, {out}/turntable.gif, "
          f"{out}/contact.png, {out}/fit.json")
    return 0
