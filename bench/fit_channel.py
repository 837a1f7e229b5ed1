"""`snapshot3d bench fit-channel`: does fitting the last phase through the print channel's model
(`FitConfig.channel_fraction`, train/field/channel_fit.py) raise e2e_psnr through real simulated prints?

Paired design: one fit is run up to the start of its last phase (`steps * (1 - qat_fraction)`), then
branched (`CONDITIONS`): `plain` finishes with the 8-bit rounding only (today's fit), the others through
the channel model: with its per-coefficient gain and noise (`channel*`, the noise scaled) or its noise
alone (`noise-only*`). Each branch's scene is embedded (print medium) in each host, photographed with `simulate` at each
severity and seed, scanned and decoded as `decode` does (bench/codec_print.py's functions), and the
decoded planes are rendered at held-out ground-truth views the fit never saw (e2e_psnr). Rows share the
photo (host, severity, seed), so the difference per photo is paired.
Writes bench/results/fit_channel.{csv,json}."""
from __future__ import annotations

import copy
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from .common import median, write_report

CONDITIONS = {"plain": (0.0, 1.0, True), "channel": (None, 1.0, True), "channel-0.5": (None, 0.5, True),
              "channel-0.25": (None, 0.25, True), "noise-only": (None, 1.0, False), "noise-only-0.5": (None, 0.5, False)}
"""name -> (channel_fraction (None: the same as qat_fraction), channel_noise, with the measured gain (False:
unit gain, the noise alone))"""


def _prefix(posed, decoder, cfg, stop: int, cache: Path | None):
    """The fit's state after `stop` steps (shared by both branches); cached in `cache` when given."""
    import torch

    from snapshot3d.train.field.fit import new_state, train_step

    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    st = new_state(posed, cfg)
    if cache is not None and cache.is_file():
        ck = torch.load(cache, weights_only=False)
        st.planes.load_state_dict(ck["planes"]), st.occ.load_state_dict(ck["occ"]), st.opt.load_state_dict(ck["opt"])
        gen.set_state(ck["gen"])
        st.step, st.train_seconds, st.rays, st.samples = ck["step"], ck["seconds"], ck["rays"], ck["samples"]
    while st.step < stop:
        train_step(st, decoder, cfg, gen)
        if st.step % 100 == 0:
            print(f"prefix step {st.step}/{stop} {st.train_seconds:.0f} s", flush=True)
    if cache is not None and not cache.is_file():
        torch.save({"step": st.step, "planes": st.planes.state_dict(), "occ": st.occ.state_dict(),
                    "opt": st.opt.state_dict(), "gen": gen.get_state(), "seconds": st.train_seconds,
                    "rays": st.rays, "samples": st.samples}, cache)
    return st, gen


def _finish(st0, gen0, decoder, cfg, channel_fraction: float, channel_noise: float, gain: bool = True):
    """A copy of the prefix state run to the end of the fit with `channel_fraction` -> (codes, seconds)."""
    import torch

    from snapshot3d.scene import quantize_planes
    from snapshot3d.train.field.fit import new_state_channel, train_step

    st = copy.deepcopy(st0)
    gen = torch.Generator().manual_seed(0)
    gen.set_state(gen0.get_state())
    c = replace(cfg, channel_fraction=channel_fraction, channel_noise=channel_noise, channel_gain=gain)
    st.channel = new_state_channel(c)   # the prefix was run without one
    t0 = st.train_seconds
    while st.step < c.steps:
        train_step(st, decoder, c, gen)
    return quantize_planes(st.planes.planes.detach().numpy()), st.train_seconds - t0


def _photo_rows(scene_path: str, host: str, severities, seeds: int, views: int) -> list[dict]:
    """e2e_psnr (`views` held-out views) and restore_psnr of the scene file printed in `host` and photographed
    at each severity and seed (one worker process's share: a single torch thread)."""
    import torch

    from snapshot3d.codecs.media import MEDIA
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.qr import scene_meta
    from snapshot3d.scene import load_scene_file

    from .codec_print import E2E, _decode, _snapshot, capture
    from .common import ViewJudge, capture_seeds

    torch.set_num_threads(1)
    scene = load_scene_file(scene_path)
    e2e, judge = E2E(scene, views=views), ViewJudge(scene, 128)
    snap = _snapshot("print", load_host(host), scene)
    meta = scene_meta(scene, MEDIA["print"].codec, 1.0)
    rows = []
    for sev in severities:
        for seed in capture_seeds(sev, seeds):
            rect = capture(snap, meta, sev, seed)
            row = {"host": host, "severity": sev, "seed": seed, "detected": int(rect is not None)}
            if rect is not None:
                planes, _ = _decode("print", rect, scene, meta)
                row.update(e2e_psnr=round(e2e.psnr(planes), 3), restore_psnr=round(judge.planes_psnr(planes), 3))
            rows.append(row)
    return rows


def _paired(rows: list[dict], severity: str) -> dict:
    """Per condition at `severity`: median e2e_psnr and restore_psnr over the photos, and the difference
    of e2e_psnr to `plain` per photo (same host and seed): median, mean, standard deviation, wins."""
    by = {c: {(r["host"], r["seed"]): r for r in rows if r["condition"] == c and r["severity"] == severity
              and "e2e_psnr" in r} for c in CONDITIONS}
    out = {}
    for c in CONDITIONS:
        rs = list(by[c].values())
        out[c] = {"photos": len(rs), "e2e_psnr": median(rs, "e2e_psnr"), "restore_psnr": median(rs, "restore_psnr")}
        both = sorted(set(by["plain"]) & set(by[c]))
        if c != "plain" and len(both) > 1:
            diff = np.array([by[c][k]["e2e_psnr"] - by["plain"][k]["e2e_psnr"] for k in both])
            out[c].update(diff_median=round(float(np.median(diff)), 3), diff_mean=round(float(np.mean(diff)), 3),
                          diff_sd=round(float(np.std(diff, ddof=1)), 3), diff_wins=int((diff > 0).sum()))
    return out


def bench_fit_channel_command(args) -> int:
    import torch

    from snapshot3d.loaders import load_scene
    from snapshot3d.scene import Scene, dequantize_planes, save_scene
    from snapshot3d.train.field.commands import _default_orbit
    from snapshot3d.train.field.config import FitConfig
    from snapshot3d.train.field.decoder import load_decoder
    from snapshot3d.train.field.evaluate import evaluate_planes

    from .codec_print import E2E

    torch.set_num_threads(max(1, args.threads))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    builtin = args.scene.startswith("builtin:")
    posed = load_scene(args.scene, size=args.size) if builtin else load_scene(args.scene, downscale=args.downscale)
    decoder = load_decoder()   # frozen
    cfg = FitConfig(plane_res=args.plane_res, plane_channels=args.plane_channels, steps=args.steps, seed=args.seed)
    stop = int(np.ceil(cfg.steps * (1 - cfg.qat_fraction)))
    t0 = time.perf_counter()
    st0, gen0 = _prefix(posed, decoder, cfg, stop, Path(args.cache) if args.cache else None)
    prefix_seconds = time.perf_counter() - t0
    hosts = [h if ":" in h or "/" in h else f"builtin:{h}" for h in args.hosts.split(",")]
    severities = args.severities.split(",")
    rows, fits, paths = [], {}, {}
    for name, (frac, noise, gain) in CONDITIONS.items():
        frac = cfg.qat_fraction if frac is None else frac
        codes, seconds = _finish(st0, gen0, decoder, cfg, frac, noise, gain)
        ev = evaluate_planes(dequantize_planes(codes), decoder, posed)
        scene = Scene(codes=codes, box=posed.box, orbit=_default_orbit(posed), name=posed.name,
                      meta={"source": args.scene, **({"size": args.size} if builtin else {"downscale": args.downscale})})
        paths[name] = str(out / f"fit_channel-{posed.name}-{name}.s3d")
        save_scene(scene, paths[name])
        fits[name] = {"channel_fraction": frac, "channel_noise": noise, "gain": gain, "field_psnr": round(ev["field_psnr"], 3),
                      "field_psnr_views": round(E2E(scene, views=args.views).psnr(scene.planes()), 3),
                      "tail_seconds": round(seconds, 1)}
        print(name, fits[name], flush=True)
    t1 = time.perf_counter()
    tasks = [(c, h) for c in CONDITIONS for h in hosts]
    with ProcessPoolExecutor(max(1, args.threads), mp_context=get_context("spawn")) as pool:
        done = pool.map(_photo_rows, [paths[c] for c, _ in tasks], [h for _, h in tasks],
                        *zip(*[(severities, args.seeds, args.views)] * len(tasks)))
        for (c, _), part in zip(tasks, done):
            rows += [{"scene": posed.name, "condition": c, **r} for r in part]
    photo_seconds = time.perf_counter() - t1
    summary = {sev: _paired(rows, sev) for sev in severities}
    doc = write_report(out, "fit_channel", rows, {
        "scene": args.scene, "plane_res": cfg.plane_res, "plane_channels": cfg.plane_channels, "steps": cfg.steps,
        "seed": cfg.seed, "views": args.views, "threads": args.threads, "prefix_steps": stop,
        "prefix_seconds": round(prefix_seconds, 1), "photo_seconds": round(photo_seconds, 1), "fits": fits, "summary": summary})
    print(doc["summary"])
    return 0
