"""The `snapshot3d` command line. Parsers are built here without importing torch (fast `--help`);
each command's work is imported lazily from its subpackage. A user's mistake (`UserError`) is
printed as one line and exits 1."""
from __future__ import annotations

import argparse
import sys

from . import __version__
from .errors import UserError
from .formats import FILE_REFINE_STEPS
from .lazy import lazy_command as _run
from .options import add_dataclass_options

__all__ = ["main", "build_parser", "Formatter"]

SEVERITY_NAMES = ("none", "jpeg90", "jpeg75", "mild", "moderate", "severe")  # = scanner.presets.SEVERITIES
DEVICE_HELP = "where training runs: auto (CUDA when present), cpu or cuda"


class Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's help ends with its default."""

    def _get_help_string(self, action):
        if action.default in (None, False) or action.help in (None, argparse.SUPPRESS) or "%(default)" in action.help:
            return action.help
        return super()._get_help_string(action)


def _hosts_help() -> str:
    from .scanner.backgrounds import BACKGROUND_NAMES
    return ("host photo: an image file, or builtin:NAME, a bundled photo (NAME one of "
            + ", ".join(BACKGROUND_NAMES + ("grace_hopper",)) + ")")


def _add(sub, name: str, help: str, func, **kw) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help, description=help[:1].upper() + help[1:] + ".", formatter_class=Formatter, **kw)
    p.set_defaults(func=func)
    return p


def _fit_parsers(sub) -> None:
    from snapshot3d.train.codec.config import CodecConfig  # torch-free dataclasses
    from snapshot3d.train.codec.print_config import PrintCodecConfig
    from snapshot3d.train.field.config import FitConfig

    f = _add(sub, "fit", "fit a compact tri-plane scene to posed images (torch)",
             _run("snapshot3d.train.field.commands", "fit_command"))
    f.add_argument("scene", help="Blender folder, nerfstudio transforms.json (or its folder), or builtin:NAME "
                                 "(procedural, spot, duck, teapot, bunny, suzanne)")
    f.add_argument("-o", "--output", required=True, help="scene file to write (.s3d)")
    f.add_argument("--budget", default="fixed", choices=("fixed", "auto"),
                   help="auto: fit a ladder of plane sizes and keep the smallest within 0.5 dB of the best (by "
                        "field_psnr, or with --medium by the e2e_psnr expected through that medium)")
    f.add_argument("--medium", default=None, choices=("print", "file"),
                   help="with --budget auto: the medium the scene will travel through; its codec's loss at each "
                        "payload counts (print: a photographed print carries far less, so smaller planes win)")
    f.add_argument("--downscale", type=int, default=1, help="divide image size by this on load")
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

    t = _add(sub, "train", "train the shared models (resumable; their weights ship in the package)", None)
    tsub = t.add_subparsers(dest="what", required=True, metavar="WHAT")
    td = _add(tsub, "decoder", "train the shared decoder jointly over builtin scenes (resumable)",
              _run("snapshot3d.train.field.commands", "train_decoder_command"))
    td.add_argument("--steps", type=int, default=6000, help="optimisation steps, the scenes taken in turn")
    td.add_argument("--seed", type=int, default=0, help="random seed")
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


def _codec_parsers(sub) -> None:
    e = _add(sub, "embed", "hide a scene in a host photo: a 380x380 snapshot for a medium (print or file)",
             _run("snapshot3d.train.codec.commands", "embed_command"))
    e.add_argument("scene", help="scene file (.s3d)")
    e.add_argument("--host", default="builtin:coffee", help=_hosts_help())
    e.add_argument("-o", "--output", required=True, help="snapshot to write (.png; .jpg is lossy)")
    e.add_argument("--medium", default="print", choices=("print", "file"),
                   help="print: a sheet to print and photograph (its own codec, numpy, about 1 s); file: a snapshot "
                        "file shared digitally (the invertible network, torch)")
    e.add_argument("--strength", type=float, default=None,
                   help="embedding strength (default 1): more survives more, shows more (print: the host fidelity "
                        "falls 20 log10(strength) dB)")
    e.add_argument("--host-psnr", type=float, default=None,
                   help="instead of --strength: the host fidelity to keep, in dB (the strength is chosen for this host "
                        "and scene; e.g. 38, the paper's setting, for a file snapshot)")
    e.add_argument("--jpeg-quality", type=int, default=95, help="quality when writing .jpg")
    e.add_argument("--refine", type=int, default=FILE_REFINE_STEPS,
                   help="file medium: embed-time refinement steps against the restore network (0: the network's "
                        "snapshot as is; more: better restores from the file and JPEG copies, about 0.25 s a step "
                        "on 2 cores)")
    e.add_argument("--report", help="write a JSON report here (host_psnr, host_ssim, embed_ms)")

    rs = _add(sub, "restore", "recover the scene from a snapshot file, with the codec its metadata names (no torch)",
              _run("snapshot3d.viewer.commands", "restore_command"))
    rs.add_argument("snapshot", help="snapshot file (.png or .jpg); its metadata comes from its text or from the "
                                     "mark in its pixels, so a shared copy (re-encoded, resized, cropped) restores")
    rs.add_argument("-o", "--output", required=True, help="scene file to write (.s3d)")
    rs.add_argument("--meta", help="the sheet's QR text, when neither the file's text nor its pixels carry the "
                                   "metadata")
    rs.add_argument("--report", help="write a JSON report here")

    dc = _add(sub, "decode", "photo of a printed sheet (or a snapshot file) -> views, turntable, report (no torch)",
              _run("snapshot3d.viewer.commands", "decode_command"))
    dc.add_argument("photo", help="photo (.jpg or .png) of a printed snapshot3d sheet, or a snapshot file (also a "
                                  "shared copy with its text stripped)")
    dc.add_argument("-o", "--output", required=True, help="output folder")
    dc.add_argument("--views", type=int, default=20, help="orbit views")
    dc.add_argument("--size", type=int, default=380, help="view size in pixels")
    dc.add_argument("--samples", type=int, default=16, help="samples per pixel (speed against accuracy)")
    dc.add_argument("--mesh", action="store_true", help="also write mesh.glb (marching cubes, vertex colours)")

    ex = _add(sub, "export", "export the restore network and the renderer as ONNX, with parity checks (torch)",
              _run("snapshot3d.export.commands", "export_command"))
    dest = ex.add_mutually_exclusive_group(required=True)
    dest.add_argument("-o", "--output", help="folder to write the models and export.json into")
    dest.add_argument("--install", action="store_true",
                      help="overwrite the models the package ships (snapshot3d/assets/), which decode uses")
    ex.add_argument("--vectors", help="also write conformance vectors of the exported models here (.npz; the "
                                      "committed ones are tests/data/onnx-conformance.npz, see docs/onnx-contract.md)")

    sv = _add(sub, "serve", "the scan-and-view API and the phone page: upload a photo, turn the scene (no torch)",
              _run("snapshot3d.viewer.commands", "serve_command"))
    from .viewer.serve_config import ServeConfig  # a torch-free dataclass
    add_dataclass_options(sv, ServeConfig)

    d = _add(sub, "demo", "decode the bundled example photo into 20 views (seconds, no torch)",
             _run("snapshot3d.viewer.demo", "demo_command"))
    d.add_argument("-o", "--output", default="snapshot3d-demo", help="output folder")

    mx = _add(sub, "make-example", "make the demo's example photo: embed + sheet + simulate (torch)",
              _run("snapshot3d.train.codec.example", "make_example_command"))
    dest = mx.add_mutually_exclusive_group(required=True)
    dest.add_argument("-o", "--output", help="photo file to write (.jpg)")
    dest.add_argument("--install", action="store_true",
                      help="overwrite the example photo the package ships (snapshot3d/assets/example-photo.jpg)")
    mx.add_argument("--scene", default=None, help="scene file (default: the demo's, snapshot3d/assets/spot-print.s3d)")
    mx.add_argument("--medium", default="print", choices=("print", "file"), help="the medium, as embed --medium")
    mx.add_argument("--host", default="builtin:chelsea", help=_hosts_help())
    mx.add_argument("--severity", default="moderate", choices=SEVERITY_NAMES, help="simulated capture severity")
    mx.add_argument("--seed", type=int, default=0, help="random seed of the simulated capture")
    mx.add_argument("--refine", type=int, default=FILE_REFINE_STEPS, help="file medium: embed-time refinement steps (as embed "
                                                           "--refine)")


def build_parser() -> argparse.ArgumentParser:
    from .cli_bench import add_bench_commands
    from .scanner.cli import add_commands

    p = argparse.ArgumentParser(prog="snapshot3d", formatter_class=Formatter,
                                description="3D snapshots: a 3D scene printed as a photograph, and a phone photo of "
                                            "the print turned back into a 3D scene.")
    p.add_argument("--version", action="version", version=f"snapshot3d {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _fit_parsers(sub)
    _codec_parsers(sub)
    add_commands(sub, _add)
    b = _add(sub, "bench", "benchmarks: write CSV, JSON and PNG charts under bench/results/", None)
    add_bench_commands(b.add_subparsers(dest="what", required=True, metavar="WHAT"), _add)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except UserError as e:
        print(f"snapshot3d {args.command}: error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"snapshot3d {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
