"""`snapshot3d make-example`: the bundled example photo the demo decodes: the demo's scene hidden in a
bundled host for a medium (`embed --medium`), laid out as a sheet and photographed by the simulator. The
default is the print medium, a `moderate` phone photo of the print (the product's promise) in the
preset's 12 MP frame."""
from __future__ import annotations

from pathlib import Path

from snapshot3d.codecs.media import MEDIA
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.presets import PRESETS
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scanner.sheet import render_sheet
from snapshot3d.scanner.simulate import simulate
from snapshot3d.scene import load_scene_file

from .embedding import check_planes_for, snapshot_for

__all__ = ["make_example_command"]


def make_example_command(args) -> int:
    from snapshot3d.paths import asset
    from snapshot3d.scanner.imageio_safe import write_atomic
    from snapshot3d.viewer.demo import EXAMPLE_PHOTO, EXAMPLE_SCENE

    scene = load_scene_file(args.scene or asset(EXAMPLE_SCENE))
    check_planes_for(args.medium, scene)
    snap = snapshot_for(args.medium, load_host(args.host), scene, refine=args.refine)
    preset = PRESETS[args.severity]   # the preset's own 12 MP frame: a 5 MP photo of the sheet costs the print
    # medium 4-6 dB (the snapshot is then captured at below 1:1)
    meta = scene_meta(scene, MEDIA[args.medium].codec)
    data, ext, _ = simulate(render_sheet(snap, meta, 2), preset, args.seed)
    out = asset(EXAMPLE_PHOTO) if args.install else Path(args.output)
    write_atomic(out, data)
    print(f"wrote {out} ({len(data) / 1e3:.0f} kB, {args.medium} medium, {args.severity}, seed {args.seed}, "
          f"host {args.host})")
    return 0
