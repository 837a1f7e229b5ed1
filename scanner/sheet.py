"""The printable sheet (DESIGN 1.3): snapshot, corner ArUco markers, colour patches, QR code (and a scene's own
head in two smaller codes beside it, `headcode`), quiet zone.

The sheet image is the layout (`scanner.layout`, `formats` "sheet and scan") drawn at an integer
number of dots per snapshot pixel, so that every snapshot pixel prints as a crisp k x k block and a
perfect capture gives the snapshot back exactly."""
from __future__ import annotations

import io
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.codecs.media import CODEC_MEDIUM
from snapshot3d.errors import UserError

from . import layout
from .headcode import HEAD_CODE_LEVEL, HEAD_CODES_FIELD, split_head
from .imageio_safe import read_image_bgr, write_atomic
from .qr import SheetMeta, encode_payload, qr_matrix, scene_meta

__all__ = ["SheetConfig", "render_sheet", "chart_sheet", "sheet_command", "write_print_files"]


@dataclass(frozen=True)
class SheetConfig:
    """How large to print the sheet."""

    width_mm: float = field(default=100.0, metadata={"help": "printed width of the whole sheet in millimetres"})
    dpi: float = field(default=300.0, metadata={"help": "printer resolution; the sheet is drawn at the nearest whole "
                                                        "number of dots per snapshot pixel"})

    def dots_per_pixel(self) -> int:
        """Dots per snapshot pixel k: the integer nearest to width_mm * dpi / 25.4 / sheet width (>= 1)."""
        return max(1, round(self.width_mm / 25.4 * self.dpi / layout.sheet_size()[0]))


def render_sheet(snapshot: np.ndarray, meta: SheetMeta, k: int) -> np.ndarray:
    """Draw the sheet at k dots per snapshot pixel.

    snapshot: (SNAPSHOT_SIZE, SNAPSHOT_SIZE, 3) uint8 RGB. Returns (H, W, 3) uint8 RGB,
    H, W = k * layout.sheet_size()[::-1]."""
    n = formats.SNAPSHOT_SIZE
    if snapshot.shape != (n, n, 3) or snapshot.dtype != np.uint8:
        raise ValueError(f"snapshot must be ({n}, {n}, 3) uint8 RGB, got {snapshot.shape} {snapshot.dtype}")
    w, h = layout.sheet_size()
    x0, y0 = formats.SHEET_BOX[:2]
    sheet = np.full((h * k, w * k, 3), 255, np.uint8)

    def put(img, x, y):  # layout (x, y) of the top-left corner
        r, c = (y - y0) * k, (x - x0) * k
        sheet[r:r + img.shape[0], c:c + img.shape[1]] = img if img.ndim == 3 else img[..., None]

    put(np.repeat(np.repeat(snapshot, k, 0), k, 1), 0, 0)
    dictionary = layout.aruco_dictionary()
    for mid, corners in layout.marker_corners(meta.version).items():
        marker = cv2.aruco.generateImageMarker(dictionary, mid, formats.MARKER_SIZE * k, borderBits=1)
        put(marker, int(corners[0, 0]), int(corners[0, 1]))
    for colour, (bx0, by0, bx1, by1) in zip(formats.PATCH_COLOURS, layout.patch_boxes()):
        r0, r1 = round((by0 - y0) * k), round((by1 - y0) * k)
        c0, c1 = round((bx0 - x0) * k), round((bx1 - x0) * k)
        sheet[r0:r1, c0:c1] = np.round(np.array(colour) * 255).astype(np.uint8)
    codes = [(formats.QR_BOX, encode_payload(replace(meta, head=None)), "M")]
    if meta.head is not None:   # the scene's own head: two smaller codes beside the QR code (scanner.headcode)
        codes = [(formats.QR_BOX, codes[0][1] + formats.QR_SEP + HEAD_CODES_FIELD, "M")]
        codes += [(box, text, HEAD_CODE_LEVEL) for box, text in zip(formats.HEAD_CODE_BOXES, split_head(meta.head))]
    for (qx0, qy0, qx1, _), text, level in codes:
        side = (qx1 - qx0) * k
        put(cv2.resize(qr_matrix(text, level), (side, side), interpolation=cv2.INTER_NEAREST), qx0, qy0)
    return sheet


def chart_sheet(k: int, caption: bool = True) -> np.ndarray:
    """The calibration chart's sheet (`scanner.chart`) at k dots per snapshot pixel: (H, W, 3) uint8 RGB, its
    QR code naming `formats.CALIB_CODEC`, with the caption on the page unless `caption` is False."""
    from .chart import chart_meta, chart_snapshot, draw_caption

    sheet = render_sheet(chart_snapshot(), chart_meta(), k)
    return draw_caption(sheet, k) if caption else sheet


def _png_bytes(rgb: np.ndarray, width_mm: float) -> bytes:
    """PNG carrying the dpi that prints it `width_mm` wide."""
    from PIL import Image

    dpi = rgb.shape[1] / (width_mm / 25.4)
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="PNG", dpi=(dpi, dpi))
    return buf.getvalue()


def write_print_files(path: Path, rgb: np.ndarray, width_mm: float) -> list[Path]:
    """A .png sheet, or a .pdf (lossless, the page exactly width_mm wide) with the same page as .png beside
    it (what `simulate` photographs). Returns the files written."""
    from .pdf import pdf_bytes

    png = path.with_suffix(".png")
    write_atomic(png, _png_bytes(rgb, width_mm))
    if path.suffix.lower() != ".pdf":
        return [png]
    write_atomic(path, pdf_bytes(rgb, width_mm))
    return [path, png]


def sheet_command(args) -> int:
    """`snapshot3d sheet SNAPSHOT -o OUT [--width-mm --dpi --scene]`, or `sheet --calibration -o OUT`."""
    cfg = SheetConfig(width_mm=args.width_mm, dpi=args.dpi)
    if not (10 <= cfg.width_mm <= 2000) or not (50 <= cfg.dpi <= 4800):
        raise UserError("--width-mm must be in [10, 2000] and --dpi in [50, 4800]")
    out = Path(args.output)
    if out.suffix.lower() not in (".png", ".pdf"):
        raise UserError(f"cannot write {out.name}: the sheet is written as .png or .pdf")
    if getattr(args, "calibration", False):
        if args.snapshot or args.scene:
            raise UserError("--calibration writes the calibration chart: give no snapshot or --scene with it")
        k = cfg.dots_per_pixel()
        files = write_print_files(out, chart_sheet(k), cfg.width_mm)
        print(f"wrote {' and '.join(str(f) for f in files)} (calibration chart, {cfg.width_mm:g} mm wide; print it at "
              f"100% and run 'snapshot3d calibrate PHOTO' on a photo of it)")
        return 0
    if not args.snapshot:
        raise UserError("give the snapshot to lay out (or --calibration for the calibration chart)")
    from .snapfile import snapshot_pixels

    snap = snapshot_pixels(cv2.cvtColor(read_image_bgr(args.snapshot, "snapshot"), cv2.COLOR_BGR2RGB))
    n = formats.SNAPSHOT_SIZE
    if snap.shape[:2] != (n, n):
        raise UserError(f"{Path(args.snapshot).name} is {snap.shape[1]}x{snap.shape[0]}; a snapshot is {n}x{n}")
    if args.scene:
        from snapshot3d.scene import load_scene_file

        meta = scene_meta(load_scene_file(args.scene), strength=None)
    else:
        meta = SheetMeta()
    if not args.scene:  # a snapshot from `embed` carries its own metadata
        from .snapfile import read_snapshot

        try:
            meta = read_snapshot(args.snapshot)[1]
        except UserError:
            pass
    if CODEC_MEDIUM.get(meta.codec) == "file":
        print(f"note: {Path(args.snapshot).name} was made for the file medium (codec {meta.codec}), which a printed "
              f"and photographed copy does not survive well; 'snapshot3d embed --medium print' makes one for printing",
              file=sys.stderr)
    k = cfg.dots_per_pixel()
    sheet = render_sheet(snap, meta, k)
    files = write_print_files(out, sheet, cfg.width_mm)
    dpi = sheet.shape[1] / (cfg.width_mm / 25.4)
    print(f"wrote {' and '.join(str(f) for f in files)} ({sheet.shape[1]}x{sheet.shape[0]} px, {k} dots per "
          f"snapshot pixel, "
          f"{cfg.width_mm:g} mm wide at {dpi:.0f} dpi; snapshot {cfg.width_mm * n / layout.sheet_size()[0]:.1f} mm)")
    return 0
