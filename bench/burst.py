"""`snapshot3d bench burst`: what several photos of one print give, against one (issue 37).

For each scene, host, physical severity and print (`--prints`, the print's own seed: its halftone and paper),
`--photos` photos are simulated of that one print (`simulate(..., print_seed=)`), scanned and read alone.
Rows (burst.csv), `e2e_psnr` at the scene's held-out views and the planes' RMS error:
- `single`: each photo alone (k = 1), as `decode PHOTO` reads it;
- for k = 2 .. photos, the first k photos: `best` (the one the pilots expect to read best, alone), `mean`
  (the rectified captures averaged with equal weights), `independent` (weighted by each photo's pilot gain over
  its noise, the maximal-ratio weights were the photos' noises independent) and `pilots` (the best linear
  unbiased weights from the pilots' residuals across the photos, as `decode P1 P2 ...` combines them:
  `viewer.burst`). Each row also has `pilot_corr`: the mean correlation of the photos' pilot residuals (the share
  of the noise the print itself made).
A decode whose photos read none of the scene's own head (its codes beside the QR code) is scored with the shared
head, as `decode` renders it; combined, the head comes from any photo that read it.
Writes burst.{csv,json,png}: medians per method, k and severity; the chart draws e2e_psnr against the photos;
burst_side_by_side.png: one held-out view per severity (ground truth, field alone, one photo, all combined)."""
from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

from snapshot3d.codecs.media import MEDIA
from snapshot3d.errors import UserError
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import load_scene_file

from .common import median, pyplot, write_report

__all__ = ["bench_burst_command", "METHODS"]

METHODS = ("single", "best", "mean", "independent", "pilots")


def _photos(sheet: np.ndarray, severity: str, print_seed: int, count: int) -> list[tuple[np.ndarray, bool]]:
    """Rectified captures (380, 380, 3) uint8 RGB of `count` photos of one print (the ones the scanner found), each
    with whether its scan read the scene's own head (its QR code and head codes)."""
    from snapshot3d.scanner.scan import scan_image
    from snapshot3d.scanner.simulate import simulate

    out = []
    for i in range(count):
        data, _, _ = simulate(sheet, severity, 1000 * print_seed + i, print_seed=10_000 + print_seed)
        try:
            got = scan_image(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))
        except UserError:
            continue
        out.append((got.snapshot, bool(got.qr and got.qr.get("head"))))
    return out


def _print_rows(photos: list[tuple[np.ndarray, bool]], meta, e2e, truth: np.ndarray, base: dict,
                keep: dict | None = None) -> list[dict]:
    """The rows of one print's photos (`_photos`). A decode whose photos read none of the scene's own head is scored
    with the shared head, as `decode` renders it. `keep`: filled with the planes of the first photo alone
    ("single") and of all of them weighted by the pilots ("pilots"), with their heads, for the side-by-side."""
    from snapshot3d.viewer.burst import blue_weights, combine_captures, pilot_residuals, pilot_weights
    from snapshot3d.viewer.media import restore_planes

    caps, heads = [c for c, _ in photos], [h for _, h in photos]
    own = meta.head is not None

    def score(planes, head: bool) -> dict:
        return {"e2e_psnr": e2e.psnr(planes, shared=own and not head), "head_read": int(head) if own else None,
                "plane_rmse": float(np.sqrt(np.mean((planes - truth) ** 2)))}
    reads = [restore_planes(c, meta) for c in caps]
    singles = [score(p, h) for (p, _), h in zip(reads, heads)]
    if keep is not None and reads:
        keep["single"] = (reads[0][0], heads[0])
    rows = [dict(base, method="single", k=1, photo=i, plane_rmse_expected=info["plane_rmse_expected"], **s)
            for i, ((_, info), s) in enumerate(zip(reads, singles))]
    pil = [pilot_residuals(c, *meta.planes, meta.codec) for c in caps]
    for k in range(2, len(caps) + 1):
        infos = [info for _, info in reads[:k]]
        best = int(np.argmin([i["plane_rmse_expected"] for i in infos]))
        d = np.stack([r for _, r in pil[:k]])
        live = d[np.all(np.isfinite(d), axis=1)]   # a photo whose pilots read nothing has no residuals
        n = len(live)
        mean_corr = float((np.corrcoef(live).sum() - n) / (n * n - n)) if n > 1 else None
        rows.append(dict(base, method="best", k=k, photo=best, pilot_corr=mean_corr, **singles[best]))
        for method, w in (("mean", np.full(k, 1.0 / k)),
                          ("independent", pilot_weights([i["pilot_gain"] for i in infos],
                                                        [i["pilot_noise"] for i in infos])),
                          ("pilots", blue_weights([g for g, _ in pil[:k]], d))):
            planes, info = restore_planes(combine_captures(np.stack(caps[:k]), w), meta)
            rows.append(dict(base, method=method, k=k, plane_rmse_expected=info["plane_rmse_expected"],
                             pilot_corr=mean_corr, weights=" ".join(f"{x:.3f}" for x in w),
                             **score(planes, any(heads[:k]))))
            if keep is not None and method == "pilots" and k == len(caps):
                keep["pilots"] = (planes, any(heads))
    return rows


def _summary(rows: list[dict], severities: list[str], photos: int) -> dict:
    out = {}
    for sev in severities:
        at = [r for r in rows if r["severity"] == sev]
        single = median([r for r in at if r["method"] == "single"], "e2e_psnr")
        out[sev] = {"single": single, "prints": len({(r["host"], r["print"]) for r in at}),
                    "pilot_corr": median([r for r in at if r["method"] == "pilots"], "pilot_corr")}
        for m in METHODS[1:]:
            out[sev][m] = {str(k): median([r for r in at if r["method"] == m and r["k"] == k], "e2e_psnr")
                           for k in range(2, photos + 1)}   # keys as the JSON file has them
    return out


def _chart(doc: dict, path: Path) -> None:
    plt = pyplot()
    sevs = list(doc["summary"])
    fig, axes = plt.subplots(1, len(sevs), figsize=(4.2 * len(sevs), 3.6), squeeze=False)
    for ax, sev in zip(axes[0], sevs):
        s = doc["summary"][sev]
        for m, style in (("best", "s--"), ("mean", "^:"), ("independent", "v-."), ("pilots", "o-")):
            ks = [int(k) for k in s[m]]
            ax.plot([1] + ks, [s["single"]] + [s[m][k] for k in s[m]], style, label=m if m != "pilots" else
                    "weighted by the pilots (decode)")
        ax.axhline(doc["field_psnr"], color="grey", lw=0.8, label="field alone")
        ax.set_title(f"{doc['scene']}, {sev} ({s['prints']} prints)")
        ax.set_xlabel("photos of one print")
        ax.set_xticks(range(1, doc["photos"] + 1))
        ax.set_ylabel("e2e_psnr (dB), median")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _side_by_side(kept: dict, e2e, scene, path: Path, photos: int) -> None:
    """One held-out view per severity: ground truth, field alone, the first photo alone, all photos combined."""
    from snapshot3d.train.field.evaluate import evaluate_planes

    def render(planes, shared=False):
        dec = e2e.shared if shared else e2e.decoder
        return evaluate_planes(planes.astype(np.float32), dec, e2e.posed, e2e.views[:1])["renders"][0]
    own = scene.head is not None
    plt = pyplot()
    cols = ["ground truth", "field alone", "one photo", f"{photos} photos, combined"]
    fig, axes = plt.subplots(len(kept), 4, figsize=(9.6, 2.5 * len(kept)), squeeze=False)
    for r, (sev, got) in enumerate(kept.items()):
        tiles = [e2e.posed.images[e2e.views[0]], render(scene.planes())] + [
            render(got[m][0], own and not got[m][1]) if m in got else np.ones((8, 8, 3)) for m in ("single", "pilots")]
        for c, img in enumerate(tiles):
            axes[r, c].imshow(np.clip(img, 0, 1))
            axes[r, c].set_xticks([]), axes[r, c].set_yticks([])
            if r == 0:
                axes[r, c].set_title(cols[c], fontsize=9)
        axes[r, 0].set_ylabel(sev, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def bench_burst_command(args) -> int:
    from snapshot3d.scanner.sheet import render_sheet
    from snapshot3d.validate import integer
    from snapshot3d.viewer.burst import MAX_PHOTOS

    from .codec_print import E2E, _snapshot, heldout_hosts

    integer(args.photos, "--photos", 2, MAX_PHOTOS)
    integer(args.prints, "--prints", 1, 100)
    t0 = time.time()
    out = Path(args.out)
    scene = load_scene_file(args.scene)
    meta = scene_meta(scene, MEDIA["print"].codec, 1.0)
    e2e = E2E(scene, args.views)
    truth = scene.planes()
    severities = [s for s in args.severities.split(",") if s]
    rows, kept = [], {}
    hosts = ["builtin:" + h for h in args.hosts.split(",") if h] + heldout_hosts(args.heldout)
    for spec in hosts:
        host_name = Path(spec.split(":", 1)[-1]).stem
        sheet = render_sheet(_snapshot("print", load_host(spec), scene), meta, 2)
        for sev in severities:
            for p in range(args.prints):
                caps = _photos(sheet, sev, p, args.photos)
                base = {"scene": Path(args.scene).stem, "host": host_name, "severity": sev, "print": p}
                rows += _print_rows(caps, meta, e2e, truth, base, kept.setdefault(sev, {}) if spec == hosts[0] and
                                    p == 0 else None)
                print(f"{host_name} {sev} print {p}: {len(caps)} photos ({time.time() - t0:.0f} s)", flush=True)
    doc = write_report(out, "burst", rows, {
        "scene": Path(args.scene).stem, "field_psnr": e2e.psnr(truth), "hosts": [Path(h).name for h in hosts],
        "prints": args.prints,
        "photos": args.photos, "views": args.views, "summary": _summary(rows, severities, args.photos),
        "seconds": round(time.time() - t0, 1)})
    _chart(doc, out / "burst.png")
    _side_by_side(kept, e2e, scene, out / "burst_side_by_side.png", args.photos)
    for sev, s in doc["summary"].items():
        k = str(args.photos)
        print(f"{sev}: one photo {s['single']:.2f} dB; {args.photos} photos weighted by the pilots "
              f"{s['pilots'][k]:.2f}, as if independent {s['independent'][k]:.2f}, the best of them "
              f"{s['best'][k]:.2f}, their mean {s['mean'][k]:.2f} (pilot residuals correlate {s['pilot_corr']:.2f})")
    print(f"wrote {out}/burst.csv, burst.json, burst.png, burst_side_by_side.png ({time.time() - t0:.0f} s)")
    return 0
