"""The `snapshot3d` command line. Parsers are built here without importing torch (fast `--help`), one
module per command group (`fit`, `codec`, `serve`, `scanner`, `bench`; shared helpers in `common`); each
command's work is imported lazily from its subpackage. A user's mistake (`UserError`) is printed as one line
and exits 1."""
from __future__ import annotations

import argparse
import sys

from snapshot3d import __version__
from snapshot3d.errors import UserError

from .common import Formatter

__all__ = ["main", "build_parser", "Formatter"]


def build_parser() -> argparse.ArgumentParser:
    from . import bench, codec, fit, scanner, serve

    p = argparse.ArgumentParser(prog="snapshot3d", formatter_class=Formatter,
                                description="3D snapshots: a 3D scene printed as a photograph, and a phone photo of "
                                            "the print turned back into a 3D scene.")
    p.add_argument("--version", action="version", version=f"snapshot3d {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    fit.add_commands(sub)
    codec.add_commands(sub)
    serve.add_commands(sub)
    codec.add_demo_commands(sub)
    scanner.add_commands(sub)
    bench.add_commands(sub)
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
