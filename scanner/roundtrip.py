"""A snapshot through its sheet, a simulated phone photo and the scanner (numpy and OpenCV only): the one
capture path that the benches, the print codec's training captures, the export's parity check and the tests
share."""
from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from .presets import get_preset
from .scan import scan_image
from .sheet import render_sheet
from .simulate import simulate

__all__ = ["capture", "capture_scan"]


def capture(snapshot: np.ndarray, meta, severity, seed: int, sheet_dots: int = 2,
            print_dots: int | None = None) -> np.ndarray:
    """`capture_scan`'s rectified snapshot (380, 380, 3) uint8 RGB."""
    return capture_scan(snapshot, meta, severity, seed, sheet_dots, print_dots).snapshot


def capture_scan(snapshot: np.ndarray, meta, severity, seed: int, sheet_dots: int = 2,
                 print_dots: int | None = None):
    """snapshot (380, 380, 3) uint8 RGB and its metadata (`scanner.qr.SheetMeta`) -> what `scan` reads (its
    `ScanResult`: the rectified snapshot (380, 380, 3) uint8 RGB, the QR code's dict) from a simulated photo
    (`severity`: a preset name or a `Preset`; `seed`) of its sheet, drawn at `sheet_dots` dots per snapshot pixel;
    `print_dots` replaces a physical preset's printer dots per snapshot pixel (the print's size). Raises `UserError`
    when the scanner does not find the sheet."""
    preset = get_preset(severity)
    if preset.physical and print_dots is not None:
        preset = replace(preset, print_dots_per_px=print_dots)
    data, _, _ = simulate(render_sheet(snapshot, meta, sheet_dots), preset, seed)
    return scan_image(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))
