"""`snapshot3d calibrate` (issue 38 item 2): scan a photo of the calibration chart (`scanner.chart`) as
`scan` does, measure the channel on it (`scanner.chart_measure`), name the nearest `simulate` preset and
write a channel profile (JSON). numpy and OpenCV only (the phone side).

The nearest preset is the one whose reference measurements (PRESET_REFERENCE: mean and spread of log
MTF50, log band gain and log noise per coefficient over simulated photos of the chart) lie nearest, in
units of their spread (a diagonal Gaussian's negative log-likelihood).

The profile's `print_channel` holds `print_channel.ChannelModel`'s fields (gain, unit) as the print codec's
receiver would measure them on mid grey (`chart_measure.measure_bands`), and `bands` each band's gain and
unit noise in the same terms; `channel.unit` stays the raw power per coefficient ([0, 1]^2 units)."""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from snapshot3d import formats
from snapshot3d.errors import UserError

__all__ = ["PROFILE_VERSION", "PRESET_REFERENCE", "E2E_REFERENCE", "calibrate_image", "nearest_preset", "photo_linear",
           "load_profile", "calibrate_command", "FEATURES"]

PROFILE_VERSION = 2
"""version of the channel profile's JSON layout and measures (`load_profile` refuses any other; 2: MTF50 in
linear light from the photo, `unit` from the median of the residual's periodogram)"""
FEATURES = ("mtf50", "gain", "unit")
"""the measurements the nearest preset is chosen by (their logs)"""
PRESET_REFERENCE = {
    # (mean, std) of log(mtf50), log(channel gain), log(channel unit) over simulated chart photos, seeds
    # 100-111 per preset, sheet at 2 dots per snapshot pixel, chart calib-2, the measure of 2026-11-26 07:10 UTC
    # (MTF in the photo's linear light, unit robust to moire; `snapshot3d bench calibrate --reference`)
    "mild": ((-0.844, 0.218), (-0.287, 0.082), (-6.773, 0.235)),
    "moderate": ((-1.071, 0.205), (-0.758, 0.138), (-6.919, 0.258)),
    "severe": ((-1.371, 0.172), (-1.303, 0.46), (-6.378, 0.491)),
}
E2E_REFERENCE = {
    # median e2e_psnr (dB) through each preset of the print codec's scenes at planes 16x4 (3072 values):
    # spot-print, lego-print-auto; 24 photos each, read as the reader does since print_read.VIEW_PRIOR
    # (`snapshot3d bench e2e --medium print ... --seeds 6 --out bench/results/e2e_chosen`, commit 9180021;
    # with the MMSE reader, bench/results/codec_print.csv at 9d6891e: 25.85 / 24.14 / 18.51, 20.06 / 17.94 / 13.46)
    "mild": (25.87, 20.06), "moderate": (24.26, 18.31), "severe": (18.52, 13.66),
}
_PLANES = (16, 4)
_MATCH_MIN = 0.04   # carrier correlation that tells a chart whose QR code could not be read


def _features(m: dict) -> np.ndarray:
    return np.log(np.maximum([m["mtf50"], m["channel"]["gain"], m["channel"]["unit"]], 1e-9))


def nearest_preset(measures: dict) -> tuple[str, dict]:
    """The preset whose reference lies nearest the measurements (`chart_measure.measure_chart`'s dict), and
    every preset's distance (negative log-likelihood, lower is nearer)."""
    means = np.array([[m for m, _ in ref] for ref in PRESET_REFERENCE.values()])
    x = np.clip(_features(measures), means.min(0), means.max(0))   # better than mild is mild, worse than severe severe
    dist = {}
    for name, ref in PRESET_REFERENCE.items():
        mu, sd = np.array(ref).T
        dist[name] = float(0.5 * np.sum(((x - mu) / sd) ** 2) + np.sum(np.log(sd)))
    return min(dist, key=dist.get), dist


def photo_linear(img: np.ndarray, fit) -> np.ndarray:
    """The photo's own linear light at the snapshot's pixels: (H, W, 3) uint8 **BGR** photo and its scan's
    geometry (`ScanResult.fit`) -> (380, 380, 3) float32 linear **RGB**, rectified as `scan` rectifies (the
    same resampling, then 2 x 2 area averaging in linear light), its codes decoded as sRGB, no colour or tone
    correction: the domain the camera's blur acted in, where the MTF is measured (ISO 12233's OECF step; the
    corrected snapshot is linear in the printer's input codes, which a printer's dot gain bends)."""
    import cv2

    from .colour import linear_lut
    from .rectify import OVERSAMPLE, rectify_sheet

    hi = cv2.LUT(rectify_sheet(img, fit), linear_lut())
    k = OVERSAMPLE
    lo = sum(hi[i::k, j::k] for i in range(k) for j in range(k)) / (k * k)
    n = formats.SNAPSHOT_SIZE
    sx0, sy0 = formats.SHEET_BOX[:2]
    return np.ascontiguousarray(lo[-sy0:-sy0 + n, -sx0:-sx0 + n, ::-1], np.float32)


def calibrate_image(img: np.ndarray) -> dict:
    """Calibrate from a photo of the chart, (H, W, 3) uint8 **BGR**. Returns the channel profile (a dict,
    JSON-ready). UserError when the photo holds no sheet, or a sheet that is not the chart."""
    from .chart_measure import chart_match, measure_chart
    from .scan import scan_image

    t0 = time.perf_counter()
    try:
        res = scan_image(img, chart=True)
    except UserError as e:
        if "'calib-" in str(e):   # a chart of another version (calib-1 carried +-1 coefficients)
            raise UserError(f"the photo holds a calibration chart of another version than this build's "
                            f"{formats.CALIB_CODEC}: print a new one with 'snapshot3d sheet --calibration -o "
                            f"chart.pdf' and photograph that") from None
        raise
    t1 = time.perf_counter()
    if res.qr is not None and res.qr["codec"] != formats.CALIB_CODEC:
        raise UserError(f"the photo holds a snapshot sheet (codec {res.qr['codec']}), not the calibration chart: print "
                        f"one with 'snapshot3d sheet --calibration -o chart.pdf' and photograph that")
    if res.qr is None and chart_match(res.snapshot) < _MATCH_MIN:
        raise UserError("the sheet in the photo is not the calibration chart (its QR code is unreadable and its "
                        "pattern does not match)")
    m = measure_chart(res.snapshot, photo_linear(img, res.fit))
    name, dist = nearest_preset(m)
    t2 = time.perf_counter()
    return {"profile_version": PROFILE_VERSION, "kind": "snapshot3d channel profile", "nearest_preset": name,
            "preset_distance": {k: round(v, 3) for k, v in dist.items()},
            "expected_e2e_psnr": {"planes": list(_PLANES), "spot": E2E_REFERENCE[name][0],
                                  "lego": E2E_REFERENCE[name][1]},
            **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in m.items()},
            "scan": {"confidence": round(float(res.confidence), 3), "reprojection_px": round(float(res.reprojection_px), 4),
                     "qr": res.qr is not None},
            "timings_ms": {"scan": round((t1 - t0) * 1e3, 1), "measure": round((t2 - t1) * 1e3, 1)}}


def load_profile(path) -> dict:
    """Read a channel profile written by `calibrate`. UserError (one line) when the file is missing, not JSON,
    of another profile_version, or lacks a field that `calibrate` writes."""
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise UserError(f"channel profile {p.name} not found") from None
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise UserError(f"{p.name} is not a channel profile (not readable JSON: {type(e).__name__})") from None
    if not isinstance(data, dict) or "profile_version" not in data:
        raise UserError(f"{p.name} is not a channel profile (no profile_version)")
    if data["profile_version"] != PROFILE_VERSION:
        raise UserError(f"{p.name} is a channel profile of version {str(data['profile_version'])[:20]!r}; this build "
                        f"reads version {PROFILE_VERSION}: run 'snapshot3d calibrate' again")
    for key in ("nearest_preset", "mtf50", "noise_std", "channel", "bands"):
        if key not in data:
            raise UserError(f"{p.name}: malformed channel profile (no {key})")
    nums = [data["mtf50"], data["noise_std"], data["channel"].get("gain") if isinstance(data["channel"], dict) else None]
    if "print_channel" in data:   # written since the chart measured the codec's terms (older profiles lack it)
        pc = data["print_channel"]
        nums += [pc.get("gain"), pc.get("unit")] if isinstance(pc, dict) else [None]
    if not all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in nums):
        raise UserError(f"{p.name}: malformed channel profile (mtf50, noise_std, channel gain and print_channel "
                        f"gain and unit must be finite numbers >= 0)")
    if data["nearest_preset"] not in PRESET_REFERENCE:
        raise UserError(f"{p.name}: malformed channel profile (unknown preset {str(data['nearest_preset'])[:20]!r})")
    return data


def summary(profile: dict) -> str:
    """The one-screen summary `calibrate` prints."""
    b = profile["bands"]
    e = profile["expected_e2e_psnr"]
    lines = [
        f"nearest preset: {profile['nearest_preset']}  (negative log-likelihood, lower is nearer: "
        + ", ".join(f"{k} {v:.1f}" for k, v in profile["preset_distance"].items()) + ")",
        f"MTF50: {profile['mtf50']:.3f} cycles/pixel (x {profile['mtf50_x']:.3f}, y {profile['mtf50_y']:.3f})",
        f"noise: {profile['noise_std']:.2f} codes std on flat greys; tone error {profile['tone_rmse']:.1f} codes RMS; "
        f"colour error after correction {profile['colour_rmse']:.1f} codes RMS",
        f"misregistration: {profile['misregistration_px']:.2f} px",
        (f"print channel, as the codec's receiver reads it: gain {profile['print_channel']['gain']:.3f}, noise "
         f"{profile['print_channel']['unit']:.2f} x the print noise model ({profile['channel']['unit']:.3g} per "
         f"coefficient)" if "print_channel" in profile else
         f"print channel: gain {profile['channel']['gain']:.3f}, noise {profile['channel']['unit']:.3g} per "
         f"coefficient"),
        "per band gain: " + ", ".join(f"{k} {v['gain']:.2f}" for k, v in b.items()),
        f"payload: planes {e['planes'][0]}x{e['planes'][1]}; expected e2e_psnr spot {e['spot']:.1f} dB, "
        f"lego {e['lego']:.1f} dB (the print codec's bench at this preset)",
    ]
    return "\n".join(lines)


def calibrate_command(args) -> int:
    """`snapshot3d calibrate PHOTO [-o profile.json] [--report report.json]`."""
    from .imageio_safe import read_image_bgr, write_atomic
    from .scan import refuse_snapshot_file

    for opt in (args.output, args.report):
        if opt and Path(opt).suffix.lower() != ".json":
            raise UserError(f"cannot write {Path(opt).name}: the profile and the report are written as .json")
    img = read_image_bgr(args.photo)
    refuse_snapshot_file(args.photo, img)
    profile = calibrate_image(img)
    print(summary(profile))
    body = lambda d: (json.dumps(d, indent=2) + "\n").encode()  # noqa: E731
    if args.output:
        write_atomic(args.output, body({k: v for k, v in profile.items() if k != "timings_ms"}))
        print(f"wrote {args.output}")
    if args.report:
        write_atomic(args.report, body({"photo": Path(args.photo).name, **profile}))
    return 0
