"""The scanner (DESIGN 1.4): find the sheet in a phone photo, fit its geometry, rectify the snapshot with
anti-aliasing, correct its colour from the patches and read the QR code. numpy and OpenCV only.

Markers are detected on a copy shrunk to about DETECT_SIDE pixels (area averaging), their corners
refined at full resolution, and the photo is searched again at full resolution only when that fails.
Every failure is a one-line `UserError` naming its cause."""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.head import parse_head

from . import layout
from .colour import colour_flat, fit_colour, flat_field, linear_lut, marker_contrast
from .detect import detect_markers, make_detector, refine_corners
from .diagnose import SHARPNESS_MIN, exposure_problem, sharpness
from .fit import Fit, fit_geometry
from .headcode import HEAD_CODES_FIELD, join_head
from .imageio_safe import read_image_bgr
from .photo_check import check_photo
from .pilot import pilot_psnr
from .qr import check_meta, decode_payload, read_qr
from .rectify import OVERSAMPLE, photo_px_per_unit, rectify_box, rectify_sheet

__all__ = ["ScanResult", "scan_image", "scan_file", "refuse_snapshot_file", "DETECT_SIDE", "MIN_SNAPSHOT_PX", "REPORT_KEYS"]

DETECT_SIDE = 1400        # longest side of the detection copy (pixels)
DETECT_MIN_SIDE = 64      # shortest side of the detection copy (pixels)
MIN_SNAPSHOT_PX = 380     # at least one photo pixel per snapshot pixel: below, the snapshot is aliased
MIN_CONTRAST = 0.3        # (paper - marker ink) / paper below this: washed out
QR_MODULES = (21, 25, 29, 33, 37, 41)  # QR versions 1-6: the sheet's payloads fit these (its head codes: 5)
HEAD_CODE_SCALE = 6      # px per layout unit the head codes are read at, from the photo
REPORT_KEYS = ("detected", "corners", "reprojection_px", "confidence", "pilot_psnr", "qr", "photo", "timings_ms")


@dataclass
class ScanResult:
    """snapshot: (380, 380, 3) uint8 RGB, colour-corrected. corners: (4, 2) photo pixels, clockwise from
    the snapshot's top-left. fit: the geometry (homography, lens). pilot_psnr: how well the markers
    came through the channel (`scanner.pilot`), dB."""

    snapshot: np.ndarray
    corners: np.ndarray
    reprojection_px: float
    confidence: float
    qr: dict | None
    timings_ms: dict
    pilot_psnr: float = float("nan")
    markers: list = field(default_factory=list)
    fit: Fit | None = None
    photo: dict | None = None
    """what the photo did to the print: its tilt, blur and glare (`scanner.photo_check`)"""

    def report(self) -> dict:
        return {"detected": True, "corners": np.round(self.corners, 3).tolist(),
                "reprojection_px": round(float(self.reprojection_px), 4), "confidence": round(float(self.confidence), 3),
                "pilot_psnr": round(float(self.pilot_psnr), 2), "qr": self.qr, "photo": self.photo,
                "timings_ms": {k: round(v, 2) for k, v in self.timings_ms.items()}}


@lru_cache(maxsize=1)
def _detector():
    return make_detector(formats.ARUCO_DICT)


def _sheet_markers(ids: np.ndarray, corners: np.ndarray) -> dict[int, np.ndarray]:
    wanted = formats.SHEET_MARKER_IDS[formats.SHEET_FORMAT_VERSION]
    found = {}
    for i, c in zip(ids.tolist(), corners):
        if i in wanted and (i not in found or cv2.contourArea(c) > cv2.contourArea(found[i])):
            found[i] = c
    return found


def _find(img: np.ndarray, factor: int) -> tuple[dict, np.ndarray]:
    """Sheet markers found on the photo shrunk by `factor`, corners in full-resolution pixels; and the grey copy
    ((H // factor, W // factor) uint8): the grey photo's factor x factor block means, the last H % factor rows
    and W % factor columns left out (OpenCV's integer-factor area path on one channel: 4 ms for a 12 MP photo,
    where shrinking the colour photo by W / (W // factor) took 21, issue 39)."""
    h, w = img.shape[:2]
    gray = cv2.cvtColor(img[:h - h % factor, :w - w % factor], cv2.COLOR_BGR2GRAY)
    if factor > 1:
        gray = cv2.resize(gray, (w // factor, h // factor), interpolation=cv2.INTER_AREA)
    ids, corners = detect_markers(gray, detector=_detector())
    corners = (corners + 0.5) * np.float32(factor) - 0.5
    return _sheet_markers(ids, corners), gray


def _why_not_found(found: dict, gray: np.ndarray) -> str:
    if found:
        return (f"the sheet is cut off or partly hidden: only {len(found)} of its 4 corner markers are visible "
                f"(ids {sorted(found)}); fit the whole sheet in the photo")
    cause = exposure_problem(gray)
    if cause:
        return cause + "; no sheet markers visible"
    s = sharpness(gray)
    if s < SHARPNESS_MIN:
        return f"the photo is too blurred to find the sheet (sharpness {s:.3f} < {SHARPNESS_MIN}); hold still and focus"
    return "no snapshot3d sheet found in the photo (none of its ArUco markers is visible)"


def scan_image(img: np.ndarray, chart: bool = False) -> ScanResult:
    """Scan an (H, W, 3) uint8 **BGR** photo. Raises UserError with the cause when it cannot. `chart`: the
    sheet may be the calibration chart (`snapshot3d calibrate`), whose QR code is refused otherwise."""
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"expected (H, W, 3) uint8 BGR, got {img.shape} {img.dtype}")
    t = {}
    t0 = time.perf_counter()
    h, w = img.shape[:2]
    if min(h, w) < MIN_SNAPSHOT_PX:
        raise UserError(f"the photo is {w}x{h} pixels: too small to hold a sheet (its snapshot alone needs at least "
                        f"{MIN_SNAPSHOT_PX} px across)")
    # the detection copy's longest side about DETECT_SIDE, its shortest at least DETECT_MIN_SIDE (a thin photo)
    factor = max(1, min(round(max(h, w) / DETECT_SIDE), min(h, w) // DETECT_MIN_SIDE))
    found, gray = _find(img, factor)
    if len(found) < 3 and factor > 1:  # small or hard to see: look again at full resolution
        found2, _ = _find(img, 1)
        found = found2 if len(found2) >= len(found) else found
    if len(found) < 3:
        raise UserError(_why_not_found(found, gray))
    t["detect"] = (time.perf_counter() - t0) * 1e3
    t1 = time.perf_counter()
    mids = sorted(found)
    photo = refine_corners(img, np.stack([found[i] for i in mids]))
    t["refine"] = (time.perf_counter() - t1) * 1e3
    t1 = time.perf_counter()
    ref = layout.marker_corners()
    marker_px = float(np.mean([np.linalg.norm(photo[k, j] - photo[k, (j + 1) % 4]) for k in range(len(mids))
                               for j in range(4)]))
    side = marker_px * formats.SNAPSHOT_SIZE / formats.MARKER_SIZE
    if side < MIN_SNAPSHOT_PX:
        raise UserError(f"the sheet is too small in the photo: the snapshot is about {side:.0f} px across, at least "
                        f"{MIN_SNAPSHOT_PX} needed (move closer)")
    max_rms = max(2.0, 0.03 * marker_px)
    fit = fit_geometry(np.concatenate([ref[i] for i in mids]), photo.reshape(-1, 2), (w, h),
                       outlier_px=max(3.0, 0.15 * marker_px))
    if (fit is None or fit.rms_px > max(0.75, 0.005 * marker_px)) and len(mids) == 4:
        # one marker misplaced as a whole (glare, a fold)? keep the best three when they agree far better
        trials = []
        for drop in range(4):
            keep = [k for k in range(4) if k != drop]
            f = fit_geometry(np.concatenate([ref[mids[k]] for k in keep]), photo[keep].reshape(-1, 2), (w, h),
                             outlier_px=max(3.0, 0.15 * marker_px))
            if f is not None:
                trials.append((f.rms_px, f, keep))
        if trials and min(trials, key=lambda x: x[0])[0] < min(max_rms, 0.5 * (fit.rms_px if fit else np.inf)):
            _, fit, keep = min(trials, key=lambda x: x[0])
            mids, photo = [mids[k] for k in keep], photo[keep]
    if fit is None or fit.rms_px > max_rms:
        f = gray.shape[1] / w  # sharpness where the markers are (the background may be sharper or softer)
        x0, y0 = np.maximum((photo.reshape(-1, 2).min(0) * f).astype(int), 0)
        x1, y1 = (photo.reshape(-1, 2).max(0) * f).astype(int) + 1
        s = sharpness(gray[y0:y1, x0:x1]) if (x1 - x0) * (y1 - y0) > 400 else sharpness(gray)
        if s < 3 * SHARPNESS_MIN:  # a sharp sheet is ~0.4 here; markers that disagree and are soft: blur
            raise UserError(f"the photo is too blurred to locate the sheet's corners (sharpness {s:.3f}); "
                            f"hold still and focus")
        raise UserError("the sheet's markers do not lie on one flat sheet (is the print folded or curled?)")
    corners = fit.to_photo(layout.snapshot_corners())
    if corners.min() < -0.5 or np.any(corners.max(0) > (w - 0.5, h - 0.5)):
        raise UserError("the sheet is cut off: part of the snapshot lies outside the photo")
    side = photo_px_per_unit(fit) * formats.SNAPSHOT_SIZE
    if side < MIN_SNAPSHOT_PX:
        raise UserError(f"the sheet is too small in the photo: the snapshot is {side:.0f} px across, at least "
                        f"{MIN_SNAPSHOT_PX} needed (move closer)")
    t["fit"] = (time.perf_counter() - t1) * 1e3
    t1 = time.perf_counter()
    hi = rectify_sheet(img, fit)
    lo = cv2.cvtColor(_halve(cv2.LUT(hi, _lut())), cv2.COLOR_BGR2RGB)  # one pixel per layout unit, linear RGB
    t["rectify"] = (time.perf_counter() - t1) * 1e3
    t1 = time.perf_counter()
    contrast = marker_contrast(lo)
    if contrast < MIN_CONTRAST:
        raise UserError(f"the photo is washed out: the markers' black is only {100 * contrast:.0f}% darker than "
                        f"the paper (glare or overexposure)")
    model = fit_colour(lo)
    n = formats.SNAPSHOT_SIZE
    sx0, sy0 = formats.SHEET_BOX[:2]
    flat = flat_field(model, lo[-sy0:-sy0 + n, -sx0:-sx0 + n], (0, 0, n, n))   # 1: the paper's level
    snapshot = colour_flat(model, flat)
    pilot = pilot_psnr(lo, model, mids)
    t["colour"] = (time.perf_counter() - t1) * 1e3
    t1 = time.perf_counter()
    qr = _read_qr(hi, img, fit, chart)
    t["qr"] = (time.perf_counter() - t1) * 1e3
    t1 = time.perf_counter()
    photo = check_photo(img, fit, mids, flat)
    t["check"] = (time.perf_counter() - t1) * 1e3
    t["total"] = (time.perf_counter() - t0) * 1e3
    rms_snap = fit.rms_px / photo_px_per_unit(fit)
    conf = len(mids) / 4 * float(np.exp(-max(0.0, rms_snap - 0.3))) * (1.0 if qr else 0.8)
    return ScanResult(snapshot, corners, fit.rms_px, conf, qr, t, pilot, mids, fit, asdict(photo))


@lru_cache(maxsize=1)
def _lut() -> np.ndarray:
    return linear_lut()


def _halve(x: np.ndarray) -> np.ndarray:
    """2x2 area average of float32 (2h, 2w, 3) -> (h, w, 3)."""
    assert OVERSAMPLE == 2
    return (x[0::2, 0::2] + x[1::2, 0::2] + x[0::2, 1::2] + x[1::2, 1::2]) * 0.25


def _read_qr(hi: np.ndarray, img: np.ndarray, fit: Fit, chart: bool = False) -> dict | None:
    """Read the QR from the rectified sheet (OVERSAMPLE px per unit), and a scene's own head from the codes beside
    it when the sheet has them (from the photo `img` through `fit`); UserError on a wrong codec id. Head codes that
    cannot be read leave the head None and add "head_codes": "unread" to the metadata's dict."""
    text = _main_code(hi)
    if text is None:
        return None
    try:
        meta = decode_payload(text)
    except ValueError as e:
        raise UserError(f"the QR code on the sheet is not a snapshot3d code ({e})") from None
    unread = False
    if meta.head is None and not chart and HEAD_CODES_FIELD in text.split(formats.QR_SEP):
        parts = [_head_code(img, fit, box) for box in formats.HEAD_CODE_BOXES]
        try:
            if None in parts:
                raise ValueError("unreadable")
            head = join_head(parts)
            parse_head(head)   # the head's own checks
            meta = replace(meta, head=head)
        except ValueError:   # the views then use the shared decoder's head: off-colour, which decode says
            unread = True
    out = check_meta(meta, "the sheet's QR code", chart=chart).as_dict()
    return {**out, "head_codes": "unread"} if unread else out


def _stretch(gray: np.ndarray) -> np.ndarray:
    """Grey levels stretched so that the 2nd and 98th percentiles span 0..255 (uint8)."""
    gray = gray.astype(np.float32)
    lo, hi_ = np.percentile(gray, (2, 98))
    return np.clip((gray - lo) / max(hi_ - lo, 1.0) * 255.0, 0, 255).astype(np.uint8)


def _main_code(hi: np.ndarray) -> str | None:
    """The text of the sheet's QR code, read from the rectified sheet (OVERSAMPLE px per unit), or None."""
    sx0, sy0 = formats.SHEET_BOX[:2]
    qx0, qy0, qx1, qy1 = formats.QR_BOX
    o, pad = OVERSAMPLE, 4
    crop = hi[(qy0 - pad - sy0) * o:(qy1 + pad - sy0) * o, (qx0 - pad - sx0) * o:(qx1 + pad - sx0) * o]
    return _read_code(_stretch(cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY)), (qx1 - qx0) * o, pad * o)


def _head_code(img: np.ndarray, fit: Fit, box) -> str | None:
    """The text of a head code, read from the photo itself at HEAD_CODE_SCALE px per unit (its modules are
    narrower than the QR code's), or None."""
    pad, k = 4, HEAD_CODE_SCALE
    x0, y0, x1, y1 = box
    crop = rectify_box(img, fit, (x0 - pad, y0 - pad, x1 + pad, y1 + pad), k)
    return _read_code(_stretch(crop), (x1 - x0) * k, pad * k)


def _read_code(gray: np.ndarray, side: float, pad: int) -> str | None:
    """The text of the QR code in a grey crop (`_stretch`ed) whose code square is `side` pixels with `pad` pixels
    round it, or None."""
    gray = cv2.copyMakeBorder(gray, 24, 24, 24, 24, cv2.BORDER_CONSTANT, value=255)
    text = read_qr(gray) or read_qr(cv2.resize(gray, None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC))
    if text is None:  # the code's square is known exactly: sample its module grid and redraw it cleanly
        for n in QR_MODULES:
            c = 24 + pad + (np.arange(n) + 0.5) * side / n - 0.5  # module centres in the bordered crop
            mx, my = np.meshgrid(c.astype(np.float32), c.astype(np.float32))
            v = cv2.remap(gray, mx, my, cv2.INTER_LINEAR)
            lo_, hi2 = np.percentile(v, (10, 90))
            local = cv2.remap(cv2.GaussianBlur(gray.astype(np.float32), (0, 0), 4 * side / n), mx, my, cv2.INTER_LINEAR)
            for threshold in ((lo_ + hi2) / 2, local):   # one level, then the level round each module (uneven light)
                modules = np.where(v > threshold, 255, 0).astype(np.uint8)
                clean = cv2.copyMakeBorder(cv2.resize(modules, (n * 8, n * 8), interpolation=cv2.INTER_NEAREST),
                                           32, 32, 32, 32, cv2.BORDER_CONSTANT, value=255)
                text = read_qr(clean)
                if text:
                    return text
    return text


def refuse_snapshot_file(path, img: np.ndarray) -> None:
    """UserError with what to do instead when `img` (a decoded file) is a snapshot file, not a photo of a
    printed sheet: a snapshot is exactly SNAPSHOT_SIZE x SNAPSHOT_SIZE."""
    n = formats.SNAPSHOT_SIZE
    if img.shape[:2] == (n, n):
        name = Path(path).name
        raise UserError(f"{name} is a {n}x{n} snapshot file, not a photo of a printed sheet: restore it with "
                        f"'snapshot3d restore {name} -o scene.s3d', or print it with 'snapshot3d sheet {name} "
                        f"-o sheet.pdf' and photograph the print")


def scan_file(path, img: np.ndarray | None = None) -> ScanResult:
    """Read (safely, `imageio_safe`) and scan a photo file (`img`: its (H, W, 3) uint8 BGR when already
    read); timings include decoding ("decode")."""
    t0 = time.perf_counter()
    img = read_image_bgr(path) if img is None else img
    refuse_snapshot_file(path, img)
    dec = (time.perf_counter() - t0) * 1e3
    res = scan_image(img)
    res.timings_ms = {"decode": dec, **res.timings_ms, "total_with_decode": dec + res.timings_ms["total"]}
    return res
