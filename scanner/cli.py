"""Command-line options of the scanner-side commands (`sheet`, `simulate`, `scan`, `bench scan`).

Kept torch-free and import-light: the work is imported lazily when a command runs."""
from __future__ import annotations

from snapshot3d.lazy import lazy_command as _run

__all__ = ["add_commands", "add_bench_commands", "SEVERITY_NAMES"]

SEVERITY_NAMES = ("none", "jpeg90", "jpeg75", "mild", "moderate", "severe")  # = scanner.presets.SEVERITIES


def add_commands(sub) -> None:
    """Add the scanner's subcommands to the top-level subparsers `sub`."""
    s = sub.add_parser("sheet", help="lay out a snapshot as a printable sheet (markers, colour patches, QR code)")
    s.add_argument("snapshot", help="380x380 snapshot image (PNG); any picture stands in until the codec exists")
    s.add_argument("-o", "--output", required=True, help="sheet file to write: .pdf or .png")
    s.add_argument("--width-mm", type=float, default=100.0, help="printed width of the whole sheet (default: 100)")
    s.add_argument("--dpi", type=float, default=300.0, help="printer resolution (default: 300)")
    s.add_argument("--scene", help="scene file (.s3d) whose box and orbit go into the QR code")
    s.set_defaults(func=_run("snapshot3d.scanner.sheet", "sheet_command"))

    m = sub.add_parser("simulate", help="photograph a sheet through a simulated printer, scene and phone camera")
    m.add_argument("sheet", help="sheet image (.png) written by `snapshot3d sheet`")
    m.add_argument("-o", "--output", required=True, help="photo to write (.jpg; .png keeps the channel's JPEG "
                                                         "losslessly; severity none needs .png)")
    m.add_argument("--severity", default="mild", choices=SEVERITY_NAMES, help="channel preset (default: mild)")
    m.add_argument("--seed", type=int, default=0, help="random seed; the same seed gives the same photo")
    m.add_argument("--truth", help="write the true snapshot corners and the preset's parameters here (JSON)")
    m.set_defaults(func=_run("snapshot3d.scanner.commands", "simulate_command"))

    c = sub.add_parser("scan", help="find the sheet in a photo and rectify the snapshot (numpy + OpenCV)")
    c.add_argument("photo", help="photo of a printed sheet (JPEG or PNG)")
    c.add_argument("-o", "--output", required=True, help="rectified, colour-corrected 380x380 snapshot (.png)")
    c.add_argument("--debug", help="write an overlay of the detections on the photo here (.png or .jpg)")
    c.add_argument("--report", help="write a JSON report here (detected, corners, reprojection_px, confidence, "
                                    "qr, timings_ms)")
    c.set_defaults(func=_run("snapshot3d.scanner.commands", "scan_command"))


def add_bench_commands(bsub) -> None:
    """Add `bench scan` to the `bench` subparsers `bsub`."""
    b = bsub.add_parser("scan", help="scanner on simulated photos: detection, corner error, PSNR, speed; charts")
    b.add_argument("--out", default="bench/results", help="output folder (default: bench/results)")
    b.add_argument("--seeds", type=int, default=200, help="simulated photos per severity for mild and moderate "
                                                         "(seeds 0..N-1; default 200)")
    b.add_argument("--severe-seeds", type=int, default=100, help="simulated severe photos (default 100)")
    b.add_argument("--negatives", type=int, default=50, help="photos with no sheet (default 50)")
    b.add_argument("--timing-runs", type=int, default=30, help="repeated scans of one 12 MP photo for the "
                                                               "time median (default 30)")
    b.set_defaults(func=_run("snapshot3d.scanner.bench", "bench_scan_command"))
    c = bsub.add_parser("channel", help="what scan leaves of a printed snapshot, as the codec channel's parameters")
    c.add_argument("--out", default="bench/results", help="output folder (default: bench/results)")
    c.add_argument("--seeds", type=int, default=8, help="simulated photos per severity (default 8)")
    c.add_argument("--severities", default="jpeg75,mild,moderate,severe", help="comma-separated severities")
    c.set_defaults(func=_run("snapshot3d.scanner.channel_fit", "bench_channel_command"))
