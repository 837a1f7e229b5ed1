"""`snapshot3d bench capture-background`: the object, not the room (issue 40 item 2). Synthetic captures
(`make-capture builtin:NAME`) fitted three ways: without masks on white (the box from the cameras, as before),
without masks with the background model (fit --background outer, the box found automatically), and with the
true masks. Each fit is scored on the held-out frames against the capture's ground truth
(`train/field/object_score.py`): the object's PSNR inside its true mask, the share of the planes' opacity outside
the mask, and the share of their density outside the true box; each capture's `ceilings`: what the object alone,
rendered perfectly, scores by those measures (its photos' outline blends in the room). Writes
capture_background.{json,csv}."""
from __future__ import annotations

import json
import tempfile
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from snapshot3d.capture import CaptureOptions
from snapshot3d.make_capture import make_capture
from snapshot3d.make_capture_config import SynthCaptureConfig
from snapshot3d.train.field.config import FitConfig

from .common import run_metadata, write_rows
from .pose_error import pose_error

__all__ = ["MODES", "fit_and_score", "int_list", "bench_capture_background_command", "bench_fit_command"]

# the background model's regularisers, all off: --background outer as first landed
PLAIN = {"distortion_weight": 0.0, "opacity_weight": 0.0, "opacity_entropy": False, "wall_weight": 0.0,
         "floor_weight": 0.0, "tighten_sides": False, "ground_texture": 0}
_SIDES_WALLS = {**PLAIN, "tighten_sides": True, "wall_weight": 0.3}
# mode: (file read, background, box, FitConfig fields over the bench's; poses as given unless the mode says
# otherwise, so that the modes compare like with like); `outer` is --background outer with its
# defaults, `outer-capture` what `fit` does with a capture by default (--refine-poses auto, --bundle auto), the
# other outer-* modes are the candidates against floaters and pose noise (docs/capture.md), kept as rows
MODES = {"white": ("transforms.json", "white", None, {}),
         "outer": ("transforms.json", "outer", "auto", {}),
         "outer-uncut": ("transforms.json", "outer", "auto", {"object_steps": 0.0}),
         "outer-nosilhouette": ("transforms.json", "outer", "auto", {"object_silhouette": 1.0}),
         "outer-silhouette-0.3": ("transforms.json", "outer", "auto", {"object_silhouette": 0.3}),
         # the floor band's vote looser (0.2 by default): spot's dark hooves over their shadow come back with it
         # (docs/capture-record.md, "The hooves cut by the silhouettes' vote")
         "outer-silhouette-0.5": ("transforms.json", "outer", "auto", {"object_silhouette": 0.5}),
         "outer-nobasekeep": ("transforms.json", "outer", "auto", {"object_base_keep": 0.0}),
         "outer-sweep": ("transforms.json", "outer", "auto", {"ground_sweep": True}),
         "outer-floor": ("transforms.json", "outer", "auto", {"floor_weight": 1.0}),
         # the object fit's last 15% / 30% of steps through the print channel model's noise (--object-channel)
         "outer-objchannel": ("transforms.json", "outer", "auto", {"object_channel": 0.15, "refit": "model"}),
         "outer-objchannel-0.3": ("transforms.json", "outer", "auto", {"object_channel": 0.3, "refit": "model"}),
         # the chosen rung of a print's ladder kept as fitted again from scratch (--refit always; auto since
         # 2026-12-08), or only where the print channel's model expects it no worse (--refit model, auto before)
         "outer-refit": ("transforms.json", "outer", "auto", {"refit": "always", "object_channel": 0.0}),
         "outer-refit-model": ("transforms.json", "outer", "auto", {"refit": "model", "object_channel": 0.0}),
         "outer-objchannel-refit": ("transforms.json", "outer", "auto", {"object_channel": 0.15, "refit": "always"}),
         "outer-noground": ("transforms.json", "outer", "auto", {"ground_texture": 0}),
         "outer-ground256": ("transforms.json", "outer", "auto", {"ground_texture": 256}),
         "outer-bg96": ("transforms.json", "outer", "auto", {"background_res": 96}),
         "outer-density": ("transforms.json", "outer", "auto", {"sparse_box": False}),
         "outer-nobox": ("transforms.json", "outer", "auto", {"object_box": 0.0}),
         "outer-plain": ("transforms.json", "outer", "auto", PLAIN),
         "outer-distortion": ("transforms.json", "outer", "auto", {**PLAIN, "distortion_weight": 0.001}),
         "outer-entropy": ("transforms.json", "outer", "auto",
                           {**PLAIN, "opacity_weight": 0.01, "opacity_entropy": True}),
         "outer-opacity": ("transforms.json", "outer", "auto", {**PLAIN, "opacity_weight": 0.1}),
         "outer-walls": ("transforms.json", "outer", "auto", {**PLAIN, "wall_weight": 1.0}),
         "outer-sides": ("transforms.json", "outer", "auto", {**PLAIN, "tighten_sides": True}),
         "outer-sides-walls": ("transforms.json", "outer", "auto", _SIDES_WALLS),
         "outer-sides-walls-floor": ("transforms.json", "outer", "auto", {**_SIDES_WALLS, "floor_weight": 1.0}),
         "outer-ground": ("transforms.json", "outer", "auto", {"ground_texture": 128, "ground_depth": 0.0}),
         "outer-ground-low": ("transforms.json", "outer", "auto", {"ground_texture": 128, "ground_depth": 0.05}),
         # the rays that show the ground, weighted (auto: 0.3 where the cameras span under 300 deg, else 0; docs/capture.md)
         "outer-noseen": ("transforms.json", "outer", "auto", {"seen_ground_weight": 0.0}),
         "outer-seen": ("transforms.json", "outer", "auto", {"seen_ground_weight": 0.1}),
         "outer-seen-03": ("transforms.json", "outer", "auto", {"seen_ground_weight": 0.3}),
         "outer-seen-1": ("transforms.json", "outer", "auto", {"seen_ground_weight": 1.0}),
         # the same rays sparing the samples in the object's cells (--seen-ground-spare; its rows say so)
         "outer-spare": ("transforms.json", "outer", "auto", {"seen_ground_spare": True}),
         # the batches drawn from the rays that cross the object's cells, as from masks (--object-rays)
         "outer-rays": ("transforms.json", "outer", "auto", {"object_rays": True}),
         # the ground's texture twice as wide (and as fine), the rays past the box's sides ending on it
         "outer-reach2": ("transforms.json", "outer", "auto", {"ground_reach": 2.0, "ground_texture": 256}),
         # the cells that growing the object's cells adds cut where the photos' silhouettes, not grown, do not hold
         # them (--object-halo)
         "outer-halo": ("transforms.json", "outer", "auto", {"object_halo": 0.2}),
         # the views the object alone is fitted to made solid over a width about one half (--object-opaque, 0.02 by
         # default since 2026-12-07; 1: as rendered, the default before); named by the opacity that goes to 0
         # (1/2 - width/2: 0.49 is width 0.02, the default's setting)
         "outer-soft": ("transforms.json", "outer", "auto", {"object_opaque": 1.0}),
         "outer-opaque": ("transforms.json", "outer", "auto", {"object_opaque": 0.5}),
         "outer-opaque-0.4": ("transforms.json", "outer", "auto", {"object_opaque": 0.2}),
         "outer-opaque-0.49": ("transforms.json", "outer", "auto", {"object_opaque": 0.02}),
         # the same made solid on a grid 4 times finer and averaged back: an anti-aliased outline (--object-subpixel)
         "outer-subpixel-4": ("transforms.json", "outer", "auto", {"object_subpixel": 4}),
         # the step on the pixels at every plane size (auto gives the grid 4 times finer at 32 texels a side or
         # fewer: a print's small rungs)
         "outer-step": ("transforms.json", "outer", "auto", {"object_subpixel": 1}),
         "masked": ("gt/transforms_masked.json", "white", None, {}),
         "masked-refine": ("gt/transforms_masked.json", "white", None, {"refine_poses": "on"}),
         "outer-refine": ("transforms.json", "outer", "auto", {"refine_poses": "on"}),
         "outer-density-refine": ("transforms.json", "outer", "auto", {"refine_poses": "on", "sparse_box": False}),
         "outer-nobox-refine": ("transforms.json", "outer", "auto", {"refine_poses": "on", "object_box": 0.0}),
         "outer-nobundle-refine": ("transforms.json", "outer", "auto", {"refine_poses": "on", "bundle": "off"}),
         "outer-bundle-fit-refine": ("transforms.json", "outer", "auto", {"refine_poses": "on", "bundle": "fit"}),
         "outer-bundle-fit-refine-lr3": ("transforms.json", "outer", "auto", {"refine_poses": "on", "bundle": "fit",
                                                                              "pose_lr": 0.003}),
         "outer-bundle-box-refine": ("transforms.json", "outer", "auto", {"refine_poses": "on", "bundle": "box"}),
         "outer-bundle-fit": ("transforms.json", "outer", "auto", {"bundle": "fit"}),   # outer-capture before 12-06
         "outer-capture": ("transforms.json", "outer", "auto", {"refine_poses": "auto"}),
         # the adjusted poses refined on by the planes from half the steps (docs/capture.md, the late start); by
         # name, since 2026-12-06 what outer-capture does too
         "outer-capture-late": ("transforms.json", "outer", "auto", {"refine_poses": "on", "bundle": "fit",
                                                                     "pose_start": 0.5}),
         "outer-capture-nobasekeep": ("transforms.json", "outer", "auto", {"refine_poses": "auto",
                                                                            "object_base_keep": 0.0}),
         "outer-capture-noground": ("transforms.json", "outer", "auto", {"refine_poses": "auto",
                                                                         "ground_texture": 0})}
# `bench fit --captures` (issue 40 item 4): this bench with these settings
CAPTURE_DEFAULTS = {"meshes": "spot,duck", "modes": "white,outer,masked", "size": 128, "views": 48, "steps": 150,
                    "occ_warmup": 32, "plane_res": 64, "plane_channels": 8, "seed": 0}
CAPTURE_QUICK = {"size": 48, "views": 8, "steps": 20}


def fit_and_score(cap: Path, mode: str, cfg: FitConfig, figure: Path | None = None) -> dict:
    """Fit capture folder `cap` (written by make-capture) the way `mode` says, in the world of its truth.json
    (--up 0,0,1), and score it against the true masks and box; pose_px_written and pose_px_fit: how far the
    training poses as written and as the fit ended with them lie from the truth (bench/pose_error.py, the median
    frame's px); with `figure`, also write `_side_by_side` there."""
    import torch

    from snapshot3d.loaders import load_scene
    from snapshot3d.train.field.commands import fit_scene
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.object_score import score_object

    name, background, box, fields = MODES[mode]
    t0 = time.perf_counter()
    fitted = fit_scene(str(cap / name), replace(cfg, background=background, **{"refine_poses": "off", **fields}),
                       quiet=True, capture=CaptureOptions(up=(0.0, 0.0, 1.0), box=box))
    scene, report, renders = fitted.scene, fitted.report, fitted.renders
    seconds = time.perf_counter() - t0
    true_poses = cap / "gt/transforms_true.json"   # absent in captures written before it was
    truth = load_scene(str(true_poses if true_poses.is_file() else cap / "gt/transforms_masked.json"),
                       capture=CaptureOptions(up=(0.0, 0.0, 1.0)))
    true_box = json.loads((cap / "gt/truth.json").read_text())["box"]
    decoder = load_decoder(cfg.decoder)
    white = cap / "gt/transforms_white.json"   # the object alone over white (captures since 2026-12-07)
    clean = load_scene(str(white), capture=CaptureOptions(up=(0.0, 0.0, 1.0))) if white.is_file() else None
    score = score_object(torch.from_numpy(scene.planes()), decoder, scene.box, truth, true_box, clean=clean)
    written = load_scene(str(cap / name), capture=CaptureOptions(up=(0.0, 0.0, 1.0)))
    at = {"written": written.c2w[written.train], "fit": fitted.train_c2w}
    true_c2w, intrinsics = truth.c2w[truth.train], truth.intrinsics[truth.train]
    poses = {f"pose_px_{k}": pose_error(c2w, true_c2w, intrinsics, true_box)["px_median"] for k, c2w in at.items()}
    if figure is not None and renders is not None:   # the photos as read (the capture's own file, not the masked)
        photos = written if name == "transforms.json" else \
            load_scene(str(cap / "transforms.json"), capture=CaptureOptions(up=(0.0, 0.0, 1.0)))
        _side_by_side(figure, scene, truth, photos.images, renders, decoder)
    return {"mode": mode, **{k: round(v, 4) for k, v in score.items()}, "field_psnr": report["field_psnr"], **poses,
            "fit_seconds": round(seconds, 1), "box": np.round(scene.box, 3).tolist(),
            "box_from": report.get("capture", {}).get("box_from"), **report.get("background", {}),
            **({"pose_refinement": report["pose_refinement"]} if "pose_refinement" in report else {})}


def _ceiling(cap: Path) -> dict:
    """The capture's `clean_ceiling`: the object alone over white scored as a render against its masked photos
    (held-out frames, true poses) -> object_psnr, object_ring_psnr, object_inner_psnr."""
    from snapshot3d.loaders import load_scene
    from snapshot3d.train.field.object_score import clean_ceiling

    up = CaptureOptions(up=(0.0, 0.0, 1.0))
    return clean_ceiling(load_scene(str(cap / "gt/transforms_true.json"), capture=up),
                         load_scene(str(cap / "gt/transforms_white.json"), capture=up))


def _side_by_side(path: Path, scene, truth, photos: np.ndarray, renders: np.ndarray, decoder, views: int = 3) -> None:
    """PNG of `views` held-out frames, one per row: the input photo (`photos` (N, H, W, 3) RGB, the capture as
    read), the fit with its background model behind the planes (`renders`, (V, H, W, 3) RGB of the held-out
    frames, from fit_scene), and the object alone over white (what the snapshot carries) at the frames' true
    poses."""
    import torch

    from snapshot3d.images import contact_sheet, write_png
    from snapshot3d.train.field.render import render_views

    idx = truth.test[:views]
    alone = render_views(torch.from_numpy(scene.planes()), decoder, scene.box, truth.c2w[idx], truth.intrinsics[idx],
                         truth.width, truth.height)
    tiles = np.stack([t for k, i in enumerate(idx) for t in (photos[i], renders[k], alone[k])])
    write_png(path, contact_sheet(tiles, cols=3))


def _fit_seeds(text: str | None, seed: int) -> list[int]:
    """--fit-seeds "0,1,2" -> [0, 1, 2]; None or "" -> [seed] (the capture's own); a one-line error otherwise."""
    return int_list(text, "--fit-seeds") if text else [seed]


def int_list(text: str, option: str) -> list[int]:
    """An option's "0,1,2" -> [0, 1, 2]; a one-line UserError naming `option` otherwise."""
    try:
        return [int(v) for v in text.split(",")]
    except ValueError:
        from snapshot3d.errors import UserError
        raise UserError(f"{option} must be comma-separated integers, not {text!r}") from None


def bench_fit_command(args) -> int:
    """`snapshot3d bench fit`: with --captures, this bench at CAPTURE_DEFAULTS (CAPTURE_QUICK with --quick);
    else `bench/fit.py`'s."""
    if getattr(args, "representations", False):
        from .representations import bench_representations_command
        return bench_representations_command(args)
    if not getattr(args, "captures", False):
        from .fit import bench_fit_command as fit_command
        return fit_command(args)
    for k, v in {**CAPTURE_DEFAULTS, **(CAPTURE_QUICK if args.quick else {})}.items():
        setattr(args, k, v)
    return bench_capture_background_command(args)


def bench_capture_background_command(args) -> int:
    for mode in args.modes.split(","):
        if mode not in MODES:
            from snapshot3d.errors import UserError
            raise UserError(f"--modes: unknown fit {mode!r} (choose from {', '.join(MODES)})")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = FitConfig(steps=args.steps, plane_res=args.plane_res, plane_channels=args.plane_channels, seed=args.seed,
                    occ_warmup=args.occ_warmup)
    capcfg = SynthCaptureConfig(size=args.size, views=args.views, seed=args.seed,
                                pose_noise_deg=getattr(args, "pose_noise_deg", 0.0),
                                pose_noise_frac=getattr(args, "pose_noise_frac", 0.0),
                                arc_deg=getattr(args, "arc_deg", 720.0))
    rows, ceilings, name = [], {}, getattr(args, "name", None) or "capture_background"
    fit_seeds = _fit_seeds(getattr(args, "fit_seeds", None), args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        for mesh in args.meshes.split(","):
            cap = make_capture(f"builtin:{mesh}", Path(tmp) / mesh, capcfg)
            ceilings[mesh] = {k: round(v, 4) for k, v in _ceiling(cap).items()}
            for mode in args.modes.split(","):
                for fit_seed in fit_seeds:   # the same capture fitted again: the fits' own spread
                    fig = out / f"{name}_side_by_side_{mesh}.png" if getattr(args, "figure", False) and \
                        mode.startswith("outer") and fit_seed == fit_seeds[0] else None
                    row = {"mesh": mesh, **fit_and_score(cap, mode, replace(cfg, seed=fit_seed), fig),
                           "fit_seed": fit_seed}
                    print(json.dumps(row), flush=True)
                    rows.append(row)
    report = {"meta": run_metadata(), "fit": asdict(cfg), "capture": {**asdict(capcfg), "lens": list(capcfg.lens)},
              "ceilings": ceilings, "rows": rows}
    (out / f"{name}.json").write_text(json.dumps(report, indent=1))
    write_rows(out / f"{name}.csv", rows)
    print(f"wrote {out / name}.json and .csv ({len(rows)} fits)")
    return 0
