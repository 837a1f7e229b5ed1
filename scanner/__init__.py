"""The print sheet, the print-and-capture simulator and the scanner (numpy and OpenCV only; never torch).

Public surface (imported lazily on first use, so that `snapshot3d --help` stays fast):
    render_sheet(snapshot_rgb, meta, k) -> sheet RGB            (scanner.sheet)
    simulate(sheet_rgb, severity, seed, print_seed=None) -> (bytes, ext, truth)  (scanner.simulate)
    scan_image(photo_bgr) -> ScanResult, scan_file(path)        (scanner.scan)
    capture(snapshot_rgb, meta, severity, seed) -> rectified RGB (scanner.roundtrip: sheet, photo, scan)
    detect_markers(image, dictionary) -> (ids (N,), corners (N, 4, 2))  (scanner.detect)
    SheetMeta, PRESETS                                          (scanner.qr, scanner.presets)
"""
from importlib import import_module

__all__ = ["render_sheet", "simulate", "scan_image", "scan_file", "ScanResult", "detect_markers", "SheetMeta",
           "PRESETS", "capture"]
_WHERE = {"render_sheet": "sheet", "simulate": "simulate", "scan_image": "scan", "scan_file": "scan",
          "ScanResult": "scan", "detect_markers": "detect", "SheetMeta": "qr", "PRESETS": "presets",
          "capture": "roundtrip"}


def __getattr__(name):
    if name in _WHERE:
        return getattr(import_module(f"{__name__}.{_WHERE[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
