"""`snapshot3d demo`: decode the bundled example photo (the bundled spot scene hidden in a bundled host
photo, put on a sheet and captured by the simulator as a JPEG-90 file; `snapshot3d make-example`) and
measure `restore_psnr` against the bundled original scene. numpy, OpenCV and onnxruntime only."""
from __future__ import annotations

from pathlib import Path

from snapshot3d import formats
from snapshot3d.metrics import psnr
from snapshot3d.paths import asset
from snapshot3d.scene import load_scene_file

__all__ = ["demo_command", "EXAMPLE_PHOTO", "EXAMPLE_SCENE"]

EXAMPLE_PHOTO = "example-photo.jpg"
EXAMPLE_SCENE = "spot.s3d"


def demo_command(args) -> int:
    from .commands import write_outputs
    from snapshot3d.cameras import orbit_cameras

    from .decode import decode_photo
    from .render import render_views
    from .runtime import model_path, session

    photo, original = asset(EXAMPLE_PHOTO), load_scene_file(asset(EXAMPLE_SCENE))
    out = Path(args.output)
    print(f"decoding the bundled example {photo.name} (the sheet captured as a JPEG-90 file by the simulator; "
          f"physical prints do not survive the current codec well, see bench/results/codec.json) ...", flush=True)
    dec = decode_photo(photo)
    c2w, intr = orbit_cameras(original.orbit, formats.ORBIT_VIEWS, formats.ORBIT_SIZE)
    ref = render_views(session(str(model_path("shade")), 1), original.planes(), original.box, c2w, intr,
                       formats.ORBIT_SIZE, formats.ORBIT_SIZE)
    dec.report["restore_psnr"] = round(psnr(dec.views, ref), 2)
    out.mkdir(parents=True, exist_ok=True)
    write_outputs(out, dec.views, dec.report)
    r = dec.report
    print(f"decode_ms {r['decode_ms']:.0f} (scan {r['timings_ms']['scan']:.0f}, restore {r['timings_ms']['restore']:.0f}, "
          f"occupancy {r['timings_ms']['occupancy']:.0f}, render {r['timings_ms']['render']:.0f}; first view "
          f"{r['timings_ms']['first_view']:.0f})")
    print(f"restore_psnr {r['restore_psnr']:.2f} dB against the original scene's views (the report's ground-truth-free "
          f"estimate, {r['quality_estimate']['plane_psnr_db']:.1f} dB, does not track it yet: see the README)")
    print(f"wrote {out}/views/000-{len(dec.views) - 1:03d}.png, {out}/turntable.gif, {out}/contact.png, "
          f"{out}/report.json")
    return 0
