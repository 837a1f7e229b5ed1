"""`snapshot3d simulate` and `snapshot3d scan`: argument handling, files and reports (no torch)."""
from __future__ import annotations

import json
import math
import warnings
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from snapshot3d.errors import UserError
from snapshot3d.validate import integer

from .imageio_safe import read_image_bgr, write_atomic, write_image

__all__ = ["simulate_command", "scan_command", "draw_overlay"]


def _json_bytes(obj) -> bytes:
    return (json.dumps(obj, indent=2) + "\n").encode()


def _printed_width_mm(png: Path, width_px: int) -> float | None:
    """The width the sheet prints at, from the dpi `sheet` writes into its PNG (None when it has none)."""
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(png) as im:
                dpi = float(im.info.get("dpi")[0])
    except (OSError, ValueError, TypeError, IndexError, SyntaxError):
        return None   # no dpi, or one that is not a number
    return width_px / dpi * 25.4 if math.isfinite(dpi) and 1 < dpi < 1e5 else None


def _sheet_png(path: Path) -> Path:
    """The sheet image to photograph: the file itself, or for a .pdf the PNG `sheet` wrote beside it."""
    if path.suffix.lower() != ".pdf":
        return path
    png = path.with_suffix(".png")
    if not png.is_file():
        raise UserError(f"simulate reads the sheet's PNG, which 'snapshot3d sheet' writes beside the PDF; "
                        f"{png.name} not found next to {path.name}")
    return png


def simulate_command(args) -> int:
    from .presets import print_dots
    from .simulate import simulate

    out = Path(args.output)
    ext = out.suffix.lower()
    if ext not in (".jpg", ".jpeg", ".png"):
        raise UserError(f"cannot write {out.name}: use a .jpg or .png file name")
    if (args.severity or "mild") == "none" and ext != ".png":
        raise UserError("severity 'none' is lossless: write the photo as .png")
    integer(args.seed, "--seed", 0, 2 ** 32 - 1)
    if args.print_seed is not None:
        integer(args.print_seed, "--print-seed", 0, 2 ** 32 - 1)
    preset, solved = _simulate_preset(args)
    png = _sheet_png(Path(args.sheet))
    sheet = cv2.cvtColor(read_image_bgr(png, "sheet"), cv2.COLOR_BGR2RGB)
    width_mm = _printed_width_mm(png, sheet.shape[1])
    if preset.physical and width_mm is not None:  # the printer's dots per snapshot pixel follow the print's size
        preset = replace(preset, print_dots_per_px=print_dots(width_mm))
    try:
        data, kind, truth = simulate(sheet, preset, args.seed, args.print_seed)
    except ValueError as e:
        raise UserError(str(e)) from None
    if (kind == ".png") != (ext == ".png"):  # keep the channel's bytes; only change the container
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        ok, buf = cv2.imencode(ext if ext != ".jpeg" else ".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 100])
        data = buf.tobytes()
    if solved is not None:
        truth["profile"] = solved
    if args.truth:
        write_atomic(args.truth, _json_bytes(truth))
    write_atomic(out, data)
    through = f"severity {args.severity or 'mild'}" if solved is None else (
        f"profile {Path(args.profile).name}: {solved['base']} with defocus {solved['defocus_px']:.2f} px, noise "
        f"x{solved['noise_scale']:.2f}" + (f"; beyond the simulator's range in {', '.join(solved['clamped'])}"
                                          if solved["clamped"] else ""))
    print(f"wrote {out} ({truth['frame'][0]}x{truth['frame'][1]}, {through}, seed {args.seed}"
          + ("" if args.print_seed is None else f", print seed {args.print_seed}") + ")")
    return 0


def _simulate_preset(args):
    """The preset `simulate` photographs through: --severity's, or one solved from --profile (and what was
    solved, else None)."""
    from .presets import get_preset

    if getattr(args, "profile", None) is None:
        return get_preset(args.severity or "mild"), None
    if args.severity is not None:
        raise UserError("give --severity or --profile, not both")
    from .calibrate import load_profile
    from .profile_channel import profile_preset

    return profile_preset(load_profile(args.profile))


def draw_overlay(img_bgr: np.ndarray, result, max_side: int = 1600) -> np.ndarray:
    """A downscaled (H', W', 3) uint8 RGB copy of the photo with the fitted markers, the snapshot's outline
    (its top-left corner marked) and the confidence drawn on it."""
    from . import layout

    s = min(1.0, max_side / max(img_bgr.shape[:2]))
    vis = cv2.resize(img_bgr, None, fx=s, fy=s, interpolation=cv2.INTER_AREA) if s < 1 else img_bgr.copy()
    to = lambda p: np.round((np.asarray(p) + 0.5) * s - 0.5).astype(np.int32)  # noqa: E731
    for mid, quad in layout.marker_corners().items():
        cv2.polylines(vis, [to(result.fit.to_photo(quad))], True, (0, 200, 0) if mid in result.markers else (0, 0, 255), 2)
    cv2.polylines(vis, [to(result.corners)], True, (255, 0, 255), 2)
    cv2.circle(vis, tuple(int(v) for v in to(result.corners[0])), 8, (255, 0, 255), -1)
    cv2.putText(vis, f"confidence {result.confidence:.2f}  reproj {result.reprojection_px:.2f}px", (10, 30),
                cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 0, 255), 2)
    return cv2.cvtColor(vis, cv2.COLOR_BGR2RGB)


def scan_command(args) -> int:
    from .scan import refuse_snapshot_file, scan_image

    out = Path(args.output)
    if out.suffix.lower() != ".png":
        raise UserError(f"cannot write {out.name}: the rectified snapshot is written losslessly as .png")
    if args.debug and Path(args.debug).suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise UserError(f"cannot write {Path(args.debug).name}: the overlay is written as .png or .jpg")
    import time

    t0 = time.perf_counter()
    img = read_image_bgr(args.photo)
    refuse_snapshot_file(args.photo, img)
    dec = (time.perf_counter() - t0) * 1e3
    res = scan_image(img)
    res.timings_ms = {"decode": dec, **res.timings_ms, "total_with_decode": dec + res.timings_ms["total"]}
    write_image(out, res.snapshot)
    if args.debug:
        write_image(args.debug, draw_overlay(img, res))
    if args.report:
        write_atomic(args.report, _json_bytes(res.report()))
    qr = "QR unreadable" if res.qr is None else f"QR codec {res.qr['codec']!r}"
    print(f"wrote {out} (confidence {res.confidence:.2f}, reprojection {res.reprojection_px:.2f} px, {qr}, "
          f"{res.timings_ms['total']:.0f} ms + {dec:.0f} ms decoding)")
    ph = res.photo
    blur = "not measured" if ph["blur_px"] is None else f"{ph['blur_px']:.2f} snapshot px"
    print(f"photo: sheet tilted {ph['tilt_deg']:.0f} degrees, blur {blur}, {100 * ph['glare_share']:.1f}% of the "
          f"snapshot brighter than its paper (glare)")
    return 0
