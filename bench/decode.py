"""`snapshot3d bench decode`: the torch-free decode on simulated photos (torch is used here only to make
the photos and the reference views).

- end to end: `moderate` photos of the bundled spot scene hidden in a held-out host, N seeds:
  `decode_ms` per stage, `restore_psnr` (decoded views vs the reference renderer's views of the
  original planes) and `e2e_psnr` (decoded views vs the mesh's ground-truth orbit views);
- a sweep on one capture (`--sweep-severity`, default `jpeg90`: there the codec's own error is small
  enough for the renderer's settings to show) of samples per pixel, bake resolution, probe size
  and render size: decode time against `restore_psnr`, with the Pareto front;
- the quality estimate's calibration: captures of every physical and JPEG severity (`--calib-seeds`
  each, seeds apart from the end-to-end ones): `restore_psnr` against the sheet markers' `pilot_psnr`,
  a least-squares line, checked on the end-to-end photos it never saw. The line is written to
  `--calibration` (by default the package's `viewer.quality.CALIBRATION_FILE`, which `decode` reads).
Writes decode.csv, decode.json and decode.png under --out."""
from __future__ import annotations

import csv
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from snapshot3d.scanner.imageio_safe import write_atomic
from snapshot3d.scanner.sheet import render_sheet
from snapshot3d.scanner.simulate import simulate
from snapshot3d.train.codec.commands import load_host, scene_meta
from snapshot3d.train.codec.hinet import embed_planes, load_codec
from snapshot3d.train.field.commands import orbit_cameras, render_scene
from snapshot3d.viewer.decode import decode_photo
from snapshot3d.viewer.render import RenderConfig

from snapshot3d import formats
from snapshot3d.metrics import psnr

from .common import pyplot

__all__ = ["bench_decode_command"]

# the default (RenderConfig: samples 16, bake 96, probe_div 4, size 380) is measured once, as "default"
SWEEP = [("samples", v) for v in (4, 8, 12, 24, 32)] + [("bake", v) for v in (32, 64, 128, 160)] + \
        [("probe_div", v) for v in (2, 8)] + [("size", v) for v in (190, 285)]
CALIB_SEVERITIES = ("jpeg90", "jpeg75", "mild", "moderate", "severe")
CALIB_SEED0 = 1000


def _ground_truth(scene, size: int) -> np.ndarray:
    from snapshot3d.builtin import load_mesh, render_mesh
    c2w, intr = orbit_cameras(scene, formats.ORBIT_VIEWS, size)
    mesh = load_mesh("spot")
    return render_mesh(mesh, c2w, intr, size, size)[0]


def _pareto(points):
    """indices of points (time, psnr) not beaten by another in both (less time, more psnr)."""
    return [i for i, (t, p) in enumerate(points)
            if not any(t2 <= t and p2 >= p and (t2, p2) != (t, p) for t2, p2 in points)]


def _photo(sheet, severity: str, seed: int, folder: Path) -> Path:
    data, ext, _ = simulate(sheet, severity, seed)
    path = folder / f".decode-bench-photo{ext}"
    write_atomic(path, data)
    return path


def _calibrate(calib, e2e) -> dict:
    """Least-squares restore_psnr = intercept + slope * pilot_psnr on the calibration captures, and how
    well it predicts the end-to-end photos (never used in the fit)."""
    x, y = np.array([r["pilot_psnr"] for r in calib]), np.array([r["restore_psnr"] for r in calib])
    slope, intercept = np.polyfit(x, y, 1)
    xe, ye = np.array([r["pilot_psnr"] for r in e2e]), np.array([r["restore_psnr"] for r in e2e])
    pred = intercept + slope * np.clip(xe, x.min(), x.max())
    corr = float(np.corrcoef(xe, ye)[0, 1]) if len(e2e) > 2 and np.std(xe) > 0 else None
    return {"slope": float(slope), "intercept": float(intercept), "pilot_range": [float(x.min()), float(x.max())],
            "fit_corr": float(np.corrcoef(x, y)[0, 1]), "held_out_corr": corr,
            "held_out_rmse_db": float(np.sqrt(np.mean((pred - ye) ** 2))),
            "held_out_median_abs_error_db": float(np.median(np.abs(pred - ye))),
            "source": "snapshot3d bench decode: spot in the held-out host, severities " + ",".join(CALIB_SEVERITIES)}


def bench_decode_command(args) -> int:
    from snapshot3d.viewer.demo import EXAMPLE_SCENE
    from snapshot3d.viewer.quality import CALIBRATION_FILE

    from snapshot3d.paths import asset
    from snapshot3d.scene import load_scene_file

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = load_scene_file(asset(EXAMPLE_SCENE))
    snap = embed_planes(load_codec()[0], load_host("builtin:" + args.host), scene.planes())
    sheet = render_sheet(snap, scene_meta(scene, 1.0), 4)
    ref = {formats.ORBIT_SIZE: render_scene(scene, formats.ORBIT_VIEWS, formats.ORBIT_SIZE, show_progress=False)}
    truth = _ground_truth(scene, formats.ORBIT_SIZE)
    rows = []
    runs = [("e2e", args.severity, seed) for seed in range(args.seeds)]
    runs += [("calib", sev, CALIB_SEED0 + seed) for sev in CALIB_SEVERITIES for seed in range(args.calib_seeds)]
    for group, severity, seed in runs:
        photo = _photo(sheet, severity, seed, out)
        dec = decode_photo(photo)
        r = dec.report
        rows.append({"group": group, "severity": severity, "seed": seed, "decode_ms": r["decode_ms"],
                     **{f"{k}_ms": v for k, v in r["timings_ms"].items()},
                     "restore_psnr": psnr(dec.views, ref[formats.ORBIT_SIZE]), "e2e_psnr": psnr(dec.views, truth),
                     "pilot_psnr": r["quality_estimate"]["pilot_psnr_db"]})
        photo.unlink(missing_ok=True)
        print(f"{group} {severity} seed {seed}: {rows[-1]['decode_ms']:.0f} ms, restore_psnr "
              f"{rows[-1]['restore_psnr']:.2f}, pilot_psnr {rows[-1]['pilot_psnr']:.1f}", flush=True)
    photo = _photo(sheet, args.sweep_severity, 0, out)
    for name, value in [("default", None)] + SWEEP:
        cfg, size = RenderConfig(), formats.ORBIT_SIZE
        if name == "size":
            size = value
        elif value is not None:
            cfg = replace(cfg, **{name: value})
        if size not in ref:
            ref[size] = render_scene(scene, formats.ORBIT_VIEWS, size, show_progress=False)
        times, dec = [], None
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            dec = decode_photo(photo, size=size, cfg=cfg)
            times.append((time.perf_counter() - t0) * 1e3)
        rows.append({"group": "sweep", "setting": name, "value": value, "decode_ms": float(np.median(times)),
                     "render_ms": dec.report["timings_ms"]["render"], "restore_psnr": psnr(dec.views, ref[size])})
    photo.unlink(missing_ok=True)
    e2e = [r for r in rows if r["group"] == "e2e"]
    sweep = [r for r in rows if r["group"] == "sweep"]
    calibration = _calibrate([r for r in rows if r["group"] == "calib"], e2e)
    cal_path = Path(args.calibration) if args.calibration else asset(CALIBRATION_FILE)
    cal_path.write_text(json.dumps(calibration, indent=2) + "\n")
    front = _pareto([(r["decode_ms"], r["restore_psnr"]) for r in sweep])
    med = lambda k: float(np.median([r[k] for r in e2e]))  # noqa: E731
    summary = {"decode_ms_median": med("decode_ms"), "first_view_ms_median": med("first_view_ms"),
               "stage_ms_median": {k: med(f"{k}_ms") for k in ("scan", "restore", "bake", "render")},
               "restore_psnr_median": med("restore_psnr"), "e2e_psnr_median": med("e2e_psnr"),
               "quality_estimate": calibration,
               "pareto": [f"{sweep[i]['setting']}={sweep[i]['value']}" for i in front],
               "default_on_front": 0 in front}
    doc = {"command": "snapshot3d " + " ".join(sys.argv[1:]), "cores": os.cpu_count(), "severity": args.severity,
           "sweep_severity": args.sweep_severity,
           "host": args.host, "targets": {"decode_ms_median": "<= 2000", "first_view_ms": "<= 500"},
           "summary": summary}
    with open(out / "decode.csv", "w", newline="") as f:
        keys = sorted(set().union(*rows))
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    (out / "decode.json").write_text(json.dumps(doc, indent=2) + "\n")
    _chart(sweep, front, [r for r in rows if r["group"] != "sweep"], calibration, out / "decode.png", os.cpu_count())
    print(json.dumps(summary, indent=2))
    return 0


def _chart(sweep, front, captures, calibration, path: Path, cores: int) -> None:
    plt = pyplot()

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(14, 5.5))
    for i, r in enumerate(sweep):
        ax.plot(r["decode_ms"], r["restore_psnr"], "o", color="C3" if i == 0 else ("C0" if i in front else "grey"))
        ax.annotate("default" if i == 0 else f"{r['setting']}={r['value']}", (r["decode_ms"], r["restore_psnr"]),
                    fontsize=7)
    pts = sorted((sweep[i]["decode_ms"], sweep[i]["restore_psnr"]) for i in front)
    ax.plot([p[0] for p in pts], [p[1] for p in pts], "-", color="C0", alpha=0.5, label="Pareto front")
    ax.set_xlabel(f"decode_ms, photo to 20 views ({cores} cores)")
    ax.set_ylabel("restore_psnr (dB)")
    ax.set_title("decode time against restore fidelity (one capture of spot's sheet)")
    ax.legend()
    for i, sev in enumerate(sorted({r["severity"] for r in captures})):
        pts = [r for r in captures if r["severity"] == sev]
        bx.plot([r["pilot_psnr"] for r in pts], [r["restore_psnr"] for r in pts], "o" if pts[0]["group"] == "calib" else "x",
                color=f"C{i}", label=f"{sev} ({pts[0]['group']})")
    xs = np.linspace(*calibration["pilot_range"], 50)
    bx.plot(xs, calibration["intercept"] + calibration["slope"] * xs, "k-", alpha=0.6,
            label=f"fit; held-out rmse {calibration['held_out_rmse_db']:.2f} dB")
    bx.set_xlabel("pilot_psnr: the sheet's markers after scanning (dB, no ground truth)")
    bx.set_ylabel("restore_psnr (dB)")
    bx.set_title("the quality estimate: markers predict restore fidelity")
    bx.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
