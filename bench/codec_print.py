"""`snapshot3d bench codec --medium print`: the print medium's codec through the real channel (sheet ->
`simulate` -> `scan` -> restore), against the file medium's codec on the same kind of captures.

Rows (codec_print.csv), for each scene, host, severity and seed (6 per physical severity):
- `print`: the print codec as `decode` runs it (designed carriers; the capture read by matched filters
  weighted by the print's noise, then MMSE with the pilots' gain and noise);
- `print-front`: the same captures through a learned CNN front-end first (`bench/models/print-front.npz`,
  `snapshot3d train print-codec`), then the same despreader: the learned loser, kept as a row;
- `file`: the file medium's codec (the invertible network, unrefined) on captures of its own snapshot:
  the baseline the print codec must beat.
Each row: `host_psnr`, `host_ssim`, `restore_psnr` (20 orbit views against the original planes'),
`e2e_psnr` (the scene's held-out ground-truth views against the decoded planes rendered there), the
pilots' `plane_rmse_expected` and the true plane RMS error. Sweeps on the first scene (`moderate`): the
payload size (`--payloads`, scene files of other plane sizes) beside `bench capacity`'s bound, the host
fidelity (`--strengths`), and the print size (`sheet --width-mm` 60, 100, 150, 200 at a 600 dpi printer).
Writes codec_print.{csv,json,png} and codec_print_side_by_side.png (original, mild, moderate, severe).
A run takes about an hour at full size; killed part-way, the same command resumes from the finished
scene-host blocks (codec_print.partial.jsonl in the output folder)."""
from __future__ import annotations

import json
import time
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.codecs import print_source
from snapshot3d.codecs.media import MEDIA
from snapshot3d.errors import UserError
from snapshot3d.images import write_png
from snapshot3d.metrics import ssim
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.presets import PRINTER_DPI, print_dots
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import load_scene_file

from .common import (
    PHYSICAL,
    SEVERITIES,
    RowBlocks,
    ViewJudge,
    capture_seeds,
    median,
    psnr,
    pyplot,
    update_budget_curve,
    write_report,
)

__all__ = ["bench_codec_print_command", "TARGETS", "PRINT_SIZES_MM", "heldout_hosts", "summarise"]

TARGETS = {"mild": {"restore_psnr": 30}, "moderate": {"restore_psnr": 25}, "severe": {"restore_psnr": 20},
           "host_psnr": 32}
PRINT_SIZES_MM = (60, 100, 150, 200)


def heldout_hosts(count: int) -> list[str]:
    """`count` photos of `../shared/data/hosts/heldout/` (every k-th by name), as host specs (file paths)."""
    from snapshot3d.builtin import shared_data_dir

    root = shared_data_dir()
    files = sorted((root / "hosts" / "heldout").glob("*.jpg")) if root is not None else []
    if not files or count <= 0:
        return []
    step = max(1, len(files) // count)
    return [str(f) for f in files[::step][:count]]


def capture(snap: np.ndarray, meta, severity: str, seed: int, dots: int | None = None) -> np.ndarray | None:
    """The rectified snapshot `scan` gives from a simulated photo of the snapshot's sheet (None: not found);
    `dots` sets the printer's dots per snapshot pixel (the print's size)."""
    got = capture_scan(snap, meta, severity, seed, dots)
    return None if got is None else got.snapshot


def capture_scan(snap: np.ndarray, meta, severity: str, seed: int, dots: int | None = None):
    """`capture`'s scan whole (`scanner.scan.ScanResult`: the rectified snapshot and the QR code's dict), or None."""
    from snapshot3d.scanner.roundtrip import capture_scan as scan_capture

    try:
        return scan_capture(snap, meta, severity, seed, print_dots=dots)
    except UserError:
        return None


def head_read(scan, meta) -> int | None:
    """1 when the head codes of a sheet with them (`meta.head`) were read from the photo, 0 when not (the views are
    then scored with the shared head; also when the QR code itself was not read, which `decode` refuses and the
    benches, knowing the metadata, read on), None when the sheet has none."""
    return None if meta.head is None else int(bool(scan.qr and scan.qr.get("head")))


class E2E:
    """e2e_psnr: decoded planes rendered at a scene's held-out ground-truth views (up to `views`)."""

    def __init__(self, scene, views: int = 5):
        from snapshot3d.loaders import load_scene
        from snapshot3d.train.field.decoder import load_decoder, scene_decoder

        src = scene.meta.get("source", "")
        kw = {"size": scene.meta.get("size", 200)} if src.startswith("builtin:") else \
            {"downscale": scene.meta.get("downscale", 4)}
        self.posed = load_scene(src, **kw)
        self.views = self.posed.test[np.linspace(0, len(self.posed.test) - 1, views).round().astype(int)]
        self.decoder = scene_decoder(scene)
        self.shared = self.decoder if scene.head is None else load_decoder(scene.decoder_version)

    def psnr(self, planes: np.ndarray, shared: bool = False) -> float:
        """Held-out field_psnr of planes (3, C, R, R) with the scene's decoder, or the shared decoder without its
        own head (`shared`: a photo whose head codes were not read decodes so)."""
        from snapshot3d.train.field.evaluate import evaluate_planes
        dec = self.shared if shared else self.decoder
        return evaluate_planes(planes.astype(np.float32), dec, self.posed, self.views)["field_psnr"]


def _decode(method: str, rect: np.ndarray, scene, meta):
    """planes (3, C, R, R) and the pilots' expected plane error (print) from a rectified capture."""
    from snapshot3d.viewer.media import restore_planes

    planes, info = restore_planes(rect, meta, {"print-front": _front_end()} if method == "print-front" else None)
    return planes, info.get("plane_rmse_expected")


@lru_cache(maxsize=1)
def _front_end():
    """The learned front-end (torch) as a runner: x (1, 3, 380, 380) -> payload estimate, same layout."""
    import torch

    from snapshot3d.train.codec.print_train import load_front_end
    net = load_front_end()[0]
    return lambda x: net(torch.from_numpy(np.ascontiguousarray(x, np.float32))).numpy()


def _snapshot(method: str, host: np.ndarray, scene, strength: float = 1.0) -> np.ndarray:
    """The snapshot `embed` writes (metadata mark included; the file codec unrefined)."""
    from snapshot3d.train.codec.embedding import snapshot_for
    return snapshot_for("file" if method == "file" else "print", host, scene, strength)


def _rows(methods, scene, sname, hname, host, severities, seeds, judge, e2e, strength=1.0, dots=None, group="main"):
    rows = []
    host8 = (host * 255 + 0.5).astype(np.uint8)
    for method in methods:
        if method == "print-front":
            continue  # read from the `print` captures below
        snap = _snapshot(method, host, scene, strength)
        codec = MEDIA["file" if method == "file" else "print"].codec
        meta = scene_meta(scene, codec, strength)
        base = {"group": group, "scene": sname, "host": hname, "strength": strength, "dots": dots,
                "host_psnr": psnr(snap / 255, host8 / 255), "host_ssim": ssim(snap / 255, host8 / 255)}
        for sev in severities:
            for seed in capture_seeds(sev, seeds):
                got = capture_scan(snap, meta, sev, seed, dots)
                rect, head = (None, None) if got is None else (got.snapshot, head_read(got, meta))
                for m in ([method, "print-front"] if method == "print" and "print-front" in methods else [method]):
                    row = dict(base, method=m, severity=sev, seed=seed, detected=int(rect is not None))
                    if got is not None:
                        row["qr_read"] = int(got.qr is not None)
                    if head is not None:
                        row["head_read"] = head
                    if rect is not None:
                        planes, expected = _decode(m, rect, scene, meta)
                        row.update(restore_psnr=judge.planes_psnr(planes), plane_rmse_expected=expected,
                                   plane_rmse=float(np.sqrt(np.mean((planes - scene.planes()) ** 2))))
                        if e2e is not None:
                            row["e2e_psnr"] = e2e.psnr(planes, shared=head == 0)
                    rows.append(row)
    return rows


def summarise(rows: list[dict], group: str = "main") -> dict:
    """Medians per method and severity (every scene, host and seed of the group)."""
    out = {}
    sel_rows = [r for r in rows if r["group"] == group]
    for method in dict.fromkeys(r["method"] for r in sel_rows):
        for sev in SEVERITIES:
            sel = [r for r in sel_rows if r["method"] == method and r["severity"] == sev]
            if sel:
                out.setdefault(method, {})[sev] = {k: median(sel, k) for k in (
                    "host_psnr", "host_ssim", "restore_psnr", "e2e_psnr", "plane_rmse", "plane_rmse_expected")}
                out[method][sev].update(detected=float(np.mean([r["detected"] for r in sel])), n=len(sel))
    return out


def _bound(scene, judge, kb: float) -> float:
    """The best restore_psnr `kb` kB of Gaussian capacity allows for the scene's planes (bench capacity)."""
    from .capacity_model import best_plane_rmse, noise_curve, psnr_at
    planes = scene.planes()
    return psnr_at(noise_curve(judge), best_plane_rmse(kb * 8000.0, planes.size, float(np.var(planes))))


def _capacity_kb(severity: str = "moderate", host_db: float = print_source.HOST_PSNR) -> float | None:
    """The channel's capacity at `severity` from bench/results/capacity.json, interpolated (in log kB) to
    `host_db` between the host targets it was measured at."""
    path = Path("bench/results/capacity.json")
    if not path.is_file():
        return None
    by = next(iter(json.loads(path.read_text())["scenes"].values()))["by_severity"].get(severity)
    if by is None:
        return None
    pts = sorted((float(k), float(v)) for k, v in by["capacity_kb_all_targets"].items())
    return float(np.exp(np.interp(host_db, [p[0] for p in pts], np.log([p[1] for p in pts]))))


def side_by_side(scene, host, judge, out: Path, seed: int = 0) -> None:
    """Rows: the original views, then those decoded from a mild, a moderate and a severe photo."""
    snap = _snapshot("print", host, scene)
    meta = scene_meta(scene, formats.PRINT_CODEC)
    pick = [0, 5, 10, 15]
    rows, lefts = [judge.ref[pick]], [cv2.resize(snap, (judge.size,) * 2, interpolation=cv2.INTER_AREA) / 255.0]
    for sev in PHYSICAL:
        rect = capture(snap, meta, sev, seed)
        planes = _decode("print", rect, scene, meta)[0] if rect is not None else np.zeros_like(scene.planes())
        rows.append(judge.views(planes)[pick])
        lefts.append(cv2.resize(rect if rect is not None else snap * 0, (judge.size,) * 2,
                                interpolation=cv2.INTER_AREA) / 255.0)
    fig = np.concatenate([np.concatenate([lft, *r], axis=1) for lft, r in zip(lefts, rows)], axis=0)
    write_png(out, fig)


def bench_codec_print_command(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    scenes = {Path(p).stem: load_scene_file(p) for p in args.scenes.split(",") if Path(p).is_file()}
    if not scenes:
        raise UserError(f"none of the scenes {args.scenes} exists")
    hosts = {h: load_host("builtin:" + h) for h in args.hosts.split(",") if h}
    hosts.update({Path(p).stem: load_host(p) for p in heldout_hosts(args.heldout)})
    methods = [m for m in args.methods.split(",") if m]
    blocks = RowBlocks(out / "codec_print.partial.jsonl",
                       {k: v for k, v in vars(args).items() if isinstance(v, (str, int, float, bool))})
    rows, judges = [], {}
    for sname, scene in scenes.items():
        judges[sname] = judge = ViewJudge(scene, args.size)
        e2e = E2E(scene)
        for hname, host in hosts.items():
            rows += blocks.rows(f"main/{sname}/{hname}", lambda: _rows(
                methods, scene, sname, hname, host, SEVERITIES, args.seeds, judge, e2e))
            print(f"{sname} / {hname}: {len(rows)} rows ({time.time() - t0:.0f} s)", flush=True)
    first = next(iter(scenes))
    scene, judge = scenes[first], judges[first]
    hname, host = next(iter(hosts.items()))
    sweep_seeds = max(1, args.seeds // 2)
    sweep_hosts = list(hosts.items())[:2]
    for p in (p for p in args.payloads.split(",") if p and Path(p).is_file()):
        s = load_scene_file(p)
        j = ViewJudge(s, args.size)
        for hn, h in sweep_hosts:
            rows += blocks.rows(f"payload/{Path(p).stem}/{hn}", lambda: _rows(
                ["print"], s, Path(p).stem, hn, h, ["moderate"], sweep_seeds, j, None, group="payload"))
    for strength in (float(v) for v in args.strengths.split(",") if v):
        rows += blocks.rows(f"strength/{strength}", lambda: _rows(
            ["print"], scene, first, hname, host, ["moderate"], sweep_seeds, judge, None, strength, group="strength"))
    for mm in PRINT_SIZES_MM:
        rows += blocks.rows(f"print/{mm}", lambda: _rows(
            ["print"], scene, first, hname, host, ["moderate"], sweep_seeds, judge, None, dots=print_dots(mm),
            group=f"print-{mm}mm"))
    print(f"all rows ({time.time() - t0:.0f} s)", flush=True)
    side_by_side(scene, host, judge, out / "codec_print_side_by_side.png")
    kb = _capacity_kb()
    payload = {}
    for sname in dict.fromkeys(r["scene"] for r in rows if r["group"] in ("main", "payload")):
        s = scenes.get(sname) or load_scene_file(next(p for p in args.payloads.split(",") if Path(p).stem == sname))
        sel = [r for r in rows if r["scene"] == sname and r["method"] == "print" and r["severity"] == "moderate"
               and r["group"] in ("main", "payload")]
        payload[sname] = {"values": int(s.planes().size), "planes": [s.resolution, s.channels],
                          "restore_psnr": median(sel, "restore_psnr"),
                          "bound_restore_psnr": _bound(s, ViewJudge(s, args.size), kb) if kb else None}
    curve = [(v["values"], v["restore_psnr"]) for name, v in payload.items()
             if name in {Path(p).stem for p in args.payloads.split(",")} and v["restore_psnr"] is not None]
    if curve and not args.quick:
        update_budget_curve("print", curve, "moderate", "snapshot3d bench codec --medium print (payload sweep, spot in "
                                                        f"{', '.join(h for h, _ in sweep_hosts)}, moderate)")
    summary = summarise(rows)
    doc = write_report(out, "codec_print", rows, {
        "view_size": args.size, "codec": formats.PRINT_CODEC, "targets": TARGETS, "hosts": list(hosts),
        "scenes": list(scenes), "seconds": round(time.time() - t0, 1), "summary": summary,
        "by_scene": {s: summarise([r for r in rows if r["scene"] == s]) for s in scenes},
        "payload_vs_bound": {"capacity_kb_moderate_at_host_psnr": kb, "host_psnr": print_source.HOST_PSNR,
                             "scenes": payload},
        "strength": summarise(rows, "strength"), "print_size": {f"{mm} mm": summarise(rows, f"print-{mm}mm")
                                                               for mm in PRINT_SIZES_MM}})
    write_chart(rows, doc, out / "codec_print.png")
    blocks.finish()
    for method, sevs in summary.items():
        print(method, {s: (round(v["host_psnr"] or 0, 1), round(v["restore_psnr"] or 0, 1)) for s, v in sevs.items()})
    return 0


def write_chart(rows: list[dict], doc: dict, path: Path) -> None:
    """restore_psnr per severity and method (targets marked); payload size against restore_psnr beside the
    capacity bound; host fidelity against restore fidelity; print size against restore_psnr."""
    plt = pyplot()
    fig, ax = plt.subplots(2, 2, figsize=(13, 9))
    a = ax[0, 0]
    for method, sevs in doc["summary"].items():
        a.plot(range(len(SEVERITIES)), [sevs.get(s, {}).get("restore_psnr") or np.nan for s in SEVERITIES], "o-",
               label=method)
    for s, t in TARGETS.items():
        if isinstance(t, dict):
            a.plot(SEVERITIES.index(s), t["restore_psnr"], "k_", ms=22, mew=2)
    a.set_xticks(range(len(SEVERITIES)), SEVERITIES)
    a.set(ylabel="restore_psnr (dB), median", title="print captures: restore fidelity per severity (bars: targets)")
    a.legend()
    a = ax[0, 1]
    pv = doc["payload_vs_bound"]["scenes"]
    xs = sorted(pv, key=lambda s: pv[s]["values"])
    a.plot([pv[s]["values"] / 1e3 for s in xs], [pv[s]["restore_psnr"] or np.nan for s in xs], "o-", label="print codec")
    a.plot([pv[s]["values"] / 1e3 for s in xs], [pv[s]["bound_restore_psnr"] or np.nan for s in xs], "s--",
           label="capacity bound (bench capacity)")
    for s in xs:
        a.annotate(f"{pv[s]['planes'][0]}x{pv[s]['planes'][1]}", (pv[s]["values"] / 1e3, pv[s]["restore_psnr"] or 0),
                   fontsize=7)
    a.set(xlabel="payload (thousand plane values)", ylabel="restore_psnr at moderate (dB)",
          title="payload size against restore fidelity")
    a.legend()
    a = ax[1, 0]
    st = [r for r in rows if r["group"] == "strength" and r.get("restore_psnr") is not None]
    for s in sorted({r["strength"] for r in st}):
        sel = [r for r in st if r["strength"] == s]
        x, y = median(sel, "host_psnr"), median(sel, "restore_psnr")
        a.plot(x, y, "o", color="C0")
        a.annotate(f"{s:g}", (x, y), fontsize=8)
    a.axvline(TARGETS["host_psnr"], ls=":", c="grey")
    a.set(xlabel="host_psnr (dB)", ylabel="restore_psnr at moderate (dB)",
          title="host fidelity against restore fidelity (labels: strength)")
    a = ax[1, 1]
    ps = doc["print_size"]
    mm = [m for m in PRINT_SIZES_MM if ps.get(f"{m} mm", {}).get("print")]
    a.plot(mm, [ps[f"{m} mm"]["print"]["moderate"]["restore_psnr"] for m in mm], "o-")
    a.set(xlabel=f"printed sheet width (mm, {PRINTER_DPI} dpi printer)", ylabel="restore_psnr at moderate (dB)",
          title="how big must a user print?")
    fig.suptitle(f"snapshot3d bench codec --medium print ({doc['cores']} cores)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
