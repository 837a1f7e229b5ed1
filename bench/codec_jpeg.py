"""`snapshot3d bench codec-jpeg`: why a snapshot file does not survive JPEG. Spot hidden in the
held-out hosts by a codec, then one digital distortion of the 380x380 snapshot itself at a time:
JPEG files at several qualities with 4:2:0 and 4:4:4 chroma, chroma subsampling alone, Gaussian noise
of about JPEG-95's size, blur, and sub-pixel shifts (the misregistration a scan leaves: about 0.4 px on
`moderate` photos, `bench/results/channel.json`). With `--refine N`, the same for snapshots refined at
embed time (`train.codec_refine`). `restore_psnr` of 20 orbit views at 128x128 (the fast renderer's views
of the restored planes against those of the original planes). Writes codec_jpeg.{csv,json,png}; and first
(`--part sharing|all`) what sharing does to the whole file path, metadata included (`bench.sharing`,
codec_sharing.{csv,json,png})."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import formats
from snapshot3d.cameras import orbit_cameras
from snapshot3d.codecs import file_layout
from snapshot3d.metrics import psnr
from snapshot3d.paths import asset
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scene import dequantize_planes, load_scene_file, quantize_planes
from snapshot3d.train.codec.hinet import load_codec, restore_secret
from snapshot3d.train.codec.refine import snapshot_of
from snapshot3d.viewer.render import render_views
from snapshot3d.viewer.runtime import scene_models

from .common import jpeg_copy, pyplot, write_report

__all__ = ["bench_codec_jpeg_command", "DISTORTIONS"]

SIZE = 128


def _chroma_420(img: np.ndarray) -> np.ndarray:
    ycc = cv2.cvtColor(img, cv2.COLOR_RGB2YCrCb).astype(np.float32)
    h, w = img.shape[:2]
    for c in (1, 2):
        ycc[..., c] = cv2.resize(cv2.resize(ycc[..., c], (w // 2, h // 2), interpolation=cv2.INTER_AREA), (w, h),
                                 interpolation=cv2.INTER_LINEAR)
    return cv2.cvtColor(np.clip(ycc + 0.5, 0, 255).astype(np.uint8), cv2.COLOR_YCrCb2RGB)


def _noise(img: np.ndarray, sigma: float) -> np.ndarray:
    rng = np.random.default_rng(0)
    return np.clip(img + rng.normal(0, sigma, img.shape), 0, 255).astype(np.uint8)


def _shift(img: np.ndarray, px: float) -> np.ndarray:
    """Translate by `px` pixels along x and y, bilinear, borders reflected."""
    m = np.float32([[1, 0, px], [0, 1, px]])
    return cv2.warpAffine(img, m, img.shape[1::-1], flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


# name -> snapshot (380, 380, 3) uint8 RGB -> what the restore network sees
DISTORTIONS = {
    "none": lambda x: x,
    "jpeg95 4:2:0": lambda x: jpeg_copy(x, 95, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420),
    "jpeg95 4:4:4": lambda x: jpeg_copy(x, 95, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444),
    "jpeg90 4:2:0": lambda x: jpeg_copy(x, 90, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420),
    "jpeg75 4:2:0": lambda x: jpeg_copy(x, 75, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420),
    "jpeg75 4:4:4": lambda x: jpeg_copy(x, 75, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444),
    "chroma 4:2:0 only": _chroma_420,
    "noise sigma 4/255": lambda x: _noise(x, 4.0),
    "blur sigma 1 px": lambda x: cv2.GaussianBlur(x, (0, 0), 1.0),
    "shift 0.25 px": lambda x: _shift(x, 0.25),
    "shift 0.5 px": lambda x: _shift(x, 0.5),
    "shift 1 px": lambda x: _shift(x, 1.0),
}


def bench_codec_jpeg_command(args) -> int:
    if args.part in ("sharing", "all"):
        from .codec_print import heldout_hosts
        from .sharing import bench_sharing

        hosts = {h: load_host("builtin:" + h) for h in args.hosts.split(",") if h}
        hosts.update({Path(p).stem: load_host(p) for p in heldout_hosts(args.heldout)})
        scenes = [str(asset("spot.s3d")), *[p for p in args.scenes.split(",") if p and Path(p).is_file()]]
        doc = bench_sharing(scenes, hosts, args.refine, SIZE, Path(args.out))
        print(json.dumps(doc["summary"], indent=1))
    if args.part == "sharing":
        return 0
    scene = load_scene_file(asset("spot.s3d"))
    c2w, intr = orbit_cameras(scene.orbit, formats.ORBIT_VIEWS, SIZE)
    models = scene_models(scene)
    ref = render_views(models, scene.planes(), scene.box, c2w, intr, SIZE, SIZE)
    rows = []
    runs = [("shipped", None, 0), *([(f"shipped, refined {args.refine}", None, args.refine)] if args.refine else []),
            *([(f"compare: {Path(args.compare).stem}", args.compare, 0)] if args.compare else [])]
    for label, path, refine in runs:
        net, _ = load_codec(Path(path) if path else None)
        for host in ("coffee", "chelsea"):
            snap = snapshot_of(net, load_host("builtin:" + host), scene.planes(), refine)
            for name, fn in DISTORTIONS.items():
                seen = fn(snap)
                planes = file_layout.secret_to_planes(restore_secret(net, seen), scene.resolution, scene.channels)
                views = render_views(models, dequantize_planes(quantize_planes(planes)), scene.box, c2w, intr, SIZE, SIZE)
                rows.append({"codec": label, "host": host, "distortion": name,
                             "image_psnr": min(psnr(seen / 255.0, snap / 255.0), 100.0),  # 100: identical
                             "restore_psnr": psnr(views, ref)})
                print(f"{label} {host} {name}: restore_psnr {rows[-1]['restore_psnr']:.2f}", flush=True)
    summary = {label: {name: {k: float(np.median([r[k] for r in rows if r["codec"] == label and r["distortion"] == name]))
                              for k in ("image_psnr", "restore_psnr")} for name in DISTORTIONS}
               for label in dict.fromkeys(r["codec"] for r in rows)}
    out = Path(args.out)
    write_report(out, "codec_jpeg", rows, {"scene": "spot", "hosts": ["coffee", "chelsea"], "view_size": SIZE,
                                           "summary": summary})
    _chart(summary, out / "codec_jpeg.png")
    print(json.dumps(summary, indent=1))
    return 0


def _chart(summary: dict, path: Path) -> None:
    plt = pyplot()

    names = list(DISTORTIONS)
    fig, ax = plt.subplots(figsize=(10, 4.5))
    width = 0.8 / len(summary)
    for i, (label, per) in enumerate(summary.items()):
        ax.bar(np.arange(len(names)) + i * width, [per[n]["restore_psnr"] for n in names], width, label=label)
    ax.set_xticks(np.arange(len(names)) + 0.4 - width / 2, names, rotation=25, ha="right", fontsize=8)
    ax.set_ylabel("restore_psnr (dB), spot, 128x128 views")
    ax.set_title("one digital distortion of the snapshot file at a time")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
