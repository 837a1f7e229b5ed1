"""The `snapshot3d` command line. Parsers are built here without importing torch (fast `--help`);
each command's work is imported lazily from its subpackage. A user's mistake (`UserError`) is
printed as one line and exits 1."""
from __future__ import annotations

import argparse
import dataclasses
import sys

from .errors import UserError
from .lazy import lazy_command as _run
from .scanner.cli import SEVERITY_NAMES

__all__ = ["main", "build_parser"]


def _add_dataclass_options(parser: argparse.ArgumentParser, cls) -> None:
    """One `--option` per dataclass field, its help from the field's metadata."""
    for f in dataclasses.fields(cls):
        flag = "--" + f.name.replace("_", "-")
        help_ = f"{f.metadata.get('help', '')} (default: {f.default})"
        if f.type in (bool, "bool"):
            parser.add_argument(flag, dest=f.name, action=argparse.BooleanOptionalAction, default=f.default, help=help_)
        else:
            typ = {"int": int, "float": float, int: int, float: float}.get(f.type, str)
            parser.add_argument(flag, dest=f.name, type=typ, default=f.default, help=help_)


def build_parser() -> argparse.ArgumentParser:
    from snapshot3d.train.config import CodecConfig, FitConfig  # torch-free dataclasses

    p = argparse.ArgumentParser(prog="snapshot3d", description="3D snapshots: a 3D scene printed as a photograph.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    f = sub.add_parser("fit", help="fit a compact tri-plane scene to posed images")
    f.add_argument("scene", help="Blender folder, nerfstudio transforms.json (or its folder), or builtin:NAME")
    f.add_argument("-o", "--output", required=True, help="scene file to write (.s3d)")
    f.add_argument("--budget", default="fixed", choices=("fixed", "auto"),
                   help="auto: fit a ladder of plane sizes and keep the smallest within 0.5 dB of the best")
    f.add_argument("--downscale", type=int, default=1, help="divide image size by this on load")
    f.add_argument("--size", type=int, default=200, help="view size of builtin scenes")
    f.add_argument("--resume", action="store_true", help="continue from OUTPUT.ckpt if present")
    f.add_argument("--report", help="write a JSON report here")
    _add_dataclass_options(f, FitConfig)
    f.set_defaults(func=_run("snapshot3d.train.commands", "fit_command"))

    r = sub.add_parser("render", help="render the orbit views of a scene (torch reference renderer)")
    r.add_argument("scene", help="scene file (.s3d)")
    r.add_argument("-o", "--output", required=True, help="folder for NNN.png, turntable.gif, contact.png")
    r.add_argument("--views", type=int, default=20)
    r.add_argument("--size", type=int, default=380)
    r.set_defaults(func=_run("snapshot3d.train.commands", "render_command"))

    m = sub.add_parser("mesh", help="extract a vertex-coloured mesh (marching cubes) as GLB or PLY")
    m.add_argument("scene", help="scene file (.s3d)")
    m.add_argument("-o", "--output", required=True, help="mesh file (.glb or .ply)")
    m.add_argument("--res", type=int, default=128, help="grid resolution per axis")
    m.set_defaults(func=_run("snapshot3d.train.commands", "mesh_command"))

    t = sub.add_parser("train", help="train shared models")
    tsub = t.add_subparsers(dest="what", required=True, metavar="WHAT")
    td = tsub.add_parser("decoder", help="train the shared decoder jointly over builtin scenes (resumable)")
    td.add_argument("--steps", type=int, default=6000)
    td.add_argument("--seed", type=int, default=0)
    td.add_argument("-o", "--output", help="weights file (default: the package's assets)")
    td.set_defaults(func=_run("snapshot3d.train.commands", "train_decoder_command"))
    tc = tsub.add_parser("codec", help="train the hiding codec through the print-and-capture channel (resumable)")
    tc.add_argument("--scenes-dir", default="cache/scenes", help="folder of fitted training scenes (.s3d)")
    tc.add_argument("-o", "--output", help="weights file (default: the package's assets)")
    _add_dataclass_options(tc, CodecConfig)
    tc.set_defaults(func=_run("snapshot3d.train.codec_commands", "train_codec_command"))

    e = sub.add_parser("embed", help="hide a scene in a host photo: a 380x380 snapshot")
    e.add_argument("scene", help="scene file (.s3d)")
    e.add_argument("--host", default="builtin:coffee", help="host photo file, or builtin:NAME (a bundled photo)")
    e.add_argument("-o", "--output", required=True, help="snapshot to write (.png; .jpg is lossy)")
    e.add_argument("--strength", type=float, default=1.0, help="embedding strength: more survives more, shows more")
    e.add_argument("--jpeg-quality", type=int, default=95, help="quality when writing .jpg")
    e.add_argument("--refine", type=int, default=100,
                   help="embed-time refinement steps against the restore network (0: the network's snapshot as is; "
                        "more: better restores from the file and JPEG copies, about 0.4 s a step on 2 cores)")
    e.add_argument("--report", help="write a JSON report here (host_psnr, host_ssim)")
    e.set_defaults(func=_run("snapshot3d.train.codec_commands", "embed_command"))

    rs = sub.add_parser("restore", help="recover the scene from a snapshot image (torch)")
    rs.add_argument("snapshot", help="snapshot image (380x380 .png or .jpg with snapshot3d metadata)")
    rs.add_argument("-o", "--output", required=True, help="scene file to write (.s3d)")
    rs.add_argument("--meta", help="the sheet's QR text, when the file carries no metadata")
    rs.add_argument("--report", help="write a JSON report here")
    rs.set_defaults(func=_run("snapshot3d.train.codec_commands", "restore_command"))

    b = sub.add_parser("bench", help="benchmarks: write CSV, JSON and PNG charts under bench/results/")
    bsub = b.add_subparsers(dest="what", required=True, metavar="WHAT")
    bf = bsub.add_parser("fit", help="field_psnr against scene_kb and fit time, spot and lego; throughput")
    bf.add_argument("--out", default="bench/results", help="output folder")
    bf.add_argument("--quick", action="store_true", help="few steps, for a smoke run")
    bf.add_argument("--scenes", default="spot,lego", help="comma-separated bench scenes; a subset writes fit_<names>.*")
    bf.add_argument("--merge", action="store_true", help="only combine fit_<scene>.json files into fit.*")
    bf.set_defaults(func=_run("snapshot3d.train.bench", "bench_fit_command"))

    bc = bsub.add_parser("codec", help="host fidelity vs restore_psnr through simulate+scan; baselines; charts")
    bc.add_argument("--out", default="bench/results", help="output folder")
    bc.add_argument("--scenes", default="snapshot3d/assets/spot.s3d,cache/scenes/lego.s3d",
                    help="comma-separated scene files to evaluate (spot is never trained on)")
    bc.add_argument("--hosts", default="coffee,chelsea", help="bundled host photos (held out from training)")
    bc.add_argument("--headline", default="spot,lego", help="scenes (file stems) the summary's medians are over")
    bc.add_argument("--seeds", type=int, default=3, help="simulated photos per physical severity")
    bc.add_argument("--size", type=int, default=128, help="orbit view size for restore_psnr")
    bc.add_argument("--refine", type=int, default=100, help="embed-time refinement steps of the ours-refined rows "
                                                           "and the side-by-side figure (0: neither)")
    bc.add_argument("--strengths", default="0.5,0.75,1,1.5,2", help="embedding strengths of the trade-off sweep")
    bc.add_argument("--digital", default="bench/models/codec-digital.npz",
                    help="baseline a: the codec trained without the channel")
    bc.set_defaults(func=_run("snapshot3d.train.codec_bench_run", "bench_codec_command"))

    bj = bsub.add_parser("codec-jpeg", help="restore_psnr of a snapshot file through JPEG (4:2:0, 4:4:4), "
                                            "chroma subsampling, noise, blur and sub-pixel shifts, one at a time")
    bj.add_argument("--out", default="bench/results", help="output folder")
    bj.add_argument("--compare", default=None, help="another codec weights file measured beside the shipped one")
    bj.add_argument("--refine", type=int, default=100, help="also the shipped codec's snapshots refined this many steps "
                                                           "at embed time (0: not)")
    bj.set_defaults(func=_run("snapshot3d.train.codec_jpeg_bench", "bench_codec_jpeg_command"))

    bq = bsub.add_parser("capacity", help="the capture channel's Gaussian capacity per severity and the best "
                                          "restore_psnr it allows, beside the shipped codec's, per plane size")
    bq.add_argument("--out", default="bench/results", help="output folder")
    bq.add_argument("--scenes", default="snapshot3d/assets/spot.s3d,bench/models/spot-r48c4.s3d,bench/models/spot-r32c4.s3d",
                    help="comma-separated scene files (spot fitted at several plane sizes)")
    bq.add_argument("--hosts", default="coffee,chelsea", help="bundled host photos (held out from training)")
    bq.add_argument("--seeds", type=int, default=3, help="simulated photos per physical severity")
    bq.add_argument("--size", type=int, default=128, help="orbit view size for restore_psnr")
    bq.set_defaults(func=_run("snapshot3d.train.capacity_bench", "bench_capacity_command"))

    bd = bsub.add_parser("decode", help="torch-free decode of simulated photos: decode_ms per stage, restore_psnr, "
                                        "e2e_psnr; a speed/accuracy sweep and its chart")
    bd.add_argument("--out", default="bench/results", help="output folder")
    bd.add_argument("--seeds", type=int, default=20, help="simulated photos")
    bd.add_argument("--severity", default="moderate", choices=SEVERITY_NAMES, help="simulated print-and-capture severity")
    bd.add_argument("--host", default="chelsea", help="bundled host photo (held out from codec training)")
    bd.add_argument("--sweep-severity", default="jpeg90", choices=SEVERITY_NAMES, help="capture the settings sweep runs on")
    bd.add_argument("--repeats", type=int, default=3, help="timed decodes per sweep setting (median)")
    bd.add_argument("--calib-seeds", type=int, default=4, help="captures per severity for the quality estimate's line")
    bd.add_argument("--calibration", default=None,
                    help="where to write that line (default: the package's file, which decode reads)")
    bd.set_defaults(func=_run("snapshot3d.train.decode_bench", "bench_decode_command"))

    from snapshot3d.scanner.cli import add_bench_commands, add_commands  # torch-free option builders
    add_commands(sub)
    add_bench_commands(bsub)

    dc = sub.add_parser("decode", help="photo of a printed sheet -> views, turntable, report (no torch)")
    dc.add_argument("photo", help="photo (.jpg or .png) of a printed snapshot3d sheet")
    dc.add_argument("-o", "--output", required=True, help="output folder")
    dc.add_argument("--views", type=int, default=20, help="orbit views")
    dc.add_argument("--size", type=int, default=380, help="view size in pixels")
    dc.add_argument("--samples", type=int, default=None, help="samples per pixel (speed against accuracy; default 16)")
    dc.add_argument("--mesh", action="store_true", help="also write mesh.glb (marching cubes, vertex colours)")
    dc.set_defaults(func=_run("snapshot3d.viewer.commands", "decode_command"))

    ex = sub.add_parser("export", help="export the restore network and the renderer as ONNX, with parity checks")
    ex.add_argument("-o", "--output", help="folder (default: the package's assets, which decode uses)")
    ex.set_defaults(func=_run("snapshot3d.export.commands", "export_command"))

    d = sub.add_parser("demo", help="decode the bundled example photo into 20 views (seconds, no torch)")
    d.add_argument("-o", "--output", default="snapshot3d-demo", help="output folder")
    d.set_defaults(func=_run("snapshot3d.viewer.demo", "demo_command"))

    mx = sub.add_parser("make-example", help="make the demo's example photo (embed + sheet + simulate)")
    mx.add_argument("-o", "--output", help="photo file (default: the package's assets)")
    mx.add_argument("--host", default="builtin:chelsea", help="host photo")
    mx.add_argument("--severity", default="jpeg90", choices=SEVERITY_NAMES, help="simulated capture severity")
    mx.add_argument("--seed", type=int, default=0)
    mx.add_argument("--refine", type=int, default=100, help="embed-time refinement steps (as embed --refine)")
    mx.set_defaults(func=_run("snapshot3d.train.example", "make_example_command"))
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
