"""`snapshot3d bench channel`: what `scan` leaves of a snapshot after print and capture, measured as
the training channel's parameters (`train/channel.py`) so that its ranges can be checked.

For each simulated photo the rectified snapshot is compared with the digital one:
- shift_px: misregistration, from phase correlation in each quadrant (largest displacement);
- blur_px: the Gaussian sigma that best explains the rectified image (after a colour fit);
- gain / offset: the per-channel linear tone fit (largest deviation from 1 and from 0);
- resid_std: what no blur and tone fit explains (the texture and noise of the channel), in [0, 1] units;
- psnr: rectified vs digital.
No torch: numpy and OpenCV. Writes channel.json (and channel.csv) under --out."""
from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.metrics import psnr
from snapshot3d.scanner.backgrounds import load_background
from snapshot3d.scanner.qr import SheetMeta
from snapshot3d.scanner.scan import scan_image
from snapshot3d.scanner.sheet import render_sheet
from snapshot3d.scanner.simulate import simulate

from .common import run_metadata

__all__ = ["measure_residual", "bench_channel_command"]

_SIGMAS = np.arange(0.0, 3.01, 0.1)


def _shift(a: np.ndarray, b: np.ndarray) -> float:
    h, w = a.shape
    win = cv2.createHanningWindow((w // 2, h // 2), cv2.CV_64F)
    out = 0.0
    for y in (0, h // 2):
        for x in (0, w // 2):
            pa, pb = a[y:y + h // 2, x:x + w // 2], b[y:y + h // 2, x:x + w // 2]
            (dx, dy), _ = cv2.phaseCorrelate(pa, pb, win)
            out = max(out, float(np.hypot(dx, dy)))
    return out


def _tone_fit(src: np.ndarray, dst: np.ndarray):
    """Per-channel dst ~ g * src + o over (H, W, 3) -> gains (3,), offsets (3,), fitted image."""
    g, o = np.zeros(3), np.zeros(3)
    fitted = np.empty_like(src)
    for c in range(3):
        a = np.stack([src[..., c].ravel(), np.ones(src[..., c].size)], 1)
        (g[c], o[c]), *_ = np.linalg.lstsq(a, dst[..., c].ravel(), rcond=None)
        fitted[..., c] = g[c] * src[..., c] + o[c]
    return g, o, fitted


def measure_residual(digital: np.ndarray, rectified: np.ndarray) -> dict:
    """Both (380, 380, 3) uint8 RGB -> the channel parameters that best explain `rectified`."""
    a, b = digital.astype(np.float64) / 255, rectified.astype(np.float64) / 255
    shift = _shift(a.mean(2), b.mean(2))
    m = 8  # ignore the border, where resampling sees outside the snapshot
    best = None
    for s in _SIGMAS:
        blurred = cv2.GaussianBlur(a, (0, 0), s) if s > 0 else a
        g, o, fitted = _tone_fit(blurred[m:-m, m:-m], b[m:-m, m:-m])
        err = float(np.mean((fitted - b[m:-m, m:-m]) ** 2))
        if best is None or err < best[0]:
            best = (err, s, g, o)
    err, s, g, o = best
    return {"shift_px": shift, "blur_px": float(s), "gain": float(np.max(np.abs(g - 1))),
            "offset": float(np.max(np.abs(o))), "resid_std": float(np.sqrt(err)), "psnr": psnr(b, a)}


def bench_channel_command(args) -> int:
    if getattr(args, "real", False):
        from .channel_real import bench_channel_real_command
        return bench_channel_real_command(args)
    host = cv2.resize(load_background("astronaut"), (formats.SNAPSHOT_SIZE,) * 2, interpolation=cv2.INTER_AREA)
    sheet = render_sheet(host, SheetMeta(), 4)
    from snapshot3d.scanner.presets import SEVERITIES
    bad = [s for s in args.severities.split(",") if s not in SEVERITIES]
    if bad:
        raise UserError(f"unknown severity {bad[0]!r}; choose from {', '.join(SEVERITIES)}")
    rows = []
    for sev in args.severities.split(","):
        for seed in range(args.seeds):
            data, _, _ = simulate(sheet, sev, seed)
            img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
            try:
                res = scan_image(img)
            except UserError:
                continue
            rows.append({"severity": sev, "seed": seed, **measure_residual(host, res.snapshot)})
    if not rows:
        raise UserError("no simulated photo was scanned")
    keys = ["shift_px", "blur_px", "gain", "offset", "resid_std", "psnr"]
    summary = {}
    for sev in dict.fromkeys(r["severity"] for r in rows):
        sel = [r for r in rows if r["severity"] == sev]
        summary[sev] = {k: {"median": float(np.median([r[k] for r in sel])),
                            "p90": float(np.percentile([r[k] for r in sel], 90))} for k in keys}
        summary[sev]["photos"] = len(sel)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "channel.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["severity", "seed", *keys])
        w.writeheader()
        w.writerows(rows)
    doc = {"command": "snapshot3d bench channel " + f"--seeds {args.seeds} --severities {args.severities}",
           "cores": os.cpu_count(), "meta": run_metadata(), "host": "astronaut", "summary": summary}
    (out / "channel.json").write_text(json.dumps(doc, indent=2) + "\n")
    for sev, s in summary.items():
        print(sev, {k: round(v["median"], 3) for k, v in s.items() if isinstance(v, dict)})
    return 0
