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

__all__ = ["PROFILE_VERSION", "PRESET_REFERENCE", "E2E_REFERENCE", "calibrate_image", "nearest_preset",
           "load_profile", "calibrate_command", "FEATURES"]

PROFILE_VERSION = 1
"""version of the channel profile's JSON layout (`load_profile` refuses any other)"""
FEATURES = ("mtf50", "gain", "unit")
"""the measurements the nearest preset is chosen by (their logs)"""
PRESET_REFERENCE = {
    # (mean, std) of log(mtf50), log(channel gain), log(channel unit) over simulated chart photos, seeds
    # 100-111 per preset, sheet at 2 dots per snapshot pixel, chart calib-2 (`snapshot3d bench calibrate --reference`)
    "mild": ((-0.859, 0.184), (-0.287, 0.082), (-6.7, 0.323)),
    "moderate": ((-1.158, 0.181), (-0.758, 0.137), (-6.978, 0.254)),
    "severe": ((-1.384, 0.211), (-1.304, 0.461), (-6.361, 0.424)),
}
E2E_REFERENCE = {
    # median e2e_psnr (dB) through each preset of the print codec's scenes at planes 16x4 (3072 values):
    # spot-print, lego-print-auto; 24 photos each (`snapshot3d bench codec-print`, bench/results/codec_print.csv
    # at commit 9d6891e)
    "mild": (25.85, 20.06), "moderate": (24.14, 17.94), "severe": (18.51, 13.46),
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
    m = measure_chart(res.snapshot)
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
