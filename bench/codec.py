"""`snapshot3d bench codec` (the `file` medium's codec): host fidelity against restore fidelity, through
the real channel. Writes codec.csv, codec.json (medians next to the targets, the command, the core count),
codec.png and codec_side_by_side.png.

Every snapshot goes the user's way: sheet -> `simulate` (severity, seed) -> `scan` -> restore -> the 20
orbit views, compared with the views of the original planes (`restore_psnr`). Rows (codec.csv):
- `ours` and `digital` (the same network and budget trained without the channel, baseline a) at
  every severity, for each evaluation scene, host and seed; `ours-refined`: ours with the snapshot
  refined at embed time (`snapshot3d embed`'s default, `train.codec.refine`);
- `strength`: ours at several embedding strengths (the host-vs-restore trade-off);
- `lsb` (baseline b): 8-bit plane codes in the two least-significant bits of the host;
- `views-N` (baseline c): N fixed rendered orbit views carried instead of planes (the Video Snapshot /
  IICNet idea), scored on the views they carry and on the orbit views they cannot produce;
- `arch`: restore time of the reverse pass at 380x380 for several depths and widths.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import cv2
import numpy as np
import torch

from snapshot3d import formats
from snapshot3d.codecs import file_layout
from snapshot3d.errors import UserError
from snapshot3d.images import write_png
from snapshot3d.metrics import ssim
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import dequantize_planes, load_scene_file, quantize_planes
from snapshot3d.train.codec.config import CodecConfig
from snapshot3d.train.codec.hinet import (
    build_codec,
    embed_planes,
    load_codec,
    restore_secret,
)
from snapshot3d.train.codec.refine import snapshot_of

from .common import (
    SEVERITIES,
    ViewJudge,
    capture_seeds,
    median,
    psnr,
    pyplot,
    run_metadata,
    through_channel,
    write_rows,
)

__all__ = ["bench_codec_command", "summarise", "lsb_embed", "lsb_extract", "FIELDS", "TARGETS", "BREAK_DB",
           "break_severity"]

FIELDS = ["method", "scene", "host", "severity", "seed", "strength", "host_psnr", "host_ssim", "restore_psnr",
          "detected", "views", "carried_psnr", "uncarried_psnr", "blocks", "width", "params", "restore_ms"]


def lsb_embed(host8: np.ndarray, codes: np.ndarray, bits: int = 2) -> np.ndarray:
    """Plane codes (uint8, any shape) into the `bits` least-significant bits of host8 (uint8 RGB)."""
    stream = np.unpackbits(codes.ravel()).reshape(-1, bits)
    vals = (stream * (1 << np.arange(bits - 1, -1, -1))).sum(1).astype(np.uint8)
    flat = host8.ravel().copy()
    if len(vals) > flat.size:
        raise ValueError("planes do not fit the host's low bits")
    flat[:len(vals)] = (flat[:len(vals)] & (0xFF ^ ((1 << bits) - 1))) | vals
    return flat.reshape(host8.shape)


def lsb_extract(img8: np.ndarray, shape: tuple, bits: int = 2) -> np.ndarray:
    n = int(np.prod(shape)) * 8 // bits
    vals = img8.ravel()[:n] & ((1 << bits) - 1)
    stream = ((vals[:, None] >> np.arange(bits - 1, -1, -1)) & 1).astype(np.uint8)
    return np.packbits(stream.ravel()).reshape(shape)


def _codec_rows(method, net, judge, scene_name, host_name, host, severities, seeds, strength, refine=0):
    """Rows of one embedding (`refine` > 0: the snapshot refined that many steps, as `embed --refine`)."""
    scene = judge.scene
    snap = snapshot_of(net, host, scene.planes(), refine, strength)
    host8 = (host * 255 + 0.5).astype(np.uint8)
    base = {"method": method, "scene": scene_name, "host": host_name, "strength": strength,
            "host_psnr": psnr(snap / 255, host8 / 255), "host_ssim": ssim(snap / 255, host8 / 255)}
    rows = []
    for sev in severities:
        for seed in capture_seeds(sev, seeds):
            rect = through_channel(snap, scene_meta(scene, formats.FILE_CODEC, strength), sev, seed)
            row = dict(base, severity=sev, seed=seed, detected=int(rect is not None))
            if rect is not None:
                row["restore_psnr"] = judge.restore_psnr(restore_secret(net, rect, strength))
            rows.append(row)
    return rows, snap


def _lsb_rows(judge, scene_name, host_name, host, severities):
    host8 = (host * 255 + 0.5).astype(np.uint8)
    codes = judge.scene.codes
    snap = lsb_embed(host8, codes)
    base = {"method": "lsb", "scene": scene_name, "host": host_name, "host_psnr": psnr(snap / 255, host8 / 255),
            "host_ssim": ssim(snap / 255, host8 / 255)}
    rows = []
    for sev in severities:
        rect = through_channel(snap, scene_meta(judge.scene, formats.FILE_CODEC, 1.0), sev, 0)
        row = dict(base, severity=sev, seed=0, detected=int(rect is not None))
        if rect is not None:
            planes = dequantize_planes(lsb_extract(rect, codes.shape))
            row["restore_psnr"] = psnr(judge.views(planes), judge.ref)
        rows.append(row)
    return rows


def _views_rows(net, judge, scene_name, host_name, host, severities, counts=(3, 5, 8)):
    """Baseline c: N orbit views (64x64, one secret channel slot per colour channel) instead of planes."""
    rows = []
    side = formats.CODEC_MAX_RES
    small = np.stack([cv2.resize(v, (side, side), interpolation=cv2.INTER_AREA) for v in judge.ref])
    for n in counts:
        idx = np.round(np.linspace(0, formats.ORBIT_VIEWS, n, endpoint=False)).astype(int)
        pseudo = np.zeros((3, formats.CODEC_CHANNELS, side, side), np.float32)
        pseudo.reshape(-1, side, side)[:3 * n] = small[idx].transpose(0, 3, 1, 2).reshape(-1, side, side) * 2 - 1
        snap = embed_planes(net, host, pseudo)
        host8 = (host * 255 + 0.5).astype(np.uint8)
        for sev in severities:
            rect = through_channel(snap, scene_meta(judge.scene, formats.FILE_CODEC, 1.0), sev, 0)
            row = {"method": f"views-{n}", "scene": scene_name, "host": host_name, "severity": sev, "seed": 0,
                   "views": n, "host_psnr": psnr(snap / 255, host8 / 255), "detected": int(rect is not None)}
            if rect is not None:
                got = file_layout.secret_to_planes(restore_secret(net, rect), side, formats.CODEC_CHANNELS)
                carried = (got.reshape(-1, side, side)[:3 * n].reshape(n, 3, side, side).transpose(0, 2, 3, 1) + 1) / 2
                row["carried_psnr"] = psnr(np.clip(carried, 0, 1), small[idx])
                # every other orbit view can only be shown as the nearest carried one
                nearest = [int(np.argmin(np.abs(((idx - i + 10) % 20) - 10))) for i in range(formats.ORBIT_VIEWS)]
                others = [i for i in range(formats.ORBIT_VIEWS) if i not in set(idx.tolist())]
                row["uncarried_psnr"] = psnr(np.clip(carried[[nearest[i] for i in others]], 0, 1), small[others])
            rows.append(row)
    return rows


def _arch_rows(grid=((2, 16), (4, 24), (4, 32), (6, 32), (8, 48))):
    rows = []
    x = torch.rand(1, 3, formats.SNAPSHOT_SIZE, formats.SNAPSHOT_SIZE)
    for blocks, width in grid:
        net = build_codec(CodecConfig(blocks=blocks, width=width)).eval()
        times = []
        with torch.no_grad():
            for _ in range(5):
                t0 = time.perf_counter()
                net.reverse(x)
                times.append((time.perf_counter() - t0) * 1e3)
        rows.append({"method": "arch", "blocks": blocks, "width": width, "restore_ms": float(np.median(times)),
                     "params": sum(p.numel() for p in net.parameters())})
    return rows


TARGETS = {"none": {"host_psnr": 38, "restore_psnr": 35}, "jpeg75": {"host_psnr": 34, "restore_psnr": 30},
           "moderate": {"host_psnr": 30, "restore_psnr": 25}, "severe": {"restore_psnr": 20}}


def summarise(rows: list[dict], scenes=None) -> dict:
    """Medians per method and severity over `scenes` (all when None) and every host and seed."""
    rows = [r for r in rows if scenes is None or r.get("scene") in scenes]
    out = {}
    for method in dict.fromkeys(r["method"] for r in rows if r["method"] not in ("arch", "strength")):
        for sev in SEVERITIES:
            sel = [r for r in rows if r["method"] == method and r.get("severity") == sev and r.get("strength", 1.0) == 1.0]
            if sel:
                out.setdefault(method, {})[sev] = {
                    "host_psnr": median(sel, "host_psnr"), "restore_psnr": median(sel, "restore_psnr"),
                    "carried_psnr": median(sel, "carried_psnr"), "uncarried_psnr": median(sel, "uncarried_psnr"),
                    "detected": float(np.mean([r["detected"] for r in sel])), "n": len(sel)}
    return out


def side_by_side(net, scene, host, judge, out: Path, refine: int = 0) -> None:
    """Rows: original views, restored from a JPEG-75 snapshot file, restored from a `moderate` photo
    (the snapshot as `snapshot3d embed --refine REFINE` writes it)."""
    snap = snapshot_of(net, host, scene.planes(), refine)
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(snap, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 75])
    jpeg = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    photo = through_channel(snap, scene_meta(scene, formats.FILE_CODEC, 1.0), "moderate", 0)
    pick = [0, 5, 10, 15]
    rows = [judge.ref[pick]]
    for rect in (jpeg, photo):
        planes = file_layout.secret_to_planes(restore_secret(net, rect), scene.resolution, scene.channels)
        rows.append(judge.views(dequantize_planes(quantize_planes(planes)))[pick])
    s = judge.size
    tiles = [np.concatenate(list(r), axis=1) for r in rows]
    left = [cv2.resize(im, (s, s), interpolation=cv2.INTER_AREA) / 255.0 for im in (host * 255, jpeg, photo)]
    fig = np.concatenate([np.concatenate([lft, t], axis=1) for lft, t in zip(left, tiles)], axis=0)
    write_png(out, fig)


_SEV = list(SEVERITIES)
BREAK_DB = 20.0
"""a method is broken at the first severity where its median restore_psnr falls below this"""


def _median_by_sev(rows, method):
    out = []
    for s in _SEV:
        vals = [r["restore_psnr"] for r in rows if r["method"] == method and r.get("severity") == s
                and r.get("strength", 1.0) == 1.0 and r.get("restore_psnr") is not None]
        out.append(float(np.median(vals)) if vals else np.nan)
    return out


def break_severity(meds: list) -> int | None:
    for i, v in enumerate(meds):
        if not np.isnan(v) and v < BREAK_DB:
            return i
    return None


def write_codec_chart(rows: list[dict], path: Path, cores: int) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(2, 2, figsize=(13, 9))
    a = ax[0, 0]
    for method in dict.fromkeys(r["method"] for r in rows if r["method"] in ("ours", "ours-refined", "digital", "lsb")):
        meds = _median_by_sev(rows, method)
        line, = a.plot(range(len(_SEV)), meds, "o-", label=method)
        b = break_severity(meds)
        if b is not None:
            a.plot([b], [meds[b]], "x", ms=14, mew=3, color=line.get_color())
    a.axhline(BREAK_DB, ls=":", c="grey")
    a.set_xticks(range(len(_SEV)), _SEV)
    a.set_ylabel("restore_psnr (dB), median")
    a.set_title(f"restore vs severity (x: breaks, < {BREAK_DB:.0f} dB)")
    a.legend()

    a = ax[0, 1]
    for sev in ("none", "jpeg75", "moderate"):
        pts = {}
        for r in rows:
            if r["method"] == "strength" and r.get("severity") == sev and r.get("restore_psnr") is not None:
                pts.setdefault(r["strength"], []).append((r["host_psnr"], r["restore_psnr"]))
        if pts:
            xs = sorted(pts)
            hp = [np.median([p[0] for p in pts[s]]) for s in xs]
            rp = [np.median([p[1] for p in pts[s]]) for s in xs]
            a.plot(hp, rp, "o-", label=sev)
            for s, x, y in zip(xs, hp, rp):
                a.annotate(f"{s:g}", (x, y), fontsize=7)
    a.set_xlabel("host_psnr (dB)")
    a.set_ylabel("restore_psnr (dB)")
    a.set_title("embedding strength sweep (labels: strength)")
    a.legend()

    a = ax[1, 0]
    arch = [r for r in rows if r["method"] == "arch"]
    a.plot([r["params"] / 1e3 for r in arch], [r["restore_ms"] for r in arch], "o-")
    for r in arch:
        a.annotate(f"{r['blocks']}x{r['width']}", (r["params"] / 1e3, r["restore_ms"]), fontsize=8)
    a.set_xlabel("codec parameters (thousands)")
    a.set_ylabel("restore ms at 380x380")
    a.set_title(f"codec depth x width: restore time ({cores} cores)")

    a = ax[1, 1]
    for sev in ("none", "jpeg75", "moderate"):
        vr = sorted((r["views"], r.get("carried_psnr"), r.get("uncarried_psnr")) for r in rows
                    if r["method"].startswith("views-") and r.get("severity") == sev)
        if vr:
            line, = a.plot([v[0] for v in vr], [v[1] for v in vr], "o-", label=f"carried views, {sev}")
            a.plot([v[0] for v in vr], [v[2] for v in vr], "s--", color=line.get_color(), label=f"other orbit views, {sev}")
    a.set_xlabel("views carried instead of planes")
    a.set_ylabel("view PSNR (dB)")
    a.set_title("baseline c: fixed views (64x64) instead of planes")
    a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


_DEFAULTS = {"file": {"scenes": "snapshot3d/assets/spot.s3d,cache/scenes/lego.s3d", "seeds": 3,
                      "strengths": "0.5,0.75,1,1.5,2"},
             "print": {"scenes": "bench/models/spot-print.s3d,bench/models/lego-print-auto.s3d", "seeds": 6,
                       "strengths": "0.5,0.71,1,1.41,2"}}


def bench_codec_command(args) -> int:
    """`bench codec --medium file|print`: the options left unset take the medium's defaults."""
    for k, v in _DEFAULTS[args.medium].items():
        if getattr(args, k) is None:
            setattr(args, k, v)
    if args.medium == "print":
        from .codec_print import bench_codec_print_command
        return bench_codec_print_command(args)
    return _bench_file_codec(args)


def _bench_file_codec(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    net, cfg = load_codec()
    digital = load_codec(Path(args.digital))[0] if args.digital and Path(args.digital).is_file() else None
    scenes = {Path(p).stem: load_scene_file(p) for p in args.scenes.split(",") if Path(p).is_file()}
    if not scenes:
        raise UserError(f"none of the scenes {args.scenes} exists")
    hosts = {h: load_host("builtin:" + h) for h in args.hosts.split(",")}
    rows = []
    for sname, scene in scenes.items():
        judge = ViewJudge(scene, args.size)
        for hname, host in hosts.items():
            rows += _codec_rows("ours", net, judge, sname, hname, host, SEVERITIES, args.seeds, 1.0)[0]
            if args.refine:
                rows += _codec_rows("ours-refined", net, judge, sname, hname, host, SEVERITIES, args.seeds, 1.0,
                                    args.refine)[0]
            if digital is not None:
                rows += _codec_rows("digital", digital, judge, sname, hname, host, SEVERITIES, args.seeds, 1.0)[0]
            rows += _lsb_rows(judge, sname, hname, host, SEVERITIES)
            print(f"{sname} / {hname}: {len(rows)} rows", flush=True)
        if sname != next(iter(scenes)):
            continue  # the sweeps and the figure: on the first scene only
        hname, host = next(iter(hosts.items()))
        for s in (float(v) for v in args.strengths.split(",")):
            rows += _codec_rows("strength", net, judge, sname, hname, host, ("none", "jpeg75", "moderate"), 1, s)[0]
        rows += _views_rows(net, judge, sname, hname, host, ("none", "jpeg75", "moderate"))
        side_by_side(net, scene, host, judge, out / "codec_side_by_side.png", args.refine)
    rows += _arch_rows()
    write_rows(out / "codec.csv", rows, FIELDS)
    headline = [s for s in args.headline.split(",") if s in scenes]
    summary = summarise(rows, headline or None)
    doc = {"command": "snapshot3d " + " ".join(__import__("sys").argv[1:]), "cores": os.cpu_count(),
           "meta": run_metadata(), "torch_threads": torch.get_num_threads(), "view_size": args.size,
           "codec": {"version": formats.FILE_CODEC, "blocks": cfg.blocks, "width": cfg.width},
           "targets": TARGETS, "headline_scenes": headline, "summary": summary,
           "by_scene": {name: summarise(rows, [name]) for name in scenes}, "arch": [r for r in rows if r["method"] == "arch"]}
    (out / "codec.json").write_text(json.dumps(doc, indent=2) + "\n")
    write_codec_chart(rows, out / "codec.png", os.cpu_count())
    for method, sevs in summary.items():
        print(method, {s: (round(v["host_psnr"] or 0, 1), round(v["restore_psnr"] or 0, 1)) for s, v in sevs.items()})
    return 0
