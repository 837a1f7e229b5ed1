"""`snapshot3d embed`, `snapshot3d restore` and `snapshot3d train codec`: files, checks and reports."""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from snapshot3d import codec_layout, formats
from snapshot3d.errors import UserError
from snapshot3d.images import fit_square
from snapshot3d.metrics import psnr, ssim
from snapshot3d.options import config_from_args
from snapshot3d.progress import progress
from snapshot3d.reports import write_json
from snapshot3d.scene import Scene, load_scene_file, quantize_planes, save_scene

__all__ = ["embed_command", "restore_command", "train_codec_command", "load_host", "scene_meta",
           "scene_from_secret"]


def load_host(spec: str) -> np.ndarray:
    """`builtin:NAME` (a bundled photo) or an image file -> (380, 380, 3) float32 RGB in [0, 1],
    the centred square crop resized."""
    from snapshot3d.scanner.backgrounds import background_names, load_background
    from snapshot3d.scanner.imageio_safe import read_image_bgr

    if spec.startswith("builtin:"):
        name = spec.split(":", 1)[1]
        if name not in background_names():
            raise UserError(f"unknown bundled host {name!r}; choose from {', '.join(background_names())}")
        rgb = load_background(name)
    else:
        rgb = cv2.cvtColor(read_image_bgr(spec), cv2.COLOR_BGR2RGB)
    return fit_square(rgb, formats.SNAPSHOT_SIZE).astype(np.float32) / 255.0


def scene_meta(scene: Scene, strength: float):
    from snapshot3d.scanner.qr import SheetMeta

    o = scene.orbit
    return SheetMeta(box=tuple(float(v) for v in scene.box.ravel()),
                     orbit=(float(o.radius), float(o.elevation_deg), float(o.fov_deg)),
                     target=tuple(float(v) for v in o.target), planes=(scene.resolution, scene.channels),
                     strength=float(strength))


def scene_from_secret(secret: np.ndarray, meta, name: str = "restored") -> Scene:
    """The restored scene: planes unspread from the secret and quantised to 8-bit codes."""
    from snapshot3d.viewer.decode import scene_from_meta

    scene = scene_from_meta(quantize_planes(codec_layout.secret_to_planes(secret, *meta.planes)), meta)
    scene.name = name
    return scene


def embed_command(args) -> int:
    from snapshot3d.scanner.snapfile import write_snapshot

    from .hinet import load_codec
    from .refine import snapshot_of

    if not 0.05 <= args.strength <= 10:
        raise UserError("--strength must be in [0.05, 10]")
    if not 0 <= args.refine <= 5000:
        raise UserError("--refine must be in [0, 5000] steps")
    if Path(args.output).suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise UserError(f"cannot write {Path(args.output).name}: a snapshot is written as .png (or .jpg)")
    scene = load_scene_file(args.scene)
    try:
        codec_layout.check_plane_shape(scene.channels, scene.resolution)
    except ValueError as e:
        raise UserError(str(e)) from None
    host = load_host(args.host)
    net, _ = load_codec()
    t0 = time.perf_counter()
    snap = snapshot_of(net, host, scene.planes(), args.refine, args.strength, show_progress=True)
    secs = time.perf_counter() - t0
    write_snapshot(args.output, snap, scene_meta(scene, args.strength), jpeg_quality=args.jpeg_quality)
    host8 = (host * 255 + 0.5).astype(np.uint8)
    report = {"host_psnr": psnr(snap / 255.0, host8 / 255.0), "host_ssim": ssim(snap / 255.0, host8 / 255.0),
              "scene_kb": scene.scene_kb, "strength": args.strength, "codec": formats.CODEC_VERSION,
              "refine_steps": args.refine, "embed_ms": secs * 1000}
    write_json(args.report, report)
    print(f"wrote {args.output}: host_psnr {report['host_psnr']:.2f} dB, host_ssim {report['host_ssim']:.4f}, "
          f"{scene.scene_kb:.1f} kB of planes hidden")
    return 0


def restore_command(args) -> int:
    from snapshot3d.scanner.qr import check_codec
    from snapshot3d.scanner.snapfile import read_snapshot

    from .hinet import load_codec, restore_secret

    if Path(args.output).suffix.lower() != ".s3d":
        raise UserError(f"cannot write {Path(args.output).name}: a scene is written as .s3d")
    with progress(3, "restore", unit="stage") as bar:
        rgb, meta = read_snapshot(args.snapshot, args.meta)
        check_codec(meta)
        net, _ = load_codec()
        bar.update(1)
        t0 = time.perf_counter()
        secret = restore_secret(net, rgb, meta.strength or 1.0)
        secs = time.perf_counter() - t0
        bar.update(1)
        scene = scene_from_secret(secret, meta, name=Path(args.snapshot).stem)
        save_scene(scene, args.output)
        bar.update(1)
    report = {"restore_ms": secs * 1000, "planes": list(meta.planes), "codec": meta.codec}
    write_json(args.report, report)
    print(f"wrote {args.output}: {meta.planes[0]}x{meta.planes[0]} planes, {meta.planes[1]} channels; "
          f"restore {secs * 1000:.0f} ms")
    return 0


def train_codec_command(args) -> int:
    from .config import CodecConfig
    from .data import load_codec_data
    from .hinet import codec_path
    from .training import train_codec

    cfg = config_from_args(CodecConfig, args)
    out = Path(args.output) if args.output else codec_path()
    scene_dir = Path(args.scenes_dir)
    try:
        data = load_codec_data(scene_dir, set(cfg.holdout_scenes.split(",")), set(cfg.holdout_hosts.split(",")))
    except ValueError as e:
        raise UserError(f"{e}; fit training scenes there first (see the README's codec section)") from None
    ckpt = out.with_name(out.name + ".ckpt")
    t0 = time.time()
    from ..device import resolve_device

    summary = train_codec(cfg, data, out, checkpoint=ckpt, log=lambda m: print(m, flush=True),
                          device=resolve_device(args.device))
    summary.update(seconds=round(time.time() - t0, 1), command="snapshot3d " + " ".join(sys.argv[1:]))
    out.with_suffix(".json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB)")
    return 0
