"""`snapshot3d bench capture-chain`: issue 40's "Done when" as a benchmark. One synthetic capture (make-capture,
the object on its ground before a photo backdrop, no masks) goes through the user's commands: `fit --budget auto
--medium print` (with the capture's own defaults: poses refined, the box found, the object alone), `embed`,
`sheet`, `simulate --severity S` (one photo per --photo-seeds) and `decode`. The scene as fitted and as decoded from
each photo are scored against the capture's truth (`object_score.score_object`: the object's PSNR in its true mask,
the opacity outside the mask + 2 px, the whole view against the object over white), per fit of --modes (those of
`bench capture-background`, whose fields go over the fit's defaults here, the poses as the defaults say).

The world is the capture's (--up 0,0,1, as `bench capture-background`), so that the truth needs no turn; `fit`'s
--up auto finds nearly that on these captures. Writes NAME.json and NAME.csv: one row per fit and photo; with
--figure, NAME_MODE_side_by_side.png per fit (`chain_figure`)."""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from snapshot3d.capture import CaptureOptions
from snapshot3d.make_capture import make_capture
from snapshot3d.make_capture_config import SynthCaptureConfig
from snapshot3d.train.field.config import FitConfig

from .capture_background import MODES, int_list
from .common import median, run_metadata, write_rows

__all__ = ["bench_capture_chain_command", "capture_truth", "chain_figure", "chain_scores"]

SCORED = ("object_psnr", "object_clean_psnr", "opacity_outside_2px", "opacity_outside", "white_psnr",
          "object_ring_psnr")


def _cli(*argv: str) -> None:
    """Run `snapshot3d ARGV` as a user would; a failed step stops the bench with its own one-line error."""
    proc = subprocess.run([sys.executable, "-m", "snapshot3d", *argv], capture_output=True, text=True)
    if proc.returncode != 0:
        from snapshot3d.errors import UserError
        said = (proc.stderr or proc.stdout).strip().splitlines()
        raise UserError(f"snapshot3d {argv[0]} failed: {said[-1] if said else f'exit status {proc.returncode}'}")


def capture_truth(cap: Path) -> tuple:
    """Capture folder `cap` (make-capture's) -> (its masked photos at the true poses, the object alone over white
    at them, the true box (2, 3)), in the capture's world (z up)."""
    from snapshot3d.loaders import load_scene

    up = CaptureOptions(up=(0.0, 0.0, 1.0))
    return (load_scene(str(cap / "gt/transforms_true.json"), capture=up),
            load_scene(str(cap / "gt/transforms_white.json"), capture=up),
            json.loads((cap / "gt/truth.json").read_text())["box"])


def chain_scores(scene, truth: tuple) -> dict:
    """Scene (a fitted or decoded snapshot3d Scene, its own decoder head if it has one) -> `score_object`'s
    measures against the capture's `capture_truth`, rounded."""
    import torch

    from snapshot3d.train.field.decoder import scene_decoder
    from snapshot3d.train.field.object_score import score_object

    photos, clean, true_box = truth
    score = score_object(torch.from_numpy(scene.planes()), scene_decoder(scene), scene.box, photos, true_box,
                         clean=clean)
    return {k: round(float(v), 4) for k, v in score.items()}


def chain_figure(path: Path, cap: Path, truth: tuple, scenes: list, views: int = 2) -> None:
    """PNG of `views` held-out frames, one per row: the capture's photo as read, the object alone over white (the
    truth), then each of `scenes` (the fitted scene, then those decoded from each photo), rendered over white at the
    frame's true pose with its own decoder head. Tiles (H, W, 3) RGB, the capture's size."""
    import torch

    from snapshot3d.images import contact_sheet, write_png
    from snapshot3d.loaders import load_scene
    from snapshot3d.train.field.decoder import scene_decoder
    from snapshot3d.train.field.render import render_views

    photos, clean, _ = truth
    read = load_scene(str(cap / "transforms.json"), capture=CaptureOptions(up=(0.0, 0.0, 1.0)))
    idx = photos.test[:views]
    renders = [render_views(torch.from_numpy(s.planes()), scene_decoder(s), s.box, photos.c2w[idx],
                            photos.intrinsics[idx], photos.width, photos.height) for s in scenes]
    tiles = [t for k, i in enumerate(idx) for t in (read.images[i], clean.images[i], *(r[k] for r in renders))]
    write_png(path, contact_sheet(np.stack(tiles), cols=2 + len(scenes)))


def _one_fit(cap: Path, mode: str, cfg: FitConfig, work: Path, severity: str, photo_seeds: list[int],
             truth: tuple, figure: Path | None = None) -> list[dict]:
    from snapshot3d.scene import save_scene
    from snapshot3d.train.field.commands import fit_scene
    from snapshot3d.viewer.decode import decode_scene

    name, background, box, fields = MODES[mode]
    t0 = time.perf_counter()
    fitted = fit_scene(str(cap / name), replace(cfg, background=background, **fields), "auto", quiet=True,
                       medium="print", capture=CaptureOptions(up=(0.0, 0.0, 1.0), box=box))
    seconds = time.perf_counter() - t0
    s3d = work / f"{mode}.s3d"
    save_scene(fitted.scene, s3d)
    _cli("embed", str(s3d), "-o", str(work / f"{mode}.png"))
    _cli("sheet", str(work / f"{mode}.png"), "-o", str(work / f"{mode}_sheet.png"))
    scene = fitted.scene
    base = {"mode": mode, "fit_seed": cfg.seed, "planes": f"{scene.resolution}x{scene.channels}",
            "head": bool(scene.head), "fit_seconds": round(seconds, 1), "ladder": fitted.report.get("ladder")}
    rows = [{**base, "stage": "fitted", "photo_seed": None, **chain_scores(scene, truth)}]
    scenes = [scene]
    for seed in photo_seeds:
        photo = work / f"{mode}_photo{seed}.jpg"
        _cli("simulate", str(work / f"{mode}_sheet.png"), "--severity", severity, "--seed", str(seed), "-o",
             str(photo))
        decoded = decode_scene(str(photo)).scene
        rows.append({**base, "stage": f"decoded_{severity}", "photo_seed": seed,
                     **chain_scores(decoded, truth)})
        scenes.append(decoded)
    if figure is not None:
        chain_figure(figure, cap, truth, scenes)
    return rows


def _summary(rows: list[dict]) -> dict:
    """Per mode and stage: the medians over the photos of SCORED (a fitted stage has one row)."""
    out: dict = {}
    for r in rows:
        out.setdefault(r["mode"], {}).setdefault(r["stage"], []).append(r)
    return {m: {s: {k: median(rs, k) for k in SCORED} for s, rs in stages.items()} for m, stages in out.items()}


def bench_capture_chain_command(args) -> int:
    from snapshot3d.errors import UserError

    modes = args.modes.split(",")
    for mode in modes:
        if mode not in MODES or MODES[mode][0] != "transforms.json":
            raise UserError(f"--modes: unknown fit {mode!r} (choose from the photos' fits of bench "
                            f"capture-background: {', '.join(m for m, v in MODES.items() if v[0] == 'transforms.json')})")
    photo_seeds = int_list(args.photo_seeds, "--photo-seeds")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = FitConfig(steps=args.steps, seed=args.fit_seed)
    capcfg = SynthCaptureConfig(size=args.size, views=args.views, seed=args.seed)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cap = make_capture(f"builtin:{args.mesh}", Path(tmp) / "cap", capcfg)
        truth = capture_truth(cap)
        for mode in modes:
            figure = out / f"{args.name}_{mode}_side_by_side.png" if args.figure else None
            for row in _one_fit(cap, mode, cfg, Path(tmp), args.severity, photo_seeds, truth, figure):
                print(json.dumps({"mesh": args.mesh, **row}), flush=True)
                rows.append({"mesh": args.mesh, **row})
    report = {"meta": run_metadata(), "fit": asdict(cfg), "capture": {**asdict(capcfg), "lens": list(capcfg.lens)},
              "severity": args.severity, "summary": _summary(rows), "rows": rows}
    (out / f"{args.name}.json").write_text(json.dumps(report, indent=1))
    write_rows(out / f"{args.name}.csv", [{k: v for k, v in r.items() if k != "ladder"} for r in rows])
    print(f"wrote {out / args.name}.json and .csv ({len(rows)} rows)")
    return 0
