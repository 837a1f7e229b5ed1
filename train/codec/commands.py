"""`snapshot3d embed`, `snapshot3d train codec` and `snapshot3d train print-codec`: files, checks and
reports. (`restore` is torch-free and lives in `viewer.commands`.)"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from snapshot3d.codecs.media import MEDIA
from snapshot3d.errors import UserError
from snapshot3d.metrics import psnr, ssim
from snapshot3d.options import config_from_args
from snapshot3d.reports import write_json
from snapshot3d.scanner.backgrounds import load_host
from snapshot3d.scanner.qr import scene_meta
from snapshot3d.scene import load_scene_file
from snapshot3d.train.field.curves import payload_hint  # embed's one-line hint (also fit's)

from .embedding import STRENGTHS, check_planes_for, snapshot_for, strength_for

__all__ = ["embed_command", "train_codec_command", "train_print_codec_command", "payload_hint", "HOST_PSNRS"]

HOST_PSNRS = (20.0, 60.0)
"""the host fidelities, in dB, `embed --host-psnr` takes"""


def embed_command(args) -> int:
    from snapshot3d.scanner.snapfile import write_snapshot

    if args.medium not in MEDIA:
        raise UserError(f"--medium must be one of {', '.join(MEDIA)}, not {args.medium!r}")
    if args.strength is not None and args.host_psnr is not None:
        raise UserError("give --strength or --host-psnr, not both")
    if args.strength is not None and not STRENGTHS[0] <= args.strength <= STRENGTHS[1]:
        raise UserError("--strength must be in [{:g}, {:g}]".format(*STRENGTHS))
    if args.host_psnr is not None and not HOST_PSNRS[0] <= args.host_psnr <= HOST_PSNRS[1]:
        raise UserError("--host-psnr must be in [{:g}, {:g}] dB".format(*HOST_PSNRS))
    if not 0 <= args.refine <= 5000:
        raise UserError("--refine must be in [0, 5000] steps")
    if not 1 <= args.jpeg_quality <= 100:
        raise UserError("--jpeg-quality must be in [1, 100]")
    if Path(args.output).suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise UserError(f"cannot write {Path(args.output).name}: a snapshot is written as .png (or .jpg)")
    scene = load_scene_file(args.scene)
    check_planes_for(args.medium, scene)
    host = load_host(args.host)
    t0 = time.perf_counter()
    strength = (strength_for(args.medium, host, scene, args.host_psnr) if args.host_psnr is not None
                else 1.0 if args.strength is None else args.strength)
    snap = snapshot_for(args.medium, host, scene, strength, args.refine, show_progress=True)
    secs = time.perf_counter() - t0
    codec = MEDIA[args.medium].codec
    write_snapshot(args.output, snap, scene_meta(scene, codec, strength), jpeg_quality=args.jpeg_quality,
                   scale=MEDIA[args.medium].file_scale)
    host8 = (host * 255 + 0.5).astype(np.uint8)
    report = {"host_psnr": psnr(snap / 255.0, host8 / 255.0), "host_ssim": ssim(snap / 255.0, host8 / 255.0),
              "scene_kb": scene.scene_kb, "strength": strength, "medium": args.medium, "codec": codec,
              "refine_steps": args.refine if args.medium == "file" else 0, "embed_ms": secs * 1000}
    write_json(args.report, report)
    print(f"wrote {args.output}: {args.medium} medium (codec {codec}), host_psnr {report['host_psnr']:.2f} dB, "
          f"host_ssim {report['host_ssim']:.4f}, strength {strength:g}, {scene.scene_kb:.1f} kB of planes hidden, "
          f"{secs:.1f} s")
    if (hint := payload_hint(args.medium, scene)) is not None:
        print(hint)
    return 0


def _finish_training(out: Path, summary: dict, t0: float) -> None:
    summary.update(seconds=round(time.time() - t0, 1), command="snapshot3d " + " ".join(sys.argv[1:]))
    out.with_suffix(".json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB) and {out.with_suffix('.json').name}")


def train_codec_command(args) -> int:
    from ..device import resolve_device
    from .config import CodecConfig
    from .data import load_codec_data
    from .hinet import codec_path
    from .training import train_codec

    cfg = config_from_args(CodecConfig, args)
    out = Path(args.output) if args.output else codec_path()
    try:
        data = load_codec_data(Path(args.scenes_dir), set(cfg.holdout_scenes.split(",")),
                               set(cfg.holdout_hosts.split(",")))
    except ValueError as e:
        raise UserError(f"{e}; fit training scenes there first (see docs/training.md, 'Training scenes')") from None
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    summary = train_codec(cfg, data, out, checkpoint=out.with_name(out.name + ".ckpt"),
                          log=lambda m: print(m, flush=True), device=resolve_device(args.device))
    _finish_training(out, summary, t0)
    return 0


def train_print_codec_command(args) -> int:
    from ..device import resolve_device
    from .print_data import CaptureConfig, load_captures, make_captures
    from .print_train import PrintCodecConfig, front_end_path, train_print_codec

    cfg = config_from_args(PrintCodecConfig, args)
    if cfg.captures < 40 or cfg.steps < 1 or cfg.batch < 1:
        raise UserError("--captures must be >= 40, --steps and --batch >= 1")
    out = Path(args.output) if args.output else front_end_path()
    out.parent.mkdir(parents=True, exist_ok=True)
    log = lambda m: print(m, flush=True)  # noqa: E731
    t0 = time.time()
    files = make_captures(Path(args.data), CaptureConfig(count=cfg.captures, seed=cfg.seed), args.workers, log)
    caps, pays, infos = load_captures(files)
    summary = train_print_codec(cfg, caps, pays, out, checkpoint=out.with_name(out.name + ".ckpt"), log=log,
                                device=resolve_device(args.device))
    summary["captures"] = {"count": len(infos), "severities": {s: sum(i["severity"] == s for i in infos)
                                                              for s in sorted({i["severity"] for i in infos})},
                           "hosts": len({i["host"] for i in infos}), "data": str(args.data)}
    _finish_training(out, summary, t0)
    return 0
