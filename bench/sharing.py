"""`snapshot3d bench codec-jpeg --part sharing`: what sharing does to a file-medium snapshot, end to end.
A snapshot made as `embed --medium file` makes it (the host marked with its metadata, `scanner.pixelmeta`,
then the invertible codec, refined `--refine` steps), then one thing a messaging app or a user does to the
file as `embed` writes it (`formats.FILE_SCALE` times the snapshot's size, 1520x1520): JPEG at 60-95 with 4:2:0
chroma, JPEG twice, a square resized (to 256, 380, 512 or 1080 px, 0.67x or 2.8x) and saved as JPEG, a few
pixels cropped or padded. The copy carries no text; restore reads the metadata from its pixels,
realigns it and restores with the codec the metadata names (`scanner.snapfile`, `viewer.media`, no torch).

Rows (codec_sharing.csv), per scene, host and distortion (3 seeds for the crops and pads, whose offsets
are random): `meta_read` (the mark read), `meta_wrong` (read, and not what was written: must stay 0),
`meta_ms`, `restore_psnr` (20 orbit views of the restored planes against the original planes'),
`host_psnr`/`host_ssim` of the snapshot, and `false_read` on the unmarked host given the same distortion.
Writes codec_sharing.{csv,json,png} and codec_sharing_side_by_side.png (spot in coffee: the original views,
then those restored from the PNG, from a JPEG-75 copy and from a 256-px JPEG-90 copy, none with text)."""
from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.metrics import ssim
from snapshot3d.scanner import pixelmeta
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scanner.snapfile import file_pixels, snapshot_in_image
from snapshot3d.scene import load_scene_file
from snapshot3d.viewer.media import restore_planes

from .common import RowBlocks, ViewJudge, jpeg_copy, median, psnr, pyplot, write_report

__all__ = ["SHARING", "bench_sharing", "TARGETS"]

TARGETS = {"meta_read": "100% for JPEG >= 60, resized 0.67x-2.8x (and to 256 px), 4-px crops", "meta_wrong": 0,
           "lossless restore_psnr": 35, "host_psnr": 38, "jpeg75 restore_psnr": 30, "resize256 restore_psnr": 25}


def _resize(rgb: np.ndarray, n: int, quality: int = 90) -> np.ndarray:
    interp = cv2.INTER_AREA if n < rgb.shape[0] else cv2.INTER_CUBIC
    return jpeg_copy(cv2.resize(rgb, (n, n), interpolation=interp), quality)


def _crop(rgb: np.ndarray, px: int, rng) -> np.ndarray:
    top, left = rng.integers(0, px + 1, 2)
    h, w = rgb.shape[:2]
    return jpeg_copy(np.ascontiguousarray(rgb[top:h - (px - top), left:w - (px - left)]), 90)


def _pad(rgb: np.ndarray, px: int, rng) -> np.ndarray:
    top, left = rng.integers(0, px + 1, 2)
    return jpeg_copy(cv2.copyMakeBorder(rgb, top, px - top, left, px - left, cv2.BORDER_CONSTANT, value=(255,) * 3), 90)


SHARING = {  # name -> (copy(rgb, rng), seeds)
    "png": (lambda x, r: x, 1),
    "jpeg95": (lambda x, r: jpeg_copy(x, 95), 1),
    "jpeg85": (lambda x, r: jpeg_copy(x, 85), 1),
    "jpeg75": (lambda x, r: jpeg_copy(x, 75), 1),
    "jpeg60": (lambda x, r: jpeg_copy(x, 60), 1),
    "jpeg75 twice": (lambda x, r: jpeg_copy(jpeg_copy(x, 75), 75), 1),
    "jpeg85 then 60": (lambda x, r: jpeg_copy(jpeg_copy(x, 85), 60), 1),
    "256 px": (lambda x, r: _resize(x, 256), 1),
    "256 px jpeg75": (lambda x, r: _resize(x, 256, 75), 1),
    "380 px jpeg75": (lambda x, r: _resize(x, 380, 75), 1),
    "512 px": (lambda x, r: _resize(x, 512), 1),
    "1080 px": (lambda x, r: _resize(x, 1080), 1),
    "0.67x": (lambda x, r: _resize(x, round(0.67 * x.shape[0])), 1),
    "2.8x": (lambda x, r: _resize(x, round(2.8 * x.shape[0])), 1),
    "crop 2 px": (lambda x, r: _crop(x, 2, r), 3),
    "crop 4 px": (lambda x, r: _crop(x, 4, r), 3),
    "crop 8 px": (lambda x, r: _crop(x, 8, r), 3),
    "pad 4 px": (lambda x, r: _pad(x, 4, r), 3),
}


def _rows(scene, sname: str, hname: str, host: np.ndarray, judge, refine: int) -> list[dict]:
    from snapshot3d.train.codec.embedding import snapshot_for

    want = pixelmeta.unpack(pixelmeta.pack(scene_meta(scene, formats.FILE_CODEC, 1.0)))
    snap = snapshot_for("file", host, scene, 1.0, refine)
    host8 = (host * 255 + 0.5).astype(np.uint8)
    file, host_file = file_pixels(snap, formats.FILE_SCALE), file_pixels(host8, formats.FILE_SCALE)
    base = {"scene": sname, "host": hname, "host_psnr": psnr(snap / 255, host8 / 255),
            "host_ssim": ssim(snap / 255, host8 / 255)}
    rows = []
    for name, (copy, seeds) in SHARING.items():
        for seed in range(seeds):
            shared = copy(file, np.random.default_rng(seed))
            t = time.perf_counter()
            got = snapshot_in_image("copy", shared, None)
            ms = (time.perf_counter() - t) * 1000
            row = dict(base, distortion=name, seed=seed, meta_read=int(got is not None),
                       meta_wrong=int(got is not None and got[1] != want), meta_ms=ms,
                       false_read=int(pixelmeta.find_meta(copy(host_file, np.random.default_rng(seed))) is not None))
            if got is not None:
                row["restore_psnr"] = judge.planes_psnr(restore_planes(got[0], got[1])[0])
            rows.append(row)
    return rows


def bench_sharing(scenes: list[str], hosts: dict, refine: int, size: int, out: Path) -> dict:
    """Rows and summary over `scenes` (.s3d paths) in `hosts` ({name: (380, 380, 3) float RGB}); writes
    out/codec_sharing.{csv,json,png} and returns the JSON document. Resumable per scene and host."""
    t0, rows = time.time(), []
    blocks = RowBlocks(Path(out) / "codec_sharing.partial.jsonl", {"scenes": scenes, "hosts": list(hosts),
                                                                  "refine": refine, "size": size})
    for path in scenes:
        scene, sname = load_scene_file(path), Path(path).stem
        judge = ViewJudge(scene, size)
        for hname, host in hosts.items():
            rows += blocks.rows(f"{sname}/{hname}", lambda: _rows(scene, sname, hname, host, judge, refine))
            print(f"{sname} / {hname}: {len(rows)} rows ({time.time() - t0:.0f} s)", flush=True)
    summary = {name: {"meta_read": float(np.mean([r["meta_read"] for r in rows if r["distortion"] == name])),
                      "meta_wrong": int(sum(r["meta_wrong"] for r in rows if r["distortion"] == name)),
                      "false_read": int(sum(r["false_read"] for r in rows if r["distortion"] == name)),
                      **{k: median([r for r in rows if r["distortion"] == name], k)
                         for k in ("restore_psnr", "meta_ms", "host_psnr", "host_ssim")},
                      "n": sum(r["distortion"] == name for r in rows)} for name in SHARING}
    doc = write_report(out, "codec_sharing", rows, {
        "scenes": [Path(p).stem for p in scenes], "hosts": list(hosts), "refine": refine, "view_size": size,
        "targets": TARGETS, "seconds": round(time.time() - t0, 1), "summary": summary})
    _chart(summary, out / "codec_sharing.png")
    side_by_side(load_scene_file(scenes[0]), next(iter(hosts.values())), refine, size, out / "codec_sharing_side_by_side.png")
    blocks.finish()
    return doc


def side_by_side(scene, host: np.ndarray, refine: int, size: int, path: Path) -> None:
    """Rows: the snapshot (or its copy) and 4 orbit views: original planes, then restored from a PNG, a
    JPEG-75 copy and a 256-px JPEG-90 copy of the file, each read with no text (metadata from the pixels)."""
    from snapshot3d.images import write_png
    from snapshot3d.train.codec.embedding import snapshot_for

    judge, pick = ViewJudge(scene, size), [0, 5, 10, 15]
    snap = snapshot_for("file", host, scene, 1.0, refine)
    rows = [(snap, judge.ref[pick])]
    for name in ("png", "jpeg75", "256 px"):
        copy = SHARING[name][0](file_pixels(snap, formats.FILE_SCALE), np.random.default_rng(0))
        rgb, meta, _ = snapshot_in_image("copy", copy, None)
        rows.append((copy, judge.views(restore_planes(rgb, meta)[0])[pick]))
    fig = np.concatenate([np.concatenate([cv2.resize(img, (size, size), interpolation=cv2.INTER_AREA) / 255.0, *views],
                                         axis=1) for img, views in rows], axis=0)
    write_png(path, fig)


def _chart(summary: dict, path: Path) -> None:
    plt = pyplot()
    names = list(summary)
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    x = np.arange(len(names))
    a.bar(x, [summary[n]["restore_psnr"] or 0 for n in names], color="tab:blue")
    a.set_ylabel("restore_psnr (dB), median")
    b.bar(x, [100 * summary[n]["meta_read"] for n in names], color="tab:green", label="metadata read")
    b.bar(x, [100 * summary[n]["meta_wrong"] / max(1, summary[n]["n"]) for n in names], color="tab:red",
          label="read wrong")
    b.set_ylabel("% of copies")
    b.legend(loc="lower left")
    for ax, title in ((a, "views after restore"), (b, "metadata from the pixels alone")):
        ax.set_xticks(x, names, rotation=35, ha="right", fontsize=8)
        ax.set_title(f"file medium, shared copies: {title}")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
