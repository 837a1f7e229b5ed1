"""`snapshot3d bench decode`: the torch-free decode on simulated photos (torch is used here only to make
the snapshots of the file codec and the reference views).

- end to end: `--severity` photos (default `moderate`) of the demo's print scene hidden in a held-out host,
  N seeds: `decode_ms` per stage, `restore_psnr` (decoded views vs the reference renderer's views of the
  original planes) and `e2e_psnr` (decoded views vs the mesh's ground-truth orbit views), and the time the
  numpy reference of the print restore graph takes on the same scan;
- a sweep on one capture (`--sweep-severity`) of samples per pixel, bake resolution, probe size and render
  size: decode time against `restore_psnr`, with the Pareto front;
- the quality estimate's calibration, one line per codec (`viewer.quality`; the print codec's views term is
  read as it is, scored here and on held-out scenes by `snapshot3d bench quality`): captures of every severity
  (jpeg90 to severe) of two scenes in calibration hosts fit `restore_psnr` against the codec's own
  predictor (print: log10 of the pilots' expected plane error; file: the markers' pilot_psnr); the line
  is then scored on captures in other hosts it never saw (its held-out error is what `decode` reports).
  The lines are written to `--calibration-dir` (default: the package's assets, which `decode` reads).
  Every print capture's planes are also restored by the numpy receiver: how often the graph's 8-bit planes
  differ from it (`print_graph_vs_numpy`).
Writes decode.csv, decode.json and decode.png under --out."""
from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from snapshot3d import formats
from snapshot3d.cameras import orbit_cameras
from snapshot3d.codecs.media import PRINT, medium_of
from snapshot3d.errors import UserError
from snapshot3d.metrics import psnr
from snapshot3d.paths import asset
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.imageio_safe import write_atomic
from snapshot3d.scanner.presets import get_preset
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scanner.sheet import render_sheet
from snapshot3d.scanner.simulate import simulate
from snapshot3d.scene import load_scene_file, quantize_planes
from snapshot3d.viewer.decode import decode_photo
from snapshot3d.viewer.quality import VIEWS_PREDICTOR, calibration_file, predictor_value
from snapshot3d.viewer.render import RenderConfig, render_views
from snapshot3d.viewer.runtime import scene_models

from .common import pyplot, run_metadata, write_rows

__all__ = ["bench_decode_command", "CALIB_SEVERITIES", "fit_calibration", "identity_calibration", "FIT_HOSTS",
           "CHECK_HOSTS"]

# the default (RenderConfig: samples 16, bake 96, probe_div 4, size 380) is measured once, as "default"
SWEEP = [("samples", v) for v in (4, 8, 12, 24, 32)] + [("bake", v) for v in (32, 64, 128, 160)] + \
        [("probe_div", v) for v in (2, 8)] + [("size", v) for v in (190, 285)]
CALIB_SEVERITIES = tuple(s for s in formats.SEVERITIES if s != "none")   # every capture but the lossless copy
CALIB_SEED0 = 1000
FIT_HOSTS = ("builtin:astronaut", "builtin:rocket")          # calibration fits on these (training hosts)
CHECK_HOSTS = ("builtin:coffee", "builtin:chelsea")          # and is scored on these (held out)


def _reference(scene, size: int) -> np.ndarray:
    c2w, intr = orbit_cameras(scene.orbit, formats.ORBIT_VIEWS, size)
    return render_views(scene_models(scene), scene.planes(), scene.box, c2w, intr, size, size)


def _ground_truth(scene, size: int) -> np.ndarray:
    from snapshot3d.builtin import load_mesh, render_mesh
    c2w, intr = orbit_cameras(scene.orbit, formats.ORBIT_VIEWS, size)
    return render_mesh(load_mesh("spot"), c2w, intr, size, size)[0]


def _pareto(points):
    """indices of points (time, psnr) not beaten by another in both (less time, more psnr)."""
    return [i for i, (t, p) in enumerate(points)
            if not any(t2 <= t and p2 >= p and (t2, p2) != (t, p) for t2, p2 in points)]


def _snapshot(scene, codec: str, host: np.ndarray) -> np.ndarray:
    if codec == formats.PRINT_CODEC:
        from snapshot3d.codecs import print_embed
        return print_embed.embed(host, scene.planes())
    from snapshot3d.train.codec.hinet import embed_planes, load_codec
    return embed_planes(load_codec()[0], host, scene.planes())


def _photo(sheet, severity: str, seed: int, folder: Path) -> Path:
    data, ext, _ = simulate(sheet, severity, seed)
    path = folder / f".decode-bench-photo{ext}"
    write_atomic(path, data)
    return path


def fit_calibration(fit_rows: list[dict], check_rows: list[dict], codec: str, key: str = "predictor") -> dict:
    """Least-squares restore_psnr = intercept + slope * row[key] on `fit_rows`, and how well it predicts
    `check_rows` (photos in other hosts, or of other scenes, never used in the fit). key "log10_rmse": the
    print line shipped before the views term (`bench quality` compares the two)."""
    x, y = np.array([r[key] for r in fit_rows]), np.array([r["restore_psnr"] for r in fit_rows])
    slope, intercept = np.polyfit(x, y, 1)
    xe, ye = np.array([r[key] for r in check_rows]), np.array([r["restore_psnr"] for r in check_rows])
    pred = intercept + slope * np.clip(xe, x.min(), x.max())
    name = ("log10(plane_rmse_expected)" if key == "log10_rmse" else VIEWS_PREDICTOR) if medium_of(codec) is PRINT \
        else "pilot_psnr (markers, dB)"
    return {"codec": codec, "predictor": name, "slope": float(slope), "intercept": float(intercept),
            "range": [float(x.min()), float(x.max())], "fit_corr": float(np.corrcoef(x, y)[0, 1]),
            "held_out_corr": float(np.corrcoef(xe, ye)[0, 1]) if len(xe) > 2 and np.std(xe) > 0 else None,
            "held_out_rmse_db": float(np.sqrt(np.mean((pred - ye) ** 2))),
            "held_out_median_abs_error_db": float(np.median(np.abs(pred - ye))), "fit_n": len(x), "held_out_n": len(xe),
            "held_out_by_severity": {s: float(np.sqrt(np.mean([(p - r["restore_psnr"]) ** 2 for p, r in zip(pred, check_rows)
                                                               if r["severity"] == s])))
                                     for s in CALIB_SEVERITIES if any(r["severity"] == s for r in check_rows)},
            "source": f"snapshot3d bench decode: scenes {sorted({r['scene'] for r in fit_rows})}, fitted on hosts "
                      f"{list(FIT_HOSTS)}, scored on {list(CHECK_HOSTS)}, severities {','.join(CALIB_SEVERITIES)}"}


def identity_calibration(check_rows: list[dict], codec: str) -> dict:
    """The views term read as the estimate itself (slope 1, no offset), in `fit_calibration`'s layout. Fitted
    lines carry the calibration hosts' own bias to other scenes (measured: worse on held-out scenes)."""
    x = np.array([r["predictor"] for r in check_rows])
    y = np.array([r["restore_psnr"] for r in check_rows])
    return {"codec": codec, "predictor": VIEWS_PREDICTOR, "slope": 1.0, "intercept": 0.0, "range": [0.0, 100.0],
            "fit_corr": None, "held_out_corr": float(np.corrcoef(x, y)[0, 1]) if len(x) > 2 else None,
            "held_out_rmse_db": float(np.sqrt(np.mean((x - y) ** 2))),
            "held_out_median_abs_error_db": float(np.median(np.abs(x - y))), "fit_n": 0, "held_out_n": len(x),
            "held_out_by_severity": {s: float(np.sqrt(np.mean([(r["predictor"] - r["restore_psnr"]) ** 2
                                                               for r in check_rows if r["severity"] == s])))
                                     for s in CALIB_SEVERITIES if any(r["severity"] == s for r in check_rows)}}


def _against_numpy(photo: Path, codes: np.ndarray) -> tuple[dict, np.ndarray]:
    """The print restore graph's 8-bit planes `codes` (as `decode` restored `photo`) against the numpy receiver
    it was written from, on the same scan: the share of codes that differ, their largest difference, and the
    numpy receiver's time (ms); and the scan."""
    from snapshot3d.codecs import print_read
    from snapshot3d.viewer.decode import read_input

    _, capture, meta, _ = read_input(photo)
    t0 = time.perf_counter()
    planes, _ = print_read.restore(*print_read.despread(capture, *meta.planes, codec=meta.codec), *meta.planes,
                                     codec=meta.codec)
    ms = (time.perf_counter() - t0) * 1e3
    d = np.abs(quantize_planes(planes).astype(int) - codes.astype(int))
    return {"graph_codes_differing": float(np.mean(d > 0)), "graph_codes_max_diff": int(d.max()),
            "restore_numpy_ms": ms}, capture


def _calibration_rows(scenes: dict, codec: str, seeds: int, out: Path,
                      hosts: tuple = FIT_HOSTS + CHECK_HOSTS) -> list[dict]:
    rows = []
    for sname, scene in scenes.items():
        ref = _reference(scene, 128)
        for host in hosts:
            sheet = render_sheet(_snapshot(scene, codec, load_host(host)), scene_meta(scene, codec), 2)
            for sev in CALIB_SEVERITIES:
                # a digital capture (jpeg90, jpeg75) is the same photo at every seed: it is taken, and counted, once
                for seed in range(seeds if get_preset(sev).physical else 1):
                    photo = _photo(sheet, sev, CALIB_SEED0 + seed, out)
                    try:
                        dec = decode_photo(photo, size=128)
                    except UserError as e:  # a capture the scanner refuses is a row with its cause
                        rows.append({"group": "calib", "codec": codec, "scene": sname, "host": host, "severity": sev,
                                     "seed": seed, "failed": str(e)[:80]})
                        continue
                    q = dec.report["quality_estimate"]
                    rows.append({"group": "calib", "codec": codec, "scene": sname, "host": host, "severity": sev,
                                 "seed": seed, "restore_psnr": psnr(dec.views, ref), "pilot_psnr": q["pilot_psnr_db"],
                                 "plane_rmse_expected": q["plane_rmse_expected"],
                                 "views_psnr_expected": q.get("views_psnr_expected_db"),
                                 "log10_rmse": predictor_value(codec, None, q["plane_rmse_expected"],
                                                               predictor="log10(plane_rmse_expected)"),
                                 "restore_psnr_expected": q["restore_psnr_expected_db"],
                                 "predictor": predictor_value(codec, q["pilot_psnr_db"], q["plane_rmse_expected"],
                                                              q.get("views_psnr_expected_db")),
                                 **(_against_numpy(photo, dec.scene.codes)[0] if codec == formats.PRINT_CODEC else {})})
                    photo.unlink(missing_ok=True)
            print(f"calibration {codec} {sname} {host}: {len(rows)} captures", flush=True)
    return rows


def _graph_agreement(rows: list[dict]) -> dict:
    """Over every print capture decoded: how often the restore graph's 8-bit planes differ from numpy's."""
    return {"captures": len(rows), "captures_with_any_code_differing": sum(r["graph_codes_differing"] > 0 for r in rows),
            "codes_differing_max_share": max((r["graph_codes_differing"] for r in rows), default=None),
            "codes_max_diff": max((r["graph_codes_max_diff"] for r in rows), default=None)}


def bench_decode_command(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if getattr(args, "profile", False):
        from .decode_profile import profile_decode

        doc = profile_decode(out, args.repeats, cold=args.cold)
        shares = ", ".join(f"{s} {doc['stages_ms_median'][s]:.0f} ms ({doc['stages_share'][s]:.0%})"
                           for s in doc["stages_share"])
        print(f"decode of {doc['photo']}: {doc['decode_ms_median']:.0f} ms median over {doc['repeats']} "
              f"({shares}); first view {doc['first_view_ms_median']:.0f} ms; wrote {out / 'decode_profile.json'} "
              f"and decode_profile.txt")
        if "cold" in doc:
            print(f"cold (a fresh process each, median of {args.cold}): {doc['cold']['decode_ms']:.0f} ms, first view "
                  f"{doc['cold']['first_view_ms']:.0f} ms; chart {out / 'decode_profile.png'}")
        return 0
    scene = load_scene_file(args.scene)
    sheet = render_sheet(_snapshot(scene, formats.PRINT_CODEC, load_host("builtin:" + args.host)),
                         scene_meta(scene, formats.PRINT_CODEC), 2)
    ref = {formats.ORBIT_SIZE: _reference(scene, formats.ORBIT_SIZE)}
    truth = _ground_truth(scene, formats.ORBIT_SIZE) if scene.meta.get("source") == "builtin:spot" else None
    rows = []
    for seed in range(args.seeds):
        photo = _photo(sheet, args.severity, seed, out)
        dec = decode_photo(photo)
        r = dec.report
        rows.append({"group": "e2e", "severity": args.severity, "seed": seed, "decode_ms": r["decode_ms"],
                     **{f"{k}_ms": v for k, v in r["timings_ms"].items()}, **_against_numpy(photo, dec.scene.codes)[0],
                     "restore_psnr": psnr(dec.views, ref[formats.ORBIT_SIZE]),
                     "e2e_psnr": psnr(dec.views, truth) if truth is not None else None,
                     "restore_psnr_expected": r["quality_estimate"]["restore_psnr_expected_db"]})
        photo.unlink(missing_ok=True)
        print(f"e2e {args.severity} seed {seed}: {rows[-1]['decode_ms']:.0f} ms, restore_psnr "
              f"{rows[-1]['restore_psnr']:.2f}", flush=True)
    photo = _photo(sheet, args.sweep_severity, 0, out)
    for name, value in [("default", None)] + SWEEP:
        cfg, size = RenderConfig(), formats.ORBIT_SIZE
        if name == "size":
            size = value
        elif value is not None:
            cfg = replace(cfg, **{name: value})
        if size not in ref:
            ref[size] = _reference(scene, size)
        times, dec = [], None
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            dec = decode_photo(photo, size=size, cfg=cfg)
            times.append((time.perf_counter() - t0) * 1e3)
        rows.append({"group": "sweep", "setting": name, "value": value, "decode_ms": float(np.median(times)),
                     "render_ms": dec.report["timings_ms"]["render"], "restore_psnr": psnr(dec.views, ref[size])})
    photo.unlink(missing_ok=True)
    calib_scenes = {Path(p).stem: load_scene_file(p) for p in args.calib_scenes.split(",") if Path(p).is_file()}
    calibrations = {}
    cal_dir = Path(args.calibration_dir) if args.calibration_dir else asset()
    for codec in (formats.PRINT_CODEC, formats.FILE_CODEC):
        cal_rows = _calibration_rows(calib_scenes, codec, args.calib_seeds, out)
        rows += cal_rows
        ok = [r for r in cal_rows if "restore_psnr" in r]
        fit = [r for r in ok if r["host"] in FIT_HOSTS]
        check = [r for r in ok if r["host"] in CHECK_HOSTS]
        if codec == formats.PRINT_CODEC and check:
            # no line: the views term is the estimate (`bench quality` scores it on held-out scenes and writes it)
            calibrations[codec] = identity_calibration(check, codec)
        elif len(fit) >= 3 and check:
            calibrations[codec] = fit_calibration(fit, check, codec)
            cal_dir.mkdir(parents=True, exist_ok=True)
            (cal_dir / calibration_file(codec)).write_text(json.dumps(calibrations[codec], indent=2) + "\n")
    e2e = [r for r in rows if r["group"] == "e2e"]
    sweep = [r for r in rows if r["group"] == "sweep"]
    front = _pareto([(r["decode_ms"], r["restore_psnr"]) for r in sweep])
    med = lambda k: float(np.median([r[k] for r in e2e])) if e2e and e2e[0].get(k) is not None else None  # noqa: E731
    summary = {"decode_ms_median": med("decode_ms"), "first_view_ms_median": med("first_view_ms"),
               "stage_ms_median": {k: med(f"{k}_ms") for k in ("scan", "restore", "bake", "render")},
               "restore_numpy_ms_median": med("restore_numpy_ms"),
               "print_graph_vs_numpy": _graph_agreement([r for r in rows if "graph_codes_differing" in r]),
               "restore_psnr_median": med("restore_psnr"), "e2e_psnr_median": med("e2e_psnr"),
               "quality_estimate": calibrations,
               "pareto": [f"{sweep[i]['setting']}={sweep[i]['value']}" for i in front], "default_on_front": 0 in front}
    doc = {"command": "snapshot3d " + " ".join(sys.argv[1:]), "cores": os.cpu_count(),
           "meta": run_metadata(), "scene": args.scene,
           "severity": args.severity, "sweep_severity": args.sweep_severity, "host": args.host,
           "targets": {"decode_ms_median": "<= 2000", "first_view_ms": "<= 500"}, "summary": summary}
    write_rows(out / "decode.csv", rows)
    (out / "decode.json").write_text(json.dumps(doc, indent=2) + "\n")
    _chart(sweep, front, [r for r in rows if r["group"] == "calib" and "restore_psnr" in r], calibrations,
           out / "decode.png", os.cpu_count())
    print(json.dumps(summary, indent=2))
    return 0


def _chart(sweep, front, calib, calibrations, path: Path, cores: int) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(19, 5.5))
    ax = axes[0]
    for i, r in enumerate(sweep):
        ax.plot(r["decode_ms"], r["restore_psnr"], "o", color="C3" if i == 0 else ("C0" if i in front else "grey"))
        ax.annotate("default" if i == 0 else f"{r['setting']}={r['value']}", (r["decode_ms"], r["restore_psnr"]),
                    fontsize=7)
    pts = sorted((sweep[i]["decode_ms"], sweep[i]["restore_psnr"]) for i in front)
    ax.plot([p[0] for p in pts], [p[1] for p in pts], "-", color="C0", alpha=0.5, label="Pareto front")
    ax.set(xlabel=f"decode_ms, photo to 20 views ({cores} cores)", ylabel="restore_psnr (dB)",
           title="decode time against restore fidelity (one capture)")
    ax.legend()
    for bx, codec in zip(axes[1:], (formats.PRINT_CODEC, formats.FILE_CODEC)):
        rows = [r for r in calib if r["codec"] == codec]
        for i, sev in enumerate(CALIB_SEVERITIES):
            for fit, mark in ((True, "o"), (False, "x")):
                pts = [r for r in rows if r["severity"] == sev and (r["host"] in FIT_HOSTS) == fit]
                if pts:
                    bx.plot([r["predictor"] for r in pts], [r["restore_psnr"] for r in pts], mark, color=f"C{i}",
                            label=f"{sev} ({'fit' if fit else 'held out'})")
        cal = calibrations.get(codec)
        if cal:
            xs = np.linspace(*cal["range"], 50)
            bx.plot(xs, cal["intercept"] + cal["slope"] * xs, "k-", alpha=0.6,
                    label=f"fit; held-out rmse {cal['held_out_rmse_db']:.2f} dB")
            bx.set_xlabel(cal["predictor"])
        bx.set(ylabel="restore_psnr (dB)", title=f"quality estimate, codec {codec} (no ground truth)")
        bx.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
