"""`snapshot3d bench calibrate` (issue 38's targets): photograph the calibration chart through each physical
preset with several seeds and check what `calibrate` measures against the simulator's own values.

- MTF50 against the simulator's blur: the same seed photographed without defocus and motion (every other
  draw identical) gives each edge's MTF without the camera blur; times the blur kernel's own transfer
  function along the edge's normal in snapshot pixels (through the photo's homography), it predicts the
  edge's MTF with the blur; the predicted MTF50 (median over the edges) is the simulator's value.
- gain: the chart's overall band gain against the gain the print codec's own pilots measure
  (`print_channel.measure`) on a print snapshot (random 16x4 planes in a bundled host) photographed with
  the same seed, and the ratio of the noise terms (different units: reported for its spread); each
  band's gain against what all the snapshot's carriers kept of that band (`print_read.band_response`).
- nearest preset: right or wrong per photo; the calibrate time per photo (scan + measure).
`--reference` prints the `scanner.calibrate.PRESET_REFERENCE` table from seeds 100-111 instead."""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from .common import PHYSICAL, write_report

__all__ = ["chart_capture", "predicted_mtf50", "bench_calibrate_command"]


def chart_capture(preset, seed: int, sheet=None):
    """(photo BGR, truth) of the chart's sheet (2 dots per snapshot pixel) through `preset` with `seed`."""
    from snapshot3d.scanner.sheet import chart_sheet
    from snapshot3d.scanner.simulate import simulate

    data, _, truth = simulate(chart_sheet(2, caption=False) if sheet is None else sheet, preset, seed)
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR), truth


def _otf(truth: dict, vertical: bool, freq: np.ndarray, at=(130.0, 68.0)) -> np.ndarray:
    """|OTF| of the simulated blur along snapshot x (vertical edges) or y, at snapshot point `at`."""
    from snapshot3d.scanner import layout
    from snapshot3d.scanner.simulate import blur_kernel

    s = truth["sampled"]
    psf = blur_kernel(s["defocus_px"], s["motion_px"], np.deg2rad(s["motion_angle_deg"]))
    H = cv2.getPerspectiveTransform(layout.snapshot_corners().astype(np.float32),
                                    np.array(truth["corners"], np.float32)).astype(np.float64)
    x, y = at
    p = H @ [x, y, 1.0]
    J = np.array([[H[0, 0] * p[2] - p[0] * H[2, 0], H[0, 1] * p[2] - p[0] * H[2, 1]],
                  [H[1, 0] * p[2] - p[1] * H[2, 0], H[1, 1] * p[2] - p[1] * H[2, 1]]]) / p[2] ** 2
    r = psf.shape[0] // 2
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    snap = np.linalg.solve(J, np.stack([xx.ravel(), yy.ravel()]).astype(np.float64))
    u = snap[0] if vertical else snap[1]
    return np.abs(np.exp(-2j * np.pi * np.outer(freq, u)) @ psf.ravel())


def predicted_mtf50(snap_noblur: np.ndarray, truth: dict) -> float:
    """The simulator's MTF50 for a photo: each edge's MTF measured on the blur-free twin (rectified chart,
    (380, 380, 3) uint8 RGB) times the blur's |OTF|; the median over the edges."""
    from snapshot3d.scanner import chart
    from snapshot3d.scanner.chart_measure import edge_mtf, linearise, measure_tone, mtf50

    lum = linearise(snap_noblur, measure_tone(snap_noblur)["tone_curve"])
    vals = []
    for x0, y0, x1, y1, vertical in chart.EDGE_ROIS:
        f, m = edge_mtf(lum[y0:y1, x0:x1], vertical)
        vals.append(mtf50(f, m * _otf(truth, vertical, f, ((x0 + x1) / 2, (y0 + y1) / 2))))
    return float(np.median(vals))


def _pilot_channel(preset, seed: int, rng):
    """Through `preset`/`seed`, for random 16x4 planes in a host: the print codec's pilots' ChannelModel, and
    the gain per band of all its carriers (`print_read.band_response`) {band: gain}."""
    from snapshot3d.codecs.print_channel import measure
    from snapshot3d.codecs.print_embed import embed
    from snapshot3d.scanner.backgrounds import background_names, load_background
    from snapshot3d.scanner.qr import SheetMeta
    from snapshot3d.scanner.roundtrip import capture

    host = cv2.resize(load_background(background_names()[0]), (380, 380), interpolation=cv2.INTER_AREA)
    planes = np.clip(rng.normal(0, 0.4, (3, 4, 16, 16)), -1, 1)
    snap = embed(host / 255.0, planes)
    from snapshot3d.codecs.print_carriers import print_layout
    from snapshot3d.codecs.print_read import band_response

    cap = capture(snap, SheetMeta(codec="print-2", planes=(16, 4)), preset, seed)
    lay = print_layout(16, 4)
    gains, _ = band_response(cap, snap, lay)
    return measure(snap, cap, 16, 4), dict(zip(lay.bands, (float(g) for g in gains)))


def bench_calibrate_command(args) -> int:
    from snapshot3d.scanner.calibrate import calibrate_image
    from snapshot3d.scanner.presets import get_preset

    t_start = time.perf_counter()
    if args.reference:
        seeds = range(100, 112)
        print("PRESET_REFERENCE = {")
        for name in PHYSICAL:
            feats = []
            for seed in seeds:
                prof = calibrate_image(chart_capture(name, seed)[0])
                feats.append(np.log([prof["mtf50"], prof["channel"]["gain"], prof["channel"]["unit"]]))
            mu, sd = np.mean(feats, 0), np.std(feats, 0, ddof=1)
            print(f'    "{name}": ' + str(tuple((round(float(m), 3), round(float(s), 3)) for m, s in zip(mu, sd))) + ",")
        print("}")
        return 0
    rows, rng = [], np.random.default_rng(0)
    for name in PHYSICAL:
        for seed in range(args.seeds):
            img, truth = chart_capture(name, seed)
            t0 = time.perf_counter()
            prof = calibrate_image(img)
            ms = (time.perf_counter() - t0) * 1e3
            p = get_preset(name)
            twin, _ = chart_capture(replace(p, defocus_px=(0.0, 0.0), motion_px=(0.0, 0.0)), seed)
            from snapshot3d.scanner.scan import scan_image

            pred = predicted_mtf50(scan_image(twin, chart=True).snapshot, truth)
            row = {"preset": name, "seed": seed, "nearest": prof["nearest_preset"],
                   "right": int(prof["nearest_preset"] == name), "mtf50": prof["mtf50"], "mtf50_sim": round(pred, 4),
                   "mtf50_err": round(prof["mtf50"] / pred - 1, 4), "gain": prof["channel"]["gain"],
                   "unit": prof["channel"]["unit"], "noise_std": prof["noise_std"],
                   "misregistration_px": prof["misregistration_px"], "calibrate_ms": round(ms, 1)}
            if args.pilots:
                ch, per_band = _pilot_channel(name, seed, rng)
                errs = {b: prof["bands"][b]["gain"] / max(g, 1e-9) - 1 for b, g in per_band.items()}
                row.update(band_gain_err_max=round(max(abs(e) for e in errs.values()), 4),
                           bands_within_10pct=sum(abs(e) <= 0.10 for e in errs.values()),
                           **{f"gain_err_{b}": round(e, 4) for b, e in errs.items()})
                row.update(pilot_gain=round(ch.gain, 4), gain_err=round(prof["channel"]["gain"] / ch.gain - 1, 4),
                           unit_ratio=float(f'{prof["channel"]["unit"] / ch.unit:.4g}'))
            rows.append(row)
            print({k: row[k] for k in row if k in ("preset", "seed", "nearest", "mtf50", "mtf50_sim", "gain",
                                                    "pilot_gain", "calibrate_ms")}, flush=True)
    summary = {}
    for name in PHYSICAL:
        r = [x for x in rows if x["preset"] == name]
        s = {"photos": len(r), "nearest_right": sum(x["right"] for x in r) / len(r),
             "mtf50_abs_err_max": max(abs(x["mtf50_err"]) for x in r),
             "mtf50_within_15pct": sum(abs(x["mtf50_err"]) <= 0.15 for x in r) / len(r),
             "calibrate_ms_median": float(np.median([x["calibrate_ms"] for x in r]))}
        if args.pilots:
            s.update(gain_within_10pct=sum(abs(x["gain_err"]) <= 0.10 for x in r) / len(r),
                     gain_err_median=float(np.median([x["gain_err"] for x in r])),
                     unit_ratio_median=float(np.median([x["unit_ratio"] for x in r])),
                     unit_ratio_spread=float(np.std([np.log(x["unit_ratio"]) for x in r])),
                     band_gains_within_10pct=sum(x["bands_within_10pct"] for x in r) / (7 * len(r)),
                     band_gain_err_median_abs=float(np.median([abs(x[k]) for x in r for k in x
                                                               if k.startswith("gain_err_")])))
        summary[name] = s
    doc = write_report(Path(args.out), "calibrate", rows,
                       {"targets": {"gain": "within 10%", "noise": "within 25%", "mtf50": "within 15%",
                                    "nearest_preset": ">= 90% right", "calibrate_s": "<= 2 s, 12 MP, 2 cores"},
                        "summary": summary, "seconds": round(time.perf_counter() - t_start, 1)})
    for name, s in doc["summary"].items():
        print(name, s)
    return 0
