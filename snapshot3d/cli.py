"""The `snapshot3d` command line. Parsers are built here without importing torch (fast `--help`);
each command's work is imported lazily from its subpackage. A user's mistake (`UserError`) is
printed as one line and exits 1."""
from __future__ import annotations

import argparse
import dataclasses
import sys

from .errors import UserError
from .lazy import lazy_command as _run

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
    from snapshot3d.train.config import FitConfig  # torch-free dataclasses

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

    b = sub.add_parser("bench", help="benchmarks: write CSV, JSON and PNG charts under bench/results/")
    bsub = b.add_subparsers(dest="what", required=True, metavar="WHAT")
    bf = bsub.add_parser("fit", help="field_psnr against scene_kb and fit time, spot and lego; throughput")
    bf.add_argument("--out", default="bench/results", help="output folder")
    bf.add_argument("--quick", action="store_true", help="few steps, for a smoke run")
    bf.add_argument("--scenes", default="spot,lego", help="comma-separated bench scenes; a subset writes fit_<names>.*")
    bf.add_argument("--merge", action="store_true", help="only combine fit_<scene>.json files into fit.*")
    bf.set_defaults(func=_run("snapshot3d.train.bench", "bench_fit_command"))

    from snapshot3d.scanner.cli import add_bench_commands, add_commands  # torch-free option builders
    add_commands(sub)
    add_bench_commands(bsub)

    d = sub.add_parser("demo", help="fit and render the built-in default scene (about a minute)")
    d.add_argument("-o", "--output", default="snapshot3d-demo", help="output folder")
    d.set_defaults(func=_run("snapshot3d.train.demo", "demo_command"))
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
