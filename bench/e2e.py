"""`snapshot3d bench e2e --medium print`: what a print gives of a scene, against the payload (issue 37 item 5).

Scene files of two scenes fitted at several plane sizes (the print budget's choice among them) go through the
print medium as `bench decoders` runs them (`decoders.e2e_rows`: embedded in each host, photographed by
`simulate` per physical severity and seed, scanned and restored), and the restored planes are rendered at
held-out ground-truth views the fit never saw: `e2e_psnr`. Charted per severity against the payload (kB):
the medians per scene, the field alone (the same views from the planes as fitted, no channel), and what
`bench capacity` says a photo carries at that severity (results/capacity.json, host target 30 dB; the print
codec keeps 32). A side-by-side of one held-out view per scene family: the ground truth, the field alone,
and one photo's decode at each severity.

Writes e2e.{csv,json,png} and e2e_side_by_side.png."""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .common import median, pyplot, write_report
from .decoders import e2e_rows

__all__ = ["bench_e2e_command"]

CAPACITY = Path(__file__).resolve().parent / "results" / "capacity.json"


def _family(name: str) -> str:
    return name.split("-")[0]


def _summary(rows: list[dict], fields: dict, severities: list[str]) -> dict:
    out = {}
    for name, info in fields.items():
        sel = [r for r in rows if r["scene"] == name]
        out[name] = {**info, "e2e_psnr": {s: median([r for r in sel if r["severity"] == s], "e2e_psnr") for s in severities},
                     "restore_psnr": {s: median([r for r in sel if r["severity"] == s], "restore_psnr") for s in severities},
                     "n": {s: sum(r["severity"] == s for r in sel) for s in severities}}
        for key in ("qr_read", "head_read"):   # photos whose QR code, and head codes, were read
            got = {s: [r[key] for r in sel if r["severity"] == s and key in r] for s in severities}
            if any(got.values()):
                out[name][key] = {s: f"{sum(v)}/{len(v)}" for s, v in got.items()}
    return out


def _capacity_kb(severities: list[str]) -> dict:
    """{severity: kB a photo carries at a 30 dB host} from `bench capacity` (median over its scenes)."""
    if not CAPACITY.is_file():
        return {}
    doc = json.loads(CAPACITY.read_text())
    out = {}
    for s in severities:
        kb = [v["by_severity"][s]["capacity_kb_all_targets"]["30"] for v in doc["scenes"].values()
              if s in v.get("by_severity", {})]
        if kb:
            out[s] = float(np.median(kb))
    return out


def _chart(doc: dict, path: Path) -> None:
    plt = pyplot()
    sev = doc["severities"]
    fig, axes = plt.subplots(1, len(sev), figsize=(5.2 * len(sev), 4.4), sharey=True)
    for ax, s in zip(np.atleast_1d(axes), sev):
        for i, fam in enumerate(sorted({_family(n) for n in doc["summary"]})):
            pts = sorted((v["scene_kb"], v["field_psnr"], v["e2e_psnr"][s]) for n, v in doc["summary"].items()
                         if _family(n) == fam)
            kb = [p[0] for p in pts]
            ax.plot(kb, [p[1] for p in pts], "--", color=f"C{i}", alpha=0.6, label=f"{fam}: field alone")
            ax.plot(kb, [p[2] for p in pts], "o-", color=f"C{i}", label=f"{fam}: through {s}")
        cap = doc["capacity_kb"].get(s)
        if cap:
            ax.axvline(cap, color="k", ls=":", lw=1, label=f"capacity {cap:.1f} kB (30 dB host)")
        ax.set_xscale("log")
        ax.set(xlabel="payload (scene kB)", title=f"{s}: e2e_psnr at held-out views")
        ax.legend(fontsize=7)
    np.atleast_1d(axes)[0].set_ylabel("dB")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _side_by_side(args, severities: list[str], path: Path) -> None:
    """One held-out view per scene family's first scene: ground truth, field alone, one decode per severity."""
    from snapshot3d.scanner.backgrounds import load_host
    from snapshot3d.scanner.qr import scene_meta
    from snapshot3d.scene import load_scene_file
    from snapshot3d.train.field.evaluate import evaluate_planes

    from .codec_print import E2E, _decode, _snapshot, capture_scan, head_read

    firsts = {}
    for p in (p for p in args.scenes.split(",") if p):
        firsts.setdefault(_family(Path(p).stem), p)
    host = load_host("builtin:" + args.hosts.split(",")[0])
    tiles = []
    for fam, p in firsts.items():
        scene = load_scene_file(p)
        e2e = E2E(scene, 1)
        def one(planes, dec=e2e.decoder):
            return evaluate_planes(planes.astype(np.float32), dec, e2e.posed, e2e.views)["renders"][0]

        row, notes = [e2e.posed.images[e2e.views[0]], one(scene.planes())], ["", ""]
        snap, meta = _snapshot("print", host, scene), scene_meta(scene, "print-2")
        for s in severities:
            got = capture_scan(snap, meta, s, 0)
            if got is None:   # the scanner refused the photo: a blank tile, said so
                row.append(np.ones_like(row[0]))
                notes.append("sheet not found")
                continue
            shared = head_read(got, meta) == 0
            row.append(one(_decode("print", got.snapshot, scene, meta)[0], e2e.shared if shared else e2e.decoder))
            notes.append("head codes unread:\nshared head" if shared else "")
        tiles.append((fam, row, notes))
    plt = pyplot()
    cols = ["ground truth", "field alone"] + severities
    fig, axes = plt.subplots(len(tiles), len(cols), figsize=(2.4 * len(cols), 2.5 * len(tiles)), squeeze=False)
    for r, (fam, row, notes) in enumerate(tiles):
        for c, (img, note) in enumerate(zip(row, notes)):
            axes[r, c].imshow(np.clip(img, 0, 1))
            if note:
                axes[r, c].text(0.5, 0.04, note, transform=axes[r, c].transAxes, ha="center", va="bottom", fontsize=7)
            axes[r, c].set_xticks([]), axes[r, c].set_yticks([])
            if r == 0:
                axes[r, c].set_title(cols[c], fontsize=9)
        axes[r, 0].set_ylabel(f"{fam} ({Path(firsts[fam]).stem})", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def bench_e2e_command(args) -> int:
    out = Path(args.out)
    t0 = time.time()
    paths, hosts, severities, rows, fields = e2e_rows(args, t0)
    doc = write_report(out, "e2e", rows, {
        "medium": args.medium, "scenes": paths, "hosts": list(hosts), "severities": severities, "seeds": args.seeds,
        "views": args.views, "view_size": args.size, "capacity_kb": _capacity_kb(severities),
        "targets": {"e2e_psnr": {"mild": "spot >= 29, lego >= 23", "moderate": "spot >= 27, lego >= 21",
                                 "severe": "spot >= 21, lego >= 17"},
                    "e2e_loss_db": "<= 2 at the chosen payload (field alone minus moderate)"},
        "summary": _summary(rows, fields, severities), "seconds": round(time.time() - t0, 1)})
    _chart(doc, out / "e2e.png")
    _side_by_side(args, severities, out / "e2e_side_by_side.png")
    for name, v in doc["summary"].items():
        print(f"{name} ({v['scene_kb']} kB): field {v['field_psnr']:.2f} dB; " + "; ".join(
            f"{s} {v['e2e_psnr'][s]:.2f}" for s in severities if v["e2e_psnr"][s] is not None))
    print(f"wrote {out}/e2e.csv, e2e.json, e2e.png, e2e_side_by_side.png ({time.time() - t0:.0f} s)")
    return 0
