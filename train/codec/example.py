"""`snapshot3d make-example`: the bundled example photo the demo decodes: the bundled spot scene
hidden in a bundled host (`embed`, refined at embed time as `embed` does by default), put on a sheet, captured by the simulator. The default is `jpeg90`
(the sheet image saved as JPEG 90): the shipped codec does not yet survive physical prints well
(bench/results/codec.json). Physical presets use a 1600x1200 frame so that the file stays small."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from snapshot3d.scanner.presets import PRESETS
from snapshot3d.scanner.sheet import render_sheet
from snapshot3d.scanner.simulate import simulate

from snapshot3d.scene import load_scene_file

from .commands import load_host, scene_meta
from .hinet import load_codec
from .refine import snapshot_of

__all__ = ["make_example_command"]


def make_example_command(args) -> int:
    from snapshot3d.scanner.imageio_safe import write_atomic
    from snapshot3d.viewer.demo import EXAMPLE_PHOTO, EXAMPLE_SCENE

    from snapshot3d.paths import asset

    scene = load_scene_file(asset(EXAMPLE_SCENE))
    snap = snapshot_of(load_codec()[0], load_host(args.host), scene.planes(), args.refine)
    preset = PRESETS[args.severity]
    preset = replace(preset, frame=(1600, 1200)) if preset.physical else preset
    data, ext, _ = simulate(render_sheet(snap, scene_meta(scene, 1.0), 4), preset, args.seed)
    out = asset(EXAMPLE_PHOTO) if args.install else Path(args.output)
    write_atomic(out, data)
    print(f"wrote {out} ({len(data) / 1e3:.0f} kB, {args.severity}, seed {args.seed}, host {args.host}, "
          f"refine {args.refine})")
    return 0
