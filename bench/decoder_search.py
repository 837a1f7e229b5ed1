"""`snapshot3d bench decoder-search`: score candidate shared decoders by what they fit. Each decoder (a
weights file written by `snapshot3d train decoder -o FILE`, or a shipped version's name) fits spot and lego at
each plane size (`--sizes`, 1500 steps, the bench fit's scenes), and the fit is scored at held-out views
(`field_psnr`), and again with Gaussian noise of std `--noise` added to its planes (`field_psnr_noise`: how
much the decoder magnifies a plane error, what a print adds), and at the print ladder's sizes through the print
channel's model (`e2e_print_model`, what `fit --budget auto --medium print` predicts with). One JSON line per fit is appended to `--out-file`
(default bench/results/decoder_search.jsonl), which `bench decoders --search` charts. Made for a lent GPU
(`--device cuda`); on 2 CPU cores a fit takes minutes."""
from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

__all__ = ["bench_decoder_search_command"]


def _decoder(spec: str, device):
    """A shipped version's name (`tri-dec-1`) or a weights file -> (name, frozen Decoder on `device`)."""
    from snapshot3d import formats
    from snapshot3d.train.field.decoder import frozen, read_decoder

    dec = frozen(read_decoder(spec))
    if spec not in formats.DECODERS:
        spec = Path(spec).stem.removeprefix("decoder-")
    return spec, dec.to(device)


def _print_score(planes: np.ndarray, dec, posed, res: int, channels: int) -> dict:
    """{"e2e_print_model": dB}: the held-out views of planes (3, C, R, R) through the print channel's model
    (`budget.predicted_e2e`, the `moderate` medians of budget-curves.json, hosts coffee and chelsea), at the
    print ladder's plane sizes; {} at others or without a model."""
    from snapshot3d.train.field.budget import predicted_e2e
    from snapshot3d.train.field.config import LADDER_PRINT
    from snapshot3d.train.field.curves import print_channel

    channel = print_channel()
    if channel is None or (res, channels) not in LADDER_PRINT:
        return {}
    return {"e2e_print_model": round(predicted_e2e(planes, dec, posed, channel), 3)}


def bench_decoder_search_command(args) -> int:
    from snapshot3d.scene import dequantize_planes
    from snapshot3d.train.device import resolve_device
    from snapshot3d.train.field.evaluate import evaluate_planes
    from snapshot3d.train.field.fit import fit, hull_grid

    from .common import run_metadata
    from .scenes import load_bench_scene

    device = resolve_device(args.device)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",") if s]
    decoders = [_decoder(s, device) for s in args.decoders.split(",") if s]
    scenes = {s: load_bench_scene(s) for s in ("spot", "lego")}
    hulls = {s: hull_grid(posed) for s, (posed, _) in scenes.items()}
    out = Path(args.out_file)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = run_metadata()
    for name, dec in decoders:
        for r, c in sizes:
            for scene, (posed, base) in scenes.items():
                cfg = replace(base, plane_res=r, plane_channels=c, steps=args.steps)
                t0 = time.perf_counter()
                res = fit(posed, dec, cfg, hull=hulls[scene], device=device)
                planes = dequantize_planes(res.codes)
                noise = np.random.default_rng(0).standard_normal(planes.shape)   # the same draw for every fit
                noisy = planes + (args.noise * noise).astype(np.float32)
                row = {"decoder": name, "scene": scene, "plane_res": r, "plane_channels": c, "steps": cfg.steps,
                       "field_psnr": round(evaluate_planes(planes, dec, posed)["field_psnr"], 3),
                       "field_psnr_noise": round(evaluate_planes(noisy, dec, posed)["field_psnr"], 3),
                       "noise_std": args.noise, "fit_seconds": round(time.perf_counter() - t0, 1),
                       **_print_score(planes, dec, posed, r, c),
                       "hidden": dec.hidden, "layers": dec.layers, "device": str(device),
                       "command": "snapshot3d bench decoder-search " + " ".join(
                           f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items()
                           if k in ("decoders", "sizes", "steps", "noise", "device")),
                       "commit": meta["commit"], "date": meta["date"]}
                with out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
                print(row, flush=True)
    print(f"appended {len(decoders) * len(sizes) * len(scenes)} rows to {out}")
    return 0
