"""`snapshot3d bench codec`: runs the rows of `codec_bench`, writes codec.csv, codec.json (medians next
to issue 4's targets, the command, the core count) and codec.png; `side_by_side` writes the figure
of original views against views restored from a JPEG-75 file and from a `moderate` photo."""
from __future__ import annotations

import csv
import json
import os
import sys
from pathlib import Path

import numpy as np

from snapshot3d import formats
from snapshot3d.errors import UserError
from snapshot3d.images import write_png
from snapshot3d.scene import load_scene_file

from .codec import load_codec
from .codec_bench import FIELDS, ViewJudge, _arch_rows, _codec_rows, _lsb_rows, _views_rows
from .codec_commands import load_host

__all__ = ["bench_codec_command", "summarise"]

SEVERITIES = ("none", "jpeg90", "jpeg75", "mild", "moderate", "severe")
TARGETS = {"none": {"host_psnr": 38, "restore_psnr": 35}, "jpeg75": {"host_psnr": 34, "restore_psnr": 30},
           "moderate": {"host_psnr": 30, "restore_psnr": 25}, "severe": {"restore_psnr": 20}}


def _med(rows, key):
    vals = [r[key] for r in rows if r.get(key) not in (None, "")]
    return float(np.median(vals)) if vals else None


def summarise(rows: list[dict], scenes=None) -> dict:
    """Medians per method and severity over `scenes` (all when None) and every host and seed."""
    rows = [r for r in rows if scenes is None or r.get("scene") in scenes]
    out = {}
    for method in dict.fromkeys(r["method"] for r in rows if r["method"] not in ("arch", "strength")):
        for sev in SEVERITIES:
            sel = [r for r in rows if r["method"] == method and r.get("severity") == sev and r.get("strength", 1.0) == 1.0]
            if sel:
                out.setdefault(method, {})[sev] = {
                    "host_psnr": _med(sel, "host_psnr"), "restore_psnr": _med(sel, "restore_psnr"),
                    "carried_psnr": _med(sel, "carried_psnr"), "uncarried_psnr": _med(sel, "uncarried_psnr"),
                    "detected": float(np.mean([r["detected"] for r in sel])), "n": len(sel)}
    return out


def side_by_side(net, scene, host, judge, out: Path, refine: int = 0) -> None:
    """Rows: original views, restored from a JPEG-75 snapshot file, restored from a `moderate` photo
    (the snapshot as `snapshot3d embed --refine REFINE` writes it)."""
    import cv2

    from snapshot3d import codec_layout
    from snapshot3d.scene import dequantize_planes, quantize_planes

    from .codec import restore_secret
    from .codec_bench import through_channel
    from .codec_commands import scene_meta
    from .codec_refine import snapshot_of

    snap = snapshot_of(net, host, scene.planes(), refine)
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(snap, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 75])
    jpeg = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    photo = through_channel(snap, scene_meta(scene, 1.0), "moderate", 0)
    pick = [0, 5, 10, 15]
    rows = [judge.ref[pick]]
    for rect in (jpeg, photo):
        planes = codec_layout.secret_to_planes(restore_secret(net, rect), scene.resolution, scene.channels)
        rows.append(judge.views(dequantize_planes(quantize_planes(planes)))[pick])
    s = judge.size
    tiles = [np.concatenate(list(r), axis=1) for r in rows]
    left = [cv2.resize(im, (s, s), interpolation=cv2.INTER_AREA) / 255.0 for im in (host * 255, jpeg, photo)]
    fig = np.concatenate([np.concatenate([lft, t], axis=1) for lft, t in zip(left, tiles)], axis=0)
    write_png(out, fig)


def bench_codec_command(args) -> int:
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
    with open(out / "codec.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    headline = [s for s in args.headline.split(",") if s in scenes]
    summary = summarise(rows, headline or None)
    doc = {"command": "snapshot3d " + " ".join(sys.argv[1:]), "cores": os.cpu_count(),
           "torch_threads": __import__("torch").get_num_threads(), "view_size": args.size,
           "codec": {"version": formats.CODEC_VERSION, "blocks": cfg.blocks, "width": cfg.width},
           "targets": TARGETS, "headline_scenes": headline, "summary": summary,
           "by_scene": {name: summarise(rows, [name]) for name in scenes}, "arch": [r for r in rows if r["method"] == "arch"]}
    (out / "codec.json").write_text(json.dumps(doc, indent=2) + "\n")
    from .codec_bench_charts import write_codec_chart
    write_codec_chart(rows, out / "codec.png", os.cpu_count())
    for method, sevs in summary.items():
        print(method, {s: (round(v["host_psnr"] or 0, 1), round(v["restore_psnr"] or 0, 1)) for s, v in sevs.items()})
    return 0
