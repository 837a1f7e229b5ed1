"""`snapshot3d demo`: decode the bundled example photo (the bundled print-sized spot scene hidden in a
bundled host photo, put on a sheet, printed and photographed by the simulator at `moderate`;
`snapshot3d make-example`) and measure `restore_psnr` against the bundled original scene. numpy, OpenCV and
onnxruntime only."""
from __future__ import annotations

from pathlib import Path

from snapshot3d import formats
from snapshot3d.metrics import psnr
from snapshot3d.paths import asset
from snapshot3d.scene import load_scene_file

__all__ = ["demo_command", "EXAMPLE_PHOTO", "EXAMPLE_SCENE"]

EXAMPLE_PHOTO = "example-photo.jpg"
EXAMPLE_SCENE = "spot-print.s3d"


def demo_command(args) -> int:
    from snapshot3d.cameras import orbit_cameras

    from .commands import write_outputs
    from .decode import decode_photo
    from .render import render_views
    from .runtime import scene_models

    photo, original = asset(EXAMPLE_PHOTO), load_scene_file(asset(EXAMPLE_SCENE))
    out = Path(args.output)
    print(f"decoding the bundled example {photo.name} (a phone photo of a printed sheet, made by the simulator at "
          f"severity moderate) ...", flush=True)
    dec = decode_photo(photo)
    c2w, intr = orbit_cameras(original.orbit, formats.ORBIT_VIEWS, formats.ORBIT_SIZE)
    ref = render_views(scene_models(original), original.planes(), original.box, c2w, intr,
                       formats.ORBIT_SIZE, formats.ORBIT_SIZE)
    dec.report["restore_psnr"] = round(psnr(dec.views, ref), 2)
    out.mkdir(parents=True, exist_ok=True)
    write_outputs(out, dec.views, dec.report)
    r = dec.report
    print(f"decode_ms {r['decode_ms']:.0f} (scan {r['timings_ms']['scan']:.0f}, restore {r['timings_ms']['restore']:.0f}, "
          f"bake {r['timings_ms']['bake']:.0f}, render {r['timings_ms']['render']:.0f}; first view "
          f"{r['timings_ms']['first_view']:.0f})")
    q = r["quality_estimate"]
    expected = "no calibration" if q["restore_psnr_expected_db"] is None else f"{q['restore_psnr_expected_db']:.1f} dB"
    print(f"restore_psnr {r['restore_psnr']:.2f} dB against the original scene's views (expected from "
          f"{q['basis']} alone, without ground truth: {expected})")
    print(f"wrote {out}/views/000-{len(dec.views) - 1:03d}.png, {out}/turntable.gif, {out}/contact.png, "
          f"{out}/report.json")
    return 0
