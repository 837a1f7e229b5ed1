"""`snapshot3d bench decode`: the torch-free decode on simulated photos (torch is used here only to make
the photos and the reference views).

- end to end: `moderate` photos of the bundled spot scene hidden in a held-out host, N seeds:
  `decode_ms` per stage, `restore_psnr` (decoded views vs the reference renderer's views of the
  original planes) and `e2e_psnr` (decoded views vs the mesh's ground-truth orbit views);
- a sweep on one capture (`--sweep-severity`, default `jpeg90`: there the codec's own error is small
  enough for the renderer's settings to show) of samples per pixel, occupancy resolution, probe size
  and render size: decode time against `restore_psnr`, with the Pareto front.
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

from snapshot3d import formats
from snapshot3d.metrics import psnr
from snapshot3d.scanner.imageio_safe import write_atomic
from snapshot3d.scanner.sheet import render_sheet
from snapshot3d.scanner.simulate import simulate
from snapshot3d.viewer.decode import decode_photo
from snapshot3d.viewer.render import RenderConfig

from .codec import embed_planes, load_codec
from .codec_commands import load_host, scene_meta
from .commands import orbit_cameras, render_scene

__all__ = ["bench_decode_command"]

# the default (RenderConfig: samples 12, occ_res 64, probe_div 4, size 380) is measured once, as "default"
SWEEP = [("samples", v) for v in (4, 8, 16, 24, 32)] + [("occ_res", v) for v in (32, 48)] + \
        [("probe_div", v) for v in (2, 8)] + [("size", v) for v in (190, 285)]


def _ground_truth(scene, size: int) -> np.ndarray:
    from snapshot3d.builtin import load_mesh, render_mesh
    c2w, intr = orbit_cameras(scene, formats.ORBIT_VIEWS, size)
    mesh = load_mesh("spot")
    return render_mesh(mesh, c2w, intr, size, size)[0]


def _pareto(points):
    """indices of points (time, psnr) not beaten by another in both (less time, more psnr)."""
    return [i for i, (t, p) in enumerate(points)
            if not any(t2 <= t and p2 >= p and (t2, p2) != (t, p) for t2, p2 in points)]


def bench_decode_command(args) -> int:
    from snapshot3d.paths import asset
    from snapshot3d.viewer.demo import EXAMPLE_SCENE
    from snapshot3d.scene import load_scene_file

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = load_scene_file(asset(EXAMPLE_SCENE))
    snap = embed_planes(load_codec()[0], load_host("builtin:" + args.host), scene.planes())
    sheet = render_sheet(snap, scene_meta(scene, 1.0), 4)
    ref = {formats.ORBIT_SIZE: render_scene(scene, formats.ORBIT_VIEWS, formats.ORBIT_SIZE, progress=False)}
    truth = _ground_truth(scene, formats.ORBIT_SIZE)
    rows = []
    tmp = out / ".decode-bench-photo.jpg"
    for seed in range(args.seeds):
        data, _, _ = simulate(sheet, args.severity, seed)
        write_atomic(tmp, data)
        dec = decode_photo(tmp)
        r = dec.report
        rows.append({"group": "e2e", "seed": seed, "decode_ms": r["decode_ms"], **{f"{k}_ms": v for k, v in r["timings_ms"].items()},
                     "restore_psnr": psnr(dec.views, ref[formats.ORBIT_SIZE]), "e2e_psnr": psnr(dec.views, truth),
                     "plane_psnr_est": r["quality_estimate"]["plane_psnr_db"]})
        print(f"seed {seed}: {rows[-1]['decode_ms']:.0f} ms, restore_psnr {rows[-1]['restore_psnr']:.2f}", flush=True)
    data, _, _ = simulate(sheet, args.sweep_severity, 0)
    write_atomic(tmp, data)
    for name, value in [("default", None)] + SWEEP:
        cfg, size = RenderConfig(), formats.ORBIT_SIZE
        if name == "size":
            size = value
        elif value is not None:
            cfg = replace(cfg, **{name: value})
        if size not in ref:
            ref[size] = render_scene(scene, formats.ORBIT_VIEWS, size, progress=False)
        times, dec = [], None
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            dec = decode_photo(tmp, size=size, cfg=cfg)
            times.append((time.perf_counter() - t0) * 1e3)
        rows.append({"group": "sweep", "setting": name, "value": value, "decode_ms": float(np.median(times)),
                     "render_ms": dec.report["timings_ms"]["render"], "restore_psnr": psnr(dec.views, ref[size])})
    tmp.unlink(missing_ok=True)
    e2e = [r for r in rows if r["group"] == "e2e"]
    sweep = [r for r in rows if r["group"] == "sweep"]
    front = _pareto([(r["decode_ms"], r["restore_psnr"]) for r in sweep])
    med = lambda k: float(np.median([r[k] for r in e2e]))  # noqa: E731
    summary = {"decode_ms_median": med("decode_ms"), "first_view_ms_median": med("first_view_ms"),
               "stage_ms_median": {k: med(f"{k}_ms") for k in ("scan", "restore", "occupancy", "render")},
               "restore_psnr_median": med("restore_psnr"), "e2e_psnr_median": med("e2e_psnr"),
               "plane_psnr_estimate_median": med("plane_psnr_est"),
               "estimate_vs_restore_corr": float(np.corrcoef([r["plane_psnr_est"] for r in e2e],
                                                              [r["restore_psnr"] for r in e2e])[0, 1]) if len(e2e) > 2 else None,
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
    _chart(sweep, front, out / "decode.png", os.cpu_count())
    print(json.dumps(summary, indent=2))
    return 0


def _chart(sweep, front, path: Path, cores: int) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
