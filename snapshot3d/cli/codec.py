"""Options of the codec and decode commands: `embed`, `restore`, `decode`, `export`, `demo` and `make-example`."""
from __future__ import annotations

from snapshot3d.formats import FILE_REFINE_STEPS, MEDIA, SEVERITIES
from snapshot3d.lazy import lazy_command as _run

from .common import add_command as _add
from .common import hosts_help

__all__ = ["add_commands", "add_demo_commands"]


def add_commands(sub) -> None:
    """Add embed, restore, decode and export to the top-level subparsers `sub`."""
    e = _add(sub, "embed", "hide a scene in a host photo: a 380x380 snapshot for a medium (print or file)",
             _run("snapshot3d.train.codec.commands", "embed_command"))
    e.add_argument("scene", help="scene file (.s3d)")
    e.add_argument("--host", default="builtin:coffee", help=hosts_help())
    e.add_argument("-o", "--output", required=True, help="snapshot to write (.png; .jpg is lossy)")
    e.add_argument("--medium", default="print", choices=MEDIA,
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
    dc.add_argument("photo", nargs="+", help="photo (.jpg or .png) of a printed snapshot3d sheet, or a snapshot file "
                                             "(also a shared copy with its text stripped); several photos of one "
                                             "printed sheet (up to 8, or a folder of them) are combined, each "
                                             "weighted by its pilots")
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


def add_demo_commands(sub) -> None:
    """Add demo and make-example to the top-level subparsers `sub`."""
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
    mx.add_argument("--medium", default="print", choices=MEDIA, help="the medium, as embed --medium")
    mx.add_argument("--host", default="builtin:chelsea", help=hosts_help())
    mx.add_argument("--severity", default="moderate", choices=SEVERITIES, help="simulated capture severity")
    mx.add_argument("--seed", type=int, default=0, help="random seed of the simulated capture")
    mx.add_argument("--refine", type=int, default=FILE_REFINE_STEPS, help="file medium: embed-time refinement steps (as embed "
                                                           "--refine)")
