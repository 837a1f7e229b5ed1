"""`snapshot3d bench decoders`: does a stronger shared decoder give sharper views from a print?

Each scene file (the same scene fitted for each decoder version, at the print budget's plane size) is
embedded (print medium) in each host, photographed by `simulate` at each physical severity and seed, scanned
and restored as `decode` does (bench/codec_print.py's rows), and the restored planes are rendered by the
scene's own decoder at held-out ground-truth views the fit never saw: `e2e_psnr`. `field_psnr` is the same
views from the planes as fitted (no channel). Rows of one host, severity and seed use the same simulator
seed for every scene.

`--search FILE` adds the decoder search's rows (JSON lines: decoder candidates trained on a GPU and scored by
fitting spot and lego at small plane sizes; their provenance is in the file's rows) to the JSON and chart.
Writes decoders.{csv,json,png}."""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from snapshot3d.errors import UserError
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scene import load_scene_file

from .codec_print import E2E, _rows, heldout_hosts
from .common import ViewJudge, median, pyplot, write_report

__all__ = ["bench_decoders_command", "e2e_rows"]


def _summary(rows: list[dict], fields: dict) -> dict:
    """Per scene file: its decoder, plane size, field_psnr and, per severity, the medians of e2e_psnr and
    restore_psnr, and the e2e loss (field_psnr minus the e2e median)."""
    out = {}
    for name, info in fields.items():
        sel = [r for r in rows if r["scene"] == name]
        per = {}
        for sev in dict.fromkeys(r["severity"] for r in sel):
            s = [r for r in sel if r["severity"] == sev]
            e2e = median(s, "e2e_psnr")
            per[sev] = {"e2e_psnr": e2e, "restore_psnr": median(s, "restore_psnr"), "n": len(s),
                        "detected": float(np.mean([r["detected"] for r in s])),
                        "e2e_loss_db": None if e2e is None else round(info["field_psnr"] - e2e, 3)}
        out[name] = {**info, "severities": per}
    return out


def _paired(rows: list[dict], a: str, b: str) -> dict:
    """Per severity: median and count of wins of e2e_psnr(b) - e2e_psnr(a) over the photos both share."""
    key = lambda r: (r["host"], r["severity"], r["seed"])  # noqa: E731
    ra = {key(r): r.get("e2e_psnr") for r in rows if r["scene"] == a}
    out = {}
    for r in rows:
        if r["scene"] != b or ra.get(key(r)) is None or r.get("e2e_psnr") is None:
            continue
        out.setdefault(r["severity"], []).append(r["e2e_psnr"] - ra[key(r)])
    return {sev: {"median_db": round(float(np.median(d)), 3), "wins": int(np.sum(np.asarray(d) > 0)), "n": len(d)}
            for sev, d in out.items()}


def write_chart(doc: dict, path: Path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2 if doc.get("search") else 1, figsize=(12 if doc.get("search") else 6.5, 4.2),
                             squeeze=False)
    ax = axes[0][0]
    sevs = doc["severities"]
    for name, s in doc["summary"].items():
        ys = [s["severities"].get(v, {}).get("e2e_psnr") for v in sevs]
        line = ax.plot(range(len(sevs)), ys, "o-", label=f"{name} ({s['decoder']}, {s['planes'][0]}x{s['planes'][1]})")
        ax.axhline(s["field_psnr"], color=line[0].get_color(), ls=":", lw=1)
    ax.set_xticks(range(len(sevs)), sevs)
    ax.set_ylabel("e2e_psnr, dB (dotted: the field alone)")
    ax.set_title("views from a print, held-out ground truth")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    if doc.get("search"):
        ax = axes[0][1]
        cands = list(dict.fromkeys(r["decoder"] for r in doc["search"]))
        keys = list(dict.fromkeys(f"{r['scene']} {r['plane_res']}x{r['plane_channels']}" for r in doc["search"]))
        width = 0.8 / len(cands)
        for i, c in enumerate(cands):
            vals = {f"{r['scene']} {r['plane_res']}x{r['plane_channels']}": r["field_psnr"]
                    for r in doc["search"] if r["decoder"] == c}
            ax.bar(np.arange(len(keys)) + i * width, [vals.get(k, np.nan) for k in keys], width, label=c)
        ax.set_xticks(np.arange(len(keys)) + 0.4 - width / 2, keys)
        ax.set_ylim(18, None)
        ax.set_ylabel("field_psnr, dB (held-out views)")
        ax.set_title("decoder search: fits at small plane sizes")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def e2e_rows(args, t0: float) -> tuple[list[str], dict, list[str], list[dict], dict]:
    """The print medium's rows of every scene file in args.scenes (comma-separated) in every host (args.hosts
    bundled, args.heldout held-out), severity and seed: restore_psnr, and e2e_psnr at args.views held-out
    ground-truth views -> (paths, hosts, severities, rows, fields: per scene its decoder, planes, scene_kb and
    field_psnr at the same views with no channel). Shared by `bench decoders` and `bench e2e`."""
    paths = [p for p in args.scenes.split(",") if p]
    missing = [p for p in paths if not Path(p).is_file()]
    if missing:
        raise UserError(f"scene file not found: {missing[0]}")
    scenes = {Path(p).stem: load_scene_file(p) for p in paths}
    hosts = {h: load_host("builtin:" + h) for h in args.hosts.split(",") if h}
    hosts.update({Path(p).stem: load_host(p) for p in heldout_hosts(args.heldout)})
    severities = [s for s in args.severities.split(",") if s]
    rows, fields = [], {}
    for name, scene in scenes.items():
        judge, e2e = ViewJudge(scene, args.size), E2E(scene, args.views)
        fields[name] = {"decoder": scene.decoder_version, "planes": [scene.resolution, scene.channels],
                        "scene_kb": round(scene.scene_kb, 2), "field_psnr": round(e2e.psnr(scene.planes()), 3)}
        for hname, host in hosts.items():
            for r in _rows(["print"], scene, name, hname, host, severities, args.seeds, judge, e2e):
                rows.append({**r, "decoder": scene.decoder_version})
        print(f"{name}: {len(rows)} rows ({time.time() - t0:.0f} s)", flush=True)
    return paths, hosts, severities, rows, fields


def bench_decoders_command(args) -> int:
    out = Path(args.out)
    t0 = time.time()
    paths, hosts, severities, rows, fields = e2e_rows(args, t0)
    scenes = dict.fromkeys(Path(p).stem for p in paths)
    search = [json.loads(line) for line in Path(args.search).read_text().splitlines() if line.strip()] \
        if args.search else []
    names = list(scenes)
    pairs = {f"{b} vs {a}": _paired(rows, a, b) for a in names for b in names
             if a != b and a.split("-")[0] == b.split("-")[0] and names.index(a) < names.index(b)}
    doc = write_report(out, "decoders", rows, {
        "scenes": paths, "hosts": list(hosts), "severities": severities, "seeds": args.seeds,
        "views": args.views, "view_size": args.size, "seconds": round(time.time() - t0, 1),
        "summary": _summary(rows, fields), "paired_e2e": pairs, "search": search})
    write_chart(doc, out / "decoders.png")
    for name, s in doc["summary"].items():
        print(f"{name} ({s['decoder']}): field {s['field_psnr']:.2f} dB; " + "; ".join(
            f"{sev} e2e {v['e2e_psnr']:.2f}" for sev, v in s["severities"].items() if v["e2e_psnr"] is not None))
    for k, v in pairs.items():
        print(f"{k}: " + "; ".join(f"{sev} {d['median_db']:+.2f} dB ({d['wins']}/{d['n']})" for sev, d in v.items()))
    print(f"wrote {out}/decoders.csv, decoders.json, decoders.png ({time.time() - t0:.0f} s)")
    return 0
