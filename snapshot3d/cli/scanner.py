"""Options of the scanner-side commands: `sheet`, `simulate` and `scan` (numpy and OpenCV when they run)."""
from __future__ import annotations

from snapshot3d.formats import SEVERITIES
from snapshot3d.lazy import lazy_command as _run

from .common import add_command as _add

__all__ = ["add_commands"]


def add_commands(sub) -> None:
    """Add sheet, simulate, scan and calibrate to the top-level subparsers `sub`."""
    s = _add(sub, "sheet", "lay out a snapshot as a printable sheet (markers, colour patches, QR code)",
            _run("snapshot3d.scanner.sheet", "sheet_command"))
    s.add_argument("snapshot", nargs="?", help="380x380 snapshot (.png from `snapshot3d embed`, which carries its "
                                               "metadata); not with --calibration")
    s.add_argument("-o", "--output", required=True,
                   help="sheet to write: .pdf (the PNG of the same page is written beside it) or .png")
    s.add_argument("--width-mm", type=float, default=100.0, help="printed width of the whole sheet in millimetres")
    s.add_argument("--dpi", type=float, default=300.0, help="printer resolution in dots per inch")
    s.add_argument("--scene", help="scene file (.s3d) whose box and orbit go into the QR code (a snapshot from "
                                   "`embed` carries them already)")
    s.add_argument("--calibration", action="store_true",
                   help="write the calibration chart instead of a snapshot's sheet (photograph its print and run "
                        "`snapshot3d calibrate`)")

    m = _add(sub, "simulate", "photograph a printed sheet through a simulated printer, scene and phone camera",
            _run("snapshot3d.scanner.commands", "simulate_command"))
    m.add_argument("sheet", help="sheet written by `snapshot3d sheet` (.png, or the .pdf with its .png beside it)")
    m.add_argument("-o", "--output", required=True, help="photo to write (.jpg; .png keeps the channel's JPEG "
                                                         "losslessly; severity none needs .png)")
    m.add_argument("--severity", default=None, choices=SEVERITIES,
                   help="channel preset (parameters in scanner/presets.py; default mild)")
    m.add_argument("--profile", help="photograph through a measured channel instead of a preset: a channel profile "
                                     "(.json) from `snapshot3d calibrate`")
    m.add_argument("--seed", type=int, default=0, help="random seed; the same seed gives the same photo")
    m.add_argument("--print-seed", type=int, default=None,
                   help="seed of the print itself (its halftone and paper): photos with other --seed values and the "
                        "same --print-seed show one print, as several photos of one sheet do (`decode` combines "
                        "them); default: a new print per photo")
    m.add_argument("--truth", help="write the true snapshot corners and the preset's parameters here (JSON)")

    c = _add(sub, "scan", "find the sheet in a photo and rectify the snapshot (numpy + OpenCV)",
            _run("snapshot3d.scanner.commands", "scan_command"))
    c.add_argument("photo", help="photo of a printed sheet (JPEG or PNG)")
    c.add_argument("-o", "--output", required=True, help="rectified, colour-corrected 380x380 snapshot (.png)")
    c.add_argument("--debug", help="write an overlay of the detections on the photo here (.png or .jpg)")
    c.add_argument("--report", help="write a JSON report here (detected, corners, reprojection_px, confidence, "
                                    "qr, photo: tilt, blur and glare, timings_ms)")

    k = _add(sub, "calibrate", "measure a printer and phone from a photo of the calibration chart (numpy + OpenCV)",
             _run("snapshot3d.scanner.calibrate", "calibrate_command"))
    k.add_argument("photo", help="photo of the printed chart from `snapshot3d sheet --calibration` (JPEG or PNG)")
    k.add_argument("-o", "--output", help="write the channel profile here (.json)")
    k.add_argument("--report", help="write a JSON report here (the profile, the photo's name, timings_ms)")
