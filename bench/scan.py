"""`snapshot3d bench scan`: the scanner on simulated 12 MP photos and on photos with no sheet.

Writes under --out: scan.csv (one row per photo), scan.json (summary next to issue 3's targets, the
command, the machine's core count) and scan_*.png charts: detection rate and corner error against tilt, blur, noise and snapshot size,
with the point where the scanner breaks marked; PSNR per severity."""
from __future__ import annotations

import csv
import io
import json
import os
import platform
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.metrics import psnr
from snapshot3d.scanner.imageio_safe import write_atomic
from snapshot3d.scanner.presets import PRESETS
from snapshot3d.scanner.qr import SheetMeta
from snapshot3d.scanner.scan import scan_image
from snapshot3d.scanner.sheet import render_sheet
from snapshot3d.scanner.simulate import simulate

from .common import pyplot, run_metadata

__all__ = ["bench_scan_command", "SWEEPS", "TARGETS"]

TARGETS = {"detection_rate_mild_moderate": ">= 0.99", "corner_err_median_px": "<= 0.5 (snapshot pixels)",
           "corner_err_p95_px": "<= 1.5 (snapshot pixels)", "false_detections": "0 of 50",
           "scan_ms_median_12mp": "<= 150 on 2 cores"}
# Stress sweeps: one factor pushed past the presets, everything else as `mild`. name: (levels, preset change)
SWEEPS = {
    "tilt": ([0, 20, 40, 50, 60, 65, 70, 75, 80], lambda v: {"tilt_deg": (v, v)}),
    "blur": ([0, 1, 2, 3, 4, 6, 8, 11, 15], lambda v: {"defocus_px": (v, v), "motion_px": (0.0, 0.0)}),
    "noise": ([0.0, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5], lambda v: {"noise_read": (v, v)}),
    "size": ([0.008, 0.012, 0.016, 0.02, 0.03, 0.05, 0.1, 0.3, 0.55], lambda v: {"coverage": (v, v)}),
}
_FIELDS = ["group", "level", "seed", "detected", "cause", "err_tl", "err_tr", "err_br", "err_bl", "err_max", "psnr",
           "tilt_deg", "coverage", "blur_px", "noise_std", "k1", "glare", "qr_read", "confidence", "decode_ms", "scan_ms"]


def _host() -> np.ndarray:
    import skimage.data
    return cv2.resize(skimage.data.astronaut(), (formats.SNAPSHOT_SIZE,) * 2, interpolation=cv2.INTER_AREA)


def _snapshot_px_errors(found: np.ndarray, true: np.ndarray) -> np.ndarray:
    side = np.linalg.norm(true - np.roll(true, 1, 0), axis=1)
    scale = (side + np.roll(side, -1)) / 2 / formats.SNAPSHOT_SIZE
    return np.linalg.norm(found - true, axis=1) / scale


def _one(sheet, snap, preset, seed, group, level="") -> dict:
    data, _, truth = simulate(sheet, preset, seed)
    t0 = time.perf_counter()
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    t1 = time.perf_counter()
    s, p = truth["sampled"], truth["pose"]
    row = {"group": group, "level": level, "seed": seed, "tilt_deg": p["tilt_deg"], "coverage": p["coverage"],
           "blur_px": s["defocus_px"] + s["motion_px"] / 2, "noise_std": float(np.sqrt(s["noise_shot"] * 0.5 + s["noise_read"] ** 2)),
           "k1": p["camera"]["k1"], "glare": s["glare"], "decode_ms": (t1 - t0) * 1e3}
    try:
        res = scan_image(img)
    except UserError as e:
        row.update(detected=0, cause=str(e), scan_ms=(time.perf_counter() - t1) * 1e3)
        return row
    err = _snapshot_px_errors(res.corners, np.array(truth["corners"]))
    row.update(detected=1, cause="", err_tl=err[0], err_tr=err[1], err_br=err[2], err_bl=err[3], err_max=err.max(),
               psnr=psnr(res.snapshot / 255.0, snap / 255.0), qr_read=int(res.qr is not None),
               confidence=res.confidence, scan_ms=res.timings_ms["total"])
    return row


def _negatives(n: int, rng: np.random.Generator):
    """No-sheet 12 MP photos: bundled photos whole and cropped, pure noise, blank paper photographed."""
    from snapshot3d.scanner.backgrounds import background_names, load_background

    names = background_names()
    blank = np.full((836, 1152, 3), 255, np.uint8)
    for i in range(n):
        kind = ("photo", "crop", "noise", "paper")[i % 4]
        if kind == "paper":
            data, _, _ = simulate(blank, ("mild", "moderate")[i % 2], 1000 + i)
            yield kind, cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
            continue
        if kind == "noise":
            img = (rng.random((3000, 4000, 3)) * 255).astype(np.uint8) if i % 8 == 2 else \
                np.clip(rng.normal(128, 40, (3000, 4000, 3)), 0, 255).astype(np.uint8)
            yield kind, img
            continue
        bg = load_background(names[i % len(names)])
        if kind == "crop":
            h, w = bg.shape[:2]
            ch, cw = int(h * rng.uniform(0.3, 0.6)), int(w * rng.uniform(0.3, 0.6))
            y, x = int(rng.integers(0, h - ch + 1)), int(rng.integers(0, w - cw + 1))
            bg = bg[y:y + ch, x:x + cw]
        yield kind, cv2.cvtColor(cv2.resize(bg, (4000, 3000), interpolation=cv2.INTER_CUBIC), cv2.COLOR_RGB2BGR)


def _summary(rows: list[dict], group: str) -> dict:
    g = [r for r in rows if r["group"] == group]
    hit = [r for r in g if r["detected"]]
    errs = np.array([r[k] for r in hit for k in ("err_tl", "err_tr", "err_br", "err_bl")])
    out = {"photos": len(g), "detected": len(hit), "detection_rate": len(hit) / max(len(g), 1)}
    if hit:
        out.update(corner_err_median_px=float(np.median(errs)), corner_err_p95_px=float(np.percentile(errs, 95)),
                   corner_err_max_px=float(errs.max()), psnr_mean_db=float(np.mean([r["psnr"] for r in hit])),
                   psnr_median_db=float(np.median([r["psnr"] for r in hit])),
                   qr_read_rate=float(np.mean([r["qr_read"] for r in hit])),
                   scan_ms_median=float(np.median([r["scan_ms"] for r in hit])))
    return out


_FACTORS = {"tilt": ("tilt_deg", "tilt (degrees)"), "blur": ("blur_px", "blur: defocus radius + motion/2 (px)"),
            "noise": ("noise_std", "sensor noise std at mid-grey (full scale 1)"),
            "size": ("coverage", "snapshot area / frame area")}
_DET_MIN, _ERR_MAX = 0.99, 0.5  # the scanner "breaks" where detection drops below or the median error exceeds


def _levels(rows, name):
    g = [r for r in rows if r["group"] == f"sweep-{name}"]
    out = []
    for lvl in sorted({r["level"] for r in g}):
        rs = [r for r in g if r["level"] == lvl]
        errs = [r["err_max"] for r in rs if r["detected"]]
        out.append((lvl, float(np.mean([r["detected"] for r in rs])),
                    float(np.median(errs)) if errs else np.nan, float(np.percentile(errs, 95)) if errs else np.nan,
                    float(np.median([r[_FACTORS[name][0]] for r in rs]))))
    return out


def break_points(rows: list[dict]) -> dict:
    """{factor: first swept level where detection < 99% or the median corner error > 0.5 px (or None)}."""
    out = {}
    for name in _FACTORS:
        lv = _levels(rows, name)
        order = lv[::-1] if name == "size" else lv  # small snapshots break, so walk sizes downwards
        hit = next((x for x in order if x[1] < _DET_MIN or (np.isfinite(x[2]) and x[2] > _ERR_MAX)), None)
        out[name] = None if hit is None else {"level": hit[0], "measured": hit[4], "detection_rate": hit[1],
                                              "median_err_px": hit[2]}
    return out


def write_charts(rows: list[dict], out: Path) -> None:
    try:
        plt = pyplot()
    except ImportError:
        raise UserError("bench charts need matplotlib: pip install 'snapshot3d[train]'") from None
    bp = break_points(rows)
    fig, ax = plt.subplots(2, 4, figsize=(18, 8))
    for j, name in enumerate(_FACTORS):
        lv = _levels(rows, name)
        if not lv:
            continue
        x = [v[4] for v in lv]  # the measured value (median over the level's photos), e.g. the coverage reached
        ax[0, j].plot(x, [100 * v[1] for v in lv], "o-")
        ax[0, j].set_ylim(-5, 105)
        ax[0, j].set_ylabel("detection rate (%)")
        ax[1, j].plot(x, [v[2] for v in lv], "o-", label="median")
        ax[1, j].plot(x, [v[3] for v in lv], "s--", label="95th percentile")
        ax[1, j].axhline(_ERR_MAX, color="grey", lw=0.8)
        ax[1, j].set_yscale("log")
        ax[1, j].set_ylabel("worst-corner error (snapshot px)")
        ax[1, j].legend(fontsize=8)
        for i in range(2):
            ax[i, j].set_xlabel(_FACTORS[name][1] + " (swept; rest as mild)")
            if name == "size":
                ax[i, j].set_xscale("log")
            if bp.get(name):
                ax[i, j].axvline(bp[name]["measured"], color="red", ls=":", lw=2)
                ax[i, j].text(bp[name]["measured"], ax[i, j].get_ylim()[1], " breaks", color="red", va="top",
                              fontsize=9)
    fig.suptitle("scanner vs one factor at a time (red: first level with detection < 99% or median error > 0.5 px)")
    fig.tight_layout()
    fig.savefig(out / "scan_breaks.png", dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(1, 4, figsize=(18, 4.5))
    colours = {"mild": "tab:green", "moderate": "tab:orange", "severe": "tab:red"}
    for j, (name, (key, label)) in enumerate(_FACTORS.items()):
        for sev, c in colours.items():
            g = [r for r in rows if r["group"] == sev]
            ax[j].scatter([r[key] for r in g if r["detected"]], [max(r["err_max"], 1e-3) for r in g if r["detected"]],
                          s=8, c=c, alpha=0.6, label=sev)
            miss = [r[key] for r in g if not r["detected"]]
            ax[j].scatter(miss, [20.0] * len(miss), marker="x", c=c, s=40)
        ax[j].set_yscale("log")
        ax[j].axhline(_ERR_MAX, color="grey", lw=0.8)
        ax[j].set_xlabel(label)
        ax[j].set_ylabel("worst-corner error (snapshot px); x = missed")
    ax[0].legend()
    fig.suptitle("random preset photos (seeds): corner error against each factor; misses drawn at the top")
    fig.tight_layout()
    fig.savefig(out / "scan_presets.png", dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 4))
    sevs = [s for s in colours if any(r["group"] == s and r["detected"] for r in rows)]
    ax.boxplot([[r["psnr"] for r in rows if r["group"] == s and r["detected"]] for s in sevs])
    ax.set_xticks(range(1, len(sevs) + 1), sevs)
    ax.set_ylabel("rectified vs true snapshot PSNR (dB)")
    fig.tight_layout()
    fig.savefig(out / "scan_psnr.png", dpi=90)
    plt.close(fig)


def bench_scan_command(args) -> int:
    from tqdm import tqdm

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    snap = _host()
    sheet = render_sheet(snap, SheetMeta(box=(-1, -1, -1, 1, 1, 1), orbit=(3.0, 20.0, 40.0)), 2)
    jobs = [(PRESETS[s], seed, s, "") for s in ("mild", "moderate") for seed in range(args.seeds)]
    jobs += [(PRESETS["severe"], seed, "severe", "") for seed in range(args.severe_seeds)]
    sweep_seeds = max(1, args.seeds // 40)
    for name, (levels, change) in SWEEPS.items():
        jobs += [(replace(PRESETS["mild"], name=f"sweep-{name}", **change(v)), 10_000 + s, f"sweep-{name}", v)
                 for v in levels for s in range(sweep_seeds)]
    t_start = time.time()
    rows = [_one(sheet, snap, p, seed, g, lvl) for p, seed, g, lvl in tqdm(jobs, desc="bench scan", unit="photo")]
    false = []
    rng = np.random.default_rng(7)
    for kind, img in tqdm(_negatives(args.negatives, rng), total=args.negatives, desc="no-sheet photos", unit="photo"):
        t1 = time.perf_counter()
        try:
            scan_image(img)
            false.append(kind)
            cause = "FALSE DETECTION"
        except UserError as e:
            cause = str(e)
        rows.append({"group": "negative", "level": kind, "seed": "", "detected": int(cause == "FALSE DETECTION"),
                     "cause": cause, "scan_ms": (time.perf_counter() - t1) * 1e3})
    timing = _timing(sheet, args.timing_runs)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=_FIELDS)
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.5g}" if isinstance(v, float) else v) for k, v in r.items()})
    write_atomic(out / "scan.csv", buf.getvalue().encode())
    mm = [r for r in rows if r["group"] in ("mild", "moderate")]
    severe_miss = [{"seed": r["seed"], "cause": r["cause"]} for r in rows if r["group"] == "severe" and not r["detected"]]
    neg_causes: dict = {}
    for r in rows:
        if r["group"] == "negative":
            key = r["cause"].split(" (")[0].split(";")[0]
            neg_causes[key] = neg_causes.get(key, 0) + 1
    report = {
        "command": f"snapshot3d bench scan --out {args.out} --seeds {args.seeds} --severe-seeds {args.severe_seeds} "
                   f"--negatives {args.negatives} --timing-runs {args.timing_runs}",
        "cpu_count": os.cpu_count(), "meta": run_metadata(),
        "machine": platform.platform(), "python": platform.python_version(),
        "opencv": cv2.__version__, "wall_seconds": round(time.time() - t_start, 1), "targets": TARGETS,
        "mild_and_moderate": _summary([dict(r, group="mm") for r in mm], "mm"),
        "mild": _summary(rows, "mild"), "moderate": _summary(rows, "moderate"), "severe": _summary(rows, "severe"),
        "severe_misses": severe_miss,
        "no_sheet": {"photos": args.negatives, "false_detections": len(false), "false_kinds": false, "causes": neg_causes},
        "timing": timing, "break_points": break_points(rows),
        "notes": "corner errors in snapshot pixels (photo-pixel error / local snapshot scale), all 4 corners pooled; "
                 "scan_ms excludes JPEG decoding, which is reported separately; CPU shared with other jobs.",
    }
    write_atomic(out / "scan.json", (json.dumps(report, indent=2) + "\n").encode())
    write_charts(rows, out)
    mmr = report["mild_and_moderate"]
    print(f"mild+moderate: detection {100 * mmr['detection_rate']:.1f}%, corner error median "
          f"{mmr.get('corner_err_median_px', float('nan')):.3f} px, p95 {mmr.get('corner_err_p95_px', float('nan')):.3f} px; "
          f"severe detection {100 * report['severe']['detection_rate']:.1f}%; false detections {len(false)}; "
          f"scan {timing['scan_ms_median']:.0f} ms median (+{timing['decode_ms_median']:.0f} ms JPEG decoding); "
          f"wrote {out}/scan.csv, scan.json, scan_*.png")
    return 0


def _timing(sheet, runs: int) -> dict:
    """Median time to scan one moderate 12 MP photo, repeated `runs` times (decode timed separately)."""
    data, _, _ = simulate(sheet, "moderate", 3)
    dec, scan = [], []
    for _ in range(max(1, runs)):
        t0 = time.perf_counter()
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        t1 = time.perf_counter()
        res = scan_image(img)
        dec.append((t1 - t0) * 1e3)
        scan.append(res.timings_ms["total"])
    stages = {k: float(np.median([v])) for k, v in res.timings_ms.items()}
    return {"runs": len(scan), "photo": "moderate seed 3, 4000x3000 JPEG", "scan_ms_median": float(np.median(scan)),
            "scan_ms_p10": float(np.percentile(scan, 10)), "decode_ms_median": float(np.median(dec)),
            "total_with_decode_ms_median": float(np.median(np.add(scan, dec))), "last_run_stages_ms": stages,
            "cv2_threads": cv2.getNumThreads()}
