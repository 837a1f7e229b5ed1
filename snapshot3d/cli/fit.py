"""Options of the training-side commands: `fit`, `render`, `mesh` and `train decoder|codec|print-codec` (torch
when they run; the parsers read only torch-free config dataclasses)."""
from __future__ import annotations

from snapshot3d.formats import MEDIA
from snapshot3d.lazy import lazy_command as _run
from snapshot3d.options import add_dataclass_options

from .common import DEVICE_HELP
from .common import add_command as _add

__all__ = ["add_commands"]


def add_commands(sub) -> None:
    """Add fit, render, mesh, make-capture and train to the top-level subparsers `sub`."""
    from snapshot3d.train.codec.config import CodecConfig  # torch-free dataclasses
    from snapshot3d.train.codec.print_config import PrintCodecConfig
    from snapshot3d.train.field.config import DecoderConfig, FitConfig

    f = _add(sub, "fit", "fit a compact tri-plane scene to posed images (torch)",
             _run("snapshot3d.train.field.commands", "fit_command"))
    f.add_argument("scene", help="Blender folder, nerfstudio transforms.json (or its folder), COLMAP text model "
                                 "(cameras.txt + images.txt, or a folder with sparse/0/), or builtin:NAME "
                                 "(procedural, spot, duck, teapot, bunny, suzanne); see docs/capture.md")
    f.add_argument("-o", "--output", required=True, help="scene file to write (.s3d)")
    f.add_argument("--budget", default="fixed", choices=("fixed", "auto"),
                   help="auto: fit a ladder of plane sizes and keep the smallest within 0.5 dB of the best (by "
                        "field_psnr, or with --medium by the e2e_psnr expected through that medium)")
    f.add_argument("--medium", default=None, choices=MEDIA,
                   help="with --budget auto: the medium the scene will travel through; its codec's loss at each "
                        "payload counts (print: a photographed print carries far less, so smaller planes win)")
    f.add_argument("--channel", help="with --budget auto --medium print: predict through the channel measured by "
                                     "`snapshot3d calibrate` (a profile .json) instead of the `moderate` preset's")
    f.add_argument("--downscale", type=int, default=1, help="divide image size by this on load")
    f.add_argument("--max-size", type=int, default=800,
                   help="then shrink images so that the longer side is at most this many pixels (not builtin scenes)")
    f.add_argument("--holdout", type=int, default=None,
                   help="hold out every N-th frame (the 0th, N-th, ...) for field_psnr; 0: none, and the training "
                        "frames are scored (default: Blender's test split, builtin's test views, else every 8th)")
    f.add_argument("--box", help="world box x0,y0,z0,x1,y1,z1 (in the world after --up; write --box=-1,... when it "
                                 "starts with a minus) instead of the one carved from masks or placed by the cameras")
    f.add_argument("--up", help="the world's up axis, x,y,z or auto (square to the cameras' level x axes); the world is "
                                "turned so that it becomes +z (default: auto for nerfstudio and COLMAP, as given for "
                                "Blender and builtin; 0,0,1 keeps it)")
    f.add_argument("--size", type=int, default=200, help="view size of builtin scenes")
    f.add_argument("--resume", action="store_true", help="continue from OUTPUT.ckpt if present")
    f.add_argument("--report", help="write a JSON report here")
    f.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"), help=DEVICE_HELP)
    add_dataclass_options(f, FitConfig)

    r = _add(sub, "render", "render the orbit views of a scene (torch reference renderer)",
             _run("snapshot3d.train.field.commands", "render_command"))
    r.add_argument("scene", help="scene file (.s3d)")
    r.add_argument("-o", "--output", required=True, help="folder for views/NNN.png, turntable.gif, contact.png")
    r.add_argument("--views", type=int, default=20, help="orbit views, evenly spaced in azimuth")
    r.add_argument("--size", type=int, default=380, help="view size in pixels (square)")

    m = _add(sub, "mesh", "extract a vertex-coloured mesh (marching cubes) as GLB or PLY",
             _run("snapshot3d.train.field.commands", "mesh_command"))
    m.add_argument("scene", help="scene file (.s3d)")
    m.add_argument("-o", "--output", required=True, help="mesh file (.glb or .ply)")
    m.add_argument("--res", type=int, default=128, help="grid resolution per axis")

    from snapshot3d.make_capture_config import SynthCaptureConfig  # torch- and numpy-free
    mc = _add(sub, "make-capture", "render a real-looking capture of a built-in mesh (nerfstudio transforms.json: a "
                                   "photo room, lens, exposure, pose noise) with ground truth aside in DIR/gt",
              _run("snapshot3d.make_capture", "make_capture_command"))
    mc.add_argument("scene", help="builtin:NAME (procedural, spot, duck, teapot, bunny, suzanne)")
    mc.add_argument("-o", "--output", required=True, help="folder to create (absent or empty); see docs/capture.md")
    add_dataclass_options(mc, SynthCaptureConfig)

    t = _add(sub, "train", "train the shared models (resumable; their weights ship in the package)", None)
    tsub = t.add_subparsers(dest="what", required=True, metavar="WHAT")
    td = _add(tsub, "decoder", "train the shared decoder jointly over builtin scenes (resumable)",
              _run("snapshot3d.train.field.commands", "train_decoder_command"))
    add_dataclass_options(td, DecoderConfig)
    td.add_argument("-o", "--output", help="weights file (default: the package's assets)")
    td.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"), help=DEVICE_HELP)
    tc = _add(tsub, "codec", "train the file medium's hiding codec through the differentiable channel (resumable)",
              _run("snapshot3d.train.codec.commands", "train_codec_command"))
    tc.add_argument("--scenes-dir", default="cache/scenes", help="folder of fitted training scenes (.s3d)")
    tc.add_argument("-o", "--output", help="weights file (default: the package's assets)")
    tc.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"), help=DEVICE_HELP)
    add_dataclass_options(tc, CodecConfig)
    tp = _add(tsub, "print-codec", "train the print medium's restore front-end on captures made through simulate "
                                   "+ scan (resumable)", _run("snapshot3d.train.codec.commands", "train_print_codec_command"))
    tp.add_argument("--data", default="cache/print-captures", help="folder of training captures (made when missing)")
    tp.add_argument("--workers", type=int, default=0, help="processes making captures (0: one per core)")
    tp.add_argument("-o", "--output", help="weights file (default: bench/models/print-front.npz)")
    tp.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"), help=DEVICE_HELP)
    add_dataclass_options(tp, PrintCodecConfig)
