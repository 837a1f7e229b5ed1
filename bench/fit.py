"""`snapshot3d bench fit`: field_psnr against scene_kb and against fit time, for spot and lego, plus
training throughput with and without empty-space skipping. Writes fit.csv, fit.json and fit.png.

Every point is a separate fit from scratch on this machine; the core count is in the JSON."""
from __future__ import annotations

import csv
import json
import os
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch

from snapshot3d.errors import UserError
from snapshot3d.scene import Orbit, Scene, dequantize_planes
from snapshot3d.train.field.config import LADDER
from snapshot3d.train.field.decoder import load_decoder
from snapshot3d.train.field.evaluate import evaluate_planes
from snapshot3d.train.field.fit import fit, hull_grid

from .common import pyplot, run_metadata
from .scenes import BENCH_SCENES, checked_scenes, load_bench_scene

__all__ = ["bench_fit_command", "BENCH_SCENES"]

def _run_fit(posed, dec, cfg, hull):
    t0 = time.perf_counter()
    res = fit(posed, dec, cfg, hull=hull)
    train_s = time.perf_counter() - t0
    ev = evaluate_planes(dequantize_planes(res.codes), dec, posed)
    kb = Scene(codes=res.codes, box=posed.box, orbit=Orbit(radius=1.0)).scene_kb
    return {"plane_res": cfg.plane_res, "plane_channels": cfg.plane_channels, "steps": cfg.steps,
            "scene_kb": round(kb, 2), "field_psnr": round(ev["field_psnr"], 3), "field_ssim": round(ev["field_ssim"], 4),
            "fit_seconds": round(time.perf_counter() - t0, 1), "train_seconds": round(train_s, 1),
            "rays_per_s": round(res.state.rays / res.seconds), "samples_per_s": round(res.state.samples / res.seconds),
            "occupancy": cfg.occupancy, "early_termination": cfg.min_transmittance > 0}


def bench_scene(name: str, quick: bool, save) -> None:
    """Runs the sweeps of one scene, handing each result row to `save`."""
    posed, base = load_bench_scene(name)
    dec = load_decoder()
    hull = hull_grid(posed)
    scale = 0.1 if quick else 1.0
    sizes = LADDER[:2] if quick else LADDER
    for res, ch in sizes:  # accuracy against size
        cfg = replace(base, plane_res=res, plane_channels=ch, steps=max(50, int(base.steps * scale)))
        save({"scene": name, "sweep": "size", **_run_fit(posed, dec, cfg, hull)})
    sweep = BENCH_SCENES[name][3]
    for steps in (sweep[:1] if quick else sweep):  # accuracy against time
        cfg = replace(base, steps=max(50, int(steps * scale)))
        save({"scene": name, "sweep": "steps", **_run_fit(posed, dec, cfg, hull)})
    n = max(50, int(400 * scale))  # throughput: skipping on/off, same steps
    for occ, ert in ((True, True), (True, False), (False, False)):
        cfg = replace(base, steps=n, occupancy=occ, min_transmittance=1e-3 if ert else 0.0)
        save({"scene": name, "sweep": "throughput", **_run_fit(posed, dec, cfg, hull if occ else None)})


def _chart(rows, path: Path, cores: int, threads: int):
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for name in sorted({r["scene"] for r in rows}):
        size = sorted((r for r in rows if r["scene"] == name and r["sweep"] == "size"), key=lambda r: r["scene_kb"])
        steps = sorted((r for r in rows if r["scene"] == name and r["sweep"] != "throughput" and r["plane_res"] == 64
                        and r["plane_channels"] == 8), key=lambda r: r["fit_seconds"])
        thr = [r for r in rows if r["scene"] == name and r["sweep"] == "throughput"]
        axes[0].plot([r["scene_kb"] for r in size], [r["field_psnr"] for r in size], "o-", label=name)
        for r in size:
            axes[0].annotate(f"R{r['plane_res']}C{r['plane_channels']}", (r["scene_kb"], r["field_psnr"]), fontsize=7)
        axes[1].plot([r["fit_seconds"] for r in steps], [r["field_psnr"] for r in steps], "o-", label=name)
        labels = ["occ+ert", "occ", "none"]
        x = np.arange(len(thr)) + (0.2 if name == "lego" else -0.2)
        bars = axes[2].bar(x, [r["rays_per_s"] / 1e3 for r in thr], width=0.4, label=name)
        for b_, r in zip(bars, thr):
            axes[2].annotate(f"{r['samples_per_s'] / r['rays_per_s']:.0f} s/ray", (b_.get_x(), b_.get_height()),
                             fontsize=7)
        axes[2].set_xticks(np.arange(len(labels)), labels)
    axes[0].axvline(160, color="grey", ls="--", lw=0.8)
    axes[0].set(xlabel="scene_kb (8-bit planes)", ylabel="field_psnr (dB, held-out)", title="accuracy vs size")
    axes[1].set(xlabel="fit seconds (train + eval)", ylabel="field_psnr (dB)", title="accuracy vs fit time (R64 C8)")
    axes[2].set(ylabel="thousand rays / s (train)", title="training rays/s: occupancy grid, early termination")
    for a in axes:
        a.grid(alpha=0.3), a.legend()
    fig.suptitle(f"snapshot3d bench fit — {cores} CPU cores, torch threads {threads}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def merge_results(out: Path) -> list[dict]:
    """Combine the per-scene results `fit_<scene>.json` (from parallel `--scenes` runs) into fit.*."""
    parts = [json.loads((out / f"fit_{n}.json").read_text()) for n in BENCH_SCENES if (out / f"fit_{n}.json").is_file()]
    if not parts:
        raise UserError(f"--merge: no fit_<scene>.json in {out}")
    rows = [r for p in parts for r in p["rows"]]
    with open(out / "fit.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader(), w.writerows(rows)
    meta = {**parts[0], "rows": rows, "command": [p["command"] for p in parts], "meta": run_metadata()}
    (out / "fit.json").write_text(json.dumps(meta, indent=2))
    _chart(rows, out / "fit.png", parts[0]["cpu_count"], parts[0]["torch_threads"])
    return rows


def bench_fit_command(args) -> int:
    out = Path(args.out)
    if args.merge:
        merge_results(out)
        print(f"wrote {out}/fit.csv, fit.json, fit.png")
        return 0
    scenes = checked_scenes(args.scenes)   # every name checked before a folder is made or a scene fitted
    out.mkdir(parents=True, exist_ok=True)
    cores = os.cpu_count()
    suffix = "" if args.scenes == ",".join(BENCH_SCENES) else "_" + args.scenes.replace(",", "_")
    rows = []

    def save(row):  # results are written after every fit, so a long run leaves what it measured
        rows.append(row)
        print(f"{row['scene']} {row['sweep']}: {row}", flush=True)
        with open(out / f"fit{suffix}.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader(), w.writerows(rows)
        meta = {"cpu_count": cores, "meta": run_metadata(), "torch_threads": torch.get_num_threads(),
                "quick": args.quick,
                "command": f"snapshot3d bench fit --scenes {args.scenes}" + (" --quick" if args.quick else ""),
                "configs": {k: asdict(v[2]) for k, v in BENCH_SCENES.items()},
                "step_sweeps": {k: v[3] for k, v in BENCH_SCENES.items()}, "rows": rows}
        (out / f"fit{suffix}.json").write_text(json.dumps(meta, indent=2))
        _chart(rows, out / f"fit{suffix}.png", cores, torch.get_num_threads())

    for name in scenes:
        bench_scene(name, args.quick, save)
    print(f"wrote {out}/fit{suffix}.csv, .json, .png")
    return 0
